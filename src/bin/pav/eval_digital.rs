//! `pav eval-digital`.

use crate::common::Bar;
use crate::scoring::Scoring;
use anyhow::{Context, Result};
use pav::studies::table2::eval_digital;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Optimization config (mesh, views, scene lighting).
    #[arg(long)]
    config: PathBuf,
    /// Texture PNGs to evaluate (named by their folder); `data:NAME` for a manifest entry; or the
    /// folder of a `pav optimize --seeds` run, its seeds pooled into one row and paired per
    /// (seed, view).
    #[arg(long = "texture", short = 't', value_parser = pav::data::arg_path)]
    textures: Vec<PathBuf>,
    /// Random textures of each kind (blocks, the paper's 32×32), pooled per row and per view.
    #[arg(long, default_value_t = 1)]
    random_seeds: u64,
    /// Feature squeezing as an attack detector (Xu et al.): also score each detector behind bit
    /// depth 4 and a 3×3 median, and flag the views whose best car score either moves by more
    /// than the threshold that flags --squeeze-false-flags of the legitimate views (the photo and
    /// the random textures); digital_squeeze.csv and a section of digital.md.
    #[arg(long)]
    squeeze: bool,
    /// With --squeeze: the share of legitimate views flagged.
    #[arg(long, default_value_t = 0.05, requires = "squeeze")]
    squeeze_false_flags: f64,
    #[command(flatten)]
    scoring: Scoring,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/digital")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    if !(0.0..1.0).contains(&a.squeeze_false_flags) {
        anyhow::bail!("--squeeze-false-flags {} must be a share in [0, 1)", a.squeeze_false_flags);
    }
    let cfg = pav::attack::config::OptimizeConfig::load(&a.config)?;
    let record = a
        .scoring
        .record(pav::provenance::Run::start())
        .config(&a.config)
        .inputs(cfg.inputs().iter().chain(&a.textures).map(|p| p.as_path()))
        .setting("random_seeds", a.random_seeds)
        .setting(
            "squeeze",
            if a.squeeze { format!("{} of legitimate views flagged", a.squeeze_false_flags) } else { "off".into() },
        )
        .tool("onnxruntime", pav_onnx::runtime::runtime_version());
    let record_path = a.out.join(pav::provenance::FILE);
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    let squeeze = a.squeeze.then_some(a.squeeze_false_flags);
    let scoring = a.scoring.to_lib(&a.config)?;
    let (md, _) = eval_digital(&a.config, &a.textures, a.random_seeds, &scoring, squeeze, &a.out, &Bar::default())?;
    outln!("{md}");
    eprintln!("wrote {}/digital.csv, digital_views.csv, digital_paired.csv and digital.md", a.out.display());
    Ok(())
}
