//! `pav views`.

use crate::common::Bar;
use anyhow::{bail, Context, Result};
use pav::scene::blender::Blender;
#[cfg(feature = "video")]
use pav::scene::rig::RigConfig;
#[cfg(feature = "video")]
use pav::scene::turntable::{write_raster_videos, write_videos};
use pav::scene::views::{contact_sheet, merge_shards, render_views, ViewsConfig};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Render a config's views with Blender Cycles (resumes where an earlier run stopped).
    Render(RenderArgs),
    /// Simulated turntable videos: the config's views with the environment turning with the
    /// camera (the car turned in a fixed room), one MP4 + angle sidecar per environment, distance
    /// and elevation, for `pav-rig evaluate` (resumes like render).
    #[cfg(feature = "video")]
    Turntable(TurntableArgs),
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
    /// Body texture instead of the config's (e.g. an optimized texture.png).
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
}

#[cfg(feature = "video")]
#[derive(clap::Args)]
pub struct TurntableArgs {
    /// Views config (TOML): the camera's distances and elevations (the paper's polar angles), the
    /// table's angles as azimuths, the room as environments; e.g. configs/views/turntable.toml.
    #[arg(required_unless_present = "rig", conflicts_with = "rig")]
    config: Option<PathBuf>,
    /// Or a rig config (configs/rig/*.toml): the model at model size on the rig's table, filmed
    /// by its camera, with the camera effects it lists; one video per camera position at the
    /// rig's frame size, `render.frames` a turn.
    #[arg(long, value_parser = pav::data::arg_path)]
    rig: Option<PathBuf>,
    /// Output folder: views/, manifest.csv and videos/.
    #[arg(long, short = 'o', default_value = "out/turntable")]
    out: PathBuf,
    /// Body texture instead of the config's (e.g. an optimized texture.png).
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
    /// With --rig: draw the frames with pav's rasterizer (Phong under one light, no Cycles) instead
    /// of Blender: the same angles, effects and file names, in seconds instead of minutes.
    #[arg(long, requires = "rig")]
    rasterizer: bool,
    /// Seconds per turn in the videos' time stamps [default: the rig's table, else 28 s, the
    /// paper's].
    #[arg(long)]
    period: Option<f64>,
}

/// Renders the views config at `config` into `out` (resuming), as `pav views render` does.
#[cfg(feature = "optimize")]
pub fn render_config(config: &std::path::Path, out: &std::path::Path) -> Result<()> {
    render(&ViewsConfig::load(config)?, config, out, None)
}

/// Renders `cfg` into `out` with provenance, printing the summary.
fn render(
    cfg: &ViewsConfig,
    config: &std::path::Path,
    out: &std::path::Path,
    shard: Option<(usize, usize)>,
) -> Result<()> {
    let blender = Blender::find()?;
    let mut inputs = vec![cfg.mesh.obj.clone()];
    inputs.extend(cfg.mesh.texture.clone());
    let record = pav::provenance::Run::start()
        .config(config)
        .inputs(inputs.iter().map(|p| p.as_path()))
        .setting("shard", shard.map_or("all".to_string(), |(k, n)| format!("{k}/{n}")))
        .setting("turntable", cfg.render.turntable)
        .setting("rig", cfg.rig.is_some())
        .tool("blender", blender.version());
    let name = match shard {
        Some((k, n)) => format!("run.{k}-of-{n}.toml"),
        None => pav::provenance::FILE.to_string(),
    };
    record.write(&out.join(&name)).with_context(|| format!("writing {}", out.join(&name).display()))?;
    let s = render_views(cfg, out, shard, &blender, &Bar::default())?;
    println!(
        "{} views: {} rendered now, {} from an earlier run; manifest {}",
        s.total,
        s.rendered,
        s.resumed,
        s.manifest.display()
    );
    if shard.is_none() {
        println!("contact sheet {}", contact_sheet(out, 12)?.display());
    }
    Ok(())
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
            let mut cfg = ViewsConfig::load(&a.config)?;
            cfg.mesh.texture = a.texture.clone().or(cfg.mesh.texture);
            render(&cfg, &a.config, &a.out, a.shard.as_deref().map(shard).transpose()?)?;
        }
        #[cfg(feature = "video")]
        Cmd::Turntable(a) => {
            let rig = a.rig.as_deref().map(RigConfig::load).transpose()?;
            let (mut cfg, config, period) = match (&a.config, &a.rig, &rig) {
                (_, Some(path), Some(rig)) => (rig.views_config()?.0, path, rig.table.period_s),
                (Some(c), None, None) => (ViewsConfig::load(c)?, c, 28.0),
                _ => unreachable!("clap requires a config or --rig"),
            };
            cfg.mesh.texture = a.texture.clone().or(cfg.mesh.texture);
            cfg.render.turntable = true;
            let videos = match (&rig, a.rasterizer) {
                (Some(rig), true) => {
                    let record = pav::provenance::Run::start()
                        .config(config)
                        .inputs(rig.inputs().iter().chain(&a.texture).map(|p| p.as_path()))
                        .setting("backend", "rasterizer")
                        .setting("rig", true);
                    record.write(&a.out.join(pav::provenance::FILE)).context("writing run.toml")?;
                    write_raster_videos(rig, a.texture.as_deref(), &a.out, a.period.unwrap_or(period))?
                }
                _ => {
                    render(&cfg, config, &a.out, None)?;
                    write_videos(&a.out, a.period.unwrap_or(period))?
                }
            };
            for v in &videos {
                println!(
                    "{}: {} frames, {} at distance {} and elevation {}°",
                    v.path.display(),
                    v.frames,
                    v.environment,
                    v.distance,
                    v.elevation_deg
                );
            }
            println!(
                "simulated A_physical (uncalibrated until compared with a real capture):\n  pav-rig evaluate {} --label NAME{} -d configs/detectors -o out/evaluate",
                videos.iter().map(|v| v.path.display().to_string()).collect::<Vec<_>>().join(" "),
                " --label NAME".repeat(videos.len().saturating_sub(1))
            );
        }
        Cmd::Merge { dir } => {
            let n = merge_shards(dir)?;
            println!("{n} views in {}", dir.join("manifest.csv").display());
        }
    }
    Ok(())
}
