//! `pav doctor`.

use anyhow::Result;
use pav::doctor::{checks, main_job_can_run, Standing};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Detector configs to load, as the main job does.
    #[arg(long, short = 'd', default_value = "configs/detectors")]
    detectors: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let all = checks(&a.detectors);
    let width = all.iter().map(|c| c.piece.len()).max().unwrap_or(0);
    for c in &all {
        let mark = match c.status {
            Standing::Ok => "ok",
            Standing::Missing => "MISSING",
            Standing::Absent => "none",
        };
        outln!("{mark:<7} {:width$}  {}", c.piece, c.found);
        if let Some(fix) = &c.fix {
            outln!("{:7} {:width$}  fix: {fix}", "", "");
        }
    }
    if main_job_can_run(&all) {
        outln!("the main job can run (pav-rig evaluate fixtures/turntable.mp4 -o out/evaluate)");
        Ok(())
    } else {
        outln!("the main job cannot run: fix each MISSING line it needs (ONNX Runtime, OpenCV, detectors)");
        std::process::exit(1);
    }
}
