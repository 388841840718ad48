//! `pav bench-step`.

use crate::common::Bar;
use anyhow::{Context, Result};
use pav::attack::bench::time_step;
use pav::detect::DetectorConfig;
use pav::table::write_csv;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Detector config of the white box to time.
    #[arg(long, default_value = "configs/detectors/yolov3-tiny.toml")]
    detector: PathBuf,
    /// Network input sizes (the composite has the same size).
    #[arg(long, value_delimiter = ',', default_value = "416,608")]
    sizes: Vec<usize>,
    /// ONNX Runtime threads (0 = its default, the physical cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Timed repetitions per size (the median is kept).
    #[arg(long, default_value_t = 10)]
    repeats: usize,
    /// Output CSV.
    #[arg(long, short = 'o', default_value = "bench/step.csv")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let cfg = DetectorConfig::load(&a.detector)?;
    let rows = time_step(&cfg, &a.sizes, a.threads, a.repeats, &Bar::default())?;
    if let Some(d) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    write_csv(&a.out, &rows)?;
    eprintln!("wrote {}", a.out.display());
    Ok(())
}
