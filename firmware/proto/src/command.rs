//! Commands (host → device): parsing on the device, encoding on the host, one definition.

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

/// A command with its optional sequence number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame {
    /// `N<seq>` prefix, echoed in the reply.
    pub seq: Option<u32>,
    /// The command.
    pub cmd: Command,
}

/// Why a line could not be parsed; carries the sequence number when it was readable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// `*<xor>` did not match the line.
    Checksum {
        /// Sequence number, if present.
        seq: Option<u32>,
    },
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
            ParseError::Checksum { seq } | ParseError::Unknown { seq } | ParseError::BadArgument { seq } => seq,
        }
    }
}

/// XOR of all bytes (the Marlin-style line checksum).
pub fn checksum(s: &str) -> u8 {
    s.bytes().fold(0, |a, b| a ^ b)
}

fn parse_u32(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 9 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

impl Frame {
    /// Parses one trimmed line.
    pub fn parse(line: &str) -> Result<Frame, ParseError> {
        let (body, sum) = match line.rsplit_once('*') {
            Some((b, s)) => (b, Some(s.trim())),
            None => (line, None),
        };
        let mut words = body.split_ascii_whitespace().peekable();
        let seq = match words.peek() {
            Some(w)
                if w.len() > 1
                    && (w.starts_with('N') || w.starts_with('n'))
                    && w[1..].bytes().all(|b| b.is_ascii_digit()) =>
            {
                let s = parse_u32(&w[1..]);
                words.next();
                s
            }
            _ => None,
        };
        if let Some(sum) = sum {
            let ok = sum.parse::<u8>().map(|v| v == checksum(body)).unwrap_or(false);
            if !ok {
                return Err(ParseError::Checksum { seq });
            }
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
        Ok(Frame { seq, cmd })
    }

    /// Encodes the frame as one line (no terminator), with `*<xor>` when `with_checksum`.
    pub fn encode(&self, with_checksum: bool) -> Text<MAX_LINE> {
        let mut t: Text<MAX_LINE> = Text::default();
        // Every command fits well inside MAX_LINE, so the writes cannot fail.
        if let Some(s) = self.seq {
            let _ = write!(t, "N{s} ");
        }
        let _ = write!(t, "{}", self.cmd);
        if with_checksum {
            let sum = checksum(t.as_str());
            let _ = write!(t, "*{sum}");
        }
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

    #[test]
    fn parses_plain_sequenced_and_checksummed_lines() {
        assert_eq!(Frame::parse("move 90"), Ok(Frame { seq: None, cmd: Command::MoveTo(Milli(90_000)) }));
        assert_eq!(
            Frame::parse("N7 SPIN 28 2"),
            Ok(Frame { seq: Some(7), cmd: Command::Spin { period_s: Milli(28_000), turns: 2 } })
        );
        let f = Frame { seq: Some(12), cmd: Command::MoveBy(Milli(-45_500)) };
        let line = f.encode(true);
        assert_eq!(Frame::parse(line.as_str()), Ok(f));
        assert!(line.as_str().starts_with("N12 MOVEBY -45.500*"));
    }

    #[test]
    fn errors_keep_the_sequence_number() {
        assert_eq!(Frame::parse("N3 MOVE 90*1"), Err(ParseError::Checksum { seq: Some(3) }));
        assert_eq!(Frame::parse("N4 FLY"), Err(ParseError::Unknown { seq: Some(4) }));
        assert_eq!(Frame::parse("N5 MOVE"), Err(ParseError::BadArgument { seq: Some(5) }));
        assert_eq!(Frame::parse("MOVE 1 2"), Err(ParseError::BadArgument { seq: None }));
        assert_eq!(Frame::parse("SPIN 0"), Err(ParseError::BadArgument { seq: None }));
        assert_eq!(Frame::parse("SPEED -3"), Err(ParseError::BadArgument { seq: None }));
        assert_eq!(Frame::parse(""), Err(ParseError::Unknown { seq: None }));
        assert_eq!(Frame::parse("SUPERCALIFRAGILISTIC"), Err(ParseError::Unknown { seq: None }));
    }
}
