//! `pav crossval`: k-fold cross-validation of the whole attack. FCA's public set has eleven
//! photos, too few for a fixed train/test split to say whether an optimized texture generalizes
//! better than random paint. So every view is held out once: the texture is optimized on the
//! other folds and scored on the held-out views by every detector, next to the photo and
//! several random textures.

use super::boxes::{
    anatomy, anatomy_section, box_records, markdown_anatomy, own_box_records, own_box_score, own_box_section,
    BoxAnatomy, BoxRecord,
};
use super::curve::{pool, score_snapshots, snapshot_mean, snapshot_mean_name, CurveOptions, CurveRecord};
use super::per_view::{conditional_asr, markdown_paired, paired, ScoredView};
use super::table2::{aggregate, detect_view, markdown, markdown_scores, DigitalRow, AP_MIN_SCORE};
use super::{create_dir, write_markdown, ExperimentError, Scoring};
use pav_attack::config::OptimizeConfig;
use pav_attack::optimize::{optimize_texture, Finish, RunOptions, LAST_ITERATE};
use pav_attack::setup::Setup;
use pav_attack::view::TrainView;
use pav_attack::whitebox::Ensemble;
use pav_core::image::save_rgb;
use pav_core::progress::{Progress, Silent};
use pav_core::table::{unique, write_csv};
use pav_detect::load::load_detectors;
use pav_detect::Detector;
use pav_eval::digital::ImageDetections;
use pav_run::shard::Shard;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// Options of a cross-validation.
#[derive(Clone, Debug)]
pub struct CrossvalOptions {
    /// Number of folds (the number of views gives leave-one-out).
    pub folds: usize,
    /// Random textures drawn per fold (pooled as "random").
    pub random_seeds: u64,
    /// Edge of the random colour blocks, in texels.
    pub random_block: usize,
    /// Output folder; fold `f` of `k` runs in `fold{f}of{k}` and resumes from there.
    pub out: PathBuf,
    /// Score threshold for ASR.
    pub threshold: f32,
    /// Names of the white-box detectors.
    pub white_box: Vec<String>,
    /// Fixed textures scored beside the optimized one (a peer's published texture), by name.
    pub references: Vec<(String, Vec<f32>)>,
    /// Rendered views over photos' plates ([`Setup::rendered_over_plates`]), each scored in
    /// the fold that holds its photo out: a street and camera that fold never trained on.
    pub rendered: Vec<TrainView>,
    /// Snapshot every fold's texture and score the snapshots on its photos
    /// (`experiments::curve`).
    pub curve: CurveOptions,
    /// Which folds this call runs.
    pub run: Folds,
}

/// Views of fold `f`: index `i` of `all` is held out when `i % k == f`.
pub fn fold_split(n: usize, k: usize, f: usize) -> (Vec<usize>, Vec<usize>) {
    (0..n).partition(|i| i % k != f)
}

/// What a cross-validation scored.
#[derive(Clone, Debug)]
pub struct Crossval {
    /// The pooled table rows (splits "held-out" and "train").
    pub rows: Vec<DigitalRow>,
    /// Every view's best car score under every texture and detector.
    pub records: Vec<ScoredView>,
    /// Every car box on a held-out view.
    pub boxes: Vec<BoxRecord>,
    /// Where those boxes sit, per detector and texture.
    pub anatomies: Vec<BoxAnatomy>,
    /// The rendered views over held-out photos' plates, when options gave some.
    pub rendered: Option<Rendered>,
    /// The snapshots' scores, when options asked for a curve.
    pub curve: Vec<CurveRecord>,
    /// Seconds the folds took, added up.
    pub seconds: f64,
}

/// What a cross-validation scored on rendered views over the held-out photos' plates.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// Pooled table rows over those views (split "held-out").
    pub rows: Vec<DigitalRow>,
    /// Every view under every texture and detector.
    pub records: Vec<RenderedRecord>,
    /// Where the car boxes sit, per detector and texture.
    pub anatomies: Vec<BoxAnatomy>,
}

/// One rendered view over a held-out photo's plate, scored.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct RenderedRecord {
    /// Fold index.
    pub fold: usize,
    /// The held-out photo whose plate the view lies over.
    pub photo: String,
    /// TrainView name.
    pub view: String,
    /// Texture name.
    pub texture: String,
    /// Random seed (0 for the others).
    pub seed: u64,
    /// Detector name.
    pub detector: String,
    /// Best car score (0 without a car box).
    pub score: f32,
    /// Best score of a box on the car (IoU ≥ 0.5; 0 without one).
    pub own_box: f32,
}

/// Per held-out photo, the mean over its rendered views of the best car score (or, with
/// `own_box`, of the car's own box), as one held-out record per photo: views of one street and
/// camera are not independent, so a bootstrap over these resamples photos.
pub fn per_photo(records: &[RenderedRecord], own_box: bool) -> Vec<ScoredView> {
    // (fold, photo, texture, seed, detector) → (sum, views)
    type Key<'a> = (usize, &'a str, &'a str, u64, &'a str);
    let mut sums: BTreeMap<Key, (f64, usize)> = BTreeMap::new();
    for r in records {
        let e = sums.entry((r.fold, &r.photo, &r.texture, r.seed, &r.detector)).or_default();
        e.0 += if own_box { r.own_box } else { r.score } as f64;
        e.1 += 1;
    }
    sums.into_iter()
        .map(|((fold, photo, texture, seed, detector), (sum, n))| ScoredView {
            fold,
            role: "held-out",
            view: photo.to_string(),
            texture: texture.to_string(),
            seed,
            detector: detector.to_string(),
            score: (sum / n as f64) as f32,
        })
        .collect()
}

/// Which folds a [`crossval`] call runs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Folds {
    /// Every fold, optimized (a finished optimization resumes) and scored here.
    All,
    /// Only these folds (one shard of a job array); the tables cover only them.
    Only(Vec<usize>),
    /// Every fold was scored already (by the shards of a job array): each is read from its
    /// folder, never optimized or scored again.
    Scored,
}

/// A fold's folder inside a crossval's output folder.
pub fn fold_dir(f: usize, k: usize) -> String {
    format!("fold{f}of{k}")
}

/// What a fold scored, kept in its folder (`scores.json`), so the tables can be pooled from the
/// folds' files whichever process ran them.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct FoldScores {
    /// Seconds the fold took (optimizing and scoring).
    pub seconds: f64,
    /// Every view's best car score under every texture and detector.
    pub records: Vec<ScoredView>,
    /// Every car box on a held-out view.
    pub boxes: Vec<BoxRecord>,
    /// Every rendered view over a held-out photo's plate.
    pub rendered: Vec<RenderedRecord>,
    /// The snapshots' scores.
    pub curve: Vec<CurveRecord>,
    /// Detections per role, texture and detector, in view order.
    pub pooled: Vec<Pooled>,
    /// Detections on the rendered views per texture and detector (role held-out).
    pub rendered_pooled: Vec<Pooled>,
}

/// The detections of one detector on one set of a fold's views under one texture.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Pooled {
    /// "train" or "held-out".
    pub role: String,
    /// Texture name.
    pub texture: String,
    /// Detector name.
    pub detector: String,
    /// One entry per view (random textures: per view and seed), in scoring order.
    pub images: Vec<ImageDetections>,
}

/// The file a fold's scores are kept in.
pub const FOLD_SCORES: &str = "scores.json";

fn write_fold_scores(dir: &Path, s: &FoldScores) -> Result<(), ExperimentError> {
    Ok(pav_run::shard::write_json(&dir.join(FOLD_SCORES), s)?)
}

/// Reads a fold's scores ([`FoldScores`]) from its folder.
pub fn read_fold_scores(dir: &Path) -> Result<FoldScores, ExperimentError> {
    Ok(pav_run::shard::read_json(&dir.join(FOLD_SCORES))?)
}

/// Pushes `im` onto the entry of (role, texture, detector), in first-seen order.
fn pool_into(list: &mut Vec<Pooled>, role: &str, texture: &str, detector: &str, im: ImageDetections) {
    match list.iter_mut().find(|p| p.role == role && p.texture == texture && p.detector == detector) {
        Some(p) => p.images.push(im),
        None => list.push(Pooled {
            role: role.into(),
            texture: texture.into(),
            detector: detector.into(),
            images: vec![im],
        }),
    }
}

/// Optimizes fold `f` (resuming a finished or interrupted optimization from its folder) and
/// scores its views under every texture.
#[allow(clippy::too_many_arguments)]
fn score_fold(
    cfg_path: &Path,
    cfg: &OptimizeConfig,
    setup: &Setup,
    wb: &Ensemble,
    detectors: &mut [Box<dyn Detector>],
    opts: &CrossvalOptions,
    f: usize,
    stage: &dyn Fn(usize, &str),
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<FoldScores, ExperimentError> {
    let all: Vec<&TrainView> = setup.train.iter().chain(&setup.test).collect();
    let k = opts.folds;
    let (tr, te) = fold_split(all.len(), k, f);
    // Synthetic views come from this fold's training photos only.
    let names: Vec<&str> = tr.iter().map(|&i| all[i].name.as_str()).collect();
    let synthetic = setup.turned_views(&names)?;
    let fs = setup.with_views(
        tr.iter().map(|&i| all[i].clone()).collect(),
        synthetic,
        te.iter().map(|&i| all[i].clone()).collect(),
    );
    stage(f, "optimizing");
    let ro = RunOptions {
        out: opts.out.join(fold_dir(f, k)),
        resume: true,
        checkpoint_every: 20,
        max_skips: 5,
        epochs: None,
        snapshot_every: opts.curve.every,
    };
    let o = optimize_texture(cfg_path, cfg, &fs, wb, &ro, &Silent, stop)?;
    if matches!(o.finish, Finish::Stopped) {
        progress.end(Some("stopped"));
        return Err(ExperimentError::Stopped(ro.out));
    }
    save_rgb(&ro.out.join("texture.png"), fs.tex_size, fs.tex_size, &o.texture)?;
    if cfg.optimizer.average.is_some() {
        save_rgb(&ro.out.join(LAST_ITERATE), fs.tex_size, fs.tex_size, &o.last)?;
    }
    let mut out = FoldScores::default();
    if opts.curve.every > 0 {
        stage(f, "scoring the snapshots");
        out.curve = score_snapshots(f, &ro.out, &fs, detectors)?;
    }
    stage(f, "scoring");
    progress.advance(1);
    let mean_name = opts.curve.mean_from.map(snapshot_mean_name);
    let mean = opts.curve.mean_from.map(|m| snapshot_mean(&ro.out, m, &fs)).transpose()?;
    let mut textures: Vec<(String, u64, Option<&[f32]>)> =
        vec![("original".into(), 0, None), ("optimized".into(), 0, Some(&o.texture))];
    if let (Some(name), Some(t)) = (&mean_name, &mean) {
        save_rgb(&ro.out.join(format!("{name}.png")), fs.tex_size, fs.tex_size, t)?;
        textures.push((name.clone(), 0, Some(t)));
    }
    // Both random baselines, the same seeds for each: blocks, and the paper's 32×32 image.
    let mut randoms = Vec::new();
    for (name, block) in [("random", opts.random_block), ("random32", fs.paper_random_block())] {
        for s in 0..opts.random_seeds {
            let seed = 1 + s + 1000 * f as u64;
            randoms.push((name, seed, fs.random_texture(block, seed)));
        }
    }
    textures.extend(randoms.iter().map(|(name, seed, r)| (name.to_string(), *seed, Some(r.as_slice()))));
    for (name, r) in &opts.references {
        textures.push((name.clone(), 0, Some(r)));
    }
    // Each texture as scores see it, once per fold rather than once per view.
    let seen: Vec<Option<std::borrow::Cow<[f32]>>> = textures.iter().map(|(_, _, t)| t.map(|t| fs.scored(t))).collect();
    for (role, views) in [("train", &fs.train), ("held-out", &fs.test)] {
        for v in views.iter() {
            for ((tname, seed, _), tex) in textures.iter().zip(&seen) {
                let dets = detect_view(v, tex.as_deref(), &fs, detectors)?;
                for (d, im) in dets.into_iter().enumerate() {
                    let detector = detectors[d].name();
                    if role == "held-out" {
                        out.boxes.extend(box_records(f, &v.name, tname, *seed, detector, &im));
                    }
                    out.records.push(ScoredView {
                        fold: f,
                        role,
                        view: v.name.clone(),
                        texture: tname.to_string(),
                        seed: *seed,
                        detector: detector.to_string(),
                        score: im.best_score(),
                    });
                    pool_into(&mut out.pooled, role, tname, detector, im);
                }
            }
        }
    }
    let held: Vec<&str> = te.iter().map(|&i| all[i].name.as_str()).collect();
    for v in &opts.rendered {
        let Some(photo) = setup.plate_of(&v.name).filter(|p| held.contains(p)) else { continue };
        for ((tname, seed, _), tex) in textures.iter().zip(&seen) {
            for (d, im) in detect_view(v, tex.as_deref(), &fs, detectors)?.into_iter().enumerate() {
                let detector = detectors[d].name();
                out.rendered.push(RenderedRecord {
                    fold: f,
                    photo: photo.to_string(),
                    view: v.name.clone(),
                    texture: tname.clone(),
                    seed: *seed,
                    detector: detector.to_string(),
                    score: im.best_score(),
                    own_box: own_box_score(&im),
                });
                pool_into(&mut out.rendered_pooled, "held-out", tname, detector, im);
            }
        }
    }
    Ok(out)
}

/// Runs every fold; returns the pooled table rows (splits "held-out" and "train") and the
/// per-view records. `progress` counts two units per fold (scored, done) and shows the stage.
#[allow(clippy::too_many_arguments)]
pub fn crossval(
    cfg_path: &Path,
    cfg: &OptimizeConfig,
    setup: &Setup,
    wb: &Ensemble,
    detectors: &mut [Box<dyn Detector>],
    opts: &CrossvalOptions,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<Crossval, ExperimentError> {
    let all: Vec<&TrainView> = setup.train.iter().chain(&setup.test).collect();
    let k = opts.folds;
    if k < 2 || k > all.len() {
        return Err(ExperimentError::Invalid(format!(
            "folds must be in 2..={} (the number of views), got {k}",
            all.len()
        )));
    }
    opts.curve.check()?;
    let mean_name = opts.curve.mean_from.map(snapshot_mean_name);
    let picked: Vec<usize> = match &opts.run {
        Folds::Only(f) => f.clone(),
        Folds::All | Folds::Scored => (0..k).collect(),
    };
    progress.begin("folds", 2 * picked.len() as u64);
    let stage = |f: usize, s: &str| progress.status(&format!("fold {}/{k}: {s}", f + 1));
    // (role, texture, detector index) → detections, pooled over folds and seeds.
    let mut pooled: HashMap<(String, String, usize), Vec<ImageDetections>> = HashMap::new();
    let mut records = Vec::new();
    let mut boxes = Vec::new();
    let mut rendered_pooled: HashMap<(String, usize), Vec<ImageDetections>> = HashMap::new();
    let mut rendered = Vec::new();
    let mut curve = Vec::new();
    let mut seconds = 0.0;
    let names: Vec<String> = detectors.iter().map(|d| d.name().to_string()).collect();
    let index = |name: &str, dir: &Path| {
        names.iter().position(|d| d == name).ok_or_else(|| {
            ExperimentError::Invalid(format!(
                "{}: scored by detector {name}, which this run does not load",
                dir.display()
            ))
        })
    };
    for &f in &picked {
        let dir = opts.out.join(fold_dir(f, k));
        if opts.run != Folds::Scored {
            let t = Instant::now();
            let scored = score_fold(cfg_path, cfg, setup, wb, detectors, opts, f, &stage, progress, stop)?;
            write_fold_scores(&dir, &FoldScores { seconds: t.elapsed().as_secs_f64(), ..scored })?;
        } else {
            stage(f, "read");
            progress.advance(1);
        }
        // Every fold is pooled from its file, so a job run in one process and one merged from
        // shards pool the very same numbers.
        let s = read_fold_scores(&dir)?;
        seconds += s.seconds;
        for p in s.pooled {
            let d = index(&p.detector, &dir)?;
            pooled.entry((p.role, p.texture, d)).or_default().extend(p.images);
        }
        for p in s.rendered_pooled {
            let d = index(&p.detector, &dir)?;
            rendered_pooled.entry((p.texture, d)).or_default().extend(p.images);
        }
        records.extend(s.records);
        boxes.extend(s.boxes);
        rendered.extend(s.rendered);
        curve.extend(s.curve);
        stage(f, "done");
        progress.advance(1);
    }
    progress.end(None);
    let mut rows = Vec::new();
    let mut anatomies = Vec::new();
    let (mut rendered_rows, mut rendered_anatomies) = (Vec::new(), Vec::new());
    let names = ["original", "random", "random32", "optimized"].map(String::from).into_iter();
    for tname in names.chain(mean_name).chain(opts.references.iter().map(|r| r.0.clone())) {
        for (d, det) in detectors.iter().enumerate() {
            let white_box = opts.white_box.iter().any(|w| w == det.name());
            if let Some(ims) = pooled.get(&("held-out".to_string(), tname.clone(), d)) {
                anatomies.extend(anatomy(det.name(), &tname, ims));
            }
            if let Some(ims) = rendered_pooled.get(&(tname.clone(), d)) {
                rendered_anatomies.extend(anatomy(det.name(), &tname, ims));
                rendered_rows.extend(aggregate(det.name(), white_box, &tname, "held-out", ims, opts.threshold));
            }
            for role in ["held-out", "train"] {
                let ims = pooled.get(&(role.to_string(), tname.clone(), d)).map(Vec::as_slice).unwrap_or_default();
                rows.extend(aggregate(det.name(), white_box, &tname, role, ims, opts.threshold));
            }
        }
    }
    let rendered = (!opts.rendered.is_empty()).then_some(Rendered {
        rows: rendered_rows,
        records: rendered,
        anatomies: rendered_anatomies,
    });
    Ok(Crossval { rows, records, boxes, anatomies, rendered, curve, seconds })
}

/// How a crossval job is cut for a job array (`pav_run::shard`).
#[derive(Clone, Debug)]
pub enum Cut {
    /// The whole job in this process.
    Whole,
    /// One shard: its folds are optimized and scored into its folder; no tables.
    Shard(Shard),
    /// The shards' folds (found and checked by `shard::find_checked`) joined into the tables.
    Merge(Vec<(Shard, PathBuf)>),
}

/// What a crossval job runs besides its config: folds, baselines, scoring, seeds and its cut.
#[derive(Clone, Debug)]
pub struct CrossvalJob {
    /// Number of folds (None: one per view, leave-one-out).
    pub folds: Option<usize>,
    /// Random textures per fold (pooled as "random").
    pub random_seeds: u64,
    /// Fixed textures scored beside the optimized one, by file.
    pub references: Vec<PathBuf>,
    /// `pav views render` folders over FCA's photos' plates.
    pub rendered: Vec<PathBuf>,
    /// Snapshot scoring.
    pub curve: CurveOptions,
    /// Optimizer seeds, each cross-validated into `seed<S>/` (empty: the config's seed, into the
    /// output folder itself).
    pub seeds: Vec<u64>,
    /// Whole, one shard, or the merge of the shards.
    pub cut: Cut,
}

/// The folder of seed `seed` of a job (the output folder itself without `--seeds`).
fn seed_dir(root: &Path, seed: Option<u64>) -> PathBuf {
    seed.map_or_else(|| root.to_path_buf(), |s| root.join(format!("seed{s}")))
}

/// Links each (seed, fold) unit's folder from the shard that scored it into the job's output
/// folder, once every unit is found scored in its own shard and in no other.
fn gather_shards(
    shards: &[(Shard, PathBuf)],
    seeds: &[Option<u64>],
    k: usize,
    out: &Path,
) -> Result<(), ExperimentError> {
    let mut units = Vec::new();
    for &seed in seeds {
        for f in 0..k {
            units.push(pav_run::shard::Unit {
                what: format!("fold {}/{k}{}", f + 1, seed.map_or(String::new(), |s| format!(" of seed {s}"))),
                dir: seed_dir(Path::new(""), seed).join(fold_dir(f, k)),
            });
        }
    }
    Ok(pav_run::shard::gather(shards, &units, &|d: &Path| d.join(FOLD_SCORES).is_file(), out)?)
}

/// `pav crossval`: cross-validates `config` with `job.folds` folds (default: leave-one-out) and
/// `job.random_seeds` random textures per fold; writes `crossval.csv`, `crossval_views.csv`,
/// `crossval_boxes.csv`, `crossval_anatomy.csv`, `crossval_paired_own_box.csv`, `crossval.md`
/// and a folder per fold into `out` (or `out/seed<S>` per seed; finished optimizations resume),
/// and returns the Markdown. A shard only optimizes and scores its folds; the merge pools them.
pub fn crossval_report(
    config: &Path,
    job: &CrossvalJob,
    scoring: &Scoring,
    out: &Path,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<String, ExperimentError> {
    let threshold = scoring.threshold;
    // Before loading anything: a refused option should not wait for the photos.
    job.curve.check()?;
    let cfg = OptimizeConfig::load(config)?;
    if !cfg.views.pbr_test.is_empty() {
        return Err(ExperimentError::Invalid(format!(
            "{}: crossval holds out photos fold by fold; views.pbr_test is for `pav optimize` and `pav eval-digital`",
            config.display()
        )));
    }
    let mut setup = Setup::load_photos(&cfg, None)?;
    let n = setup.train.len() + setup.test.len();
    let k = job.folds.unwrap_or(n);
    if k < 2 || k > n {
        return Err(ExperimentError::Invalid(format!("folds must be in 2..={n} (the number of views), got {k}")));
    }
    let seeds: Vec<Option<u64>> =
        if job.seeds.is_empty() { vec![None] } else { job.seeds.iter().copied().map(Some).collect() };
    if let Cut::Merge(shards) = &job.cut {
        gather_shards(shards, &seeds, k, out)?;
    }
    scoring.apply_print(&mut setup)?;
    let wb = Ensemble::load(&cfg, cfg.views.size)?;
    let pbr_kept = cfg.views.pbr_min_score.map(|t| setup.keep_detected_pbr(&wb, t, stop)).transpose()?;
    if let Some(k) = &pbr_kept {
        progress.note(&format!("views.pbr: {k}"));
    }
    let rendered_views = setup.rendered_over_plates(&cfg, &job.rendered)?;
    let mut dets = load_detectors(&scoring.detectors, &[], &scoring.defences, 1)?;
    create_dir(out)?;
    let references: Vec<(String, Vec<f32>)> = job
        .references
        .iter()
        .map(|p| {
            let name =
                p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string());
            setup.load_texture(p).map(|t| (name, t))
        })
        .collect::<Result<_, _>>()?;
    let mut mds = Vec::new();
    for (si, &seed) in seeds.iter().enumerate() {
        let mut cfg = cfg.clone();
        if let Some(s) = seed {
            cfg.optimizer.seed = s;
        }
        let (root, run) = match &job.cut {
            Cut::Whole => (seed_dir(out, seed), Folds::All),
            Cut::Merge(_) => (seed_dir(out, seed), Folds::Scored),
            Cut::Shard(s) => {
                let mine: Vec<usize> = (0..k).filter(|f| s.picks(si * k + f)).collect();
                if mine.is_empty() {
                    continue;
                }
                (seed_dir(&s.dir(out), seed), Folds::Only(mine))
            }
        };
        let opts = CrossvalOptions {
            folds: k,
            random_seeds: job.random_seeds,
            random_block: setup.random_block(),
            out: root.clone(),
            threshold,
            white_box: cfg.white_box_names()?,
            references: references.clone(),
            rendered: rendered_views.clone(),
            curve: job.curve,
            run: run.clone(),
        };
        create_dir(&root)?;
        let cv = crossval(config, &cfg, &setup, &wb, &mut dets, &opts, progress, stop)?;
        match run {
            Folds::Only(f) => mds.push(format!(
                "{}: folds {} scored",
                root.display(),
                f.iter().map(|f| (f + 1).to_string()).collect::<Vec<_>>().join(", ")
            )),
            _ => mds.push(write_report(config, &cfg, &setup, &opts, cv, &job.rendered, pbr_kept.as_ref(), n, &root)?),
        }
    }
    Ok(mds.join("\n"))
}

/// Writes crossval's tables and Markdown for one seed into `out` and returns the Markdown.
#[allow(clippy::too_many_arguments)]
fn write_report(
    config: &Path,
    cfg: &OptimizeConfig,
    setup: &Setup,
    opts: &CrossvalOptions,
    cv: Crossval,
    rendered: &[PathBuf],
    pbr_kept: Option<&pav_attack::setup::PbrKept>,
    n: usize,
    out: &Path,
) -> Result<String, ExperimentError> {
    let (k, threshold, random_seeds, curve) = (opts.folds, opts.threshold, opts.random_seeds, opts.curve);
    let Crossval { rows, records, boxes, anatomies, rendered: scored, curve: scored_curve, .. } = cv;
    write_csv(&out.join("crossval.csv"), &rows)?;
    write_csv(&out.join("crossval_views.csv"), &records)?;
    write_csv(&out.join("crossval_boxes.csv"), &boxes)?;
    write_csv(&out.join("crossval_anatomy.csv"), &anatomies)?;
    let pairs = paired(&records, &opts.white_box, "optimized");
    write_csv(&out.join("crossval_paired.csv"), &pairs)?;
    let mut md = format!(
        "# Cross-validation, {k} folds over {n} views ({:.0} s of folds)\n\nEach texture is optimized on the other folds' views{} ({}, {} epochs) and scored on its held-out views; \"random\" pools {random_seeds} random textures of {}-texel blocks per fold, \"random32\" as many of the paper's kind (a 32×32 random image scaled up){}. Car detected at score ≥ {threshold}; P@0.5 over boxes from score {AP_MIN_SCORE}; * = white-box.\n",
        cv.seconds,
        if cfg.views.turns.is_empty() {
            String::new()
        } else {
            format!(" and their synthetic turns by {:?}° (baked from that fold's photos; scores are photos only)", cfg.views.turns)
        },
        config.display(),
        cfg.optimizer.epochs,
        setup.random_block(),
        opts.references.iter().map(|r| format!("; reference texture {}", r.0)).collect::<String>(),
    );
    if let Some(k) = &pbr_kept {
        md.push_str(&format!("\nRendered training views (`views.pbr`): {k}.\n"));
    }
    for (split, title) in
        [("held-out", "held-out views"), ("train", "training views (each view once per fold it trained in)")]
    {
        md.push_str(&format!("\n## {title}: ASR / P@0.5 (%)\n\n{}", markdown(&rows, split)));
        md.push_str(&format!("\n## {title}: mean best car score\n\n{}", markdown_scores(&rows, split)));
    }
    let cond = conditional_asr(&records, threshold);
    write_csv(&out.join("crossval_asr_detected.csv"), &cond)?;
    let texs = unique(cond.iter().map(|c| c.texture.clone()));
    md.push_str(&format!(
        "\n## ASR (%) over the held-out views whose original paint is detected\n\n| detector | views | {} |\n|---|---:|{}\n",
        texs.join(" | "),
        "---:|".repeat(texs.len())
    ));
    for det in unique(cond.iter().map(|c| c.detector.clone())) {
        let n = cond.iter().find(|c| c.detector == det).map_or(0, |c| c.views);
        md.push_str(&format!("| {det} | {n} |"));
        for t in &texs {
            match cond.iter().find(|c| c.detector == det && &c.texture == t) {
                Some(c) => md.push_str(&format!(" {:.1} |", 100.0 * c.asr)),
                None => md.push_str(" – |"),
            }
        }
        md.push('\n');
    }
    md.push_str(&format!(
        "\n## Optimized against each other texture, held-out views: mean difference of the best car score [95 % paired-bootstrap interval over views]\n\nBelow zero: the optimized texture leaves the car a lower score. An interval entirely below zero is a win with error bars.\n\n{}",
        markdown_paired(&pairs)
    ));
    md.push_str(&anatomy_section(&markdown_anatomy(&anatomies), "Boxes per view: `crossval_boxes.csv`."));
    let own = paired(&own_box_records(&records, &boxes), &opts.white_box, "optimized");
    write_csv(&out.join("crossval_paired_own_box.csv"), &own)?;
    md.push_str(&own_box_section(&markdown_paired(&own)));
    if let Some(r) = &scored {
        md.push_str(&rendered_report(r, rendered, &opts.white_box, &out.join(PLATES_DIR))?);
    }
    if !scored_curve.is_empty() {
        write_csv(&out.join("crossval_curve.csv"), &scored_curve)?;
        let points = pool(&scored_curve);
        super::curve::plot(&out.join("crossval_curve.png"), &points, threshold)?;
        md.push_str(&format!(
            "\n## The texture as it was optimized: mean best car score of its snapshots, every {} steps (`crossval_curve.csv`, `crossval_curve.png`)\n\nEach fold's snapshots scored on that fold's photos, pooled at the steps every fold reached; the end row is the folds' final textures (8-bit, as saved){}.\n\n{}",
            curve.every,
            curve.mean_from.map_or(String::new(), |m| format!(
                ". The texture {} in the tables above is each fold's pixel mean of its snapshots from step {m} to its end",
                snapshot_mean_name(m)
            )),
            super::curve::markdown(&points)
        ));
    }
    write_markdown(out, "crossval.md", &md)?;
    Ok(md)
}

/// Where crossval writes what it scored on rendered views over the held-out photos' plates: the
/// files of a crossval folder, one record per photo, so `pav table1` reads it as a run.
pub const PLATES_DIR: &str = "plates";

/// Writes the rendered views' files into `dir` (per photo: `crossval_views.csv` of best car
/// scores, `crossval_own_views.csv` of the car's own box; every view: `crossval_rendered.csv`;
/// the pooled table, anatomy and pairs; `crossval.md`), and returns a section for crossval.md.
fn rendered_report(
    r: &Rendered,
    dirs: &[PathBuf],
    white_box: &[String],
    dir: &Path,
) -> Result<String, ExperimentError> {
    create_dir(dir)?;
    let scores = per_photo(&r.records, false);
    let own = per_photo(&r.records, true);
    write_csv(&dir.join("crossval.csv"), &r.rows)?;
    write_csv(&dir.join("crossval_views.csv"), &scores)?;
    write_csv(&dir.join("crossval_own_views.csv"), &own)?;
    write_csv(&dir.join("crossval_rendered.csv"), &r.records)?;
    write_csv(&dir.join("crossval_anatomy.csv"), &r.anatomies)?;
    let pairs = paired(&scores, white_box, "optimized");
    let own_pairs = paired(&own, white_box, "optimized");
    write_csv(&dir.join("crossval_paired.csv"), &pairs)?;
    write_csv(&dir.join("crossval_paired_own_box.csv"), &own_pairs)?;
    let views = unique(r.records.iter().map(|x| x.view.clone())).len();
    let photos = unique(r.records.iter().map(|x| x.photo.clone())).len();
    let intro = format!(
        "{views} rendered views over {photos} photos' plates ({}), each scored in the fold that holds its photo out, so its street and camera were never trained on. Views of one photo are not independent: the pairs compare per-photo means, bootstrapped over photos.",
        dirs.iter().map(|d| d.display().to_string()).collect::<Vec<_>>().join(", ")
    );
    let body = format!(
        "{intro}\n\n## ASR / P@0.5 (%), every view\n\n{}\n## Mean best car score, every view\n\n{}\n## Optimized against each other texture: mean difference of the per-photo mean best car score [95 % paired-bootstrap interval over photos]\n\n{}{}{}",
        markdown(&r.rows, "held-out"),
        markdown_scores(&r.rows, "held-out"),
        markdown_paired(&pairs),
        anatomy_section(&markdown_anatomy(&r.anatomies), "Every view: `crossval_rendered.csv`."),
        own_box_section(&markdown_paired(&own_pairs)),
    );
    write_markdown(
        dir,
        "crossval.md",
        &format!("# Cross-validation: rendered views over the held-out photos' plates\n\n{body}"),
    )?;
    Ok(format!(
        "\n## Rendered views over the held-out photos' plates (`{PLATES_DIR}/`)\n\n{intro}\n\n{}\n{}",
        markdown_scores(&r.rows, "held-out"),
        markdown_paired(&pairs)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_view_is_held_out_exactly_once() {
        let (n, k) = (11, 4);
        let mut held = vec![0; n];
        for f in 0..k {
            let (tr, te) = fold_split(n, k, f);
            assert_eq!(tr.len() + te.len(), n);
            assert!(tr.iter().all(|i| !te.contains(i)));
            te.iter().for_each(|&i| held[i] += 1);
        }
        assert!(held.iter().all(|&h| h == 1));
    }
}
