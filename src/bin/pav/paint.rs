//! `pav paint`.

use anyhow::{Context, Result};
use pav::attack::config::OptimizeConfig;
use pav::attack::export::on_the_car;
use pav::attack::setup::mesh_and_region;
use pav::image::{save_rgb, Rgb};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The optimize config whose car and region the texture belongs to.
    #[arg(long)]
    config: PathBuf,
    /// The texture (an optimize or crossval texture.png, or a peer's, e.g. data:rauca-e2e/RAUCA_E2E.png).
    #[arg(long, value_parser = pav::data::arg_path, required_unless_present = "random", conflicts_with = "random")]
    texture: Option<PathBuf>,
    /// Or the "random" baseline of `pav crossval`: uniform random colours in blocks 1/64 of the
    /// atlas side, drawn from this seed.
    #[arg(long, value_name = "SEED")]
    random: Option<u64>,
    /// The car's paint outside the region (default: the mesh's own map_Kd).
    #[arg(long, value_parser = pav::data::arg_path)]
    base: Option<PathBuf>,
    /// Stick on the texture as printed (the config's [print] table, or the printer options).
    #[arg(long)]
    print: bool,
    #[command(flatten)]
    printer: crate::print::PrinterArgs,
    /// Output PNG, at the base's resolution.
    #[arg(long, short = 'o')]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let cfg = OptimizeConfig::load(&a.config)?;
    let (mesh, region) = mesh_and_region(&cfg)?;
    let base =
        match &a.base {
            Some(b) => b.clone(),
            None => mesh.materials.iter().find_map(|m| m.map_kd.clone()).with_context(|| {
                format!("{} names no map_Kd: give the car's paint with --base", cfg.mesh.obj.display())
            })?,
        };
    let base_img = Rgb::load(&base)?;
    let (mut texture, named) = match (&a.texture, a.random) {
        (Some(t), _) => (Rgb::load(t)?, t.display().to_string()),
        (None, Some(seed)) => {
            let n = cfg.mesh.texture_size;
            let rgb = pav::attack::setup::random_blocks(n, pav::attack::setup::random_block_side(n), seed);
            (Rgb { width: n, height: n, rgb }, format!("random blocks (seed {seed})"))
        }
        (None, None) => unreachable!("clap requires --texture or --random"),
    };
    if a.print {
        let p = a.printer.resolve(&cfg);
        let channel = pav::print::channel::PrintChannel::open(&p)?;
        let region = pav::attack::setup::region_at(&cfg, texture.width, texture.height)?;
        outln!("as printed ({}): the region's {}", p.profile.display(), channel.shift(&texture.rgb, region.as_deref()));
        texture.rgb = channel.printed(&texture.rgb);
    }
    let painted = on_the_car(&base_img, &texture, &region, cfg.mesh.texture_size);
    save_rgb(&a.out, painted.width, painted.height, &painted.rgb)?;
    let on = region.iter().filter(|r| **r > 0.5).count();
    outln!(
        "wrote {} ({}x{}): {} over {on} of {} region texels, {} elsewhere",
        a.out.display(),
        painted.width,
        painted.height,
        named,
        region.len(),
        base.display()
    );
    Ok(())
}
