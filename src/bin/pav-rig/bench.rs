//! `pav-rig bench`.

use crate::common::Bar;
use anyhow::{bail, Result};
use pav::detect::load::expand_configs;
use pav::eval::bench::{bench_evaluate, BenchOptions};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Video to score.
    #[arg(long, default_value = "fixtures/carla_orbit.mp4")]
    video: PathBuf,
    /// Detector configs or directories of them.
    #[arg(long = "detectors", short = 'd', alias = "detector", default_value = "configs/detectors")]
    detectors: Vec<PathBuf>,
    /// Strides for the trade-off.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    strides: Vec<usize>,
    /// Second input size, for models that accept any input size (0: none).
    #[arg(long, default_value_t = 320)]
    alt_size: usize,
    /// ONNX Runtime intra-op threads per model copy (0: as evaluate chooses).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Frames scored at once, each by its own copy of the model (0: as evaluate chooses).
    #[arg(long, default_value_t = 0)]
    lanes: usize,
    /// Timed repetitions; the fastest is kept.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Score threshold.
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    /// Output directory (the tracked tables under bench/ are written only when named here).
    #[arg(long, short = 'o', default_value = "out/bench")]
    out: PathBuf,
}

pub fn run(b: &Args) -> Result<()> {
    let given = if b.detectors.is_empty() { vec![PathBuf::from("configs/detectors")] } else { b.detectors.clone() };
    if b.strides.is_empty() || b.strides.contains(&0) {
        bail!("--strides must be positive, got {:?}", b.strides);
    }
    let opts = BenchOptions {
        video: b.video.clone(),
        detectors: expand_configs(&given)?,
        strides: b.strides.clone(),
        alt_size: Some(b.alt_size).filter(|&s| s > 0),
        threads: b.threads,
        lanes: b.lanes,
        repeats: b.repeats,
        threshold: b.threshold,
        out_dir: b.out.clone(),
    };
    bench_evaluate(&opts, &Bar::default())?;
    for f in ["throughput.csv", "tradeoff.csv", "tradeoff.png"] {
        eprintln!("wrote {}", b.out.join(f).display());
    }
    Ok(())
}
