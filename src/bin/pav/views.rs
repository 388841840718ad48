//! `pav views`.

use crate::common::{Bar, ShardArgs};
use anyhow::Result;
#[cfg(feature = "video")]
use anyhow::{bail, Context};
use pav::scene::blender::Blender;
#[cfg(feature = "video")]
use pav::scene::rig::RigConfig;
#[cfg(feature = "video")]
use pav::scene::turntable::{write_raster_videos, write_videos};
use pav::scene::views::{contact_sheet, merge_shards, render_views, Renderer, ViewsConfig};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Render a config's views with Blender Cycles (resumes where an earlier run stopped).
    #[command(after_help = "Examples:
  pav views render --config configs/views/ci.toml -o out/views
  pav views render --config configs/views/ci.toml --shard 1/4 -o out/views")]
    Render(RenderArgs),
    /// Simulated turntable videos: the config's views with the environment turning with the
    /// camera (the car turned in a fixed room), one MP4 + angle sidecar per environment, distance
    /// and elevation, for `pav-rig evaluate` (resumes like render).
    #[cfg(feature = "video")]
    #[command(after_help = "Examples:
  pav views turntable --rig configs/rig/phone-etron.toml --texture out/paper/painted.png -o out/tt_camo
  pav views turntable --rig configs/rig/phone-etron.toml --rasterizer --period 28s -o out/tt_raster")]
    Turntable(TurntableArgs),
}

#[derive(clap::Args)]
pub struct RenderArgs {
    /// Views config (TOML), e.g. configs/views/ci.toml.
    #[arg(long, required_unless_present = "config_at", conflicts_with = "config_at", value_parser = pav::data::arg_path)]
    config: Option<PathBuf>,
    /// The config as the first argument (accepted as before).
    #[arg(value_name = "CONFIG", hide = true, value_parser = pav::data::arg_path)]
    config_at: Option<PathBuf>,
    /// Output folder.
    #[arg(long, short = 'o', default_value = "out/views")]
    out: PathBuf,
    #[command(flatten)]
    shard: ShardArgs,
    /// Body texture instead of the config's (e.g. an optimized texture.png).
    #[arg(long, value_parser = pav::data::arg_path)]
    texture: Option<PathBuf>,
}

#[cfg(feature = "video")]
#[derive(clap::Args)]
pub struct TurntableArgs {
    /// Views config (TOML): the camera's distances and elevations (the paper's polar angles), the
    /// table's angles as azimuths, the room as environments; e.g. configs/views/turntable.toml.
    #[arg(long, conflicts_with_all = ["rig", "config_at"], value_parser = pav::data::arg_path)]
    config: Option<PathBuf>,
    /// The config as the first argument (accepted as before).
    #[arg(value_name = "CONFIG", hide = true, conflicts_with = "rig", value_parser = pav::data::arg_path)]
    config_at: Option<PathBuf>,
    /// Or a rig config (configs/rig/*.toml): the model at model size on the rig's table, filmed
    /// by its camera, with the camera effects it lists; one video per camera position at the
    /// rig's frame size, `render.frames` a turn.
    #[arg(long, value_parser = pav::data::arg_path, required_unless_present_any = ["config", "config_at"])]
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
    /// Seconds per turn in the videos' time stamps, e.g. `28s` or `28` [default: the rig's
    /// table, else 28 s, the paper's].
    #[arg(long, value_parser = crate::common::parse_seconds)]
    period: Option<f64>,
    /// (Blender only) a shard renders its frames; the merge joins them and cuts the videos.
    #[command(flatten)]
    shard: ShardArgs,
}

/// Renders the views config (or the rig config's turntable views) at `config` into `out`
/// (resuming), as `pav views render` does.
#[cfg(feature = "optimize")]
pub fn render_config(config: &std::path::Path, out: &std::path::Path) -> Result<()> {
    let whole = ShardArgs { shard: None, merge: false };
    render(&pav::scene::rig::load_views_config(config)?, config, out, &whole).map(|_| ())
}

/// Renders `cfg` into `out` with provenance, printing the summary: the whole set, one shard of
/// it into its folder, or the merge of the shards. Returns whether `out` now holds every view.
fn render(cfg: &ViewsConfig, config: &std::path::Path, out: &std::path::Path, shard: &ShardArgs) -> Result<bool> {
    // The rasterizer draws without Blender, so a machine without it can still make its views.
    let blender = match cfg.render.renderer {
        Renderer::Cycles => Some(Blender::find()?),
        Renderer::Rasterizer => None,
    };
    let mut inputs = vec![cfg.mesh.obj.clone()];
    inputs.extend(cfg.mesh.texture.clone());
    let mut record = pav::provenance::Run::start()
        .config(config)
        .inputs(inputs.iter().map(|p| p.as_path()))
        .setting("turntable", cfg.render.turntable)
        .setting("rig", cfg.rig.is_some())
        .setting("renderer", format!("{:?}", cfg.render.renderer).to_lowercase());
    if let Some(b) = &blender {
        record = record.tool("blender", b.version());
    }
    if let Some(shards) = shard.write_record(record, out)? {
        let n = merge_shards(cfg, &shards, out)?;
        outln!("{n} views from {} shards; manifest {}", shards.len(), out.join("manifest.csv").display());
    } else {
        let s = render_views(cfg, &shard.record_dir(out), shard.shard, blender.as_ref(), &Bar::default())?;
        outln!(
            "{} views: {} rendered now, {} from an earlier run; manifest {}",
            s.total,
            s.rendered,
            s.resumed,
            s.manifest.display()
        );
        if shard.shard.is_some() {
            return Ok(false);
        }
    }
    outln!("contact sheet {}", contact_sheet(out, 12)?.display());
    Ok(true)
}

pub fn run(c: &Cmd) -> Result<()> {
    match c {
        Cmd::Render(a) => {
            let config = crate::common::config_path(&a.config, &a.config_at);
            let mut cfg = ViewsConfig::load(config)?;
            cfg.mesh.texture = a.texture.clone().or(cfg.mesh.texture);
            render(&cfg, config, &a.out, &a.shard)?;
        }
        #[cfg(feature = "video")]
        Cmd::Turntable(a) => {
            let rig = a.rig.as_deref().map(RigConfig::load).transpose()?;
            let (mut cfg, config, period) = match (a.config.as_ref().or(a.config_at.as_ref()), &a.rig, &rig) {
                (_, Some(path), Some(rig)) => (rig.views_config()?.0, path, rig.table.period_s),
                (Some(c), None, None) => (ViewsConfig::load(c)?, c, 28.0),
                _ => unreachable!("clap requires a config or --rig"),
            };
            cfg.mesh.texture = a.texture.clone().or(cfg.mesh.texture);
            cfg.render.turntable = true;
            let videos = match (&rig, a.rasterizer) {
                (_, true) if a.shard.shard.is_some() || a.shard.merge => {
                    bail!("--rasterizer draws a turntable in seconds: it has no shards")
                }
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
                    if !render(&cfg, config, &a.out, &a.shard)? {
                        outln!("`--merge` with the same arguments joins the shards and cuts the videos");
                        return Ok(());
                    }
                    write_videos(&a.out, a.period.unwrap_or(period))?
                }
            };
            for v in &videos {
                outln!(
                    "{}: {} frames, {} at distance {} and elevation {}°",
                    v.path.display(),
                    v.frames,
                    v.environment,
                    v.distance,
                    v.elevation_deg
                );
            }
            outln!(
                "simulated A_physical (uncalibrated until compared with a real capture):\n  pav-rig evaluate {} --label NAME{} -d configs/detectors -o out/evaluate",
                videos.iter().map(|v| v.path.display().to_string()).collect::<Vec<_>>().join(" "),
                " --label NAME".repeat(videos.len().saturating_sub(1))
            );
        }
    }
    Ok(())
}
