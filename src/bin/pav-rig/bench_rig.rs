//! `pav-rig bench-rig`.

use crate::common::Bar;
use anyhow::Result;
use pav::rig::bench::bench_rig;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Serial ports to time besides the simulator (e.g. a QEMU pty or /dev/ttyACM0).
    #[arg(long = "port")]
    ports: Vec<String>,
    /// Round trips per link.
    #[arg(long, default_value_t = 500)]
    n: usize,
    /// Simulated time scales for the angle-sync capture (28 s turn / scale of wall time each).
    #[arg(long, value_delimiter = ',', default_value = "1,4,10")]
    time_scales: Vec<f64>,
    /// Output directory (the tracked tables under bench/ are written only when named here).
    #[arg(long, short = 'o', default_value = "out/bench")]
    out: PathBuf,
}

pub fn run(b: &Args) -> Result<()> {
    bench_rig(&b.ports, b.n, &b.time_scales, &b.out, &Bar::default())?;
    eprintln!("wrote {} and {}", b.out.join("rig_latency.csv").display(), b.out.join("rig_angle_sync.csv").display());
    Ok(())
}
