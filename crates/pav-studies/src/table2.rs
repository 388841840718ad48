//! The paper's Table II on composites (`pav eval-digital`). Every view is composited with each
//! texture (lit, no EoT), quantized to 8 bits as a saved image would be, and scored by every
//! ONNX detector; the white-box model is marked.

use super::per_view::{markdown_paired, paired, Paired, ScoredView};
use super::{create_dir, write_markdown, ExperimentError, Scoring};
use pav_attack::config::OptimizeConfig;
use pav_attack::setup::Setup;
use pav_attack::view::TrainView;
use pav_core::image::{to_u8, Frame};
use pav_core::progress::Progress;
use pav_core::table::{unique, write_csv};
use pav_detect::load::load_detectors;
use pav_detect::Detector;
use pav_eval::digital::{ap50, asr, ImageDetections};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Lowest car score kept for P@0.5 (COCO evaluations keep low-scoring boxes for the PR curve).
pub const AP_MIN_SCORE: f32 = 0.05;

/// One cell of the table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DigitalRow {
    /// Detector name.
    pub detector: String,
    /// Whether the texture was optimized against this detector.
    pub white_box: bool,
    /// Texture condition.
    pub texture: String,
    /// "train", "test" or "all".
    pub split: String,
    /// Images.
    pub images: usize,
    /// ASR at `threshold`.
    pub asr: f64,
    /// ASR over the images whose original paint is detected (a view the original already
    /// misses is no success of the texture); empty where not computed (crossval writes it to
    /// `crossval_asr_detected.csv`) or when the original is detected on none.
    pub asr_detected: Option<f64>,
    /// Car AP at IoU 0.5 (NaN without ground truth).
    pub p50: f64,
    /// Mean over images of the best car score (0 when no box): the attack's effect below the threshold.
    pub mean_score: f64,
    /// Score threshold of the ASR.
    pub threshold: f32,
}

/// The composite of `view` with `tex` (as scores see it, or the photo itself) as an 8-bit BGR
/// frame.
pub(crate) fn frame(view: &TrainView, tex: Option<&[f32]>, setup: &Setup) -> Frame {
    let img = match tex {
        Some(t) => view.composite(t, &setup.eval_scene()),
        None => view.photo.clone(),
    };
    Frame {
        width: view.size,
        height: view.size,
        bgr: img.chunks(3).flat_map(|c| [to_u8(c[2]), to_u8(c[1]), to_u8(c[0])]).collect(),
    }
}

/// The car detections of every detector on `view` composited with `tex` (`None` = the photo),
/// a texture as scores see it ([`Setup::scored`]).
pub fn detect_view(
    view: &TrainView,
    tex: Option<&[f32]>,
    setup: &Setup,
    detectors: &mut [Box<dyn Detector>],
) -> Result<Vec<ImageDetections>, pav_detect::DetectError> {
    let f = frame(view, tex, setup);
    let mut out = Vec::with_capacity(detectors.len());
    for det in detectors.iter_mut() {
        let p = det.propose(&f)?;
        let cars = p
            .target_detections(det.target_classes(), AP_MIN_SCORE, det.nms_iou())
            .into_iter()
            .map(|x| (x.score, x.bbox))
            .collect();
        out.push(ImageDetections { gt: setup.boxes.get(&view.name).copied(), cars });
    }
    Ok(out)
}

/// [`detect_view`] over `views`, dealt out among the `workers` (one set of the same detectors
/// each) on threads of their own; the detections come back in view order.
pub fn detect_views(
    views: &[(&'static str, &TrainView)],
    tex: Option<&[f32]>,
    setup: &Setup,
    workers: &mut [Vec<Box<dyn Detector>>],
    progress: &dyn Progress,
) -> Result<Vec<Vec<ImageDetections>>, pav_detect::DetectError> {
    let n = workers.len().max(1);
    let (done, ticks) = std::sync::mpsc::channel::<()>();
    let dealt = std::thread::scope(|scope| {
        let handles: Vec<_> = workers
            .iter_mut()
            .enumerate()
            .map(|(w, dets)| {
                let done = done.clone();
                scope.spawn(move || {
                    let mut out = Vec::new();
                    for (i, (_, v)) in views.iter().enumerate().skip(w).step_by(n) {
                        out.push((i, detect_view(v, tex, setup, dets)?));
                        // The receiver outlives the workers; a send cannot fail while it waits.
                        let _ = done.send(());
                    }
                    Ok::<_, pav_detect::DetectError>(out)
                })
            })
            .collect();
        drop(done);
        // The progress bar is not shared across threads: this thread counts for the workers.
        for () in ticks.iter() {
            progress.advance(1);
        }
        handles.into_iter().map(|h| h.join().expect("a scoring worker panicked")).collect::<Vec<_>>()
    });
    let mut slots: Vec<Option<Vec<ImageDetections>>> = vec![None; views.len()];
    for part in dealt {
        for (i, ims) in part? {
            slots[i] = Some(ims);
        }
    }
    Ok(slots.into_iter().map(|s| s.expect("every view is dealt to one worker")).collect())
}

/// One cell from the detections of its images; `None` when there are none.
pub fn aggregate(
    detector: &str,
    white_box: bool,
    texture: &str,
    split: &str,
    ims: &[ImageDetections],
    threshold: f32,
) -> Option<DigitalRow> {
    let a = asr(ims, threshold)?;
    Some(DigitalRow {
        detector: detector.to_string(),
        white_box,
        texture: texture.to_string(),
        split: split.into(),
        images: ims.len(),
        asr: a,
        asr_detected: None,
        p50: ap50(ims).unwrap_or(f64::NAN),
        mean_score: ims.iter().map(|i| i.best_score() as f64).sum::<f64>() / ims.len() as f64,
        threshold,
    })
}

/// One scored view: its split, its detections, and whether the original paint is detected there.
type Scored = (&'static str, ImageDetections, bool);

/// One texture condition of [`score_textures`].
pub struct Condition {
    /// Texture name; conditions of one name (a random kind's seeds) pool into one row.
    pub name: String,
    /// Random seed (0 for the others).
    pub seed: u64,
    /// The texture (`None` = the unmodified photo).
    pub texture: Option<Vec<f32>>,
}

/// Scores every (detector, texture, split) of `setup`, pooling the conditions of one name, and
/// returns the rows and every view's best score per condition (fold 0; role "train" or
/// "held-out"); `progress` counts composites. The first condition must be the original.
/// `workers` holds one set of the same detectors per thread: the views are dealt out among them
/// and the results kept in view order, so the rows do not depend on how many there are.
pub fn score_textures(
    setup: &Setup,
    workers: &mut [Vec<Box<dyn Detector>>],
    conditions: &[Condition],
    threshold: f32,
    white_box: &dyn Fn(&str) -> Vec<String>,
    progress: &dyn Progress,
) -> Result<(Vec<DigitalRow>, Vec<ScoredView>), pav_detect::DetectError> {
    let names: Vec<String> = match workers.first() {
        Some(w) => w.iter().map(|d| d.name().to_string()).collect(),
        None => return Ok((Vec::new(), Vec::new())),
    };
    let views: Vec<(&'static str, &TrainView)> =
        setup.train.iter().map(|v| ("train", v)).chain(setup.test.iter().map(|v| ("test", v))).collect();
    progress.begin("composites", (conditions.len() * views.len()) as u64);
    let mut records = Vec::new();
    // Per name, per detector: every view it was scored on.
    let mut pooled: Vec<(String, Vec<Vec<Scored>>)> = Vec::new();
    // Per detector, whether the unmodified photo of each view (in view order) is detected.
    let mut original: Option<Vec<Vec<bool>>> = None;
    for c in conditions {
        let tex = c.texture.as_deref().map(|t| setup.scored(t));
        let detected = detect_views(&views, tex.as_deref(), setup, workers, progress)?;
        let mut per: Vec<Vec<(&'static str, ImageDetections)>> = vec![Vec::new(); names.len()];
        for ((split, v), ims) in views.iter().zip(detected) {
            for (d, im) in ims.into_iter().enumerate() {
                records.push(ScoredView {
                    fold: 0,
                    role: if *split == "test" { "held-out" } else { "train" },
                    view: v.name.clone(),
                    texture: c.name.clone(),
                    seed: c.seed,
                    detector: names[d].clone(),
                    score: im.best_score(),
                });
                per[d].push((split, im));
            }
        }
        if c.texture.is_none() && original.is_none() {
            original = Some(per.iter().map(|p| p.iter().map(|(_, i)| i.car_detected(threshold)).collect()).collect());
        }
        let seen = original.as_ref();
        let k = match pooled.iter().position(|(n, _)| n == &c.name) {
            Some(k) => k,
            None => {
                pooled.push((c.name.clone(), vec![Vec::new(); names.len()]));
                pooled.len() - 1
            }
        };
        for (d, ims) in per.into_iter().enumerate() {
            for (i, (split, im)) in ims.into_iter().enumerate() {
                pooled[k].1[d].push((split, im, seen.is_some_and(|o| o[d][i])));
            }
        }
    }
    let mut rows = Vec::new();
    for (name, per) in &pooled {
        for (d, det) in names.iter().enumerate() {
            for split in ["train", "test", "all"] {
                let keep = |s: &str| split == "all" || s == split;
                let ims: Vec<ImageDetections> =
                    per[d].iter().filter(|(s, _, _)| keep(s)).map(|(_, i, _)| i.clone()).collect();
                let mut row = aggregate(det, white_box(name).iter().any(|w| w == det), name, split, &ims, threshold);
                if let (Some(r), true) = (row.as_mut(), original.is_some()) {
                    let missed: Vec<bool> = per[d]
                        .iter()
                        .filter(|(s, _, o)| keep(s) && *o)
                        .map(|(_, i, _)| !i.car_detected(threshold))
                        .collect();
                    if !missed.is_empty() {
                        r.asr_detected = Some(missed.iter().filter(|&&x| x).count() as f64 / missed.len() as f64);
                    }
                }
                rows.extend(row);
            }
        }
    }
    progress.end(None);
    Ok((rows, records))
}

/// A texture file's name in tables: its folder's (a run's `texture.png`), else its stem.
pub fn texture_name(t: &Path) -> String {
    t.parent()
        .and_then(|p| p.file_name())
        .or(t.file_stem())
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| t.display().to_string())
}

/// A texture argument of `pav eval-digital` as its name and its (seed, PNG) runs: a PNG is one
/// run (seed 0) named by [`texture_name`]; a folder of a `pav optimize --seeds` run is its
/// `seed<N>/texture.png` files, pooled under the folder's name like a random kind's seeds.
pub fn texture_seeds(t: &Path) -> Result<(String, Vec<(u64, PathBuf)>), ExperimentError> {
    if !t.is_dir() {
        return Ok((texture_name(t), vec![(0, t.to_path_buf())]));
    }
    let entries = std::fs::read_dir(t).map_err(|source| ExperimentError::Io { path: t.into(), source })?;
    let mut runs = Vec::new();
    for e in entries {
        let e = e.map_err(|source| ExperimentError::Io { path: t.into(), source })?;
        let name = e.file_name().to_string_lossy().into_owned();
        let seed = name.strip_prefix("seed").and_then(|n| n.parse::<u64>().ok());
        let png = e.path().join("texture.png");
        if let (Some(seed), true) = (seed, png.is_file()) {
            runs.push((seed, png));
        }
    }
    if runs.is_empty() {
        return Err(ExperimentError::Invalid(format!(
            "{}: a folder without seed<N>/texture.png in it; give a texture PNG or the folder of a `pav optimize --seeds` run",
            t.display()
        )));
    }
    runs.sort();
    let name = t.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| t.display().to_string());
    Ok((name, runs))
}

/// `pav eval-digital`: the original paint, `random_seeds` random textures of each kind and each
/// texture of `textures` (a PNG named by its folder, or a `--seeds` run's folder with its seeds
/// pooled, [`texture_seeds`]) on the views of `config`; writes
/// `digital.csv`, every view's scores (`digital_views.csv`), each file's paired comparisons on
/// held-out views (`digital_paired.csv`) and `digital.md` into `out`, and returns the Markdown
/// with every view's scores.
#[allow(clippy::too_many_arguments)]
pub fn eval_digital(
    config: &Path,
    textures: &[PathBuf],
    random_seeds: u64,
    scoring: &Scoring,
    squeeze: Option<f64>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<(String, Vec<ScoredView>), ExperimentError> {
    let threshold = scoring.threshold;
    let cfg = OptimizeConfig::load(config)?;
    let mut setup = Setup::load_photos(&cfg, None)?;
    scoring.apply_print(&mut setup)?;
    let mut conditions = vec![Condition { name: "original".into(), seed: 0, texture: None }];
    for seed in 1..=random_seeds.max(1) {
        for (name, block) in [("random", setup.random_block()), ("random32", setup.paper_random_block())] {
            conditions.push(Condition { name: name.into(), seed, texture: Some(setup.random_texture(block, seed)) });
        }
    }
    let mut mine = Vec::new();
    // A texture whose folder records the config it was optimized with is starred for that
    // config's white boxes; any other texture for this config's.
    let config_wb = cfg.white_box_names()?;
    let mut own_wb: HashMap<String, Vec<String>> = HashMap::new();
    let mut seeds_of = HashMap::new();
    for t in textures {
        let (name, runs) = texture_seeds(t)?;
        for (seed, file) in &runs {
            let tex = setup.load_texture(file)?;
            let recorded = file.parent().and_then(pav_run::provenance::recorded_config);
            if let Some(wb) = recorded.and_then(|c| OptimizeConfig::load(&c).ok()?.white_box_names().ok()) {
                own_wb.insert(name.clone(), wb);
            }
            conditions.push(Condition { name: name.clone(), seed: *seed, texture: Some(tex) });
        }
        seeds_of.insert(name.clone(), runs.len());
        mine.push(name);
    }
    let mut defences = scoring.defences.clone();
    if squeeze.is_some() {
        pav_eval::squeeze::add_squeezers(&mut defences);
    }
    // One set of single-threaded sessions per core: views are independent, and single-threaded
    // sessions give the same floats whatever the machine's core count.
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let views = setup.train.len() + setup.test.len();
    let first = load_detectors(&scoring.detectors, &[], &defences, 1)?;
    let copies = (1..cores.min(views).max(1))
        .map(|_| first.iter().map(|d| d.replica()).collect::<Result<Vec<_>, _>>())
        .collect::<Result<Vec<_>, _>>()?;
    let mut workers: Vec<_> = std::iter::once(first).chain(copies).collect();
    let white_box = |name: &str| own_wb.get(name).cloned().unwrap_or_else(|| config_wb.clone());
    let (rows, records) = score_textures(&setup, &mut workers, &conditions, threshold, &white_box, progress)?;
    create_dir(out)?;
    write_csv(&out.join("digital.csv"), &rows)?;
    write_csv(&out.join("digital_views.csv"), &records)?;
    let pairs: Vec<Paired> = mine.iter().flat_map(|m| paired(&records, &white_box(m), m)).collect();
    write_csv(&out.join("digital_paired.csv"), &pairs)?;
    let mut md = format!(
        "# Digital evaluation (ASR / P@0.5 in %, * = white-box)\n\nCar = COCO `car`; detected at score ≥ {threshold}; P@0.5 is car AP at IoU 0.5 over boxes from score {AP_MIN_SCORE}. Views composited at {}² (lit, no EoT), 8-bit. Config: {}.\n",
        cfg.views.size,
        config.display()
    );
    // "all" repeats the other table when a split is empty (a config with rendered test views only).
    let both = ["train", "test"].iter().all(|s| rows.iter().any(|r| r.split == *s));
    for (split, title) in [("train", "training views"), ("test", "held-out views"), ("all", "all views")] {
        if rows.iter().any(|r| r.split == split) && (split != "all" || both) {
            let n = rows.iter().find(|r| r.split == split).map(|r| r.images).unwrap_or(0);
            md.push_str(&format!("\n## {title} ({n})\n\n{}", markdown(&rows, split)));
            md.push_str(&format!(
                "\nASR (%) over the {title} whose original paint is detected:\n\n{}",
                table(&rows, split, |r, star| r
                    .asr_detected
                    .map_or("–".into(), |a| format!("{:.1}{star}", 100.0 * a)))
            ));
        }
    }
    for m in &mine {
        let p: Vec<Paired> = pairs.iter().filter(|p| &p.texture == m).cloned().collect();
        if !p.is_empty() {
            let pairs_are = match seeds_of.get(m).copied().unwrap_or(1) {
                1 => "views".to_string(),
                k => format!("(seed, view) pairs of its {k} seeds"),
            };
            md.push_str(&format!(
                "\n## {m} against each other texture, held-out views: mean difference of the best car score [95 % paired-bootstrap interval over {pairs_are}; random kinds: each view's mean over {} seeds]\n\n{}",
                random_seeds.max(1),
                markdown_paired(&p)
            ));
        }
    }
    if let Some(false_flags) = squeeze {
        md.push_str(&squeeze_section(&records, false_flags, out)?);
    }
    write_markdown(out, "digital.md", &md)?;
    Ok((md, records))
}

/// One view's squeeze gap under one texture, as `digital_squeeze.csv` lists it.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SqueezeView {
    /// Texture name.
    pub texture: String,
    /// Its seed (random textures).
    pub seed: u64,
    /// TrainView name.
    pub view: String,
    /// The undefended detector.
    pub detector: String,
    /// The largest change of the best car score under bit depth 4 or a 3×3 median.
    pub gap: f32,
    /// Whether it is above the detector's threshold.
    pub flagged: bool,
}

/// The textures whose views count as legitimate when the squeezing detector's thresholds are set.
const LEGITIMATE: [&str; 3] = ["original", "random", "random32"];

/// Feature squeezing as an attack detector over the scored views: each detector's threshold
/// flags `false_flags` of the legitimate views (the photo and the random textures); writes
/// `digital_squeeze.csv` and returns the Markdown section.
fn squeeze_section(records: &[ScoredView], false_flags: f64, out: &Path) -> Result<String, ExperimentError> {
    use pav_eval::squeeze;
    let scores: Vec<_> = records
        .iter()
        .map(|r| ((r.view.clone(), r.texture.clone(), r.seed), r.texture.as_str(), r.detector.as_str(), r.score))
        .collect();
    let mut gaps = squeeze::gaps(&scores, &squeeze::labels());
    let legit: Vec<String> = LEGITIMATE.map(String::from).to_vec();
    let thresholds = squeeze::thresholds(&gaps, &legit, false_flags);
    let rows = squeeze::flag(&mut gaps, &thresholds);
    let views: Vec<SqueezeView> = gaps
        .iter()
        .map(|g| SqueezeView {
            texture: g.group.clone(),
            seed: g.key.2,
            view: g.key.0.clone(),
            detector: g.detector.clone(),
            gap: g.gap,
            flagged: g.flagged,
        })
        .collect();
    write_csv(&out.join("digital_squeeze.csv"), &views)?;
    Ok(format!(
        "\n## Feature squeezing as an attack detector (Xu et al.)\n\n{}\nPer-view gaps: `digital_squeeze.csv`.\n",
        squeeze::markdown(
            &rows,
            "view",
            &format!("set so that {} % of the views of {} are flagged", 100.0 * false_flags, LEGITIMATE.join(", "))
        )
    ))
}

/// The table in the paper's shape: detectors down, textures across, "ASR / P@0.5" in percent,
/// white-box cells starred; one table per split.
pub fn markdown(rows: &[DigitalRow], split: &str) -> String {
    table(rows, split, |r, star| format!("{:.1}{star} / {:.1}{star}", 100.0 * r.asr, 100.0 * r.p50))
}

/// The same table with the mean best car score per cell: the attack's effect below the threshold.
pub fn markdown_scores(rows: &[DigitalRow], split: &str) -> String {
    table(rows, split, |r, star| format!("{:.3}{star}", r.mean_score))
}

fn table(rows: &[DigitalRow], split: &str, cell: impl Fn(&DigitalRow, &str) -> String) -> String {
    let textures = unique(rows.iter().map(|r| r.texture.clone()));
    let detectors = unique(rows.iter().map(|r| r.detector.clone()));
    let mut s = format!("| detector | {} |\n|---|{}\n", textures.join(" | "), "---|".repeat(textures.len()));
    for d in &detectors {
        // Labelled white-box when every texture was trained against it; else the cells say.
        let wb = rows.iter().filter(|r| &r.detector == d).all(|r| r.white_box);
        s.push_str(&format!("| {d}{} |", if wb { " (white-box)" } else { "" }));
        for t in &textures {
            match rows.iter().find(|r| &r.detector == d && &r.texture == t && r.split == split) {
                Some(r) => {
                    s.push_str(&format!(" {} |", cell(r, if r.white_box && t != "original" { "*" } else { "" })))
                }
                None => s.push_str(" – |"),
            }
        }
        s.push('\n');
    }
    s
}
