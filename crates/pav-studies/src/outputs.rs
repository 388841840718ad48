//! A whole `pav optimize` run and what it leaves behind besides the checkpoint: the region and
//! texture PNGs (and the texture as printed, with `[print]`), loss and score curves, a
//! before/after preview of every view, the white-box scores per view, and the printable sheet.

use super::{create_dir, ExperimentError};
use pav_attack::config::OptimizeConfig;
use pav_attack::export::{atlas_side_m, write_sheet, PrintSpec, WrittenSheet};
use pav_attack::optimize::{optimize_texture, Finish, RunOptions, StepLog, LAST_ITERATE};
use pav_attack::setup::{PbrKept, Setup};
use pav_attack::view::TrainView;
use pav_attack::whitebox::{Ensemble, WhiteBox, WhiteBoxError};
use pav_core::image::{halve, save_rgb, tile, ImageError};
use pav_core::plot::{loss_curve, PlotError};
use pav_core::progress::Progress;
use pav_core::table::write_csv;
use pav_print::channel::Shift;
use pav_scene::Scene;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// The texture as the config's printer prints it, beside `texture.png` (with `[print]`).
pub const PROOF: &str = "texture_proof.png";

/// White-box score of one view under three textures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ViewScore {
    /// "train" or "test".
    pub split: &'static str,
    /// TrainView name.
    pub view: String,
    /// Car score on the unmodified photo.
    pub original: f32,
    /// Car score with the initial texture.
    pub initial: f32,
    /// Car score with the optimized texture.
    pub optimized: f32,
}

/// Scores every photo view of `setup` with the white-box model.
pub fn score_views(
    setup: &Setup,
    wb: &WhiteBox,
    initial: &[f32],
    optimized: &[f32],
) -> Result<Vec<ViewScore>, WhiteBoxError> {
    let scene = setup.eval_scene();
    let mut out = Vec::new();
    for (split, views) in [("train", &setup.train), ("test", &setup.test)] {
        for v in views.iter() {
            let s = |img: &[f32]| wb.loss(img, v.size).map(|l| l.max_score);
            out.push(ViewScore {
                split,
                view: v.name.clone(),
                original: s(&v.photo)?,
                initial: s(&v.composite(initial, &scene))?,
                optimized: s(&v.composite(optimized, &scene))?,
            });
        }
    }
    Ok(out)
}

/// A grid of (photo | composite) pairs at half size, four views per row.
pub fn preview(path: &Path, views: &[&TrainView], tex: &[f32], scene: &Scene) -> Result<(), ImageError> {
    let Some(first) = views.first() else { return Ok(()) };
    let s = first.size / 2;
    let tiles: Vec<Vec<f32>> = views
        .iter()
        .flat_map(|v| [halve(&v.photo, v.size, v.size), halve(&v.composite(tex, scene), v.size, v.size)])
        .collect();
    let (w, h, img) = tile(&tiles, s, s, 2 * 4.min(views.len()), 1.0);
    save_rgb(path, w, h, &img)
}

/// Loss terms and the car score over steps; the running mean spans `window` steps.
fn plot_log(path: &Path, log: &[StepLog], window: usize) -> Result<(), PlotError> {
    let pts = |f: &dyn Fn(&StepLog) -> f64| log.iter().map(|r| (r.step as f64, f(r))).collect::<Vec<_>>();
    let series = vec![
        ("L = L1 + β·L2 + γ·Ls".to_string(), pts(&|r| r.total)),
        ("L1 (mean objectness)".to_string(), pts(&|r| r.l1 as f64)),
        ("L2 (mean car confidence)".to_string(), pts(&|r| r.l2 as f64)),
        ("car score under EoT (dashed: 0.5)".to_string(), pts(&|r| r.max_score as f64)),
    ];
    loss_curve(path, "PAV-Camou optimization (faint: per step; bold: running mean)", &series, window, Some(0.5))
}

/// A loaded optimization problem: the config, its views and the white-box detector.
pub struct Prepared {
    /// The config file.
    pub path: PathBuf,
    /// The config, with any overrides applied.
    pub cfg: OptimizeConfig,
    /// Mesh, region, scene and views.
    pub setup: Setup,
    /// The white-box detectors.
    pub wb: Ensemble,
    /// What `views.pbr_min_score` kept of the rendered views (None: the config sets none).
    pub pbr_kept: Option<PbrKept>,
    /// Seconds the preparation took.
    pub seconds: f64,
}

impl Prepared {
    /// Loads `config` with its views (synthetic ones included) rendered at `size` (default: the
    /// config's); a raised `stop` ends the scoring of rendered views with what it scored kept.
    pub fn load(config: &Path, size: Option<usize>, stop: &AtomicBool) -> Result<Prepared, ExperimentError> {
        let mut cfg = OptimizeConfig::load(config)?;
        cfg.views.size = size.unwrap_or(cfg.views.size);
        let t = Instant::now();
        let mut setup = Setup::load(&cfg, None)?;
        let wb = Ensemble::load(&cfg, cfg.views.size)?;
        let pbr_kept = cfg.views.pbr_min_score.map(|t| setup.keep_detected_pbr(&wb, t, stop)).transpose()?;
        Ok(Prepared { path: config.into(), cfg, setup, wb, pbr_kept, seconds: t.elapsed().as_secs_f64() })
    }

    /// Share of the atlas's values that are optimized.
    pub fn region_share(&self) -> f64 {
        let n = self.setup.tex_size;
        self.setup.region_values.len() as f64 / (3 * n * n) as f64
    }
}

/// What a `pav optimize` run is asked for besides the config.
#[derive(Clone, Debug)]
pub struct OptimizeRun {
    /// Output folder.
    pub out: PathBuf,
    /// Continue from the checkpoint in `out`.
    pub resume: bool,
    /// Override the config's epochs (and its steps budget).
    pub epochs: Option<usize>,
    /// Texture snapshots every this many steps (0: none; `attack::optimize::RunOptions`).
    pub snapshot_every: u64,
    /// The printable sheet's scale and resolution.
    pub print: PrintSpec,
}

/// What a finished (or stopped) run wrote.
pub struct OptimizeReport {
    /// How the optimization ended; a stopped run writes only the region, texture and loss files.
    pub finish: Finish,
    /// White-box scores per view (empty when stopped).
    pub scores: Vec<ViewScore>,
    /// The printable sheet (when finished).
    pub sheet: Option<WrittenSheet>,
    /// How far printing moves the region's texels (with `[print]`).
    pub shift: Option<Shift>,
    /// The files written, in `out`.
    pub files: Vec<&'static str>,
}

/// Runs the optimization of `p` into `run.out` and writes every output; `progress` counts steps.
pub fn optimize_and_report(
    p: &Prepared,
    run: &OptimizeRun,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<OptimizeReport, ExperimentError> {
    let (setup, out) = (&p.setup, &run.out);
    let n = setup.tex_size;
    create_dir(out)?;
    let region_rgb: Vec<f32> = setup.region.iter().flat_map(|v| [*v; 3]).collect();
    save_rgb(&out.join("region.png"), n, n, &region_rgb)?;
    let opts = RunOptions {
        out: out.clone(),
        resume: run.resume,
        checkpoint_every: 20,
        max_skips: 5,
        epochs: run.epochs,
        snapshot_every: run.snapshot_every,
    };
    let o = optimize_texture(&p.path, &p.cfg, setup, &p.wb, &opts, progress, stop)?;
    save_rgb(&out.join("texture.png"), n, n, &o.texture)?;
    plot_log(&out.join("loss.png"), &o.log, setup.training_views().len())?;
    let mut files = vec!["region.png", "texture.png", "loss.csv", "loss_detectors.csv", "loss.png"];
    if p.cfg.optimizer.average.is_some() {
        // texture.png is the average; the last iterate beside it, for comparison.
        save_rgb(&out.join(LAST_ITERATE), n, n, &o.last)?;
        files.push(LAST_ITERATE);
    }
    if matches!(o.finish, Finish::Stopped) {
        return Ok(OptimizeReport { finish: o.finish, scores: Vec::new(), sheet: None, shift: None, files });
    }
    // With a print channel, previews and scores show the texture as printed: what a camera sees.
    let printed = setup.scored(&o.texture);
    let shift = setup.print.as_ref().map(|c| c.shift(&o.texture, Some(&setup.region)));
    if setup.print.is_some() {
        save_rgb(&out.join(PROOF), n, n, &printed)?;
        files.push(PROOF);
    }
    let scene = setup.eval_scene();
    let views: Vec<&TrainView> = setup.train.iter().chain(&setup.test).collect();
    preview(&out.join("preview.png"), &views, &printed, &scene)?;
    files.push("preview.png");
    if !setup.synthetic.is_empty() {
        let synthetic: Vec<&TrainView> = setup.synthetic.iter().collect();
        preview(&out.join("synthetic.png"), &synthetic, &printed, &scene)?;
        files.push("synthetic.png");
    }
    let initial = setup.initial_texture(&p.cfg.mesh.init, p.cfg.optimizer.seed)?;
    let scores = score_views(setup, p.wb.first(), &setup.scored(&initial), &printed)?;
    write_csv(&out.join("scores.csv"), &scores)?;
    files.push("scores.csv");
    let (side, spread) = atlas_side_m(&setup.mesh, &setup.region, n, p.cfg.mesh.car_length_m)
        .ok_or_else(|| ExperimentError::Invalid("the optimizable region covers no face with area".into()))?;
    let sheet = write_sheet(&out.join("texture_print.png"), &o.texture, n, side, spread, run.print)?;
    files.push("texture_print.png");
    Ok(OptimizeReport { finish: o.finish, scores, sheet: Some(sheet), shift, files })
}
