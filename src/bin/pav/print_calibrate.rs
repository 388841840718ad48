//! `pav print calibrate`.

use anyhow::{Context, Result};
use pav::print::calibrate::{calibrate_to, Target};
use pav::print::chart::Chart;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Photos of the printed chart (or videos of it, e.g. on the turntable: a dozen frames each are read).
    #[arg(required = true, value_parser = pav::data::arg_path)]
    photos: Vec<PathBuf>,
    /// The chart's folder (`pav print chart -o`).
    #[arg(long, conflicts_with = "colorchecker")]
    chart: Option<PathBuf>,
    /// The photos show an X-Rite ColorChecker Classic, on a sheet with four ArUco markers
    /// (DICT_4X4_50, IDs 0–3) or alone (found by OpenCV's mcc): fit the camera alone against
    /// the chart's published values.
    #[arg(long)]
    colorchecker: bool,
    /// The ColorChecker's published CIELAB (D50) values (id,square,Lab_l,Lab_a,Lab_b).
    #[arg(long, alias = "reference", value_parser = pav::data::arg_path, default_value = "data:charts/reference/jtvd_reference_values.csv")]
    lab: PathBuf,
    /// Refuse a fit whose held-out median ΔE2000 exceeds this.
    #[arg(long, default_value_t = 5.0)]
    max_delta_e: f64,
    /// Keep a fit above --max-delta-e (the bound and the miss are written into the file).
    #[arg(long)]
    force: bool,
    /// Output calibration file; the per-patch CSV and the report PNG go beside it.
    #[arg(long, short = 'o', default_value = "out/calibration/calibration.toml")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let chart = a.chart.as_ref().map(|c| Chart::load(c)).transpose()?;
    let target = match (&chart, a.colorchecker) {
        (Some(c), _) => Target::Chart(c),
        (None, true) => Target::ColorChecker { reference: &a.lab },
        (None, false) => anyhow::bail!("name the chart the photos show: --chart DIR (pav's) or --colorchecker"),
    };
    let (cal, [csv, png]) = calibrate_to(target, &a.photos, a.max_delta_e, a.force, &a.out)?;
    let record = pav::provenance::Run::start()
        .inputs(a.photos.iter().map(|p| p.as_path()))
        .inputs(
            a.chart
                .iter()
                .map(|c| c.join(pav::print::chart::PATCHES_FILE))
                .collect::<Vec<_>>()
                .iter()
                .map(|p| p.as_path()),
        )
        .inputs(a.colorchecker.then_some(a.lab.as_path()))
        .setting("max_delta_e", a.max_delta_e)
        .setting("force", a.force)
        .tool("opencv", pav::video::opencv_version());
    let record_path = a.out.with_file_name(pav::provenance::FILE);
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    let r = cal.residual();
    for h in &cal.held_out {
        outln!(
            "  {:7} held-out ΔE2000 median {:.2}, p90 {:.2}, max {:.2}",
            format!("{:?}", h.model),
            h.median,
            h.p90,
            h.max
        );
    }
    for how in pav::table::unique(cal.found.iter().cloned()) {
        outln!("  {how}");
    }
    outln!(
        "kept {:?} ({} map from {} patches; {} clipped and {} unreadable left out){}",
        r.model,
        cal.measures,
        cal.patches,
        cal.clipped.len(),
        cal.unreadable.len(),
        if cal.forced { format!("; above the bound {} (--force)", cal.bound) } else { String::new() }
    );
    outln!("wrote {}, {} and {}", a.out.display(), csv.display(), png.display());
    Ok(())
}
