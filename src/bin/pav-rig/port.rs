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
    /// (on a pseudo-terminal in real time; in simulated time when `--camera sim` films it)
    /// [default: the one USB serial port there is; with several, pav lists them and asks].
    #[arg(long)]
    pub port: Option<String>,
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
    /// The port as named or found (`sim` for the simulator).
    pub port: String,
    /// The simulated table's exact motion, for a simulated camera to film.
    pub truth: Option<Truth>,
    /// Keeps a pseudo-terminal simulator's thread alive as long as the table is used.
    _pty: Option<SimTurntable>,
}

impl PortArgs {
    /// Whether the table is the simulator.
    pub fn is_sim(&self) -> bool {
        self.port.as_deref() == Some("sim")
    }

    /// The port named, else the one USB serial port this machine has.
    pub fn port(&self) -> Result<String> {
        match &self.port {
            Some(p) => Ok(p.clone()),
            None => only_one(
                "serial port",
                "--port",
                pav::rig::transport::usb_serial_ports(),
                "`--port sim` for the simulator",
            ),
        }
    }
}

/// The one device of a kind that was found, said aloud; none or several are refused with the
/// list, so that a capture never films or turns the wrong one.
pub fn only_one(kind: &str, flag: &str, found: Vec<std::path::PathBuf>, otherwise: &str) -> Result<String> {
    match &found[..] {
        [one] => {
            eprintln!("{kind}: {} (the only one; name it with {flag})", one.display());
            Ok(one.display().to_string())
        }
        [] => anyhow::bail!("no {kind} found on this machine: plug it in and name it with {flag}, or use {otherwise}"),
        several => anyhow::bail!(
            "{} {kind}s found, pav does not guess which: name one with {flag} ({})",
            several.len(),
            several.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        ),
    }
}

/// Opens the turntable, starting a simulator first for `--port sim`, in `time`.
pub fn connect(p: &PortArgs, time: SimTime) -> Result<Connected> {
    let timeout = Duration::from_millis(p.timeout_ms);
    let opts = SimOptions { time_scale: p.time_scale, ..SimOptions::default() };
    let port = p.port()?;
    let (table, truth, pty, path) = match (port.as_str(), time) {
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
    Ok(Connected { table, port, truth, _pty: pty })
}

/// A non-zero duration like `28s` or `-28` (negative: the other way round).
pub fn parse_signed_seconds(s: &str) -> Result<f64, String> {
    crate::common::seconds_value(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn one_device_is_taken_and_none_or_several_are_refused_with_the_list() {
        let p = |s: &str| PathBuf::from(s);
        assert_eq!(only_one("serial port", "--port", vec![p("/dev/ttyACM0")], "sim").unwrap(), "/dev/ttyACM0");
        let none = only_one("serial port", "--port", vec![], "`--port sim`").unwrap_err().to_string();
        assert!(none.contains("no serial port found") && none.contains("--port sim"), "{none}");
        let two = only_one("V4L2 camera", "--camera", vec![p("/dev/video0"), p("/dev/video2")], "sim")
            .unwrap_err()
            .to_string();
        assert!(two.contains("2 V4L2 cameras found") && two.contains("/dev/video0, /dev/video2"), "{two}");
    }
}
