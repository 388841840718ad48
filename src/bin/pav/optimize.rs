//! `pav optimize`.

use crate::common::{ctrl_c_flag, Bar};
use anyhow::{bail, Context, Result};
use pav::attack::config::OptimizeConfig;
use pav::attack::export::PrintSpec;
use pav::attack::optimize::Finish;
use pav::experiments::outputs::{optimize_and_report, OptimizeRun, Prepared};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Optimization config.
    #[arg(long, default_value = "configs/optimize/paper.toml")]
    config: PathBuf,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/optimize")]
    out: PathBuf,
    /// Continue from the checkpoint in the output folder.
    #[arg(long)]
    resume: bool,
    /// Override the config's epochs.
    #[arg(long)]
    epochs: Option<usize>,
    /// Save the texture to <out>/snapshots/stepNNNNNN.png every this many steps (0: never).
    #[arg(long, default_value_t = 0)]
    snapshot_every: u64,
    /// Override the config's render size (views.size).
    #[arg(long)]
    size: Option<usize>,
    /// Model scale of the printable sheet (20 = 1:20).
    #[arg(long, default_value_t = 20.0)]
    scale: f64,
    /// Printer resolution of the sheet.
    #[arg(long, default_value_t = 300.0)]
    dpi: f64,
    /// Render the config's missing `views.pbr` folders first (Blender; minutes per hundred views).
    #[arg(long)]
    render_views: bool,
}

pub fn run(a: &Args) -> Result<()> {
    let missing = OptimizeConfig::load(&a.config)?.missing_views();
    if !missing.is_empty() && !a.render_views {
        let lines: Vec<String> = missing.iter().map(|m| format!("  {m}")).collect();
        bail!(
            "{} needs rendered views that are not there yet (or pass --render-views to render them now):\n{}",
            a.config.display(),
            lines.join("\n")
        );
    }
    for m in &missing {
        let Some(views) = &m.config else { bail!("{m}") };
        eprintln!("rendering {} into {}", views.display(), m.dir.display());
        crate::views::render_config(views, &m.dir)?;
    }
    let p = Prepared::load(&a.config, a.size)?;
    let s = &p.setup;
    eprintln!(
        "{} training (+{} synthetic, +{} rendered) and {} held-out views at {}², texture {}² ({} optimizable values, {:.1} % of the atlas), scene {}; prepared in {:.1} s",
        s.train.len(),
        s.synthetic.len(),
        s.pbr.len(),
        s.test.len(),
        p.cfg.views.size,
        s.tex_size,
        s.region_values.len(),
        100.0 * p.region_share(),
        s.scene.describe(),
        p.seconds
    );
    if let Some(k) = &p.pbr_kept {
        eprintln!("views.pbr: {k}");
    }
    let held_out = s.plates_held_out();
    if held_out > 0 {
        eprintln!("views.pbr: {held_out} views over held-out photos' backgrounds left out of training");
    }
    let [none, one, more] = s.region_views_shares();
    eprintln!(
        "region texels read by no training view {:.1} %, by one {:.1} %, by two or more {:.1} %",
        100.0 * none,
        100.0 * one,
        100.0 * more
    );
    let record = pav::provenance::Run::start()
        .config(&a.config)
        .inputs(p.cfg.inputs().iter().map(|p| p.as_path()))
        .setting("seed", p.cfg.optimizer.seed)
        .setting("resume", a.resume)
        .tool("onnxruntime", pav_onnx::runtime::runtime_version());
    let record_path = a.out.join(pav::provenance::FILE);
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    let stop = ctrl_c_flag()?;
    let run = OptimizeRun {
        out: a.out.clone(),
        resume: a.resume,
        epochs: a.epochs,
        snapshot_every: a.snapshot_every,
        print: PrintSpec { scale: a.scale, dpi: a.dpi },
    };
    let r = optimize_and_report(&p, &run, &Bar::default(), &stop)?;
    if matches!(r.finish, Finish::Stopped) {
        // Not a success: `pav optimize && pav eval-digital` must not go on with a partial texture.
        bail!("stopped: state saved in {}; run again with --resume", a.out.join("checkpoint.bin").display());
    }
    println!(
        "white-box {} car score per view (no EoT): original photo / initial texture / optimized",
        p.wb.first().name()
    );
    for s in &r.scores {
        println!("  {:5} {:10} {:.3} / {:.3} / {:.3}", s.split, s.view, s.original, s.initial, s.optimized);
    }
    if let Some(sheet) = r.sheet {
        println!(
            "printable sheet: {} ({}x{} px at {} dpi): print at 100 % so the atlas is {:.1} mm wide for a 1:{} model (the bar is 10 mm; texel density varies {:.2}x between faces, 10th-90th percentile)",
            a.out.join("texture_print.png").display(),
            sheet.width_px,
            sheet.height_px,
            a.dpi,
            sheet.atlas_mm,
            a.scale,
            sheet.density_spread
        );
    }
    if let Some(shift) = r.shift {
        println!("as printed (print.profile), the region's {shift}");
    }
    eprintln!("wrote {} in {}", r.files.join(", "), a.out.display());
    Ok(())
}
