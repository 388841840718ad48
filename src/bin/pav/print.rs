//! `pav print`: the print channel's tools.

use anyhow::{Context, Result};
use clap::Subcommand;
use pav::attack::config::OptimizeConfig;
use pav::attack::setup::mesh_and_region;
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
}

impl PrinterArgs {
    /// The print settings for `cfg`: its `[print]` table (or the defaults) with these options applied.
    pub fn resolve(&self, cfg: &OptimizeConfig) -> PrintConfig {
        let mut p = cfg.print.clone().unwrap_or_default();
        if let Some(f) = &self.profile {
            p.profile = f.clone();
        }
        if let Some(i) = self.intent {
            p.intent = i;
        }
        p.black_point_compensation |= self.black_point_compensation;
        p
    }
}

#[derive(Subcommand)]
pub enum Cmd {
    /// A texture as the printer prints it (ICC soft proof): writes the proof PNG and says how far
    /// the region's texels move (ΔE2000).
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
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Proof { config, texture, printer, out } => proof(config, texture, printer, out),
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
    println!(
        "wrote {} ({}, {}{}): the region's {}",
        out.display(),
        p.profile.display(),
        p.intent,
        if p.black_point_compensation { ", black-point compensation" } else { "" },
        channel.shift(&tex.rgb, region.as_deref())
    );
    Ok(())
}

/// The config's region at a texture's size (None when the texture is not square: every texel counts).
pub fn region_at(cfg: &OptimizeConfig, width: usize, height: usize) -> Result<Option<Vec<f32>>> {
    if width != height {
        return Ok(None);
    }
    let mut c = cfg.clone();
    c.mesh.texture_size = width;
    Ok(Some(mesh_and_region(&c)?.1))
}
