//! `pav print proof`, `pav print chart` and `pav print calibrate`.

use anyhow::{Context, Result};
use clap::Subcommand;
use pav::attack::config::OptimizeConfig;
use pav::attack::setup::region_at;
use pav::image::{save_rgb, Rgb};
use pav::print::channel::{PrintChannel, PrintConfig};
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
    /// The texture as numbered pieces on pages of your paper, at the model's scale.
    ///
    /// The config's textured region split into its connected parts (8-connected), each printed
    /// as the printable sheet has it, with a cut line and its number; parts too large for a
    /// page are tiled with an overlap, parts too narrow to cut are listed to paint by hand.
    /// Writes pages/page-N.png at the DPI, pieces.csv (where each piece goes and what it is)
    /// and by_hand.csv.
    #[command(after_help = "Examples:
  pav print pieces --config configs/optimize/paper.toml --texture out/paper/texture.png --paper a4 -o out/pieces
  pav print pieces --config configs/optimize/paper.toml --texture out/paper/texture.png --paper letter --scale 1:24 -o out/pieces-24")]
    Pieces(crate::print_pieces::Args),
    /// A printable colour chart: ArUco markers at the corners, patches spanning the RGB cube,
    /// greys and a texture's most frequent colours, each with its ID; the layout and intended
    /// colours beside it.
    #[cfg(feature = "video")]
    #[command(after_help = "Examples:
  pav print chart --config configs/optimize/paper.toml --texture out/paper/texture.png --paper a4 -o out/chart")]
    Chart(crate::print_chart::Args),
    /// Fit the colour map of printer + camera from photos of the printed chart (or of the camera
    /// alone from a ColorChecker): affine, second-order polynomial and smoothed 3D LUT compared
    /// on held-out patches; writes calibration.toml, a per-patch CSV and a report PNG.
    #[cfg(feature = "video")]
    #[command(after_help = "Examples:
  pav print calibrate photos/chart-1.jpg photos/chart-2.jpg --chart out/chart -o out/chart/calibration.toml
  pav print calibrate --colorchecker photos/colorchecker.jpg -o out/camera/calibration.toml")]
    Calibrate(crate::print_calibrate::Args),
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Proof { config, texture, printer, out } => proof(config, texture, printer, out),
        Cmd::Pieces(a) => crate::print_pieces::run(a),
        #[cfg(feature = "video")]
        Cmd::Chart(a) => crate::print_chart::run(a),
        #[cfg(feature = "video")]
        Cmd::Calibrate(a) => crate::print_calibrate::run(a),
    }
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
