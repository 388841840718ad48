//! `pav adv-train`.

use crate::common::Bar;
use anyhow::{Context, Result};
use pav::studies::advtrain::{adv_train, AdvTrainConfig};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The recipe (e.g. configs/advtrain/yolox_nano.toml).
    #[arg(long = "config", required_unless_present = "config_at", conflicts_with = "config_at")]
    config: Option<PathBuf>,
    /// The recipe as the first argument (accepted as before).
    #[arg(value_name = "CONFIG", hide = true)]
    config_at: Option<PathBuf>,
    /// Another adversarial texture to tune on (repeat for several); the recipe's sha256 is then
    /// not checked, since the model is another.
    #[arg(long = "train-texture", value_parser = pav::data::arg_path)]
    train_textures: Vec<PathBuf>,
    /// Another texture to score on the held-out views, `[NAME=]PATH` (repeat for several; the
    /// textures of one NAME, e.g. a recipe's seeds, pool into one row; default name: the folder).
    #[arg(long = "test-texture", value_name = "[NAME=]PATH", value_parser = named_texture)]
    test_textures: Vec<(String, PathBuf)>,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/advtrain")]
    out: PathBuf,
}

pub fn run(a: &Args) -> Result<()> {
    let recipe = crate::common::config_path(&a.config, &a.config_at);
    let mut cfg = AdvTrainConfig::load(recipe)?;
    let check = cfg.sha256.clone().filter(|_| a.train_textures.is_empty());
    cfg.train_textures.extend(a.train_textures.iter().cloned());
    let mut record = pav::provenance::Run::start()
        .config(recipe)
        .inputs(cfg.inputs().iter().chain(a.test_textures.iter().map(|t| &t.1)).map(|p| p.as_path()))
        .setting("steps", cfg.steps)
        .setting("lr", cfg.lr)
        .setting("l2", cfg.l2)
        .tool("onnxruntime", pav_onnx::runtime::runtime_version());
    let record_path = a.out.join(pav::provenance::FILE);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    let done = adv_train(&cfg, &a.test_textures, &a.out, &Bar::default())?;
    record.result("sha256", &done.sha256);
    record.result("finished", "yes");
    record.write(&record_path).with_context(|| format!("writing {}", record_path.display()))?;
    outln!("{}", done.markdown);
    eprintln!(
        "wrote {} (sha256 {}) and its detector config {}; loss {:.4} → {:.4}",
        done.model.display(),
        done.sha256,
        done.config.display(),
        done.loss.0,
        done.loss.1
    );
    if let Some(want) = check {
        anyhow::ensure!(
            want == done.sha256,
            "the rebuilt model's sha256 is {}, the recipe's {want}: the tuned weights differ (another ONNX \
             Runtime or CPU computes the features a little differently); {} is kept",
            done.sha256,
            done.model.display()
        );
        eprintln!("sha256 matches the recipe's");
    }
    Ok(())
}

/// `NAME=PATH` or `PATH` (named by its folder, as `eval-digital` names textures).
fn named_texture(s: &str) -> Result<(String, PathBuf), String> {
    let (name, path) = match s.split_once('=') {
        Some((n, p)) if !n.is_empty() && !n.contains('/') => (Some(n.to_string()), p),
        _ => (None, s),
    };
    let path = pav::data::arg_path(path)?;
    Ok((name.unwrap_or_else(|| pav::studies::table2::texture_name(&path)), path))
}
