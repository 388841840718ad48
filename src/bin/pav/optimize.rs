//! `pav optimize`.

use crate::common::{ctrl_c_flag, Bar, ShardArgs};
use anyhow::{bail, Context, Result};
use pav::attack::config::OptimizeConfig;
use pav::attack::export::PrintSpec;
use pav::attack::optimize::Finish;
use pav::studies::outputs::{optimize_and_report, OptimizeRun, Prepared};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Optimization config, e.g. configs/optimize/recommended.toml (docs/configs.md says which to start from).
    #[arg(long)]
    config: PathBuf,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/optimize")]
    out: PathBuf,
    /// Continue from the checkpoint in the output folder.
    #[arg(long)]
    resume: bool,
    /// Override the config's epochs (and its `optimizer.steps` budget).
    #[arg(long)]
    epochs: Option<usize>,
    /// Save the texture to <out>/snapshots/stepNNNNNN.png every this many steps (0: never).
    #[arg(long, default_value_t = 0)]
    snapshot_every: u64,
    /// Override the config's render size (views.size).
    #[arg(long)]
    size: Option<usize>,
    /// Model scale of the printable sheet: `20` or `1:20`.
    #[arg(long, default_value = "20", value_parser = pav::print::paper::parse_scale)]
    scale: f64,
    /// Printer resolution of the sheet.
    #[arg(long, default_value_t = 300.0)]
    dpi: f64,
    /// Render the config's missing `views.pbr` folders first (Blender; minutes per hundred views).
    #[arg(long)]
    render_views: bool,
    /// Optimizer seeds, comma-separated: one run per seed into <out>/seed<S> (the seeds a
    /// result is averaged over); with --shard K/N each array task runs its seeds.
    #[arg(long, value_delimiter = ',')]
    seeds: Vec<u64>,
    #[command(flatten)]
    shard: ShardArgs,
}

/// A seed's folder of a `--seeds` run.
fn seed_dir(out: &std::path::Path, seed: u64) -> PathBuf {
    out.join(format!("seed{seed}"))
}

/// The result key a seed's run.toml gets once its run finished.
const FINISHED: &str = "finished";

pub fn run(a: &Args) -> Result<()> {
    if a.seeds.is_empty() && (a.shard.shard.is_some() || a.shard.merge) {
        bail!("--shard and --merge cut a run into its seeds: give them with --seeds");
    }
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
    let stop = ctrl_c_flag()?;
    let p = Prepared::load(&a.config, a.size, &stop)?;
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
    let (bytes, n) = (s.training_bytes() as f64 / 1048576.0, s.training_views().len().max(1) as f64);
    eprintln!(
        "training views hold {bytes:.0} MiB ({:.2} MiB per view){}",
        bytes / n,
        if p.cfg.views.stream {
            "; rendered views are rebuilt from their files at each step (views.stream)"
        } else {
            ""
        }
    );
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
        .setting("resume", a.resume)
        .tool("onnxruntime", pav_onnx::runtime::runtime_version());
    let once = |p: &Prepared, out: &std::path::Path, record: pav::provenance::Run| -> Result<()> {
        let record_path = out.join(pav::provenance::FILE);
        record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
        let run = OptimizeRun {
            out: out.to_path_buf(),
            resume: a.resume,
            epochs: a.epochs,
            snapshot_every: a.snapshot_every,
            print: PrintSpec { scale: a.scale, dpi: a.dpi },
        };
        let r = optimize_and_report(p, &run, &Bar::default(), &stop)?;
        if matches!(r.finish, Finish::Stopped) {
            // Not a success: `pav optimize && pav eval-digital` must not go on with a partial texture.
            bail!("stopped: state saved in {}; run again with --resume", out.join("checkpoint.bin").display());
        }
        let mut record = record;
        record.result(FINISHED, "yes");
        record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
        print_report(&r, p, a, out);
        Ok(())
    };
    if a.seeds.is_empty() {
        return once(&p, &a.out, record.setting("seed", p.cfg.optimizer.seed));
    }
    let seeds = a.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", ");
    let shards = a.shard.write_record(record.clone().setting("seed", &seeds), &a.out)?;
    if let Some(shards) = shards {
        let units: Vec<pav::shard::Unit> = a
            .seeds
            .iter()
            .map(|&s| pav::shard::Unit { what: format!("seed {s}"), dir: format!("seed{s}").into() })
            .collect();
        let finished = |d: &std::path::Path| {
            pav::provenance::Run::read(&d.join(pav::provenance::FILE))
                .is_ok_and(|r| r.result.get(FINISHED).is_some_and(|v| v == "yes"))
        };
        pav::shard::gather(&shards, &units, &finished, &a.out)?;
        eprintln!("gathered {} seeds from {} shards into {}/seed<S>", a.seeds.len(), shards.len(), a.out.display());
        return Ok(());
    }
    let root = a.shard.record_dir(&a.out);
    let mut p = p;
    for (i, &seed) in a.seeds.iter().enumerate() {
        if a.shard.shard.is_some_and(|s| !s.picks(i)) {
            continue;
        }
        p.cfg.optimizer.seed = seed;
        eprintln!("seed {seed}");
        once(&p, &seed_dir(&root, seed), record.clone().setting("seed", seed))?;
    }
    Ok(())
}

/// Prints a finished run's per-view scores, its sheet and print shift, and its files.
fn print_report(r: &pav::studies::outputs::OptimizeReport, p: &Prepared, a: &Args, out: &std::path::Path) {
    outln!(
        "white-box {} car score per view (no EoT): original photo / initial texture / optimized",
        p.wb.first().name()
    );
    for s in &r.scores {
        outln!("  {:5} {:10} {:.3} / {:.3} / {:.3}", s.split, s.view, s.original, s.initial, s.optimized);
    }
    if let Some(sheet) = &r.sheet {
        outln!(
            "printable sheet: {} ({}x{} px at {} dpi): print at 100 % so the atlas is {:.1} mm wide for a 1:{} model (the bar is 10 mm; texel density varies {:.2}x between faces, 10th-90th percentile)",
            out.join("texture_print.png").display(),
            sheet.width_px,
            sheet.height_px,
            a.dpi,
            sheet.atlas_mm,
            a.scale,
            sheet.density_spread
        );
    }
    if let Some(shift) = &r.shift {
        outln!("as printed (print.profile), the region's {shift}");
    }
    eprintln!("wrote {} in {}", r.files.join(", "), out.display());
}
