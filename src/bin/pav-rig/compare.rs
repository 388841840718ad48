//! `pav-rig compare`.

use anyhow::{bail, Context, Result};
use pav::eval::compare::{compare, csv_rows, markdown, read_frames};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// An `evaluate` output folder (or its frames.csv) that scored the real capture and its
    /// simulation under two labels, e.g. `pav-rig evaluate real.mp4 sim_e0.mp4 sim_e20.mp4
    /// --label real --label sim --label sim`.
    eval: PathBuf,
    /// The real capture's label.
    #[arg(long)]
    real: String,
    /// The simulation's label.
    #[arg(long)]
    sim: String,
    /// Angle sectors a turn is split into.
    #[arg(long, default_value_t = 12)]
    sectors: usize,
    /// Degrees to add to the real capture's angles to put them in the simulation's [default:
    /// found, the whole degree that best matches the per-angle car scores].
    #[arg(long, allow_hyphen_values = true)]
    offset: Option<f64>,
    /// Output folder: compare.md and compare.csv.
    #[arg(long, short = 'o')]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    if !(1..=360).contains(&a.sectors) {
        bail!("--sectors must lie in 1..=360, not {}", a.sectors);
    }
    if a.offset.is_some_and(|o| !o.is_finite()) {
        bail!("--offset must be a number of degrees");
    }
    let frames_path = if a.eval.is_dir() { a.eval.join("frames.csv") } else { a.eval.clone() };
    let frames = read_frames(&frames_path)?;
    let c = compare(&frames, &a.real, &a.sim, a.sectors, a.offset)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let md = markdown(&c, &a.real, &a.sim);
    for (name, text) in [("compare.md", md.clone()), ("compare.csv", csv_rows(&c))] {
        let p = a.out.join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))?;
    }
    let mut record = pav::provenance::Run::start()
        .inputs([frames_path.as_path()])
        .setting("real", &a.real)
        .setting("sim", &a.sim)
        .setting("sectors", a.sectors);
    record.result("offset_deg", c.offset_deg);
    record.write(&a.out.join(pav::provenance::FILE)).context("writing run.toml")?;
    out!("{md}");
    outln!("\nwrote {} and {}", a.out.join("compare.md").display(), a.out.join("compare.csv").display());
    Ok(())
}
