//! The turntable options that `turntable` and `capture` share, and durations on the command line.

use anyhow::{Context, Result};
use pav::rig::clock::{Clock, SimClock};
use pav::rig::sim::{SimOptions, SimTransport, SimTurntable, Truth};
use pav::rig::turntable::Turntable;
use std::sync::Arc;
use std::time::Duration;

#[derive(clap::Args)]
pub struct PortArgs {
    /// Serial port of the turntable (e.g. /dev/ttyACM0), or `sim` for an in-process simulator
    /// (on a pseudo-terminal in real time; in simulated time when `--camera sim` films it).
    #[arg(long, default_value = "/dev/ttyACM0")]
    pub port: String,
    /// Baud rate (ignored by USB-CDC).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Per-command timeout in milliseconds.
    #[arg(long, default_value_t = 1000)]
    timeout_ms: u64,
    /// With --port sim: the simulated table turns this many times faster than the host's (or
    /// the simulated camera's) clock.
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
}

/// Which time a simulated table runs in.
#[derive(Clone, Copy, PartialEq)]
pub enum SimTime {
    /// On a pseudo-terminal in real time, as a real table on a serial port.
    Real,
    /// On an in-memory wire in simulated time: waiting moves the clock on at once, so what is
    /// filmed does not depend on how fast or busy the machine is.
    Simulated,
}

/// A connected turntable and, for `--port sim`, the simulator behind it.
pub struct Connected {
    /// The table.
    pub table: Turntable,
    /// The simulated table's exact motion, for a simulated camera to film.
    pub truth: Option<Truth>,
    /// Keeps a pseudo-terminal simulator's thread alive as long as the table is used.
    _pty: Option<SimTurntable>,
}

/// Opens the turntable, starting a simulator first for `--port sim`, in `time`.
pub fn connect(p: &PortArgs, time: SimTime) -> Result<Connected> {
    let timeout = Duration::from_millis(p.timeout_ms);
    let opts = SimOptions { time_scale: p.time_scale, ..SimOptions::default() };
    let (table, truth, pty, path) = match (p.port.as_str(), time) {
        ("sim", SimTime::Simulated) => {
            let clock: Arc<dyn Clock> = Arc::new(SimClock::new());
            let link = SimTransport::new(opts, clock.clone()).context("starting the simulated turntable")?;
            let truth = link.truth();
            let table = Turntable::connect(Box::new(link), clock, timeout)?;
            (table, Some(truth), None, "memory, in simulated time".to_string())
        }
        ("sim", SimTime::Real) => {
            let sim = SimTurntable::spawn(opts).context("starting the simulated turntable")?;
            let path = sim.path().display().to_string();
            let table = Turntable::open(&path, p.baud, timeout)?;
            (table, Some(sim.truth()), Some(sim), path)
        }
        (port, _) => (Turntable::open(port, p.baud, timeout)?, None, None, port.to_string()),
    };
    eprintln!("turntable on {path}: firmware {}, {} microsteps/rev", table.firmware(), table.usteps_per_rev());
    Ok(Connected { table, truth, _pty: pty })
}

/// A non-zero duration like `28s` or `-28` (negative: the other way round).
pub fn parse_signed_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().trim_end_matches('s').parse().map_err(|_| format!("`{s}` is not a duration like 28s"))?;
    if v.is_finite() && v != 0.0 {
        Ok(v)
    } else {
        Err(format!("period must be non-zero, got {s}"))
    }
}

/// A positive duration like `28s` or `28`.
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().trim_end_matches('s').parse().map_err(|_| format!("`{s}` is not a duration like 28s"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("rotation period must be positive, got {s}"))
    }
}
