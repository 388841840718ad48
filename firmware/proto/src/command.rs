//! Commands (host → device): parsing on the device, encoding on the host, one definition.

use crate::frame::{self, Check};
use crate::text::{Milli, Text};
use crate::MAX_LINE;
use core::fmt::{self, Write};

/// A turntable command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// `PING`: liveness check, answered `ok`.
    Ping,
    /// `INFO`: print the banner again.
    Info,
    /// `STATUS`: one `<State ...>` line, then `ok`.
    Status,
    /// `HOME`: turn to the nearest whole turn (angle 0) and restart the turn count there.
    Home,
    /// `MOVE <deg>`: absolute move to an angle in degrees (3 decimals), shortest way is not implied.
    MoveTo(Milli),
    /// `MOVEBY <deg>`: relative move in degrees.
    MoveBy(Milli),
    /// `SPIN <seconds-per-turn> [turns]`: continuous rotation; negative period turns backwards,
    /// 0 turns = until `STOP`.
    Spin {
        /// Seconds per revolution (sign = direction).
        period_s: Milli,
        /// Whole revolutions to make; 0 = endless.
        turns: u32,
    },
    /// `SPEED <deg/s>`: maximum speed for moves.
    Speed(Milli),
    /// `ACCEL <deg/s²>`: acceleration for moves and stops.
    Accel(Milli),
    /// `REPORT <ms>`: interval of `@t pos` angle reports while moving (0 = off).
    Report(u32),
    /// `STOP`: decelerate to a halt.
    Stop,
    /// `UNLOCK`: clear an alarm.
    Unlock,
}

impl Command {
    /// A motion: it runs until its `done`, an alarm refuses it, another motion in progress makes
    /// it `Busy`, and a host never retries it (a lost `ok` would start it twice). Every command
    /// is listed, so a new one must say which it is.
    pub const fn is_motion(&self) -> bool {
        match self {
            Command::Home | Command::MoveTo(_) | Command::MoveBy(_) | Command::Spin { .. } => true,
            Command::Ping
            | Command::Info
            | Command::Status
            | Command::Speed(_)
            | Command::Accel(_)
            | Command::Report(_)
            | Command::Stop
            | Command::Unlock => false,
        }
    }
}

/// A command with its optional sequence number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// `N<seq>` prefix, echoed in the reply; below [`SEQ_MODULUS`].
    pub seq: Option<u32>,
    /// The command.
    pub cmd: Command,
}

/// Sequence numbers have at most 9 digits; hosts count modulo this and wrap to 0.
pub const SEQ_MODULUS: u32 = 1_000_000_000;

/// A command line that parsed, and whether it carried a valid CRC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Received {
    /// The command.
    pub frame: Frame,
    /// The line was sealed with a matching CRC (see [`crate::frame`]).
    pub sealed: bool,
}

/// Why a line could not be parsed; carries the sequence number only from a sealed line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// The CRC field does not match the line: nothing in it can be trusted, not its sequence number either.
    Checksum,
    /// A protocol-1 XOR checksum: the host speaks an older protocol.
    Legacy,
    /// A sequence number without a CRC: a sealed line that lost its `*`, or a host that does not seal.
    Unsealed,
    /// `N` followed by more than 9 digits.
    Sequence,
    /// Unknown keyword.
    Unknown {
        /// Sequence number, if present.
        seq: Option<u32>,
    },
    /// Known keyword, wrong or missing arguments.
    BadArgument {
        /// Sequence number, if present.
        seq: Option<u32>,
    },
}

impl ParseError {
    /// The sequence number the reply should echo.
    pub fn seq(&self) -> Option<u32> {
        match *self {
            ParseError::Unknown { seq } | ParseError::BadArgument { seq } => seq,
            ParseError::Checksum | ParseError::Legacy | ParseError::Unsealed | ParseError::Sequence => None,
        }
    }
}

fn parse_u32(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 9 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

impl Frame {
    /// Parses one trimmed line, sealed (`…*XXXX`) or bare.
    pub fn parse(line: &str) -> Result<Received, ParseError> {
        let (body, sealed) = match frame::check(line) {
            Check::Sealed(b) => (b, true),
            Check::Bare(b) => (b, false),
            Check::Legacy => return Err(ParseError::Legacy),
            Check::Damaged => return Err(ParseError::Checksum),
        };
        let mut words = body.split_ascii_whitespace().peekable();
        let seq = match words.peek() {
            Some(w)
                if w.len() > 1
                    && (w.starts_with('N') || w.starts_with('n'))
                    && w[1..].bytes().all(|b| b.is_ascii_digit()) =>
            {
                let s = parse_u32(&w[1..]).ok_or(ParseError::Sequence)?;
                words.next();
                Some(s)
            }
            _ => None,
        };
        if seq.is_some() && !sealed {
            return Err(ParseError::Unsealed);
        }
        let bad = ParseError::BadArgument { seq };
        let kw = words.next().ok_or(ParseError::Unknown { seq })?;
        let mut arg = || words.next();
        // Keywords are case-insensitive; upper-case into a stack buffer (all are ≤ 8 bytes).
        let mut kwbuf = [0u8; 8];
        let Some(dst) = kwbuf.get_mut(..kw.len()) else {
            return Err(ParseError::Unknown { seq });
        };
        dst.copy_from_slice(kw.as_bytes());
        dst.make_ascii_uppercase();
        let kwu = core::str::from_utf8(dst).unwrap_or("");
        let milli = |a: Option<&str>| a.and_then(Milli::parse).ok_or(bad);
        let cmd = match kwu {
            "PING" => Command::Ping,
            "INFO" => Command::Info,
            "STATUS" => Command::Status,
            "HOME" => Command::Home,
            "STOP" => Command::Stop,
            "UNLOCK" => Command::Unlock,
            "MOVE" => Command::MoveTo(milli(arg())?),
            "MOVEBY" => Command::MoveBy(milli(arg())?),
            "SPEED" => Command::Speed(milli(arg()).and_then(|m| if m.0 > 0 { Ok(m) } else { Err(bad) })?),
            "ACCEL" => Command::Accel(milli(arg()).and_then(|m| if m.0 > 0 { Ok(m) } else { Err(bad) })?),
            "REPORT" => Command::Report(arg().and_then(parse_u32).ok_or(bad)?),
            "SPIN" => {
                let period_s = milli(arg())?;
                if period_s.0 == 0 {
                    return Err(bad);
                }
                let turns = match arg() {
                    Some(t) => parse_u32(t).ok_or(bad)?,
                    None => 0,
                };
                Command::Spin { period_s, turns }
            }
            _ => return Err(ParseError::Unknown { seq }),
        };
        if words.next().is_some() {
            return Err(bad);
        }
        Ok(Received { frame: Frame { seq, cmd }, sealed })
    }

    /// Encodes the frame as one sealed line (no terminator): `N<seq> <command>*XXXX`.
    pub fn encode(&self) -> Text<MAX_LINE> {
        let mut t: Text<MAX_LINE> = Text::default();
        // Every command fits well inside MAX_LINE, so the writes cannot fail.
        if let Some(s) = self.seq {
            let _ = write!(t, "N{s} ");
        }
        let _ = write!(t, "{}", self.cmd);
        let _ = frame::seal(&mut t);
        t
    }
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Command::Ping => f.write_str("PING"),
            Command::Info => f.write_str("INFO"),
            Command::Status => f.write_str("STATUS"),
            Command::Home => f.write_str("HOME"),
            Command::Stop => f.write_str("STOP"),
            Command::Unlock => f.write_str("UNLOCK"),
            Command::MoveTo(d) => write!(f, "MOVE {d}"),
            Command::MoveBy(d) => write!(f, "MOVEBY {d}"),
            Command::Speed(v) => write!(f, "SPEED {v}"),
            Command::Accel(a) => write!(f, "ACCEL {a}"),
            Command::Report(ms) => write!(f, "REPORT {ms}"),
            Command::Spin { period_s, turns } => write!(f, "SPIN {period_s} {turns}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bare(line: &str) -> Result<Frame, ParseError> {
        Frame::parse(line).map(|r| {
            assert!(!r.sealed, "{line}");
            r.frame
        })
    }

    #[test]
    fn parses_bare_and_sealed_lines() {
        assert_eq!(bare("move 90"), Ok(Frame { seq: None, cmd: Command::MoveTo(Milli(90_000)) }));
        let f = Frame { seq: Some(12), cmd: Command::MoveBy(Milli(-45_500)) };
        let line = f.encode();
        assert_eq!(Frame::parse(line.as_str()), Ok(Received { frame: f, sealed: true }));
        assert!(line.as_str().starts_with("N12 MOVEBY -45.500*"));
        let f = Frame { seq: Some(SEQ_MODULUS - 1), cmd: Command::Spin { period_s: Milli(-28_000), turns: 4 } };
        assert_eq!(Frame::parse(f.encode().as_str()).map(|r| r.frame), Ok(f));
    }

    #[test]
    fn errors_keep_only_a_trusted_sequence_number() {
        let sealed = |s: u32, c: &str| {
            let mut t: Text<MAX_LINE> = Text::default();
            write!(t, "N{s} {c}").unwrap();
            frame::seal(&mut t).unwrap();
            t
        };
        assert_eq!(Frame::parse(sealed(4, "FLY").as_str()), Err(ParseError::Unknown { seq: Some(4) }));
        assert_eq!(Frame::parse(sealed(5, "MOVE").as_str()), Err(ParseError::BadArgument { seq: Some(5) }));
        assert_eq!(Frame::parse("N3 MOVE 90*1A2B"), Err(ParseError::Checksum));
        assert_eq!(Frame::parse("N3 MOVE 90*17"), Err(ParseError::Legacy));
        // A sequence number promises a seal: the line lost its `*`, or its sender does not seal.
        assert_eq!(Frame::parse("N5 MOVE 90"), Err(ParseError::Unsealed));
        // Ten digits used to be read as "no sequence number" and run unsequenced.
        assert_eq!(
            Frame::parse(sealed(0, "PING").as_str().replacen("N0", "N1000000000", 1).as_str()),
            Err(ParseError::Checksum)
        );
        let mut t: Text<MAX_LINE> = Text::default();
        write!(t, "N1000000000 PING").unwrap();
        frame::seal(&mut t).unwrap();
        assert_eq!(Frame::parse(t.as_str()), Err(ParseError::Sequence));
        assert_eq!(bare("MOVE 1 2"), Err(ParseError::BadArgument { seq: None }));
        assert_eq!(bare("SPIN 0"), Err(ParseError::BadArgument { seq: None }));
        assert_eq!(bare("SPEED -3"), Err(ParseError::BadArgument { seq: None }));
        assert_eq!(bare(""), Err(ParseError::Unknown { seq: None }));
        assert_eq!(bare("SUPERCALIFRAGILISTIC"), Err(ParseError::Unknown { seq: None }));
    }
}
