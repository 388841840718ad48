//! Line integrity, both directions: a line is sealed as `<body>*XXXX`, where `XXXX` is the
//! CRC-16 of the body in four upper-case hex digits.
//!
//! CRC-16/CCITT-FALSE (polynomial 0x1021, as in XMODEM and Bluetooth; Klipper and MAVLink use a
//! CRC-16 too) detects every error burst up to 16 bits, so a flipped bit, a swapped pair of
//! bytes or a changed digit never passes; a dropped or inserted byte passes with probability
//! 2⁻¹⁶. The field has a fixed width, so a digit lost from the CRC itself is caught too.
//! Protocol 1 sealed lines with a decimal XOR (`*<0–255>`), which passed about 30 % of such
//! damage; its lines are recognised here only to refuse them with a clear message.

use crate::text::Text;
use core::fmt::Write;

/// Hex digits of the CRC field.
pub const CRC_DIGITS: usize = 4;

/// CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xffff;
    for &b in bytes {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
        }
    }
    crc
}

/// Appends `*XXXX` (the CRC of everything written so far); fails only when the buffer is full.
pub fn seal<const N: usize>(t: &mut Text<N>) -> core::fmt::Result {
    let crc = crc16(t.as_str().as_bytes());
    write!(t, "*{crc:04X}")
}

/// What a line's integrity field says about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Check<'a> {
    /// `body*XXXX` with the body's CRC: the body, trimmed.
    Sealed(&'a str),
    /// No `*` at all: the whole line, unchecked.
    Bare(&'a str),
    /// `*` and 1–3 decimal digits: a protocol-1 XOR checksum.
    Legacy,
    /// A CRC field that does not match its body, or is not four hex digits.
    Damaged,
}

/// Splits a trimmed line into its body and checks the seal.
pub fn check(line: &str) -> Check<'_> {
    let Some((body, field)) = line.rsplit_once('*') else {
        return Check::Bare(line.trim());
    };
    let digits = field.as_bytes();
    if digits.len() == CRC_DIGITS && digits.iter().all(|b| b.is_ascii_digit() || (b'A'..=b'F').contains(b)) {
        // Four hex digits always fit a u16.
        let want = u16::from_str_radix(field, 16).unwrap_or(0);
        return if crc16(body.as_bytes()) == want { Check::Sealed(body.trim()) } else { Check::Damaged };
    }
    if (1..=3).contains(&digits.len()) && digits.iter().all(u8::is_ascii_digit) {
        return Check::Legacy;
    }
    Check::Damaged
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::format;
    use std::string::ToString;

    #[test]
    fn crc16_matches_the_standard_check_value() {
        // The catalogue's check value for CRC-16/CCITT-FALSE over "123456789".
        assert_eq!(crc16(b"123456789"), 0x29B1);
        assert_eq!(crc16(b""), 0xffff);
    }

    #[test]
    fn sealed_lines_open_and_damage_is_told_apart() {
        let mut t: Text<32> = Text::default();
        write!(t, "N7 MOVE 90.000").unwrap();
        seal(&mut t).unwrap();
        let line = t.as_str();
        assert_eq!(line.len(), "N7 MOVE 90.000".len() + 1 + CRC_DIGITS);
        assert_eq!(check(line), Check::Sealed("N7 MOVE 90.000"));
        assert_eq!(check("N7 MOVE 90.000"), Check::Bare("N7 MOVE 90.000"));
        assert_eq!(check("N7 MOVE 90.000*5"), Check::Legacy);
        assert_eq!(check("N7 MOVE 90.000*255"), Check::Legacy);
        // Lower-case, short, long or non-hex fields are damage, not another format.
        let crc = &line[line.len() - 4..];
        for bad in [crc.to_ascii_lowercase(), crc[..3].to_string() + "G", crc.to_string() + "0", "".into()] {
            if bad == crc {
                continue;
            }
            let l = format!("N7 MOVE 90.000*{bad}");
            assert_eq!(check(&l), Check::Damaged, "{l}");
        }
        assert_eq!(check(&line.replace("90", "80")), Check::Damaged);
    }
}
