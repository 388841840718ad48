//! `pav-rig simulate`.

use crate::common::ctrl_c_flag;
use anyhow::Result;
use pav::rig::sim::{fault_seconds, Faults, SimOptions, SimTurntable};
use std::sync::atomic::Ordering;
use std::time::Duration;

#[derive(clap::Args)]
pub struct Args {
    /// Simulated time runs this many times faster than wall time.
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
    /// Probability of dropping each byte the device sends.
    #[arg(long, default_value_t = 0.0)]
    drop_rate: f64,
    /// Probability of a garbage line before each reply.
    #[arg(long, default_value_t = 0.0)]
    garbage_rate: f64,
    /// Latency of every line the table sends, in milliseconds (throughput unchanged).
    #[arg(long, default_value_t = 0)]
    delay_ms: u64,
    /// Raise a stall alarm this many (simulated) seconds into the first motion.
    #[arg(long)]
    stall_after: Option<f64>,
    /// Hang up the line after this many seconds.
    #[arg(long)]
    disconnect_after: Option<f64>,
}

pub fn run(a: &Args) -> Result<()> {
    let secs = |name: &str, s: Option<f64>| s.map(|v| fault_seconds(name, v)).transpose();
    let faults = Faults {
        drop_byte: a.drop_rate,
        garbage_line: a.garbage_rate,
        delay: Duration::from_millis(a.delay_ms),
        stall_after: secs("--stall-after", a.stall_after)?,
        disconnect_after: secs("--disconnect-after", a.disconnect_after)?,
        ..Faults::default()
    };
    let sim = SimTurntable::spawn(SimOptions { time_scale: a.time_scale, faults, ..SimOptions::default() })?;
    outln!("{}", sim.path().display());
    eprintln!("simulated turntable on {} (time x{}); Ctrl-C to stop", sim.path().display(), a.time_scale);
    let stop = ctrl_c_flag()?;
    while !stop.load(Ordering::Relaxed) && sim.is_running() {
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}
