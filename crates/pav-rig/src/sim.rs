//! A simulated turntable: the firmware's own protocol logic ([`turntable_proto::Device`]) with
//! optional fault injection, served on a pseudo-terminal in real time ([`SimTurntable`]) or on an
//! in-memory wire in the time of any [`Clock`] ([`SimTransport`]).

use super::clock::Clock;
use super::transport::{Lines, LinkError, Transport};
use serialport::{SerialPort, TTYPort};
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use turntable_proto::{Alarm, Config, Device, Sink};

/// Faults the simulator can inject.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Faults {
    /// Probability of dropping each byte the device sends (0–1).
    pub drop_byte: f64,
    /// Probability of inserting a garbage line before each line the device sends (0–1).
    pub garbage_line: f64,
    /// Latency of every line the device sends (replies arrive this much later; the line's
    /// throughput is unchanged).
    pub delay: Duration,
    /// Close the port (as an unplugged USB cable) after this long (wall time on a pty, the
    /// clock's time in memory).
    pub disconnect_after: Option<Duration>,
    /// Raise one stall alarm this long (simulated time) into the first motion.
    pub stall_after: Option<Duration>,
    /// Stop answering anything after this long (a hung firmware).
    pub hang_after: Option<Duration>,
    /// Lose every motion's last angle report and its `done` on the line.
    pub lose_end: bool,
    /// Lose every `ok` line after this many have been sent.
    pub lose_ok_after: Option<usize>,
}

/// Why a simulator could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// An option out of its range.
    #[error("simulator: {0}")]
    Invalid(String),
    /// The pseudo-terminal or the thread could not be made.
    #[error("simulator: {0}")]
    Io(#[from] std::io::Error),
}

/// A fault time given in seconds: finite, not negative, and short enough for a `Duration`.
pub fn fault_seconds(name: &str, secs: f64) -> Result<Duration, SimError> {
    if secs.is_nan() || secs < 0.0 {
        return Err(SimError::Invalid(format!("{name} must be a number of seconds ≥ 0, not {secs:?}")));
    }
    Duration::try_from_secs_f64(secs)
        .map_err(|_| SimError::Invalid(format!("{name} = {secs:?} s is beyond any time the simulator can wait")))
}

impl SimOptions {
    /// Refuses options that make no simulation: a time scale that is not a positive finite
    /// number, or probabilities outside [0, 1].
    pub fn check(&self) -> Result<(), SimError> {
        if !(self.time_scale.is_finite() && self.time_scale > 0.0) {
            return Err(SimError::Invalid(format!("time scale must be positive and finite, not {}", self.time_scale)));
        }
        for (name, p) in [("drop rate", self.faults.drop_byte), ("garbage rate", self.faults.garbage_line)] {
            if !(0.0..=1.0).contains(&p) {
                return Err(SimError::Invalid(format!("{name} is a probability in [0, 1], not {p}")));
            }
        }
        Ok(())
    }
}

/// Simulator settings.
#[derive(Clone, Debug)]
pub struct SimOptions {
    /// Device configuration (microsteps per turn, speeds).
    pub config: Config,
    /// Simulated time runs this many times faster than wall time (1 = real time).
    pub time_scale: f64,
    /// Faults to inject.
    pub faults: Faults,
    /// Seed for the fault dice.
    pub seed: u64,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions { config: Config::default(), time_scale: 1.0, faults: Faults::default(), seed: 1 }
    }
}

/// The device polls this often, in device time: a motion's reports and its end are stamped to
/// the millisecond, as the firmware's are.
const TICK_US: u64 = 1000;

/// The simulated table and its side of the line: the firmware's logic, the injected faults and
/// the lines on their way to the host, all in device microseconds.
struct World {
    dev: Device,
    faults: Faults,
    time_scale: f64,
    dice: Dice,
    /// Device time reached.
    t_us: u64,
    motion_started: Option<u64>,
    stalled: bool,
    oks: usize,
    /// Lines the device sent since the last flush.
    sent: Vec<String>,
    /// Bytes on the line with the device time they arrive.
    outbox: VecDeque<(u64, Vec<u8>)>,
    /// The device time the line was cut, if it was.
    cut_at: Option<u64>,
}

struct Out<'a> {
    lines: &'a mut Vec<String>,
}
impl Sink for Out<'_> {
    fn send(&mut self, line: &str) {
        self.lines.push(line.to_string());
    }
}

/// xorshift64*: tiny deterministic dice for fault injection.
struct Dice(u64);
impl Dice {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

impl World {
    fn new(opts: &SimOptions) -> Self {
        let mut dev = Device::new(opts.config, 0);
        let mut sent = Vec::new();
        dev.reset(0, &mut Out { lines: &mut sent });
        let mut w = World {
            dev,
            faults: opts.faults.clone(),
            time_scale: opts.time_scale,
            dice: Dice(opts.seed.max(1)),
            t_us: 0,
            motion_started: None,
            stalled: false,
            oks: 0,
            sent,
            outbox: VecDeque::new(),
            cut_at: None,
        };
        w.flush();
        w
    }

    /// Device microseconds as wall (or clock) time.
    fn wall(&self, t_us: u64) -> Duration {
        Duration::from_secs_f64(t_us as f64 / 1e6 / self.time_scale)
    }

    fn hung(&self) -> bool {
        self.faults.hang_after.is_some_and(|d| self.wall(self.t_us) >= d)
    }

    /// Moves device time on to `to_us` (never back), a tick at a time.
    fn advance(&mut self, to_us: u64) {
        while self.t_us < to_us && self.cut_at.is_none() {
            self.t_us = (self.t_us + TICK_US).min(to_us);
            if self.faults.disconnect_after.is_some_and(|d| self.wall(self.t_us) >= d) {
                self.cut_at = Some(self.t_us);
                return;
            }
            self.step();
        }
    }

    fn step(&mut self) {
        let t = self.t_us;
        self.dev.poll(t, &mut Out { lines: &mut self.sent });
        let moving = matches!(
            self.dev.state(),
            turntable_proto::State::Moving | turntable_proto::State::Spinning | turntable_proto::State::Homing
        );
        if moving && self.motion_started.is_none() {
            self.motion_started = Some(t);
        }
        if let (Some(s), Some(after)) = (self.motion_started, self.faults.stall_after) {
            // One stall, in the first motion; the table works again after UNLOCK.
            if moving && !self.stalled && t - s >= after.as_micros() as u64 {
                self.stalled = true;
                self.dev.fault(Alarm::Stall, t, &mut Out { lines: &mut self.sent });
            }
        }
        self.flush();
    }

    /// Bytes from the host, arriving now.
    fn feed(&mut self, bytes: &[u8]) {
        if self.hung() || self.cut_at.is_some() {
            return;
        }
        for &b in bytes {
            self.dev.feed(b, self.t_us, &mut Out { lines: &mut self.sent });
        }
        self.flush();
    }

    /// Puts the lines the device sent on the line, through the faults.
    fn flush(&mut self) {
        let f = &self.faults;
        if self.hung() {
            self.sent.clear();
            return;
        }
        if f.lose_end {
            // The device sends a motion's last `@t pos` and its `done` together.
            while let Some(i) = self.sent.iter().position(|l| l.starts_with("done")) {
                self.sent.remove(i);
                if i > 0 && self.sent[i - 1].starts_with('@') {
                    self.sent.remove(i - 1);
                }
            }
        }
        if let Some(n) = f.lose_ok_after {
            let oks = &mut self.oks;
            self.sent.retain(|l| {
                let ok = l.starts_with("ok");
                *oks += usize::from(ok);
                !(ok && *oks > n)
            });
        }
        // Latency holds each line back without slowing the line down: lines queue with the
        // instant they are due, as on a link that is slow to deliver but not narrow.
        let due = self.t_us + (f.delay.as_secs_f64() * self.time_scale * 1e6) as u64;
        for line in self.sent.drain(..) {
            let mut bytes = Vec::with_capacity(line.len() + 8);
            if f.garbage_line > 0.0 && self.dice.unit() < f.garbage_line {
                bytes.extend_from_slice(b"\x07#%garbage~\n");
            }
            bytes.extend_from_slice(line.as_bytes());
            bytes.push(b'\n');
            if f.drop_byte > 0.0 {
                bytes.retain(|_| self.dice.unit() >= f.drop_byte);
            }
            self.outbox.push_back((due, bytes));
        }
    }

    /// Bytes that have reached the host by device time `t_us` (none sent after the cut arrive).
    fn arrived(&mut self, t_us: u64) -> Vec<(u64, Vec<u8>)> {
        let until = self.cut_at.map_or(t_us, |c| c.min(t_us));
        let n = self.outbox.iter().take_while(|(due, _)| *due <= until).count();
        self.outbox.drain(..n).collect()
    }
}

/// The simulated table's exact motion, readable from outside: the simulated camera and tests
/// use it as ground truth.
#[derive(Clone)]
pub struct Truth {
    start: Instant,
    time_scale: f64,
    usteps_per_rev: u32,
    world: Arc<Mutex<World>>,
    clock: Arc<dyn Clock>,
    /// The table runs when it is looked at ([`SimTransport`]), not on a thread of its own.
    lazy: bool,
}

impl Truth {
    fn world(&self) -> MutexGuard<'_, World> {
        self.world.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Device microseconds at instant `at`.
    fn device_us(&self, at: Instant) -> u64 {
        (at.saturating_duration_since(self.start).as_secs_f64() * self.time_scale * 1e6) as u64
    }

    /// The instant of device microsecond `t_us`.
    fn instant(&self, t_us: u64) -> Instant {
        self.start + Duration::from_secs_f64(t_us as f64 / 1e6 / self.time_scale)
    }

    /// The clock the table runs on; a camera filming it waits on the same one.
    pub fn clock(&self) -> Arc<dyn Clock> {
        self.clock.clone()
    }

    /// True position in microsteps from home at instant `at`.
    pub fn position_at(&self, at: Instant) -> i64 {
        let t = self.device_us(at);
        let mut w = self.world();
        if self.lazy {
            w.advance(t);
        }
        let (m, origin) = w.dev.motion();
        m.position_at(t) - origin
    }

    /// True turntable angle in degrees, [0, 360), at `at`.
    pub fn angle_at(&self, at: Instant) -> f64 {
        let rev = self.usteps_per_rev as i64;
        self.position_at(at).rem_euclid(rev) as f64 * 360.0 / rev as f64
    }
}

/// A running simulator on a pseudo-terminal, in real time; dropping it stops the thread and
/// closes the port.
pub struct SimTurntable {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    truth: Truth,
}

impl SimTurntable {
    /// Starts a simulator; the host opens [`SimTurntable::path`] like a real serial device.
    pub fn spawn(opts: SimOptions) -> Result<Self, SimError> {
        opts.check()?;
        let (mut master, slave) = TTYPort::pair().map_err(std::io::Error::other)?;
        let path = PathBuf::from(slave.name().ok_or_else(|| std::io::Error::other("pty has no name"))?);
        master.set_timeout(Duration::from_millis(2)).map_err(std::io::Error::other)?;
        let stop = Arc::new(AtomicBool::new(false));
        let truth = Truth {
            start: Instant::now(),
            time_scale: opts.time_scale,
            usteps_per_rev: opts.config.usteps_per_rev,
            world: Arc::new(Mutex::new(World::new(&opts))),
            clock: Arc::new(super::clock::SystemClock),
            lazy: false,
        };
        let (stop2, truth2) = (stop.clone(), truth.clone());
        let thread = std::thread::Builder::new().name("sim-turntable".into()).spawn(move || {
            // Keep the slave end open so the master never reads EIO between host connections.
            let _slave = slave;
            serve(master, stop2, truth2);
        })?;
        Ok(SimTurntable { path, stop, thread: Some(thread), truth })
    }

    /// The pty path to open, e.g. `/dev/pts/7`.
    pub fn path(&self) -> &std::path::Path {
        &self.path
    }

    /// Ground truth of the simulated table.
    pub fn truth(&self) -> Truth {
        self.truth.clone()
    }

    /// Whether the simulator thread still runs (false after an injected disconnect).
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }
}

impl Drop for SimTurntable {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn serve(mut port: TTYPort, stop: Arc<AtomicBool>, truth: Truth) {
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        let n = match port.read(&mut buf) {
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::WouldBlock => 0,
            Err(_) => {
                std::thread::sleep(Duration::from_millis(5));
                0
            }
        };
        let arrived = {
            let mut w = truth.world();
            w.advance(truth.device_us(Instant::now()));
            if w.cut_at.is_some() {
                return; // dropping the master hangs up the line
            }
            w.feed(&buf[..n]);
            let t = w.t_us;
            w.arrived(t)
        };
        for (_, bytes) in arrived {
            if port.write_all(&bytes).is_err() {
                break;
            }
        }
    }
}

/// The simulated table on an in-memory wire, in the time of `clock`: waiting for a reply moves
/// the clock on, so with a [`super::clock::SimClock`] a 28 s capture takes the computer's time
/// only, and every run with the same faults and seed is the same run.
pub struct SimTransport {
    truth: Truth,
    lines: Lines,
    ready: VecDeque<(String, Instant)>,
}

impl SimTransport {
    /// A simulator at rest at home, booted at the clock's present instant.
    pub fn new(opts: SimOptions, clock: Arc<dyn Clock>) -> Result<Self, SimError> {
        opts.check()?;
        let truth = Truth {
            start: clock.now(),
            time_scale: opts.time_scale,
            usteps_per_rev: opts.config.usteps_per_rev,
            world: Arc::new(Mutex::new(World::new(&opts))),
            clock,
            lazy: true,
        };
        Ok(SimTransport { truth, lines: Lines::default(), ready: VecDeque::new() })
    }

    /// Ground truth of the simulated table.
    pub fn truth(&self) -> Truth {
        self.truth.clone()
    }

    /// Runs the table to the clock's present and takes the lines that reached the host;
    /// returns whether the line was cut.
    fn pump(&mut self) -> bool {
        let now = self.truth.device_us(self.truth.clock.now());
        let (arrived, cut) = {
            let mut w = self.truth.world();
            w.advance(now);
            (w.arrived(now), w.cut_at.is_some())
        };
        for (due, bytes) in arrived {
            let at = self.truth.instant(due);
            self.ready.extend(self.lines.push(&bytes).into_iter().map(|l| (l, at)));
        }
        cut
    }

    fn unplugged(&self) -> LinkError {
        LinkError::Closed(format!("{} was unplugged", self.name()))
    }
}

impl Transport for SimTransport {
    fn name(&self) -> &str {
        "simulated turntable"
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), LinkError> {
        if self.pump() {
            return Err(self.unplugged());
        }
        self.truth.world().feed(bytes);
        Ok(())
    }

    fn read_line(&mut self, deadline: Instant) -> Result<Option<(String, Instant)>, LinkError> {
        let clock = self.truth.clock.clone();
        // The device's own tick, as host time: nothing new reaches the host between two.
        let tick = Duration::from_secs_f64(TICK_US as f64 / 1e6 / self.truth.time_scale);
        loop {
            let cut = self.pump();
            if let Some(line) = self.ready.pop_front() {
                return Ok(Some(line));
            }
            if cut {
                return Err(self.unplugged());
            }
            let now = clock.now();
            if now >= deadline {
                return Ok(None);
            }
            clock.sleep_until((now + tick).min(deadline));
        }
    }

    fn discard_input(&mut self) {
        self.pump();
        self.ready.clear();
        self.lines.clear();
    }

    fn reopen(&mut self) -> Result<(), LinkError> {
        if self.pump() {
            let why = std::io::Error::new(ErrorKind::NotFound, "the simulated turntable was unplugged");
            return Err(LinkError::Open { path: self.name().into(), source: why });
        }
        self.discard_input();
        Ok(())
    }
}
