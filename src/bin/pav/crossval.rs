//! `pav crossval`.

use crate::common::{ctrl_c_flag, Bar, ShardArgs};
use crate::scoring::Scoring;
use anyhow::{Context, Result};
use pav::studies::crossval::{crossval_report, CrossvalJob, Cut};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Optimization config; its training and held-out views are pooled and re-split.
    #[arg(long)]
    config: PathBuf,
    /// Number of folds (default: one per view, leave-one-out).
    #[arg(long)]
    folds: Option<usize>,
    /// Random textures per fold (pooled as "random").
    #[arg(long, default_value_t = 5)]
    random_seeds: u64,
    /// Fixed textures scored beside the optimized one on every fold (e.g. a peer's published
    /// texture, `data:rauca-e2e/RAUCA_E2E.png`); any size, resampled to the atlas. Repeatable.
    #[arg(long = "reference", value_parser = pav::data::arg_path)]
    references: Vec<PathBuf>,
    /// Rendered views over FCA's photos' plates (a `pav views render` folder with `[plates]`,
    /// e.g. out/views_etron_plates_wide): each scored in the fold that holds its photo out, into
    /// <out>/plates (a folder `pav table1` reads). Repeatable.
    #[arg(long = "held-out-views")]
    held_out_views: Vec<PathBuf>,
    /// Snapshot each fold's texture every N steps and score the snapshots on the fold's photos:
    /// the held-out and training curves in crossval.md, crossval_curve.csv and .png (0: none).
    #[arg(long, default_value_t = 0)]
    curve_every: u64,
    /// With --curve-every: also score each fold's pixel mean of its snapshots from this step to
    /// its end (averaged iterates against the final texture).
    #[arg(long)]
    curve_mean_from: Option<u64>,
    /// Optimizer seeds, comma-separated: each seed's cross-validation goes into <out>/seed<S>
    /// (a folder `pav table1` reads; give the folders one --label to average the seeds). Default:
    /// the config's seed, into <out> itself.
    #[arg(long, value_delimiter = ',')]
    seeds: Vec<u64>,
    #[command(flatten)]
    shard: ShardArgs,
    #[command(flatten)]
    scoring: Scoring,
    /// Output folder; an interrupted run resumes from it.
    #[arg(long, short = 'o', default_value = "out/crossval")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let cfg = pav::attack::config::OptimizeConfig::load(&a.config)?;
    let seeds = if a.seeds.is_empty() {
        cfg.optimizer.seed.to_string()
    } else {
        a.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", ")
    };
    let record = a
        .scoring
        .record(pav::provenance::Run::start())
        .config(&a.config)
        .inputs(cfg.inputs().iter().chain(&a.references).map(|p| p.as_path()))
        .setting("seed", seeds)
        .setting("folds", a.folds.map_or("one per view".to_string(), |k| k.to_string()))
        .setting("random_seeds", a.random_seeds)
        .setting(
            "held_out_views",
            a.held_out_views.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "),
        )
        .setting("curve_every", a.curve_every)
        .setting("curve_mean_from", a.curve_mean_from.map_or("none".to_string(), |m| m.to_string()))
        .tool("onnxruntime", pav_onnx::runtime::runtime_version());
    let shards = a.shard.write_record(record.clone(), &a.out)?;
    if a.shard.shard.is_none() {
        // Each seed's folder is a crossval run of its own (`pav table1` reads it, `eval-digital`
        // finds the config of a fold's texture through it), so it gets its own record.
        for s in &a.seeds {
            let path = a.out.join(format!("seed{s}")).join(pav::provenance::FILE);
            record.clone().setting("seed", s).write(&path).with_context(|| format!("writing {}", path.display()))?;
        }
    }
    let stop = ctrl_c_flag()?;
    let job = CrossvalJob {
        folds: a.folds,
        random_seeds: a.random_seeds,
        references: a.references.clone(),
        rendered: a.held_out_views.clone(),
        curve: pav::studies::curve::CurveOptions { every: a.curve_every, mean_from: a.curve_mean_from },
        seeds: a.seeds.clone(),
        cut: match (a.shard.shard, shards) {
            (Some(s), _) => Cut::Shard(s),
            (None, Some(shards)) => Cut::Merge(shards),
            (None, None) => Cut::Whole,
        },
    };
    let md = crossval_report(&a.config, &job, &a.scoring.to_lib(&a.config)?, &a.out, &Bar::default(), &stop)?;
    outln!("{md}");
    match a.shard.shard {
        Some(s) => eprintln!("wrote shard {s}'s folds into {}; `--merge` joins the shards", s.dir(&a.out).display()),
        None => eprintln!(
            "wrote crossval.md, its CSVs (scores, views, boxes, pairs) and a folder per fold in {}",
            a.out.display()
        ),
    }
    Ok(())
}
