//! `pav views`.

use crate::common::Bar;
use anyhow::{bail, Context, Result};
use pav::scene::blender::Blender;
use pav::scene::views::{contact_sheet, merge_shards, render_views, ViewsConfig};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Render a config's views with Blender Cycles (resumes where an earlier run stopped).
    Render(RenderArgs),
    /// Join the shard manifests of a view folder into its manifest.csv.
    Merge {
        /// The view folder the shards wrote into.
        dir: PathBuf,
    },
}

#[derive(clap::Args)]
pub struct RenderArgs {
    /// Views config (TOML), e.g. configs/views/ci.toml.
    config: PathBuf,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/views")]
    out: PathBuf,
    /// Render only shard K of N (1-based, views K, K+N, …), e.g. from a job array; `pav views
    /// merge` joins the shards' manifests afterwards.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
}

fn shard(s: &str) -> Result<(usize, usize)> {
    let (k, n) = s.split_once('/').with_context(|| format!("--shard `{s}`: expected K/N, e.g. 2/8"))?;
    let (k, n): (usize, usize) = (k.parse()?, n.parse()?);
    if n == 0 || k == 0 || k > n {
        bail!("--shard {k}/{n}: need 1 ≤ K ≤ N");
    }
    Ok((k, n))
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Render(a) => {
            let cfg = ViewsConfig::load(&a.config)?;
            let shard = a.shard.as_deref().map(shard).transpose()?;
            let blender = Blender::find()?;
            let mut inputs = vec![cfg.mesh.obj.clone()];
            inputs.extend(cfg.mesh.texture.clone());
            let record = pav::provenance::Run::start()
                .config(&a.config)
                .inputs(inputs.iter().map(|p| p.as_path()))
                .setting("shard", a.shard.as_deref().unwrap_or("all"))
                .tool("blender", blender.version());
            let name = match shard {
                Some((k, n)) => format!("run.{k}-of-{n}.toml"),
                None => pav::provenance::FILE.to_string(),
            };
            record.write(&a.out.join(&name)).with_context(|| format!("writing {}", a.out.join(&name).display()))?;
            let s = render_views(&cfg, &a.out, shard, &blender, &Bar::default())?;
            println!(
                "{} views: {} rendered now, {} from an earlier run; manifest {}",
                s.total,
                s.rendered,
                s.resumed,
                s.manifest.display()
            );
            if shard.is_none() {
                println!("contact sheet {}", contact_sheet(&a.out, 12)?.display());
            }
        }
        Cmd::Merge { dir } => {
            let n = merge_shards(dir)?;
            println!("{n} views in {}", dir.join("manifest.csv").display());
        }
    }
    Ok(())
}
