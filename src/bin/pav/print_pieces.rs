//! `pav print pieces`.

use anyhow::{Context, Result};
use pav::attack::config::OptimizeConfig;
use pav::attack::pieces::write_pieces;
use pav::print::paper::{parse_scale, scale_from_length, Paper};
use pav::print::pieces::Spec;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The optimize config whose region the texture covers (its mesh, region and `mesh.parts`).
    #[arg(long, value_parser = pav::data::arg_path)]
    config: PathBuf,
    /// The texture: an optimized texture.png, or any square atlas of the config's mesh.
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: PathBuf,
    /// Paper: a4, a3, a5, letter, legal, tabloid, WIDTHxHEIGHT in millimetres, or roll:WIDTHmm
    /// (a wide-format or wrap printer's roll, cut to the length the pieces take).
    #[arg(long, default_value = "a4")]
    paper: Paper,
    /// Model scale: `20` or `1:20`.
    #[arg(long, default_value = "20", value_parser = parse_scale)]
    scale: f64,
    /// The model's length as measured bumper to bumper, mm: sets the scale instead of --scale
    /// (refused when no common scale is within 15 % of it: probably another car).
    #[arg(long, value_name = "MM", conflicts_with = "scale")]
    model_length: Option<f64>,
    /// Printer resolution of the pages (lowered to four pixels a texel where the texture
    /// carries less: a full-size layout).
    #[arg(long, default_value_t = 300.0)]
    dpi: f64,
    /// Unprinted border on every side of a page, mm.
    #[arg(long, default_value_t = 5.0)]
    margin: f64,
    /// A part narrower than this, mm, is listed to paint by hand in its colour instead of printed.
    #[arg(long, default_value_t = 3.0)]
    min_piece: f64,
    /// How far the tiles of a part too large for one page overlap, mm.
    #[arg(long, default_value_t = 5.0)]
    overlap: f64,
    /// How far each piece's own texels are printed past its cut line, mm (a cut a little off
    /// the line then shows no white paper).
    #[arg(long, default_value_t = 0.0)]
    bleed: f64,
    /// Output folder: pieces.pdf, placement.pdf, pages/page-N.png, placement/, pieces.csv, by_hand.csv, summary.csv and run.toml.
    #[arg(long, short = 'o', default_value = "out/pieces")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let cfg = OptimizeConfig::load(&a.config)?;
    let spec = Spec {
        paper: a.paper,
        margin_mm: a.margin,
        min_mm: a.min_piece,
        overlap_mm: a.overlap,
        bleed_mm: a.bleed,
        dpi: a.dpi,
        ..Spec::default()
    };
    let car_m = cfg.mesh.car_length_m;
    let scale = match a.model_length {
        Some(mm) => scale_from_length(car_m, mm).map_err(anyhow::Error::msg)?,
        None => a.scale,
    };
    outln!("scale 1:{scale:.2}: the {car_m:.2} m car is {:.0} mm long on the model", car_m * 1000.0 / scale);
    let r = write_pieces(&cfg, &a.texture, scale, spec, &a.out)?;
    let l = &r.layout;
    let mut record = pav::provenance::Run::start()
        .config(&a.config)
        // What the layout reads: the mesh (the atlas's size on the car), the region, the texture.
        .inputs([cfg.mesh.obj.as_path(), cfg.mesh.region.as_path(), a.texture.as_path()])
        .setting("paper", a.paper)
        .setting("scale", scale)
        .setting("model_length_mm", a.model_length.map_or("not given".into(), |m| m.to_string()))
        .setting("dpi", a.dpi)
        .setting("margin_mm", a.margin)
        .setting("min_piece_mm", a.min_piece)
        .setting("overlap_mm", a.overlap)
        .setting("bleed_mm", a.bleed);
    record.result("pages", l.pages);
    record.result("pieces", l.pieces.len());
    record.result("by_hand", l.by_hand.len());
    record.result("paper_used", format!("{:.4}", r.paper_used));
    record.result("paper_length_m", format!("{:.3}", r.length_m));
    record.result("dpi", l.spec.dpi);
    record.peak_memory();
    let path = a.out.join(pav::provenance::FILE);
    record.write(&path).with_context(|| format!("writing {}", path.display()))?;
    outln!(
        "{} pieces on {} {} pages at 1:{} (the atlas {:.0} mm across; {:.0} % of the printable paper used)",
        l.pieces.len(),
        l.pages,
        a.paper,
        format!("{scale:.2}").trim_end_matches('0').trim_end_matches('.'),
        l.sheet.atlas_mm,
        100.0 * r.paper_used
    );
    if l.spec.dpi < a.dpi {
        outln!("{} dpi: the texture's texels carry no more at this scale (four pixels a texel)", l.spec.dpi);
    }
    if a.paper.roll {
        outln!("{:.2} m of the {} roll", r.length_m, a.paper);
    }
    if !l.by_hand.is_empty() {
        outln!(
            "{} parts narrower than {} mm to paint by hand in their colour (by_hand.csv)",
            l.by_hand.len(),
            a.min_piece
        );
    }
    outln!("print each page at 100 % (no fit to page) and check its 10 mm and 50 mm bars");
    if !r.front_known {
        outln!("the config names no [mesh] front: the guide takes the mesh's longest axis for it, and names no panels");
    }
    outln!(
        "pdf     {}\npages   {}\npieces  {}\nguide   {} (where each piece goes)",
        r.pdf.display(),
        a.out.join("pages").display(),
        r.csv.display(),
        r.guide.display()
    );
    Ok(())
}
