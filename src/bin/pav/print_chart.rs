//! `pav print chart`.

use anyhow::{Context, Result};
use pav::attack::config::OptimizeConfig;
use pav::attack::setup::region_at;
use pav::image::Rgb;
use pav::print::chart::{frequent_colours, Chart, ChartSpec};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Output folder: chart.pdf and chart.png (print one at 100 %), chart.toml (layout), chart.csv
    /// (intended colours).
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

pub fn run(a: &Args) -> Result<()> {
    if a.paper.roll {
        anyhow::bail!("a chart goes on a sheet, not a roll: give --paper a4 (or the sheet size the pieces print on)");
    }
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
