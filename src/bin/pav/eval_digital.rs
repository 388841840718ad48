//! `pav eval-digital`.

use crate::common::Bar;
use crate::Scoring;
use anyhow::{Context, Result};
use pav::experiments::table2::eval_digital;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Optimization config (mesh, views, scene lighting).
    #[arg(long, default_value = "configs/optimize/paper.toml")]
    config: PathBuf,
    /// Texture PNGs to evaluate (named by their folder); `data:NAME` for a manifest entry.
    #[arg(long = "texture", short = 't', value_parser = pav::data::arg_path)]
    textures: Vec<PathBuf>,
    /// Random textures of each kind (blocks, the paper's 32×32), pooled per row and per view.
    #[arg(long, default_value_t = 1)]
    random_seeds: u64,
    #[command(flatten)]
    scoring: Scoring,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/digital")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let cfg = pav::attack::config::OptimizeConfig::load(&a.config)?;
    let record = a
        .scoring
        .record(pav::provenance::Run::start())
        .config(&a.config)
        .inputs(cfg.inputs().iter().chain(&a.textures).map(|p| p.as_path()))
        .setting("random_seeds", a.random_seeds)
        .tool("onnxruntime", pav_onnx::runtime::runtime_version());
    let record_path = a.out.join(pav::provenance::FILE);
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    let md =
        eval_digital(&a.config, &a.textures, a.random_seeds, &a.scoring.to_lib(&a.config)?, &a.out, &Bar::default())?;
    println!("{md}");
    eprintln!("wrote {}/digital.csv, digital_views.csv, digital_paired.csv and digital.md", a.out.display());
    Ok(())
}
