//! `pav bench-step`.

use crate::common::Bar;
use anyhow::{Context, Result};
use pav::attack::bench::{time_step, StepBench};
use pav::detect::DetectorConfig;
use pav::table::write_csv;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Detector config of the white box to time.
    #[arg(long = "detectors", short = 'd', alias = "detector", default_value = "configs/detectors/yolov3-tiny.toml")]
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
    /// Differentiate the float surrogate of a dynamically quantized model (YOLOv8n, DEIMv2).
    #[arg(long)]
    surrogate: bool,
    /// Also time RAUCA-E2E's loss with the IoU weight (`loss.iou`: the boxes read every step)
    /// beside the paper's means.
    #[arg(long)]
    iou: bool,
    /// Also time that loss with its weight differentiated through the boxes (`loss.box_gradient`).
    #[arg(long)]
    box_gradient: bool,
    /// Output CSV.
    #[arg(long, short = 'o', default_value = "out/bench/step.csv")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let cfg = DetectorConfig::load(&a.detector)?;
    let mut rows = Vec::new();
    // Size by size, the two losses one after the other, so that a change of load hits both.
    for &size in &a.sizes {
        let mut losses = vec![(false, false)];
        losses.extend(a.iou.then_some((true, false)));
        losses.extend(a.box_gradient.then_some((true, true)));
        for (iou, box_gradient) in losses {
            let b = StepBench { threads: a.threads, repeats: a.repeats, surrogate: a.surrogate, iou, box_gradient };
            rows.extend(time_step(&cfg, &[size], b, &Bar::default())?);
        }
    }
    if let Some(d) = a.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    write_csv(&a.out, &rows)?;
    eprintln!("wrote {}", a.out.display());
    Ok(())
}
