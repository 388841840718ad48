//! `pav-rig paired`.

use anyhow::{Context, Result};
use pav::eval::compare::read_frames;
use pav::eval::paired::{markdown, paired_frames};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// An `evaluate` output folder (or its frames.csv) that scored paints filmed on the same
    /// shots, one label per paint, e.g. `pav-rig evaluate rauca/*.mp4 pav/*.mp4 --label rauca
    /// --label rauca --label pav --label pav`.
    eval: PathBuf,
    /// The reference label every other label is paired against.
    #[arg(long)]
    against: String,
    /// Output folder: paired.md and paired.csv.
    #[arg(long, short = 'o')]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let frames_path = if a.eval.is_dir() { a.eval.join("frames.csv") } else { a.eval.clone() };
    let frames = read_frames(&frames_path)?;
    let rows = paired_frames(&frames, &a.against)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let md = markdown(&rows);
    let p = a.out.join("paired.md");
    std::fs::write(&p, &md).with_context(|| format!("writing {}", p.display()))?;
    let p = a.out.join("paired.csv");
    let mut w = csv::Writer::from_path(&p).with_context(|| format!("writing {}", p.display()))?;
    for r in &rows {
        w.serialize(r).with_context(|| format!("writing {}", p.display()))?;
    }
    w.flush().with_context(|| format!("writing {}", p.display()))?;
    pav::provenance::Run::start()
        .inputs([frames_path.as_path()])
        .setting("against", &a.against)
        .write(&a.out.join(pav::provenance::FILE))
        .context("writing run.toml")?;
    out!("{md}");
    outln!("\nwrote {} and {}", a.out.join("paired.md").display(), p.display());
    Ok(())
}
