//! `pav table1`.

use anyhow::{bail, Result};
use pav::studies::table1::table1_report;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Output folders of `pav crossval`, one row each (or one per label), in this order.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// A run's label (default: its folder's name); give one per run or none. Runs sharing a
    /// label (seeds of one config) make one row, averaged per held-out view.
    #[arg(long = "label")]
    labels: Vec<String>,
    /// The texture of a run that makes its row (default: "optimized", its final texture; e.g.
    /// snapshot-mean-from-100 of a `--curve-mean-from 100` run); give one per run or none.
    #[arg(long = "texture")]
    textures: Vec<String>,
    /// Also pair every row with the row of this label (a variant against the config it varies).
    /// Repeatable.
    #[arg(long)]
    against: Vec<String>,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/table1")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    if !a.labels.is_empty() && a.labels.len() != a.runs.len() {
        bail!("{} labels for {} runs: give one per run or none", a.labels.len(), a.runs.len());
    }
    if !a.textures.is_empty() && a.textures.len() != a.runs.len() {
        bail!("{} textures for {} runs: give one per run or none", a.textures.len(), a.runs.len());
    }
    let runs: Vec<(String, PathBuf, String)> = a
        .runs
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let name = a.labels.get(i).cloned().unwrap_or_else(|| {
                d.file_name().map_or_else(|| d.display().to_string(), |n| n.to_string_lossy().into_owned())
            });
            (name, d.clone(), a.textures.get(i).cloned().unwrap_or_else(|| "optimized".into()))
        })
        .collect();
    outln!("{}", table1_report(&runs, &a.against, &a.out)?);
    eprintln!("wrote table1.md and its CSVs in {}", a.out.display());
    Ok(())
}
