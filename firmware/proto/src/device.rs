//! The turntable's protocol logic: bytes and time in, reply lines and a commanded position out.
//!
//! The hardware layer (RP2040, QEMU or the host simulator) feeds received bytes to
//! [`Device::feed`], calls [`Device::poll`] often, sends every line handed to its [`Sink`], and
//! drives the motor toward [`Device::physical_position`].

use crate::codec::{Event, LineCodec, Realtime};
use crate::command::{Command, Frame, ParseError};
use crate::frame;
use crate::motion::{Motion, Profile};
use crate::reply::{Alarm, ErrorCode, Reply, State};
use crate::text::{Milli, Text};
use crate::{MAX_LINE, PROTOCOL_VERSION};
use core::fmt::Write;

/// Where reply lines go (without the line terminator).
pub trait Sink {
    /// Sends one line.
    fn send(&mut self, line: &str);
}

/// Machine settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    /// Firmware version for the banner.
    pub fw_version: &'static str,
    /// Microsteps per turntable revolution (motor steps × microstepping × gear ratio).
    pub usteps_per_rev: u32,
    /// Maximum speed for moves, microsteps/s.
    pub max_speed: i64,
    /// Acceleration, microsteps/s².
    pub accel: i64,
    /// Angle report interval while moving, ms (0 = off).
    pub report_ms: u32,
    /// Keep-alive interval during long motions, ms.
    pub busy_ms: u32,
}

impl Default for Config {
    fn default() -> Self {
        // 200-step motor, 16 microsteps, direct drive; one turn per second at most.
        Config { fw_version: "0.2.0", usteps_per_rev: 3200, max_speed: 3200, accel: 6400, report_ms: 50, busy_ms: 1000 }
    }
}

/// The protocol state machine.
pub struct Device {
    cfg: Config,
    codec: LineCodec<MAX_LINE>,
    motion: Motion,
    state: State,
    alarm: Option<Alarm>,
    /// The running motion command, awaiting `done` (inner = its sequence number).
    active: Option<Option<u32>>,
    /// Physical microsteps that read as position 0 (set by `HOME`).
    origin: i64,
    /// A sealed, sequenced line was accepted since the last reset: bare lines are refused now.
    framed: bool,
    boot_us: u64,
    next_report_us: u64,
    next_busy_us: u64,
}

/// Sends one reply, sealed with its CRC.
fn send(out: &mut impl Sink, r: Reply<'_>) {
    let mut t: Text<128> = Text::default();
    // Replies are short and bounded; 128 bytes holds the longest with its seal.
    let _ = write!(t, "{r}");
    let _ = frame::seal(&mut t);
    out.send(t.as_str());
}

impl Device {
    /// A device at rest at position 0, booted at `now_us`; call [`Device::reset`] to print the banner.
    pub fn new(cfg: Config, now_us: u64) -> Self {
        Device {
            cfg,
            codec: LineCodec::default(),
            motion: Motion::Idle(0),
            state: State::Idle,
            alarm: None,
            active: None,
            origin: 0,
            framed: false,
            boot_us: now_us,
            next_report_us: 0,
            next_busy_us: 0,
        }
    }

    /// Current settings.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Soft reset: halts at once, drops any partial line, ends a framed session, keeps an active
    /// alarm, prints the banner.
    pub fn reset(&mut self, now_us: u64, out: &mut impl Sink) {
        self.motion.halt(now_us);
        self.active = None;
        self.framed = false;
        self.codec = LineCodec::default();
        self.state = if self.alarm.is_some() { State::Alarm } else { State::Idle };
        send(out, self.banner());
    }

    /// Position the motor must be at, in physical microsteps (not shifted by `HOME`).
    pub fn physical_position(&self, now_us: u64) -> i64 {
        self.motion.position_at(now_us)
    }

    /// Position as reported to the host (0 at home).
    pub fn position(&self, now_us: u64) -> i64 {
        self.physical_position(now_us) - self.origin
    }

    /// The running motion and the home offset: with them the position at any time is known
    /// (simulators use this as ground truth).
    pub fn motion(&self) -> (Motion, i64) {
        (self.motion, self.origin)
    }

    /// Machine state.
    pub fn state(&self) -> State {
        self.state
    }

    /// Active alarm.
    pub fn alarm(&self) -> Option<Alarm> {
        self.alarm
    }

    fn banner(&self) -> Reply<'static> {
        Reply::Banner { fw: self.cfg.fw_version, usteps_per_rev: self.cfg.usteps_per_rev, proto: PROTOCOL_VERSION }
    }

    fn t_ms(&self, now_us: u64) -> u64 {
        now_us.saturating_sub(self.boot_us) / 1000
    }

    fn status(&self, now_us: u64) -> Reply<'static> {
        Reply::Status { state: self.state, alarm: self.alarm, pos: self.position(now_us), t_ms: self.t_ms(now_us) }
    }

    /// Raises an alarm detected by the hardware layer (stall, homing failure): halts and locks.
    pub fn fault(&mut self, alarm: Alarm, now_us: u64, out: &mut impl Sink) {
        self.motion.halt(now_us);
        self.active = None;
        self.alarm = Some(alarm);
        self.state = State::Alarm;
        send(out, Reply::Alarm(alarm));
    }

    /// Feeds one received byte.
    pub fn feed(&mut self, b: u8, now_us: u64, out: &mut impl Sink) {
        match self.codec.push(b) {
            None => {}
            Some(Event::Realtime(Realtime::EStop)) => self.fault(Alarm::EStop, now_us, out),
            Some(Event::Realtime(Realtime::Status)) => send(out, self.status(now_us)),
            Some(Event::Realtime(Realtime::Reset)) => self.reset(now_us, out),
            Some(Event::Overflow) => {
                send(out, Reply::Error { code: ErrorCode::LineTooLong, seq: None, msg: "line too long" })
            }
            Some(Event::Garbage) => {
                send(out, Reply::Error { code: ErrorCode::Garbage, seq: None, msg: "non-printable bytes" })
            }
            Some(Event::Line) => {
                if self.codec.line().is_empty() {
                    return;
                }
                match Frame::parse(self.codec.line()) {
                    Ok(r) if self.framed && !(r.sealed && r.frame.seq.is_some()) => send(
                        out,
                        Reply::Error {
                            code: ErrorCode::Framing,
                            seq: None,
                            msg: "framed session: seal and number every line (Ctrl-X resets)",
                        },
                    ),
                    Ok(r) => {
                        self.framed |= r.sealed && r.frame.seq.is_some();
                        self.execute(r.frame, now_us, out)
                    }
                    Err(e) => {
                        let (code, msg) = match e {
                            ParseError::Checksum => (ErrorCode::Checksum, "bad CRC"),
                            ParseError::Legacy => (
                                ErrorCode::Checksum,
                                "protocol 1 checksum: this turntable speaks protocol 2 (CRC-16 seals); update pav",
                            ),
                            ParseError::Unsealed => (ErrorCode::Framing, "sequence number without a CRC"),
                            ParseError::Sequence => (ErrorCode::Framing, "sequence number of more than 9 digits"),
                            ParseError::Unknown { .. } => (ErrorCode::Unknown, "unknown command"),
                            ParseError::BadArgument { .. } => (ErrorCode::BadArgument, "bad argument"),
                        };
                        send(out, Reply::Error { code, seq: e.seq(), msg });
                    }
                }
            }
        }
    }

    fn usteps(&self, deg: Milli) -> i64 {
        // Round half away from zero: deg·rev/360, with deg in thousandths.
        let n = deg.0 as i128 * self.cfg.usteps_per_rev as i128;
        let d = 360_000i128;
        (if n >= 0 { (n + d / 2) / d } else { (n - d / 2) / d }) as i64
    }

    fn execute(&mut self, f: Frame, now: u64, out: &mut impl Sink) {
        let seq = f.seq;
        if f.cmd.is_motion() {
            return self.start_motion(f.cmd, seq, now, out);
        }
        let ok = Reply::Ok { seq };
        match f.cmd {
            Command::Ping => send(out, ok),
            Command::Info => {
                send(out, self.banner());
                send(out, ok);
            }
            Command::Status => {
                send(out, self.status(now));
                send(out, ok);
            }
            Command::Speed(v) => {
                self.cfg.max_speed = self.usteps(v).max(1);
                send(out, ok);
            }
            Command::Accel(a) => {
                self.cfg.accel = self.usteps(a).max(1);
                send(out, ok);
            }
            Command::Report(ms) => {
                self.cfg.report_ms = ms;
                send(out, ok);
            }
            Command::Unlock => {
                self.alarm = None;
                if self.state == State::Alarm {
                    self.state = State::Idle;
                }
                send(out, ok);
            }
            Command::Stop => {
                if let Motion::Running(p) = self.motion {
                    if self.motion.is_moving(now) {
                        self.motion = Motion::Running(p.stop_at(now));
                    }
                }
                send(out, ok);
            }
            Command::Home | Command::MoveTo(_) | Command::MoveBy(_) | Command::Spin { .. } => {
                unreachable!("motions start above")
            }
        }
    }

    /// Starts a motion command unless an alarm locks the table or another motion runs.
    fn start_motion(&mut self, cmd: Command, seq: Option<u32>, now: u64, out: &mut impl Sink) {
        if let Some(a) = self.alarm {
            send(out, Reply::Error { code: ErrorCode::Locked, seq, msg: a.text() });
            return;
        }
        if self.active.is_some() {
            send(out, Reply::Error { code: ErrorCode::Busy, seq, msg: "moving: wait for done or STOP" });
            return;
        }
        let here = self.physical_position(now);
        let rev = self.cfg.usteps_per_rev as i64;
        let (profile, state) = match cmd {
            Command::Home => {
                // Nearest whole turn of the current count; origin moves there when done.
                let rel = here - self.origin;
                let target = self.origin + (rel + rel.signum() * rev / 2) / rev * rev;
                (Profile::new(here, target, self.cfg.max_speed, self.cfg.accel, now), State::Homing)
            }
            Command::MoveTo(d) => (
                Profile::new(here, self.origin + self.usteps(d), self.cfg.max_speed, self.cfg.accel, now),
                State::Moving,
            ),
            Command::MoveBy(d) => {
                (Profile::new(here, here + self.usteps(d), self.cfg.max_speed, self.cfg.accel, now), State::Moving)
            }
            Command::Spin { period_s, turns } => {
                (Profile::spin(here, self.cfg.usteps_per_rev, period_s.0, turns, self.cfg.accel, now), State::Spinning)
            }
            _ => unreachable!("motion commands only"),
        };
        self.motion = Motion::Running(profile);
        self.state = state;
        self.active = Some(seq);
        self.next_report_us = now;
        self.next_busy_us = now + self.cfg.busy_ms as u64 * 1000;
        send(out, Reply::Ok { seq });
    }

    /// Advances time: emits angle reports and keep-alives, and `done` when a motion ends.
    pub fn poll(&mut self, now_us: u64, out: &mut impl Sink) {
        let Some(seq) = self.active else { return };
        if !self.motion.is_moving(now_us) {
            let end = self.motion.position_at(now_us);
            self.motion = Motion::Idle(end);
            if self.state == State::Homing {
                self.origin = end;
            }
            self.state = State::Idle;
            self.active = None;
            send(out, Reply::Angle { t_ms: self.t_ms(now_us), pos: self.position(now_us) });
            send(out, Reply::Done { seq, pos: self.position(now_us) });
            return;
        }
        if self.cfg.report_ms > 0 && now_us >= self.next_report_us {
            send(out, Reply::Angle { t_ms: self.t_ms(now_us), pos: self.position(now_us) });
            let period = self.cfg.report_ms as u64 * 1000;
            // Skip missed slots instead of bursting when polled late.
            self.next_report_us = (self.next_report_us + period).max(now_us + 1);
        }
        if self.cfg.busy_ms > 0 && now_us >= self.next_busy_us {
            send(out, Reply::Busy { seq });
            self.next_busy_us = now_us + self.cfg.busy_ms as u64 * 1000;
        }
    }
}
