//! `pav lofo`.

use crate::common::{ctrl_c_flag, Bar, ShardArgs};
use anyhow::{bail, Context, Result};
use pav::attack::config::OptimizeConfig;
use pav::studies::lofo::{arms, finished, score, train, unit_dir, units};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The arms: recipe configs, each training against every family but one (repeat, or list
    /// them after the flags).
    #[arg(long = "config", required_unless_present = "configs_at")]
    configs: Vec<PathBuf>,
    /// The arms as arguments (accepted as before).
    #[arg(value_name = "CONFIG", hide = true)]
    configs_at: Vec<PathBuf>,
    /// Optimizer seeds of every arm, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0,1,2,3")]
    seeds: Vec<u64>,
    /// The config whose held-out views score the arms (its test photos and `views.pbr_test`).
    #[arg(long, default_value = "configs/studies/lofo/heldout.toml")]
    heldout: PathBuf,
    /// Fixed textures each arm is paired against (a peer's published texture). Repeatable.
    #[arg(long = "reference", value_parser = pav::data::arg_path, default_value = "data:rauca-e2e/RAUCA_E2E.png")]
    references: Vec<PathBuf>,
    /// Random textures of each kind each arm is paired against (each view's mean over them).
    #[arg(long, default_value_t = 4)]
    random_seeds: u64,
    /// A car counts as detected when its score reaches this.
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    #[command(flatten)]
    shard: ShardArgs,
    /// Output folder: without-NAME/seed<S>/ per trained texture (an interrupted run resumes from
    /// it), without-NAME/heldout/ per arm's scoring (kept while its inputs are unchanged), lofo.csv
    /// and lofo.md.
    #[arg(long, short = 'o', default_value = "out/lofo")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let configs: Vec<PathBuf> = a.configs.iter().chain(&a.configs_at).cloned().collect();
    let arms = arms(&configs)?;
    let missing = OptimizeConfig::load(&a.heldout)?.missing_views();
    if !missing.is_empty() {
        let lines: Vec<String> = missing.iter().map(|m| format!("  {m}")).collect();
        bail!("{} needs rendered views that are not there yet:\n{}", a.heldout.display(), lines.join("\n"));
    }
    if a.seeds.is_empty() {
        bail!("--seeds: give at least one");
    }
    let record = pav::provenance::Run::start()
        .inputs(configs.iter().chain([&a.heldout]).chain(&a.references).map(|p| p.as_path()))
        .setting("seeds", a.seeds.iter().map(u64::to_string).collect::<Vec<_>>().join(", "))
        .setting("held_out", arms.iter().map(|a| a.held_out.clone()).collect::<Vec<_>>().join(", "))
        .setting("random_seeds", a.random_seeds)
        .setting("threshold", a.threshold)
        .tool("onnxruntime", pav_onnx::runtime::runtime_version())
        .inputs(arms.iter().flat_map(|a| &a.inputs).map(|p| p.as_path()));
    let units = units(&arms, &a.seeds);
    let shards = a.shard.write_record(record.clone(), &a.out)?;
    if let Some(shards) = shards {
        let named: Vec<pav::shard::Unit> = units
            .iter()
            .map(|&(arm, seed)| pav::shard::Unit {
                what: format!("seed {seed} without {}", arms[arm].held_out),
                dir: unit_dir(&arms[arm], seed),
            })
            .collect();
        pav::shard::gather(&shards, &named, &finished, &a.out)?;
        eprintln!("gathered {} trained textures from {} shards into {}", units.len(), shards.len(), a.out.display());
    } else {
        let root = a.shard.record_dir(&a.out);
        let stop = ctrl_c_flag()?;
        for (i, &(arm, seed)) in units.iter().enumerate() {
            if a.shard.shard.is_some_and(|s| !s.picks(i)) {
                continue;
            }
            let dir = root.join(unit_dir(&arms[arm], seed));
            eprintln!("[{}/{}] seed {seed} without {}", i + 1, units.len(), arms[arm].held_out);
            train(&arms[arm], seed, &dir, &Bar::default(), &stop)?;
        }
        if let Some(s) = a.shard.shard {
            eprintln!("trained shard {s}'s textures into {}; `--merge` joins the shards and scores", root.display());
            return Ok(());
        }
    }
    let rows = score(&arms, &a.seeds, &a.heldout, &a.references, a.random_seeds, a.threshold, &a.out, &Bar::default())?;
    outln!("{}", pav::studies::lofo::markdown(&rows));
    let path = a.out.join(pav::provenance::FILE);
    record.write(&path).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("wrote lofo.csv, lofo.md and each arm's held-out scores (without-NAME/heldout/) in {}", a.out.display());
    Ok(())
}
