//! Host-side turntable client over a serial port: commands with sequence numbers sealed by a
//! CRC-16, replies read only when their own CRC-16 matches, per-command timeouts,
//! resynchronisation after timeouts, and reconnection. The wire is a [`Transport`] and time a
//! [`Clock`], so the same client drives a real table and a simulated one in simulated time.

use super::clock::{Clock, SystemClock};
use super::transport::{LinkError, SerialTransport, Transport};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use turntable_proto::frame::{self, Check};
use turntable_proto::{Alarm, Command, ErrorCode, Frame, Reply, State, PROTOCOL_VERSION, SEQ_MODULUS};

/// Errors talking to the turntable.
#[derive(Debug, thiserror::Error)]
pub enum TurntableError {
    /// The port could not be opened.
    #[error("{0}")]
    Open(#[source] LinkError),
    /// Something answered, but not as a pav turntable.
    #[error("{path}: no pav turntable answered within {after:?} (wrong port or baud rate, or firmware not running)")]
    NoDevice {
        /// Port path.
        path: String,
        /// How long we waited.
        after: Duration,
    },
    /// The device speaks another protocol version.
    #[error("{path}: the turntable speaks protocol {found} and this pav speaks {need}: flash the firmware in firmware/ (0.2.0 or newer for protocol 2), or use the pav that matches it")]
    Protocol {
        /// Port path.
        path: String,
        /// The device's protocol version.
        found: u32,
        /// This host's.
        need: u32,
    },
    /// A command got no answer in time.
    #[error("turntable did not answer `{cmd}` within {after:?}")]
    Timeout {
        /// The command line.
        cmd: String,
        /// How long we waited.
        after: Duration,
    },
    /// The device answered `error:`.
    #[error("turntable refused `{cmd}`: {code:?}: {msg}")]
    Refused {
        /// The command line.
        cmd: String,
        /// Error code.
        code: ErrorCode,
        /// Device message.
        msg: String,
    },
    /// The device raised an alarm; motion is locked until `unlock`.
    #[error("turntable alarm: {} (fix the cause, then `pav-rig turntable unlock`)", .0.text())]
    Alarm(Alarm),
    /// A motion sent neither progress nor `done` for too long.
    #[error("turntable motion sent no progress for {0:?}")]
    NoProgress(Duration),
    /// The port went away (cable pulled, device reset).
    #[error("turntable disconnected: {0}")]
    Disconnected(String),
}

type Result<T> = std::result::Result<T, TurntableError>;

/// Something the device reported on its own.
#[derive(Clone, Debug, PartialEq)]
pub enum TableEvent {
    /// Position sample while moving, with the host time it arrived.
    Angle {
        /// Device clock, ms.
        t_ms: u64,
        /// Microsteps from home.
        pos: i64,
        /// Host receive time.
        rx: Instant,
    },
    /// A motion finished.
    Done {
        /// Its command's sequence number.
        seq: Option<u32>,
        /// Final microsteps from home.
        pos: i64,
    },
    /// An alarm was raised.
    Alarm(Alarm),
}

/// A status report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TableStatus {
    /// State.
    pub state: State,
    /// Active alarm.
    pub alarm: Option<Alarm>,
    /// Microsteps from home.
    pub pos: i64,
    /// Device clock, ms.
    pub t_ms: u64,
}

/// One round trip that read the device clock: the device stamped `t_ms` after the host's
/// `sent` and before its `rx`, so the device-to-host clock offset is bounded from both sides.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockProbe {
    /// Host instant just before the request left.
    pub sent: Instant,
    /// Host instant the status line arrived.
    pub rx: Instant,
    /// Device clock in the reply, ms.
    pub t_ms: u64,
    /// Table position in the reply, microsteps from home.
    pub pos: i64,
}

/// A connected turntable.
pub struct Turntable {
    link: Box<dyn Transport>,
    clock: Arc<dyn Clock>,
    seq: u32,
    usteps_per_rev: u32,
    firmware: String,
    events: VecDeque<TableEvent>,
    timeout: Duration,
    /// Lines dropped because their CRC was missing or wrong, or they were no reply (line noise).
    pub garbage_lines: usize,
    /// Unsealed lines that read as replies: a protocol-1 device.
    bare_replies: usize,
    /// Protocol version of the last banner seen.
    proto: Option<u32>,
    /// When the device last showed a motion is alive (`busy`, an angle report, `done`, an alarm).
    last_alive: Instant,
}

impl From<LinkError> for TurntableError {
    fn from(e: LinkError) -> Self {
        match e {
            LinkError::Open { .. } => TurntableError::Open(e),
            LinkError::Closed(msg) => TurntableError::Disconnected(msg),
        }
    }
}

impl Turntable {
    /// Opens the serial port `path` and checks that a pav turntable answers; `timeout` bounds
    /// each command.
    pub fn open(path: &str, baud: u32, timeout: Duration) -> Result<Self> {
        Turntable::connect(Box::new(SerialTransport::open(path, baud)?), Arc::new(SystemClock), timeout)
    }

    /// Checks that a pav turntable answers on `link`, whose deadlines and stamps are instants
    /// of `clock`; `timeout` bounds each command.
    pub fn connect(link: Box<dyn Transport>, clock: Arc<dyn Clock>, timeout: Duration) -> Result<Self> {
        let now = clock.now();
        let mut t = Turntable {
            link,
            clock,
            seq: 0,
            usteps_per_rev: 0,
            firmware: String::new(),
            events: VecDeque::new(),
            timeout,
            garbage_lines: 0,
            bare_replies: 0,
            proto: None,
            last_alive: now,
        };
        t.handshake()?;
        Ok(t)
    }

    /// Microsteps per turntable revolution, from the banner.
    pub fn usteps_per_rev(&self) -> u32 {
        self.usteps_per_rev
    }

    /// Firmware version, from the banner.
    pub fn firmware(&self) -> &str {
        &self.firmware
    }

    /// Converts microsteps from home to degrees (not wrapped).
    pub fn degrees(&self, pos: i64) -> f64 {
        pos as f64 * 360.0 / self.usteps_per_rev.max(1) as f64
    }

    /// The clock this table's times are read on: capture stamps its frames on the same one.
    pub fn clock(&self) -> Arc<dyn Clock> {
        self.clock.clone()
    }

    fn now(&self) -> Instant {
        self.clock.now()
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        Ok(self.link.write(bytes)?)
    }

    /// Drops every byte and line received but not yet read.
    fn discard_input(&mut self) -> Result<()> {
        self.link.discard_input();
        Ok(())
    }

    fn handshake(&mut self) -> Result<()> {
        self.discard_input()?;
        self.bare_replies = 0;
        self.proto = None;
        // A few tries: the first bytes after opening may meet a device still booting.
        for _ in 0..3 {
            match self.request(Command::Info, self.timeout) {
                Ok(_) if self.usteps_per_rev > 0 => return self.same_protocol(),
                Ok(_) | Err(TurntableError::Timeout { .. }) if self.bare_replies == 0 => continue,
                Ok(_) | Err(TurntableError::Timeout { .. }) => break,
                Err(e) => return Err(e),
            }
        }
        if self.bare_replies > 0 {
            return Err(self.older_protocol());
        }
        Err(TurntableError::NoDevice { path: self.link.name().to_string(), after: self.timeout * 3 })
    }

    fn same_protocol(&self) -> Result<()> {
        match self.proto {
            Some(p) if p != PROTOCOL_VERSION => {
                Err(TurntableError::Protocol { path: self.link.name().to_string(), found: p, need: PROTOCOL_VERSION })
            }
            _ => Ok(()),
        }
    }

    /// Unsealed replies came back: ask for the banner the old way, which a protocol-1 device
    /// answers, to name its version.
    fn older_protocol(&mut self) -> TurntableError {
        let _ = self.discard_input();
        let mut found = 1;
        if self.write(b"INFO\n").is_ok() {
            let deadline = self.now() + self.timeout;
            while let Ok(Some((l, _))) = self.read_line(deadline) {
                if let Some(Reply::Banner { proto, .. }) = Reply::parse(&l) {
                    found = proto;
                    break;
                }
            }
        }
        TurntableError::Protocol { path: self.link.name().to_string(), found, need: PROTOCOL_VERSION }
    }

    /// Next line with its arrival time, or `None` when `deadline` passes first (a past deadline
    /// still returns a line that is already waiting, so this doubles as a non-blocking poll).
    fn read_line(&mut self, deadline: Instant) -> Result<Option<(String, Instant)>> {
        Ok(self.link.read_line(deadline)?)
    }

    /// Files an unsolicited line as an event; returns the parsed reply for the caller to inspect.
    fn file<'l>(&mut self, line: &'l str, rx: Instant) -> Option<Reply<'l>> {
        let Some(r) = Reply::open(line) else {
            if let Check::Bare(body) = frame::check(line) {
                self.bare_replies += usize::from(Reply::parse(body).is_some());
            }
            if !line.is_empty() {
                self.garbage_lines += 1;
            }
            return None;
        };
        if matches!(r, Reply::Angle { .. } | Reply::Done { .. } | Reply::Alarm(_) | Reply::Busy { .. }) {
            self.last_alive = rx;
        }
        match r {
            Reply::Angle { t_ms, pos } => self.events.push_back(TableEvent::Angle { t_ms, pos, rx }),
            Reply::Done { seq, pos } => self.events.push_back(TableEvent::Done { seq, pos }),
            Reply::Alarm(a) => self.events.push_back(TableEvent::Alarm(a)),
            Reply::Banner { fw, usteps_per_rev, proto } => {
                self.usteps_per_rev = usteps_per_rev;
                self.firmware = fw.to_string();
                self.proto = Some(proto);
            }
            _ => {}
        }
        Some(r)
    }

    /// The next sequence number: 9 digits, wrapping to 0.
    fn next_seq(&mut self) -> u32 {
        self.seq = (self.seq + 1) % SEQ_MODULUS;
        self.seq
    }

    /// Seals `cmd` with the next sequence number and sends it; returns that number.
    fn send(&mut self, cmd: Command) -> Result<u32> {
        let seq = self.next_seq();
        let line = format!("{}\n", Frame { seq: Some(seq), cmd }.encode().as_str());
        self.write(line.as_bytes())?;
        Ok(seq)
    }

    /// Sends `cmd` and waits for its `ok`; returns the sequence number and the status line, if any.
    fn request(&mut self, cmd: Command, timeout: Duration) -> Result<(u32, Option<TableStatus>)> {
        let seq = self.send(cmd)?;
        let deadline = self.now() + timeout;
        let mut status = None;
        while let Some((l, rx)) = self.read_line(deadline)? {
            match self.file(&l, rx) {
                Some(Reply::Ok { seq: Some(s) }) if s == seq => return Ok((seq, status)),
                Some(Reply::Error { code, seq: Some(s), msg }) if s == seq => {
                    return Err(TurntableError::Refused { cmd: cmd.to_string(), code, msg: msg.to_string() });
                }
                // A damaged line cannot be tied to a sequence number: the device does not echo one.
                Some(Reply::Error {
                    code: ErrorCode::Checksum | ErrorCode::Garbage | ErrorCode::LineTooLong | ErrorCode::Framing,
                    seq: None,
                    ..
                }) => {
                    self.resync()?;
                    return Err(TurntableError::Timeout { cmd: cmd.to_string(), after: timeout });
                }
                Some(Reply::Status { state, alarm, pos, t_ms }) => {
                    status = Some(TableStatus { state, alarm, pos, t_ms })
                }
                _ => {}
            }
        }
        self.resync()?;
        Err(TurntableError::Timeout { cmd: cmd.to_string(), after: timeout })
    }

    /// Drops everything buffered and confirms a fresh round trip, so late replies to a timed-out
    /// command cannot be taken for answers to the next one.
    fn resync(&mut self) -> Result<()> {
        self.discard_input()?;
        let seq = self.send(Command::Ping)?;
        let deadline = self.now() + self.timeout;
        while let Some((l, rx)) = self.read_line(deadline)? {
            if let Some(Reply::Ok { seq: Some(s) }) = self.file(&l, rx) {
                if s == seq {
                    return Ok(());
                }
            }
        }
        // No answer either: leave it to the caller's timeout error.
        Ok(())
    }

    /// Sends a command and waits for its acknowledgement; motions then run until [`Turntable::wait_done`].
    pub fn command(&mut self, cmd: Command) -> Result<u32> {
        self.request(cmd, self.timeout).map(|r| r.0)
    }

    /// Starts a motion; returns its sequence number for [`Turntable::wait_done`]. A motion is
    /// never sent twice, but its `ok` can be lost on the line: after a timeout the table is
    /// asked for its status, and a table that is moving (or has sent this motion's `done`) took
    /// the command; its `done` carries this sequence number.
    pub fn start_motion(&mut self, cmd: Command) -> Result<u32> {
        let seq = (self.seq + 1) % SEQ_MODULUS;
        let sent = self.now();
        let e = match self.command(cmd) {
            Err(e @ TurntableError::Timeout { .. }) => e,
            other => return other,
        };
        // A short motion may be over already (its `done` waits for wait_done), and a table
        // reports angles only while it moves, after the last motion's `done`: listen a while
        // for either, then ask for the status (one line each, so some get through a lossy line).
        let taken = |events: &VecDeque<TableEvent>| {
            events.iter().any(|e| match e {
                TableEvent::Done { seq: Some(s), .. } => *s == seq,
                TableEvent::Angle { rx, .. } => *rx > sent,
                _ => false,
            })
        };
        let deadline = self.now() + (self.timeout / 2).max(Duration::from_millis(200));
        while !taken(&self.events) {
            let Some((l, rx)) = self.read_line(deadline)? else { break };
            self.file(&l, rx);
        }
        let moving = taken(&self.events)
            || matches!(
                self.realtime_status()?,
                Some(st) if matches!(st.state, State::Moving | State::Spinning | State::Homing)
            );
        if moving {
            self.last_alive = self.now();
            Ok(seq)
        } else {
            Err(e)
        }
    }

    /// Sends a command that is safe to repeat (not a motion), retrying after timeouts.
    pub fn command_retry(&mut self, cmd: Command, attempts: usize) -> Result<u32> {
        assert!(!cmd.is_motion(), "motions are not retried: a lost `ok` would start them twice");
        let mut last = None;
        for _ in 0..attempts.max(1) {
            match self.command(cmd) {
                Err(e @ TurntableError::Timeout { .. }) => last = Some(e),
                other => return other,
            }
        }
        Err(last.expect("at least one attempt"))
    }

    /// Current status (retried up to 3 times on line noise).
    pub fn status(&mut self) -> Result<TableStatus> {
        let mut last = None;
        for _ in 0..3 {
            match self.request(Command::Status, self.timeout) {
                Ok((_, Some(st))) => return Ok(st),
                Ok((_, None)) => {
                    last = Some(TurntableError::Timeout { cmd: "STATUS (report line)".into(), after: self.timeout })
                }
                Err(e @ TurntableError::Timeout { .. }) => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.expect("three attempts"))
    }

    /// One `STATUS` round trip for the clock map, or `None` when its reply did not get through
    /// (a timeout is no error here: the caller tries again). The status line counts only when
    /// the `ok` of this very request follows it, so a late reply cannot pass for this one.
    pub fn clock_probe(&mut self) -> Result<Option<ClockProbe>> {
        let sent = self.now();
        let seq = self.send(Command::Status)?;
        let deadline = sent + self.timeout;
        let mut status = None;
        // No resync on a timeout: replies are matched by sequence number, and a status line
        // that arrived before this request was sent was read by the request it answered.
        while let Some((l, rx)) = self.read_line(deadline)? {
            match self.file(&l, rx) {
                Some(Reply::Status { t_ms, pos, .. }) => status = Some(ClockProbe { sent, rx, t_ms, pos }),
                Some(Reply::Ok { seq: Some(s) }) if s == seq => return Ok(status),
                Some(Reply::Error { code, seq: Some(s), msg }) if s == seq => {
                    return Err(TurntableError::Refused { cmd: "STATUS".into(), code, msg: msg.to_string() });
                }
                _ => {}
            }
        }
        Ok(None)
    }

    /// Waits until the motion started by `seq` reports `done`; fails on an alarm or when nothing
    /// (no `busy`, no angle report) arrives for `no_progress`.
    pub fn wait_done(&mut self, seq: u32, no_progress: Duration) -> Result<i64> {
        self.wait_done_or_stop(seq, no_progress, &AtomicBool::new(false))
    }

    /// [`Turntable::wait_done`], and when `stop` is raised (Ctrl-C) the table is told to ramp
    /// down, once; the motion then ends with its `done` at wherever the table stopped.
    ///
    /// A `done` lost on the line (its CRC failed) is not waited for until `no_progress`: after a
    /// third of that without news the table is asked for its status, and an idle table has ended
    /// the motion.
    pub fn wait_done_or_stop(&mut self, seq: u32, no_progress: Duration, stop: &AtomicBool) -> Result<i64> {
        // Poll often enough to act on `stop` promptly.
        const POLL: Duration = Duration::from_millis(100);
        let quiet = (no_progress / 3).max(POLL);
        let start = self.now();
        let mut asked = start;
        let mut stopping = false;
        loop {
            if !stopping && stop.load(Ordering::Relaxed) {
                stopping = true;
                self.command(Command::Stop)?;
            }
            match self.next_event(POLL.min(no_progress))? {
                Some(TableEvent::Done { seq: Some(s), pos }) if s == seq => return Ok(pos),
                Some(TableEvent::Alarm(a)) => return Err(TurntableError::Alarm(a)),
                _ => {}
            }
            if self.clock.since(self.last_alive.max(asked)) >= quiet {
                asked = self.now();
                if let Some(pos) = self.motion_ended(seq)? {
                    return Ok(pos);
                }
            }
            if self.clock.since(self.last_alive.max(start)) >= no_progress {
                return Err(TurntableError::NoProgress(no_progress));
            }
        }
    }

    /// Asks the table whether the motion `seq` is over, for when its `done` may have been lost:
    /// `Some(final position)` if the table is idle (or its `done` arrived meanwhile), `None`
    /// while it still moves or when no status report got through (ask again later). A table
    /// that answers while moving counts as alive.
    pub fn motion_ended(&mut self, seq: u32) -> Result<Option<i64>> {
        let Some(st) = self.realtime_status()? else { return Ok(None) };
        // Replies are in order: a `done` sent before the status line has been filed by now.
        if let Some(i) =
            self.events.iter().position(|e| matches!(e, TableEvent::Done { seq: Some(s), .. } if *s == seq))
        {
            let Some(TableEvent::Done { pos, .. }) = self.events.remove(i) else { unreachable!("found above") };
            return Ok(Some(pos));
        }
        if let Some(a) = st.alarm {
            return Err(TurntableError::Alarm(a));
        }
        match st.state {
            State::Idle | State::Alarm => Ok(Some(st.pos)),
            State::Moving | State::Spinning | State::Homing => {
                self.last_alive = self.now();
                Ok(None)
            }
        }
    }

    /// A status report by the real-time `?` byte: one reply line instead of `STATUS`'s two, so
    /// it gets through a lossy line more often. Three tries of 150 ms; `None` if none answered.
    fn realtime_status(&mut self) -> Result<Option<TableStatus>> {
        for _ in 0..3 {
            self.write(&[turntable_proto::Realtime::Status.byte()])?;
            let deadline = self.now() + Duration::from_millis(150).min(self.timeout);
            while let Some((l, rx)) = self.read_line(deadline)? {
                if let Some(Reply::Status { state, alarm, pos, t_ms }) = self.file(&l, rx) {
                    return Ok(Some(TableStatus { state, alarm, pos, t_ms }));
                }
            }
        }
        Ok(None)
    }

    /// Next event, waiting up to `timeout` for one; keep-alives reset nothing here but count as traffic.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<TableEvent>> {
        let mut deadline = self.now() + timeout;
        loop {
            if let Some(e) = self.events.pop_front() {
                return Ok(Some(e));
            }
            let Some((l, rx)) = self.read_line(deadline)? else {
                return Ok(None);
            };
            if let Some(Reply::Busy { .. }) = self.file(&l, rx) {
                deadline = self.now() + timeout;
            }
        }
    }

    /// Sends the real-time emergency stop byte.
    pub fn estop(&mut self) -> Result<()> {
        self.write(b"!")
    }

    /// Reopens the port (after a USB re-enumeration or cable glitch) and handshakes again.
    pub fn reconnect(&mut self, attempts: usize, wait: Duration) -> Result<()> {
        let mut last = TurntableError::Disconnected(self.link.name().to_string());
        for _ in 0..attempts.max(1) {
            match self.link.reopen() {
                Ok(()) => {
                    self.events.clear();
                    match self.handshake() {
                        Ok(()) => return Ok(()),
                        Err(e) => last = e,
                    }
                }
                Err(e) => last = e.into(),
            }
            self.clock.sleep_until(self.now() + wait);
        }
        Err(last)
    }
}
