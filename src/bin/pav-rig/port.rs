//! The turntable options that `turntable` and `capture` share, and durations on the command line.

use anyhow::{Context, Result};
use pav::rig::sim::{SimOptions, SimTurntable};
use pav::rig::turntable::Turntable;
use std::time::Duration;

#[derive(clap::Args)]
pub struct PortArgs {
    /// Serial port of the turntable (e.g. /dev/ttyACM0), or `sim` for an in-process simulator.
    #[arg(long, default_value = "/dev/ttyACM0")]
    pub port: String,
    /// Baud rate (ignored by USB-CDC).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Per-command timeout in milliseconds.
    #[arg(long, default_value_t = 1000)]
    timeout_ms: u64,
    /// Simulated time speed-up when --port sim.
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
}

/// Opens the turntable, spawning a simulator first for `--port sim` (kept alive by the caller).
pub fn connect(p: &PortArgs) -> Result<(Option<SimTurntable>, Turntable)> {
    let sim = if p.port == "sim" {
        Some(
            SimTurntable::spawn(SimOptions { time_scale: p.time_scale, ..SimOptions::default() })
                .context("starting the simulated turntable")?,
        )
    } else {
        None
    };
    let path = sim.as_ref().map_or(p.port.clone(), |s| s.path().display().to_string());
    let table = Turntable::open(&path, p.baud, Duration::from_millis(p.timeout_ms))?;
    eprintln!("turntable on {path}: firmware {}, {} microsteps/rev", table.firmware(), table.usteps_per_rev());
    Ok((sim, table))
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
