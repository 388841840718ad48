//! `pav eval-digital`.

use crate::common::Bar;
use crate::Scoring;
use anyhow::Result;
use pav::experiments::table2::eval_digital;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Optimization config (mesh, views, scene lighting).
    #[arg(long, default_value = "configs/optimize/paper.toml")]
    config: PathBuf,
    /// Texture PNGs to evaluate (named by their folder).
    #[arg(long = "texture", short = 't')]
    textures: Vec<PathBuf>,
    #[command(flatten)]
    scoring: Scoring,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/digital")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let md = eval_digital(&a.config, &a.textures, &a.scoring.to_lib(), &a.out, &Bar::default())?;
    println!("{md}");
    eprintln!("wrote {}/digital.csv and digital.md", a.out.display());
    Ok(())
}
