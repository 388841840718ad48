//! The optimization loop (paper Algorithm 1): for each epoch and each training view, render the
//! texture, apply EoT, composite (zoomed when the scene lists `zoom`), run the white-box detector, and take an Adam step on
//! L = L1 + β·L2 + γ·Ls over the optimizable texels only.
//!
//! With `optimizer.average` the output is the pixel mean of the late iterates, not the last one.
//!
//! Checkpoints are written every epoch and every `checkpoint_every` steps (and on a stop
//! request); a non-finite loss or gradient skips the step instead of poisoning the texture.

use super::adam::Adam;
use super::checkpoint::{fingerprint, Average, Checkpoint};
use super::config::OptimizeConfig;
use super::pyramid::Pyramid;
use super::setup::Setup;
use super::smooth::smoothness;
use super::view::TrainView;
use super::whitebox::{Ensemble, EnsembleGrad};
use pav_core::progress::Progress;
use pav_core::rng::Rng;
use pav_core::step::{StageTime, Step};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// One step's record (a row of `loss.csv`), with the time split per stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepLog {
    /// Global step (0-based).
    pub step: u64,
    /// Epoch (0-based).
    pub epoch: u64,
    /// Training view.
    pub view: String,
    /// L1: mean objectness over boxes.
    pub l1: f32,
    /// L2: mean car confidence over car proposals.
    pub l2: f32,
    /// Ls: smoothness of the texture.
    pub ls: f64,
    /// The print channel's gamut term, weighted (0 without `[print]`).
    #[serde(default)]
    pub gamut: f64,
    /// L1 + β·L2 + γ·Ls + the gamut term.
    pub total: f64,
    /// Boxes (n_o).
    pub boxes: usize,
    /// Car proposals (n_c).
    pub proposals: usize,
    /// Highest car score on this (EoT-transformed) composite.
    pub max_score: f32,
    /// Whether the step was skipped (non-finite loss or gradient).
    pub skipped: bool,
    /// Texture → composite (the print channel, gather and shading), ms.
    pub render_ms: f64,
    /// EoT (and the zoom, when the scene lists it), ms.
    pub eot_ms: f64,
    /// Detector forward and loss, ms.
    pub forward_ms: f64,
    /// Detector backward, ms.
    pub backward_ms: f64,
    /// Adjoint of EoT, shading and gather into the texture, ms.
    pub adjoint_ms: f64,
    /// Smoothness loss and Adam step, ms.
    pub optimizer_ms: f64,
    /// Rebuilding the view from its files (`views.stream`), ms; 0 for a view held in memory.
    #[serde(default)]
    pub view_ms: f64,
    /// Each white-box detector's own terms (`loss_detectors.csv`), those that took part.
    #[serde(skip)]
    pub per_detector: Vec<DetectorStep>,
    /// Each stage of the chain from the texture to the white boxes' input, timed
    /// (`loss_stages.csv`).
    #[serde(skip)]
    pub stages: Vec<StageStep>,
}

/// One stage's time at one step (a row of `loss_stages.csv`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageStep {
    /// Global step.
    pub step: u64,
    /// The stage (`print`, `render`, `eot`, `zoom`).
    pub stage: String,
    /// Its forward pass, ms.
    pub forward_ms: f64,
    /// Its adjoint, ms.
    pub adjoint_ms: f64,
}

impl StageStep {
    fn of(step: u64, t: &StageTime) -> Self {
        StageStep { step, stage: t.stage.into(), forward_ms: t.forward_ms, adjoint_ms: t.adjoint_ms }
    }
}

/// One white-box detector's terms at one step (a row of `loss_detectors.csv`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetectorStep {
    /// Global step.
    pub step: u64,
    /// Detector name.
    pub detector: String,
    /// Its weight in the loss.
    pub weight: f32,
    /// Its L1.
    pub l1: f32,
    /// Its L2.
    pub l2: f32,
    /// Its boxes.
    pub boxes: usize,
    /// Its car proposals.
    pub proposals: usize,
    /// Its highest car score.
    pub max_score: f32,
}

/// How a run ended.
#[derive(Debug)]
pub enum Finish {
    /// All epochs done.
    Done,
    /// A stop was requested; the checkpoint holds the state.
    Stopped,
}

/// Options for [`run`] beyond the config.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Output folder.
    pub out: PathBuf,
    /// Continue from `out/checkpoint.bin`.
    pub resume: bool,
    /// Steps between checkpoints (besides every epoch end).
    pub checkpoint_every: u64,
    /// Give up after this many consecutive skipped steps.
    pub max_skips: u64,
    /// Override the epochs of the config (and its `steps` budget).
    pub epochs: Option<usize>,
    /// Save the texture as `snapshots/step{N:06}.png` at the start and every this many steps
    /// (and at the end); 0 saves none.
    pub snapshot_every: u64,
}

/// Folder of a run's texture snapshots in its output folder.
pub const SNAPSHOTS: &str = "snapshots";

/// The last iterate's file beside `texture.png` when that is an average (`optimizer.average`).
pub const LAST_ITERATE: &str = "texture-last.png";

/// The texture snapshots in `out` ([`RunOptions::snapshot_every`]) as (step, path), by step.
pub fn snapshots(out: &Path) -> Vec<(u64, PathBuf)> {
    let Ok(dir) = std::fs::read_dir(out.join(SNAPSHOTS)) else { return Vec::new() };
    let mut v: Vec<(u64, PathBuf)> = dir
        .filter_map(|e| {
            let p = e.ok()?.path();
            let step = p.file_name()?.to_str()?.strip_prefix("step")?.strip_suffix(".png")?.parse().ok()?;
            Some((step, p))
        })
        .collect();
    v.sort();
    v
}

/// Errors of a run.
#[derive(Debug, thiserror::Error)]
pub enum OptimizeError {
    /// Preparing the problem.
    #[error(transparent)]
    Setup(#[from] super::setup::SetupError),
    /// The detector.
    #[error(transparent)]
    WhiteBox(#[from] super::whitebox::WhiteBoxError),
    /// Checkpoints.
    #[error(transparent)]
    Checkpoint(#[from] super::checkpoint::CheckpointError),
    /// A file or folder of the run.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The initial texture's file.
    #[error(transparent)]
    Init(#[from] pav_core::image::ImageError),
    /// A stage of the chain from the texture to the white boxes' input.
    #[error(transparent)]
    Chain(#[from] pav_core::step::ChainError),
    /// The config's `optimizer.levels` do not fit its texture size.
    #[error(transparent)]
    Pyramid(#[from] super::pyramid::PyramidError),
    /// Writing a texture snapshot.
    #[error("writing a texture snapshot: {0}")]
    Snapshot(pav_core::image::ImageError),
    /// Writing `loss.csv`.
    #[error("writing {path}: {source}")]
    Log {
        /// The file.
        path: PathBuf,
        /// Why.
        source: csv::Error,
    },
    /// The checkpoint in the output folder belongs to another run.
    #[error("{checkpoint}: {why}")]
    Resume {
        /// The checkpoint.
        checkpoint: PathBuf,
        /// What does not match, and what to do.
        why: String,
    },
    /// `optimizer.average.from` lies beyond the run's last step: nothing would be averaged.
    #[error("optimizer.average.from = {from} is beyond this run's {total} steps: lower it or run more epochs")]
    AverageBeyondEnd {
        /// The first step counted.
        from: u64,
        /// The run's steps.
        total: u64,
    },
    /// Too many steps in a row had a non-finite loss or gradient.
    #[error("{skips} consecutive steps had a non-finite loss or gradient (last at step {step}, view {view}); the last good state is in {checkpoint}")]
    NotFinite {
        /// Steps skipped in a row.
        skips: u64,
        /// The last one.
        step: u64,
        /// Its view.
        view: String,
        /// Where the last good state is.
        checkpoint: PathBuf,
    },
}

/// The result of a run: the texture, its log, and how it ended.
pub struct Outcome {
    /// The output texture (RGB interleaved, `tex_size²`): the mean of the iterates that
    /// `optimizer.average` counts (those so far, on a stop), else the last iterate.
    pub texture: Vec<f32>,
    /// The last iterate (the same as `texture` without `optimizer.average`).
    pub last: Vec<f32>,
    /// All step records, resumed runs included.
    pub log: Vec<StepLog>,
    /// How it ended.
    pub finish: Finish,
}

/// TrainView order of `epoch`: a permutation from the seed, independent of the EoT draws so a resumed
/// run visits the same views.
fn epoch_order(n: usize, seed: u64, epoch: u64) -> Vec<usize> {
    let mut r = Rng::new(seed ^ epoch.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0x5eed);
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        let j = (r.next_u64() % (i as u64 + 1)) as usize;
        p.swap(i, j);
    }
    p
}

/// The ensemble members that take part in a step: all of them, or `k` drawn without
/// replacement from `rng` (so a resumed run draws the same ones), in member order.
fn draw_members(n: usize, k: Option<usize>, rng: &mut Rng) -> Vec<usize> {
    let mut all: Vec<usize> = (0..n).collect();
    let Some(k) = k.filter(|&k| k < n) else { return all };
    for i in 0..k {
        let j = i + (rng.next_u64() % (n - i) as u64) as usize;
        all.swap(i, j);
    }
    all.truncate(k);
    all.sort_unstable();
    all
}

/// One step on `view`: returns its record and adds ∂L/∂texture into `grad`.
pub fn step(
    setup: &Setup,
    wb: &Ensemble,
    cfg: &OptimizeConfig,
    view: &TrainView,
    tex: &[f32],
    rng: &mut Rng,
    grad: &mut [f32],
) -> Result<StepLog, OptimizeError> {
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    let chain = setup.chain(view);
    let (img, mut tape) = chain.forward(tex, rng)?;
    let drawn = draw_members(wb.members.len(), cfg.optimizer.white_boxes_per_step, rng);
    let car = chain.map_box(&tape, None);
    let EnsembleGrad { sum: g, per_detector } = wb.loss_and_grad_of(&drawn, &img, view.size, cfg.loss.beta, car)?;
    chain.adjoint_timed(&mut tape, &g.grad, grad);
    let t = Instant::now();
    let gamut = setup.print.as_ref().map_or(0.0, |p| p.gamut(tex, &setup.region_texels, grad));
    let adjoint_ms = tape.adjoint_ms() + ms(t);
    let t = Instant::now();
    let ls = smoothness(tex, setup.tex_size, setup.tex_size, cfg.loss.smoothness, cfg.loss.gamma, grad);
    let optimizer_ms = ms(t);
    let d = g.loss;
    let per_detector = per_detector
        .iter()
        .zip(&wb.members)
        .filter_map(|(t, m)| Some((t.as_ref()?, m)))
        .map(|(t, (w, weight))| DetectorStep {
            step: 0,
            detector: w.name().into(),
            weight: *weight,
            l1: t.l1,
            l2: t.l2,
            boxes: t.boxes,
            proposals: t.proposals,
            max_score: t.max_score,
        })
        .collect();
    Ok(StepLog {
        step: 0,
        epoch: 0,
        view: view.name.clone(),
        l1: d.l1,
        l2: d.l2,
        ls,
        gamut,
        total: d.l1 as f64 + cfg.loss.beta as f64 * d.l2 as f64 + cfg.loss.gamma as f64 * ls + gamut,
        boxes: d.boxes,
        proposals: d.proposals,
        max_score: d.max_score,
        skipped: false,
        render_ms: tape.forward_ms(&["print", "render"]),
        eot_ms: tape.forward_ms(&["eot", "zoom"]),
        forward_ms: g.forward_ms,
        backward_ms: g.backward_ms,
        adjoint_ms,
        optimizer_ms,
        view_ms: 0.0,
        per_detector,
        stages: tape.times.iter().map(|s| StageStep::of(0, s)).collect(),
    })
}

/// Writes rows to `path` through a temporary file, so a crash never leaves half a log.
fn write_rows<T: Serialize>(path: &Path, rows: impl Iterator<Item = T>) -> Result<(), OptimizeError> {
    let tmp = path.with_extension("csv.tmp");
    let csv_err = |source| OptimizeError::Log { path: tmp.clone(), source };
    let mut w = csv::Writer::from_path(&tmp).map_err(csv_err)?;
    for r in rows {
        w.serialize(r).map_err(csv_err)?;
    }
    w.flush().map_err(|source| OptimizeError::Io { path: tmp.clone(), source })?;
    std::fs::rename(&tmp, path).map_err(|source| OptimizeError::Io { path: path.into(), source })
}

/// `loss.csv`, `loss_detectors.csv` and `loss_stages.csv` in `dir`.
fn write_log(dir: &Path, log: &[StepLog]) -> Result<(), OptimizeError> {
    write_rows(&dir.join("loss.csv"), log.iter())?;
    write_rows(&dir.join("loss_detectors.csv"), log.iter().flat_map(|s| s.per_detector.iter()))?;
    write_rows(&dir.join("loss_stages.csv"), log.iter().flat_map(|s| s.stages.iter()))
}

/// The records of the steps before `upto` from `dir`'s logs (for a resumed run).
fn read_log(dir: &Path, upto: u64) -> Vec<StepLog> {
    let Ok(mut r) = csv::Reader::from_path(dir.join("loss.csv")) else { return Vec::new() };
    let mut log: Vec<StepLog> = r.deserialize::<StepLog>().filter_map(Result::ok).filter(|s| s.step < upto).collect();
    for d in read_rows::<DetectorStep>(&dir.join("loss_detectors.csv")) {
        if let Some(s) = log.iter_mut().find(|s| s.step == d.step) {
            s.per_detector.push(d);
        }
    }
    for d in read_rows::<StageStep>(&dir.join("loss_stages.csv")) {
        if let Some(s) = log.iter_mut().find(|s| s.step == d.step) {
            s.stages.push(d);
        }
    }
    log
}

/// The rows of a log beside `loss.csv` that read (none when the file is missing).
fn read_rows<T: serde::de::DeserializeOwned>(path: &Path) -> Vec<T> {
    csv::Reader::from_path(path).map(|mut r| r.deserialize().filter_map(Result::ok).collect()).unwrap_or_default()
}

/// Runs (or resumes) the optimization of `cfg` (loaded from `cfg_path`) on `setup`; `progress`
/// counts steps, and a raised `stop` saves the state and returns [`Finish::Stopped`].
pub fn optimize_texture(
    cfg_path: &Path,
    cfg: &OptimizeConfig,
    setup: &Setup,
    wb: &Ensemble,
    opts: &RunOptions,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<Outcome, OptimizeError> {
    std::fs::create_dir_all(&opts.out).map_err(|source| OptimizeError::Io { path: opts.out.clone(), source })?;
    let bytes = if cfg.files.is_empty() {
        std::fs::read(cfg_path).map_err(|source| OptimizeError::Io { path: cfg_path.into(), source })?
    } else {
        cfg.file_bytes().map_err(|(path, source)| OptimizeError::Io { path, source })?
    };
    let hash = fingerprint(&bytes);
    let ckpt_path = opts.out.join("checkpoint.bin");
    let n_values = setup.tex_size * setup.tex_size * 3;
    let pyramid = Pyramid::new(setup.tex_size, cfg.optimizer.levels)?;
    // The start is needed after a resume too: the pyramid's projection restores it off the region.
    let start_tex = setup.initial_texture(&cfg.mesh.init, cfg.optimizer.seed)?;
    let (mut params, mut adam, mut rng, start, mut log, mut average) = if opts.resume && ckpt_path.exists() {
        let c = Checkpoint::load(&ckpt_path)?;
        let refuse = |why: String| OptimizeError::Resume { checkpoint: ckpt_path.clone(), why };
        if c.config_hash != hash {
            return Err(refuse(format!(
                "written for a different config than {}: resume with the same config or use another --out",
                cfg_path.display()
            )));
        }
        if c.params.len() != pyramid.len() {
            return Err(refuse("its parameter count does not match the config's texture size and levels".into()));
        }
        let log = read_log(&opts.out, c.steps_done);
        progress.note(&format!("resuming from step {} ({})", c.steps_done, ckpt_path.display()));
        (c.params, c.adam, Rng { state: c.rng_state }, c.steps_done, log, c.average)
    } else {
        if ckpt_path.exists() {
            return Err(OptimizeError::Resume {
                checkpoint: ckpt_path.clone(),
                why: "exists: pass --resume to continue it, or choose another --out".into(),
            });
        }
        let p = pyramid.from_texture(&start_tex);
        let adam = Adam::new(pyramid.len(), cfg.optimizer.lr);
        (p, adam, Rng::new(cfg.optimizer.seed), 0, Vec::new(), Average::default())
    };
    let active = pyramid.active(&setup.region_values);
    let clamp = (cfg.optimizer.clamp[0], cfg.optimizer.clamp[1]);
    let mut tex = pyramid.compose(&params);
    let views = setup.training_views();
    let n = views.len() as u64;
    let total = match (opts.epochs, cfg.optimizer.steps) {
        (None, Some(steps)) => steps,
        (epochs, _) => n * epochs.unwrap_or(cfg.optimizer.epochs) as u64,
    };
    if let Some(a) = cfg.optimizer.average.filter(|a| a.from > total) {
        return Err(OptimizeError::AverageBeyondEnd { from: a.from, total });
    }
    // The output: the grid's textures so far and, at the end, the last one if off the grid.
    let output = |average: &Average, tex: Vec<f32>, end: bool| {
        let mut a = average.clone();
        if end && cfg.optimizer.average.is_some_and(|g| !g.on_grid(total)) {
            a.add(&tex);
        }
        Outcome { texture: a.mean().unwrap_or_else(|| tex.clone()), last: tex, log: Vec::new(), finish: Finish::Done }
    };
    type Saved = Result<(), OptimizeError>;
    let save = |params: &[f32], adam: &Adam, rng: &Rng, average: &Average, done: u64, log: &[StepLog]| -> Saved {
        Checkpoint {
            config_hash: hash,
            steps_done: done,
            rng_state: rng.state,
            params: params.to_vec(),
            adam: adam.clone(),
            average: average.clone(),
        }
        .save(&ckpt_path)?;
        write_log(&opts.out, log)
    };
    let snapshot = |tex: &[f32], done: u64| -> Result<(), OptimizeError> {
        let dir = opts.out.join(SNAPSHOTS);
        std::fs::create_dir_all(&dir).map_err(|source| OptimizeError::Io { path: dir.clone(), source })?;
        let path = dir.join(format!("step{done:06}.png"));
        pav_core::image::save_rgb(&path, setup.tex_size, setup.tex_size, tex).map_err(OptimizeError::Snapshot)
    };
    if opts.snapshot_every > 0 && start == 0 {
        snapshot(&tex, 0)?;
    }
    progress.begin("step", total);
    progress.set_position(start);
    let mut grad = vec![0f32; n_values];
    let mut skips = 0u64;
    let mut order = epoch_order(n as usize, cfg.optimizer.seed, start / n.max(1));
    for s in start..total {
        if stop.load(Ordering::SeqCst) {
            save(&params, &adam, &rng, &average, s, &log)?;
            progress.end(Some("stopped; continue with --resume"));
            return Ok(Outcome { log, finish: Finish::Stopped, ..output(&average, tex, false) });
        }
        let (epoch, k) = (s / n, (s % n) as usize);
        if k == 0 {
            order = epoch_order(n as usize, cfg.optimizer.seed, epoch);
        }
        let t = Instant::now();
        let view = setup.view(views[order[k]])?;
        let view_ms = t.elapsed().as_secs_f64() * 1e3;
        grad.fill(0.0);
        let mut rec = step(setup, wb, cfg, &view, &tex, &mut rng, &mut grad)?;
        (rec.step, rec.epoch, rec.view_ms) = (s, epoch, view_ms);
        rec.per_detector.iter_mut().for_each(|d| d.step = s);
        rec.stages.iter_mut().for_each(|d| d.step = s);
        let finite = rec.total.is_finite() && setup.region_values.iter().all(|&i| grad[i as usize].is_finite());
        if finite {
            let t = Instant::now();
            if pyramid.sides.len() == 1 {
                adam.step(&mut params, &grad, &setup.region_values, clamp);
            } else {
                // Unclamped on the levels; the projection then clamps the composed texture.
                adam.step(&mut params, &pyramid.pullback(&grad), &active, (f32::NEG_INFINITY, f32::INFINITY));
                pyramid.project(&mut params, &setup.region_values, &start_tex, clamp);
            }
            tex = pyramid.compose(&params);
            rec.optimizer_ms += t.elapsed().as_secs_f64() * 1e3;
            skips = 0;
        } else {
            rec.skipped = true;
            skips += 1;
            progress.note(&format!("step {s} ({}): non-finite loss or gradient, step skipped", view.name));
            if skips >= opts.max_skips {
                save(&params, &adam, &rng, &average, s, &log)?;
                progress.end(None);
                return Err(OptimizeError::NotFinite {
                    skips,
                    step: s,
                    view: view.name.clone(),
                    checkpoint: ckpt_path.clone(),
                });
            }
        }
        progress.status(&format!("L {:.3} car {:.2}", rec.total, rec.max_score));
        progress.advance(1);
        log.push(rec);
        let done = s + 1;
        if cfg.optimizer.average.is_some_and(|a| a.on_grid(done)) {
            average.add(&tex);
        }
        if opts.snapshot_every > 0 && (done % opts.snapshot_every == 0 || done == total) {
            snapshot(&tex, done)?;
        }
        if done % n == 0 || done % opts.checkpoint_every.max(1) == 0 || done == total {
            save(&params, &adam, &rng, &average, done, &log)?;
        }
    }
    progress.end(None);
    Ok(Outcome { log, ..output(&average, tex, true) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn members_drawn_per_step_are_distinct_in_order_and_each_drawn_as_often() {
        let mut rng = Rng::new(7);
        // Every member, and no draw: a config without the option keeps its EoT draws.
        assert_eq!(draw_members(3, None, &mut rng), [0, 1, 2]);
        assert_eq!(draw_members(3, Some(3), &mut rng), [0, 1, 2]);
        assert_eq!(rng.state, Rng::new(7).state);
        let mut count = [0usize; 4];
        for _ in 0..4000 {
            let d = draw_members(4, Some(2), &mut rng);
            assert_eq!(d.len(), 2);
            assert!(d[0] < d[1], "{d:?}");
            d.iter().for_each(|&i| count[i] += 1);
        }
        // 2000 draws each expected; a binomial's sd is 27, so ±150 holds unless the draw is biased.
        assert!(count.iter().all(|&c| c.abs_diff(2000) < 150), "{count:?}");
    }
}
