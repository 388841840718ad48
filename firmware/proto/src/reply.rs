//! Replies and reports (device → host): formatting on the device, parsing on the host.

use crate::frame::{self, Check};
use core::fmt;

/// Error codes in `error:<code>` replies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorCode {
    /// 1: unknown command.
    Unknown = 1,
    /// 2: bad or missing argument.
    BadArgument = 2,
    /// 3: checksum mismatch.
    Checksum = 3,
    /// 4: line longer than the buffer.
    LineTooLong = 4,
    /// 5: motion refused while an alarm is active.
    Locked = 5,
    /// 6: motion refused while another motion runs (send `STOP` or wait for `done`).
    Busy = 6,
    /// 7: non-printable bytes in the line.
    Garbage = 7,
    /// 8: framing: a sequence number without a CRC, an unsealed or unsequenced line once the
    /// session is framed, or a sequence number of more than 9 digits.
    Framing = 8,
}

impl ErrorCode {
    /// From the numeric code.
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            1 => ErrorCode::Unknown,
            2 => ErrorCode::BadArgument,
            3 => ErrorCode::Checksum,
            4 => ErrorCode::LineTooLong,
            5 => ErrorCode::Locked,
            6 => ErrorCode::Busy,
            7 => ErrorCode::Garbage,
            8 => ErrorCode::Framing,
            _ => return None,
        })
    }
}

/// Alarms that lock motion until `UNLOCK`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Alarm {
    /// 1: homing did not find the index.
    HomingFailed = 1,
    /// 2: the motor stalled (lost steps).
    Stall = 2,
    /// 3: emergency stop (`!`).
    EStop = 3,
}

impl Alarm {
    /// From the numeric code.
    pub fn from_code(c: u8) -> Option<Self> {
        Some(match c {
            1 => Alarm::HomingFailed,
            2 => Alarm::Stall,
            3 => Alarm::EStop,
            _ => return None,
        })
    }
    /// Short description.
    pub fn text(self) -> &'static str {
        match self {
            Alarm::HomingFailed => "homing failed",
            Alarm::Stall => "motor stall",
            Alarm::EStop => "emergency stop",
        }
    }
}

/// Machine state in status reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    /// Not moving.
    Idle,
    /// Homing.
    Homing,
    /// A finite move.
    Moving,
    /// Continuous rotation.
    Spinning,
    /// Locked by an alarm.
    Alarm,
}

impl State {
    fn name(self) -> &'static str {
        match self {
            State::Idle => "Idle",
            State::Homing => "Homing",
            State::Moving => "Moving",
            State::Spinning => "Spinning",
            State::Alarm => "Alarm",
        }
    }
    fn from_name(s: &str) -> Option<Self> {
        Some(match s {
            "Idle" => State::Idle,
            "Homing" => State::Homing,
            "Moving" => State::Moving,
            "Spinning" => State::Spinning,
            "Alarm" => State::Alarm,
            _ => return None,
        })
    }
}

/// One line from the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply<'a> {
    /// `ok [N<seq>]`: the line was accepted (moves: accepted and started).
    Ok {
        /// Echoed sequence number.
        seq: Option<u32>,
    },
    /// `error:<code> [N<seq>] <msg>`.
    Error {
        /// Why.
        code: ErrorCode,
        /// Echoed sequence number.
        seq: Option<u32>,
        /// Human-readable detail.
        msg: &'a str,
    },
    /// `done [N<seq>] pos=<usteps>`: a move or a finite spin finished.
    Done {
        /// Sequence number of the command that started it.
        seq: Option<u32>,
        /// Final position in microsteps.
        pos: i64,
    },
    /// `busy [N<seq>]`: keep-alive while a long move runs.
    Busy {
        /// Sequence number of the running command.
        seq: Option<u32>,
    },
    /// `<State pos=<usteps> t=<ms>>`, or `<Alarm:<code> ...>`.
    Status {
        /// State.
        state: State,
        /// Active alarm.
        alarm: Option<Alarm>,
        /// Position in microsteps.
        pos: i64,
        /// Device clock in ms.
        t_ms: u64,
    },
    /// `@<t_ms> <usteps>`: timestamped position sample while moving.
    Angle {
        /// Device clock in ms.
        t_ms: u64,
        /// Position in microsteps.
        pos: i64,
    },
    /// `ALARM:<code> <msg>`: an alarm was raised.
    Alarm(Alarm),
    /// `pav-turntable <fw> usteps=<n> proto=<v>`: printed on reset.
    Banner {
        /// Firmware version.
        fw: &'a str,
        /// Microsteps per revolution.
        usteps_per_rev: u32,
        /// Protocol version.
        proto: u32,
    },
}

struct Seq(Option<u32>);
impl fmt::Display for Seq {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(s) => write!(f, " N{s}"),
            None => Ok(()),
        }
    }
}

impl fmt::Display for Reply<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Reply::Ok { seq } => write!(f, "ok{}", Seq(seq)),
            Reply::Error { code, seq, msg } => write!(f, "error:{}{} {msg}", code as u8, Seq(seq)),
            Reply::Done { seq, pos } => write!(f, "done{} pos={pos}", Seq(seq)),
            Reply::Busy { seq } => write!(f, "busy{}", Seq(seq)),
            Reply::Status { state, alarm, pos, t_ms } => match alarm {
                Some(a) => write!(f, "<Alarm:{} pos={pos} t={t_ms}>", a as u8),
                None => write!(f, "<{} pos={pos} t={t_ms}>", state.name()),
            },
            Reply::Angle { t_ms, pos } => write!(f, "@{t_ms} {pos}"),
            Reply::Alarm(a) => write!(f, "ALARM:{} {}", a as u8, a.text()),
            Reply::Banner { fw, usteps_per_rev, proto } => {
                write!(f, "pav-turntable {fw} usteps={usteps_per_rev} proto={proto}")
            }
        }
    }
}

fn seq_word(w: Option<&str>) -> Option<Option<u32>> {
    match w {
        Some(w) if w.starts_with('N') => w[1..].parse().ok().map(Some),
        _ => Some(None),
    }
}

fn kv<'a>(w: &'a str, key: &str) -> Option<&'a str> {
    w.strip_prefix(key)?.strip_prefix('=')
}

impl<'a> Reply<'a> {
    /// Parses one sealed line from the device (`<reply>*XXXX`); `None` for a line whose CRC is
    /// missing or wrong, or that is not a reply.
    pub fn open(line: &'a str) -> Option<Reply<'a>> {
        match frame::check(line.trim()) {
            Check::Sealed(body) => Reply::parse(body),
            _ => None,
        }
    }

    /// Parses the body of one line from the device, without its seal; `None` for anything that
    /// is not a reply.
    pub fn parse(line: &'a str) -> Option<Reply<'a>> {
        let line = line.trim();
        if let Some(rest) = line.strip_prefix("ok") {
            let mut w = rest.split_ascii_whitespace();
            let seq = seq_word(w.next())?;
            return w.next().is_none().then_some(Reply::Ok { seq });
        }
        if let Some(rest) = line.strip_prefix("error:") {
            let (code, rest) = rest.split_once(' ').unwrap_or((rest, ""));
            let code = ErrorCode::from_code(code.parse().ok()?)?;
            let rest = rest.trim_start();
            let (seq, msg) = match rest.split_once(' ') {
                Some((w, m)) if w.starts_with('N') && w[1..].parse::<u32>().is_ok() => (w[1..].parse().ok(), m),
                _ if rest.starts_with('N') && rest[1..].parse::<u32>().is_ok() => (rest[1..].parse().ok(), ""),
                _ => (None, rest),
            };
            return Some(Reply::Error { code, seq, msg });
        }
        if let Some(rest) = line.strip_prefix("done") {
            let mut w = rest.split_ascii_whitespace().peekable();
            let seq = if w.peek().is_some_and(|x| x.starts_with('N')) { seq_word(w.next())? } else { None };
            let pos = kv(w.next()?, "pos")?.parse().ok()?;
            return Some(Reply::Done { seq, pos });
        }
        if let Some(rest) = line.strip_prefix("busy") {
            return Some(Reply::Busy { seq: seq_word(rest.split_ascii_whitespace().next())? });
        }
        if let Some(rest) = line.strip_prefix('<').and_then(|r| r.strip_suffix('>')) {
            let mut w = rest.split_ascii_whitespace();
            let head = w.next()?;
            let (state, alarm) = match head.strip_prefix("Alarm:") {
                Some(c) => (State::Alarm, Some(Alarm::from_code(c.parse().ok()?)?)),
                None => (State::from_name(head)?, None),
            };
            let pos = kv(w.next()?, "pos")?.parse().ok()?;
            let t_ms = kv(w.next()?, "t")?.parse().ok()?;
            return Some(Reply::Status { state, alarm, pos, t_ms });
        }
        if let Some(rest) = line.strip_prefix('@') {
            let (t, p) = rest.split_once(' ')?;
            return Some(Reply::Angle { t_ms: t.parse().ok()?, pos: p.trim().parse().ok()? });
        }
        if let Some(rest) = line.strip_prefix("ALARM:") {
            let code = rest.split(' ').next()?;
            return Some(Reply::Alarm(Alarm::from_code(code.parse().ok()?)?));
        }
        if let Some(rest) = line.strip_prefix("pav-turntable ") {
            let mut w = rest.split_ascii_whitespace();
            let fw = w.next()?;
            let usteps_per_rev = kv(w.next()?, "usteps")?.parse().ok()?;
            let proto = kv(w.next()?, "proto")?.parse().ok()?;
            return Some(Reply::Banner { fw, usteps_per_rev, proto });
        }
        None
    }

    /// The sequence number this reply answers, if any.
    pub fn seq(&self) -> Option<u32> {
        match *self {
            Reply::Ok { seq } | Reply::Error { seq, .. } | Reply::Done { seq, .. } | Reply::Busy { seq } => seq,
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::text::Text;
    use core::fmt::Write;

    #[test]
    fn every_reply_round_trips() {
        let all = [
            Reply::Ok { seq: None },
            Reply::Ok { seq: Some(4) },
            Reply::Error { code: ErrorCode::Busy, seq: Some(9), msg: "moving" },
            Reply::Error { code: ErrorCode::Checksum, seq: None, msg: "bad checksum" },
            Reply::Error { code: ErrorCode::Garbage, seq: Some(1), msg: "" },
            Reply::Done { seq: Some(2), pos: -3200 },
            Reply::Done { seq: None, pos: 5 },
            Reply::Busy { seq: Some(8) },
            Reply::Status { state: State::Spinning, alarm: None, pos: 77, t_ms: 1234 },
            Reply::Status { state: State::Alarm, alarm: Some(Alarm::Stall), pos: -1, t_ms: 0 },
            Reply::Angle { t_ms: 99, pos: -12 },
            Reply::Alarm(Alarm::EStop),
            Reply::Banner { fw: "0.1.0", usteps_per_rev: 3200, proto: 1 },
        ];
        for r in all {
            let mut t: Text<96> = Text::default();
            write!(t, "{r}").unwrap();
            assert_eq!(Reply::parse(t.as_str()), Some(r), "{}", t.as_str());
        }
        assert_eq!(Reply::parse("garbage"), None);
        assert_eq!(Reply::parse("ok N"), None);
    }

    #[test]
    fn open_reads_sealed_lines_only() {
        let mut t: Text<96> = Text::default();
        write!(t, "{}", Reply::Done { seq: Some(3), pos: 3200 }).unwrap();
        assert_eq!(Reply::open(t.as_str()), None, "a bare line is not trusted");
        crate::frame::seal(&mut t).unwrap();
        assert_eq!(Reply::open(t.as_str()), Some(Reply::Done { seq: Some(3), pos: 3200 }));
        assert_eq!(Reply::open(&t.as_str().replace("3200", "3300")), None);
    }
}
