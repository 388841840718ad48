//! Small fixed-capacity text buffer and exact decimal helpers (no heap, no floats).

use core::fmt;

/// A string buffer with a fixed capacity; writes past it fail instead of allocating.
#[derive(Clone)]
pub struct Text<const N: usize> {
    buf: [u8; N],
    len: usize,
}

impl<const N: usize> Default for Text<N> {
    fn default() -> Self {
        Text { buf: [0; N], len: 0 }
    }
}

impl<const N: usize> Text<N> {
    /// The text written so far.
    pub fn as_str(&self) -> &str {
        // Only whole `&str`s are ever copied in, so the bytes are valid UTF-8.
        core::str::from_utf8(&self.buf[..self.len]).unwrap_or("")
    }
    /// Empties the buffer.
    pub fn clear(&mut self) {
        self.len = 0;
    }
}

impl<const N: usize> fmt::Write for Text<N> {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        if end > N {
            return Err(fmt::Error);
        }
        self.buf[self.len..end].copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

impl<const N: usize> fmt::Debug for Text<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self.as_str(), f)
    }
}

/// A decimal number with up to 3 fraction digits, held exactly as thousandths.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Milli(pub i64);

impl Milli {
    /// Parses `-12`, `3.5`, `+0.125`; more than 3 fraction digits or overflow is an error.
    pub fn parse(s: &str) -> Option<Milli> {
        let (neg, body) = match s.as_bytes().first()? {
            b'-' => (true, &s[1..]),
            b'+' => (false, &s[1..]),
            _ => (false, s),
        };
        let (int, frac) = match body.split_once('.') {
            Some((i, f)) => (i, f),
            None => (body, ""),
        };
        if (int.is_empty() && frac.is_empty()) || frac.len() > 3 {
            return None;
        }
        let digits = |t: &str| t.bytes().all(|b| b.is_ascii_digit());
        if !digits(int) || !digits(frac) || int.len() > 12 {
            return None;
        }
        let mut v: i64 = 0;
        for b in int.bytes() {
            v = v * 10 + (b - b'0') as i64;
        }
        let mut f: i64 = 0;
        for i in 0..3 {
            f = f * 10 + frac.as_bytes().get(i).map_or(0, |b| (b - b'0') as i64);
        }
        let m = v * 1000 + f;
        Some(Milli(if neg { -m } else { m }))
    }
}

impl fmt::Display for Milli {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sign = if self.0 < 0 { "-" } else { "" };
        let a = self.0.unsigned_abs();
        write!(f, "{sign}{}.{:03}", a / 1000, a % 1000)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::fmt::Write;

    #[test]
    fn milli_parses_exactly() {
        assert_eq!(Milli::parse("90"), Some(Milli(90_000)));
        assert_eq!(Milli::parse("-0.125"), Some(Milli(-125)));
        assert_eq!(Milli::parse("+.5"), Some(Milli(500)));
        assert_eq!(Milli::parse("1.2345"), None);
        assert_eq!(Milli::parse("1e3"), None);
        assert_eq!(Milli::parse("-"), None);
        assert_eq!(Milli::parse("."), None);
        assert_eq!(Milli::parse("9999999999999"), None);
        let mut t: Text<16> = Text::default();
        write!(t, "{}", Milli(-1005)).unwrap();
        assert_eq!(t.as_str(), "-1.005");
    }

    #[test]
    fn text_refuses_overflow() {
        let mut t: Text<4> = Text::default();
        assert!(write!(t, "abcde").is_err());
        assert_eq!(t.as_str(), "");
        assert!(write!(t, "abcd").is_ok());
        assert!(write!(t, "e").is_err());
        assert_eq!(t.as_str(), "abcd");
    }
}
