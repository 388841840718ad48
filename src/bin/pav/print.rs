//! `pav print proof`, `pav print chart` and `pav print calibrate`.

use anyhow::{Context, Result};
use clap::Subcommand;
use pav::attack::config::OptimizeConfig;
use pav::attack::setup::region_at;
use pav::image::{save_rgb, Rgb};
#[cfg(feature = "video")]
use pav::print::calibrate::{calibrate_to, Target};
use pav::print::channel::{PrintChannel, PrintConfig};
#[cfg(feature = "video")]
use pav::print::chart::{frequent_colours, Chart, ChartSpec};
use pav::print::proof::RenderingIntent;
use std::path::{Path, PathBuf};

/// Which printer: the optimize config's `[print]` table, each option overriding it.
#[derive(clap::Args, Debug, Default)]
pub struct PrinterArgs {
    /// The printer's ICC output profile (default: the config's print.profile, else Ghostscript's
    /// CMYK profile).
    #[arg(long, value_parser = pav::data::arg_path)]
    profile: Option<PathBuf>,
    /// Rendering intent on the way to the printer: perceptual, relative-colorimetric,
    /// saturation or absolute-colorimetric (default: the config's, else relative-colorimetric).
    #[arg(long)]
    intent: Option<RenderingIntent>,
    /// Black-point compensation on the way to the printer.
    #[arg(long)]
    black_point_compensation: bool,
    /// A `pav print calibrate` file whose fitted map replaces the profile.
    #[arg(long)]
    calibration: Option<PathBuf>,
}

impl PrinterArgs {
    /// The print settings for `cfg`: its `[print]` table (or the defaults) with these options applied.
    pub fn resolve(&self, cfg: &OptimizeConfig) -> PrintConfig {
        cfg.print.clone().unwrap_or_default().overridden(
            self.profile.as_deref(),
            self.intent,
            self.black_point_compensation,
            self.calibration.as_deref(),
        )
    }
}

#[derive(Subcommand)]
pub enum Cmd {
    /// A texture as the printer prints it (ICC soft proof): writes the proof PNG and says how far
    /// the region's texels move (ΔE2000).
    #[command(after_help = "Examples:
  pav print proof --config configs/optimize/paper.toml --texture out/paper/texture.png -o out/paper/proof.png")]
    Proof {
        /// The optimize config whose region (and [print] table) the texture belongs to.
        #[arg(long)]
        config: PathBuf,
        /// The texture (`data:NAME` for a manifest entry).
        #[arg(long, value_parser = pav::data::arg_path)]
        texture: PathBuf,
        #[command(flatten)]
        printer: PrinterArgs,
        /// Output PNG (the texture as printed, at the texture's size).
        #[arg(long, short = 'o')]
        out: PathBuf,
    },
    /// A printable colour chart: ArUco markers at the corners, patches spanning the RGB cube,
    /// greys and a texture's most frequent colours, each with its ID; the layout and intended
    /// colours beside it.
    #[cfg(feature = "video")]
    #[command(after_help = "Examples:
  pav print chart --config configs/optimize/paper.toml --texture out/paper/texture.png --paper a4 -o out/chart")]
    Chart(ChartArgs),
    /// Fit the colour map of printer + camera from photos of the printed chart (or of the camera
    /// alone from a ColorChecker): affine, second-order polynomial and smoothed 3D LUT compared
    /// on held-out patches; writes calibration.toml, a per-patch CSV and a report PNG.
    #[cfg(feature = "video")]
    #[command(after_help = "Examples:
  pav print calibrate photos/chart-1.jpg photos/chart-2.jpg --chart out/chart -o out/chart/calibration.toml
  pav print calibrate --colorchecker photos/colorchecker.jpg -o out/camera/calibration.toml")]
    Calibrate(CalibrateArgs),
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Proof { config, texture, printer, out } => proof(config, texture, printer, out),
        #[cfg(feature = "video")]
        Cmd::Chart(a) => chart(a),
        #[cfg(feature = "video")]
        Cmd::Calibrate(a) => calibrate(a),
    }
}

#[cfg(feature = "video")]
#[derive(clap::Args)]
pub struct ChartArgs {
    /// Output folder: chart.png (print it at 100 %), chart.toml (layout), chart.csv (intended colours).
    #[arg(long, short = 'o', default_value = "out/chart")]
    out: PathBuf,
    /// Add the most frequent colours of this texture (over its config's region with --config).
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
    /// The optimize config whose region --texture is read over.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Printer resolution of the PNG (its pHYs chunk).
    #[arg(long, default_value_t = 300.0)]
    dpi: f64,
    /// Paper: a4, a3, a5, letter, legal, tabloid, or WIDTHxHEIGHT in millimetres.
    #[arg(long, alias = "page", default_value = "a4")]
    paper: pav::print::paper::Paper,
    /// Patch side in millimetres.
    #[arg(long, default_value_t = 8.0)]
    patch_mm: f64,
}

#[cfg(feature = "video")]
#[derive(clap::Args)]
pub struct CalibrateArgs {
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

#[cfg(feature = "video")]
fn chart(a: &ChartArgs) -> Result<()> {
    let mut spec = ChartSpec { page_mm: a.paper.mm(), dpi: a.dpi, patch_mm: a.patch_mm, ..Default::default() };
    if let Some(t) = &a.texture {
        let tex = Rgb::load(t)?;
        let region = match &a.config {
            Some(c) => region_at(&OptimizeConfig::load(c)?, tex.width, tex.height)?,
            None => None,
        };
        spec.texture_colours = frequent_colours(&tex.rgb, region.as_deref(), usize::MAX);
    }
    let c = Chart::new(&spec)?;
    let png = c.write(&a.out)?;
    let record = pav::provenance::Run::start()
        .inputs(a.texture.iter().chain(&a.config).map(|p| p.as_path()))
        .setting("dpi", a.dpi)
        .setting("page_mm", format!("{}x{}", a.paper.width_mm, a.paper.height_mm))
        .setting("patch_mm", a.patch_mm);
    let record_path = a.out.join(pav::provenance::FILE);
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    let count = |s: &str| c.patches.iter().filter(|p| p.source == s).count();
    outln!(
        "wrote {} ({:.0}×{:.0} mm at {} dpi: print at 100 %, the bar is 10 mm), {} and {}: {} patches ({} spanning the cube, {} greys, {} from the texture, {} to fill)",
        png.display(),
        a.paper.width_mm,
        a.paper.height_mm,
        a.dpi,
        a.out.join(pav::print::chart::LAYOUT_FILE).display(),
        a.out.join(pav::print::chart::PATCHES_FILE).display(),
        c.patches.len(),
        count("cube"),
        count("grey"),
        count("texture"),
        count("fill")
    );
    Ok(())
}

#[cfg(feature = "video")]
fn calibrate(a: &CalibrateArgs) -> Result<()> {
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

/// The texture's proof at its own size, and the region (resampled to it) for the shift.
fn proof(config: &Path, texture: &Path, printer: &PrinterArgs, out: &Path) -> Result<()> {
    let cfg = OptimizeConfig::load(config)?;
    let p = printer.resolve(&cfg);
    let channel = PrintChannel::open(&p)?;
    let tex = Rgb::load(texture)?;
    let printed = channel.printed(&tex.rgb);
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    save_rgb(out, tex.width, tex.height, &printed)?;
    let region = region_at(&cfg, tex.width, tex.height)?;
    outln!(
        "wrote {} ({}, {}{}): the region's {}",
        out.display(),
        p.profile.display(),
        p.intent,
        if p.black_point_compensation { ", black-point compensation" } else { "" },
        channel.shift(&tex.rgb, region.as_deref())
    );
    Ok(())
}
