//! A simulated turntable: the firmware's own protocol logic ([`turntable_proto::Device`]) served
//! on a pseudo-terminal, with optional fault injection for tests.

use serialport::{SerialPort, TTYPort};
use std::io::{ErrorKind, Read, Write};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use turntable_proto::{Alarm, Config, Device, Motion, Sink};

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
    /// Close the port (as an unplugged USB cable) after this long.
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

/// The simulated table's exact motion, readable from outside: the simulated camera and tests
/// use it as ground truth.
#[derive(Clone)]
pub struct Truth {
    start: Instant,
    time_scale: f64,
    usteps_per_rev: u32,
    motion: Arc<Mutex<(Motion, i64)>>,
}

impl Truth {
    /// True position in microsteps from home at wall-clock instant `at`.
    pub fn position_at(&self, at: Instant) -> i64 {
        let sim_us = (at.saturating_duration_since(self.start).as_secs_f64() * self.time_scale * 1e6) as u64;
        let (m, origin) = *self.motion.lock().expect("truth lock");
        m.position_at(sim_us) - origin
    }

    /// True turntable angle in degrees, [0, 360), at `at`.
    pub fn angle_at(&self, at: Instant) -> f64 {
        let rev = self.usteps_per_rev as i64;
        self.position_at(at).rem_euclid(rev) as f64 * 360.0 / rev as f64
    }
}

/// A running simulator; dropping it stops the thread and closes the port.
pub struct SimTurntable {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
    truth: Truth,
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
            motion: Arc::new(Mutex::new((Motion::Idle(0), 0))),
        };
        let (stop2, truth2) = (stop.clone(), truth.clone());
        let thread = std::thread::Builder::new().name("sim-turntable".into()).spawn(move || {
            // Keep the slave end open so the master never reads EIO between host connections.
            let _slave = slave;
            serve(master, opts, stop2, truth2);
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

fn serve(mut port: TTYPort, opts: SimOptions, stop: Arc<AtomicBool>, truth: Truth) {
    let start = truth.start;
    let now_us = || (start.elapsed().as_secs_f64() * opts.time_scale * 1e6) as u64;
    let mut dev = Device::new(opts.config, 0);
    let mut lines = Vec::new();
    dev.reset(0, &mut Out { lines: &mut lines });
    let mut dice = Dice(opts.seed.max(1));
    let mut buf = [0u8; 256];
    let mut motion_started: Option<u64> = None;
    let mut stalled = false;
    let f = &opts.faults;
    let mut outbox: std::collections::VecDeque<(Instant, Vec<u8>)> = std::collections::VecDeque::new();
    let mut oks = 0usize;
    while !stop.load(Ordering::Relaxed) {
        let wall = start.elapsed();
        if f.disconnect_after.is_some_and(|d| wall >= d) {
            return; // dropping the master hangs up the line
        }
        let hung = f.hang_after.is_some_and(|d| wall >= d);
        match port.read(&mut buf) {
            Ok(n) if !hung => {
                let t = now_us();
                for &b in &buf[..n] {
                    dev.feed(b, t, &mut Out { lines: &mut lines });
                }
            }
            Ok(_) => {}
            Err(e) if e.kind() == ErrorKind::TimedOut || e.kind() == ErrorKind::WouldBlock => {}
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
        let t = now_us();
        dev.poll(t, &mut Out { lines: &mut lines });
        let moving = matches!(
            dev.state(),
            turntable_proto::State::Moving | turntable_proto::State::Spinning | turntable_proto::State::Homing
        );
        if moving && motion_started.is_none() {
            motion_started = Some(t);
        }
        if let (Some(s), Some(after)) = (motion_started, f.stall_after) {
            // One stall, in the first motion; the table works again after UNLOCK.
            if moving && !stalled && t - s >= after.as_micros() as u64 {
                stalled = true;
                dev.fault(Alarm::Stall, t, &mut Out { lines: &mut lines });
            }
        }
        *truth.motion.lock().expect("truth lock") = dev.motion();
        if hung {
            lines.clear();
            continue;
        }
        if f.lose_end {
            // The device sends a motion's last `@t pos` and its `done` together.
            while let Some(i) = lines.iter().position(|l| l.starts_with("done")) {
                lines.remove(i);
                if i > 0 && lines[i - 1].starts_with('@') {
                    lines.remove(i - 1);
                }
            }
        }
        if let Some(n) = f.lose_ok_after {
            lines.retain(|l| {
                let ok = l.starts_with("ok");
                oks += usize::from(ok);
                !(ok && oks > n)
            });
        }
        // Latency holds each line back without slowing the line down: lines queue with the
        // instant they are due, as on a link that is slow to deliver but not narrow.
        let now = Instant::now();
        for line in lines.drain(..) {
            let mut bytes = Vec::with_capacity(line.len() + 8);
            if f.garbage_line > 0.0 && dice.unit() < f.garbage_line {
                bytes.extend_from_slice(b"\x07#%garbage~\n");
            }
            bytes.extend_from_slice(line.as_bytes());
            bytes.push(b'\n');
            if f.drop_byte > 0.0 {
                bytes.retain(|_| dice.unit() >= f.drop_byte);
            }
            outbox.push_back((now + f.delay, bytes));
        }
        while outbox.front().is_some_and(|(due, _)| *due <= Instant::now()) {
            let (_, bytes) = outbox.pop_front().expect("checked above");
            if port.write_all(&bytes).is_err() {
                break;
            }
        }
    }
}
