//! The paper's Table I from `pav crossval` runs: a row per texture (the baselines, then one per
//! run: what it was trained against), a column per detector it is scored on, every cell over
//! held-out views; then each run's paired difference against every baseline, with its interval.

use super::boxes::{
    anatomy_section, markdown_anatomy, mean_anatomy, own_box_records, own_box_section, BoxAnatomy, BoxRecord,
};
use super::curve::is_snapshot_mean;
use super::per_view::{paired, Paired, ScoredView};
use super::ExperimentError;
use pav_core::table::unique;
use std::path::{Path, PathBuf};

/// The texture a crossval optimizes; every other texture of its tables is a baseline, except a
/// run's snapshot mean.
const OPTIMIZED: &str = "optimized";

/// One cell of the transfer table: a texture on one detector over the held-out views.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Cell {
    /// The row: a baseline texture's name, or a run's label.
    pub row: String,
    /// The detector scored.
    pub detector: String,
    /// Whether the row's texture was optimized against this detector.
    pub white_box: bool,
    /// Mean over held-out views of the best car score.
    pub mean_score: f64,
    /// Car AP at IoU 0.5 over the held-out views (a row of several runs: their mean).
    pub p50: f64,
    /// The lowest P@0.5 of the row's runs.
    pub p50_min: f64,
    /// The highest P@0.5 of the row's runs.
    pub p50_max: f64,
    /// Runs averaged in this row.
    pub runs: usize,
    /// Held-out images scored per run (random textures count each seed).
    pub images: usize,
}

/// A run's optimized texture against a baseline, per detector, paired over held-out views.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Difference {
    /// The row's label.
    pub row: String,
    /// The baseline, or another row's label.
    pub against: String,
    /// The detector scored.
    pub detector: String,
    /// Whether the run trained against this detector.
    pub white_box: bool,
    /// Mean over held-out views of optimized − baseline (below zero: the optimized texture
    /// hides the car better).
    pub mean: f64,
    /// 95 % paired-bootstrap interval, low end.
    pub lo: f64,
    /// 95 % paired-bootstrap interval, high end.
    pub hi: f64,
    /// Held-out views paired.
    pub views: usize,
}

impl Difference {
    /// The paired comparison `p` as a row of `row`.
    fn of(row: &str, p: Paired) -> Self {
        let Paired { against, detector, white_box, mean, lo, hi, views, .. } = p;
        Difference { row: row.to_string(), against, detector, white_box, mean, lo, hi, views }
    }
}

/// The transfer table of several runs.
#[derive(Clone, Debug)]
pub struct Table1 {
    /// Baseline rows (from the first run), then one row per label.
    pub cells: Vec<Cell>,
    /// Every label against every baseline and every `against` label.
    pub differences: Vec<Difference>,
    /// The same pairs over the car's own box: each view's best car box on the car (IoU ≥ 0.5,
    /// 0 without one), the boxes P@0.5 counts as hits (labels whose runs all wrote their boxes).
    pub own_box: Vec<Difference>,
    /// The largest difference of a baseline's held-out mean between runs: zero when the runs
    /// scored the same baselines on the same views.
    pub baseline_spread: f64,
    /// Where the car boxes sit on held-out views: the first run's baselines, then each label's
    /// optimized texture averaged over its runs (labels whose runs all have them).
    pub anatomy: Vec<BoxAnatomy>,
    /// Every held-out view's best car score: the first run's baselines (random ones averaged
    /// over their seeds), then each label's texture averaged over its runs (texture: the label).
    pub views: Vec<ScoredView>,
    /// Each label's mean best car score on the photos it trained on and on the same photos held out.
    pub trained_cells: Vec<TrainedCell>,
    /// Each label on the photos it trained on against every baseline: trained-on − baseline,
    /// paired over photos (a gap already there is not one of generalization over photos).
    pub trained_on: Vec<Difference>,
    /// Each label held out against itself trained on (against = "trained-on"): held-out −
    /// trained-on, paired over photos, what a texture loses on a photo it has not seen.
    pub generalization: Vec<Difference>,
}

/// A label's texture on one detector: its mean best car score over the photos, each photo
/// scored where it trained (mean over those folds) and where it was held out.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TrainedCell {
    /// The label.
    pub row: String,
    /// The detector scored.
    pub detector: String,
    /// Whether the label trained against it.
    pub white_box: bool,
    /// Mean over photos of the best car score in the folds that trained on the photo.
    pub trained_on: f64,
    /// Mean over the same photos of the best car score in the fold that held it out.
    pub held_out: f64,
    /// Photos.
    pub views: usize,
}

/// The texture name of a label's trained-on records in its pairings.
const TRAINED_ON: &str = "trained-on";

/// One row of `crossval.csv`, as read back.
#[derive(serde::Deserialize)]
struct CrossvalRow {
    detector: String,
    white_box: bool,
    texture: String,
    split: String,
    images: usize,
    p50: f64,
    mean_score: f64,
}

/// One row of `crossval_views.csv`, as read back.
#[derive(serde::Deserialize)]
struct ViewRow {
    fold: usize,
    role: String,
    view: String,
    texture: String,
    seed: u64,
    detector: String,
    score: f32,
}

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Vec<T>, ExperimentError> {
    let bad = |e: csv::Error| {
        ExperimentError::Invalid(format!("{}: {e} (is this a folder written by `pav crossval`?)", path.display()))
    };
    let mut r = csv::Reader::from_path(path).map_err(bad)?;
    r.deserialize().collect::<Result<Vec<T>, _>>().map_err(bad)
}

/// One run read back: its held-out table rows, view records and box anatomies (empty for a
/// run written before crossval wrote them).
struct Run {
    held: Vec<CrossvalRow>,
    records: Vec<ScoredView>,
    anatomy: Vec<BoxAnatomy>,
    /// The records with each view's score replaced by its best box on the car (IoU ≥ 0.5; 0
    /// without one); empty for a run written before crossval wrote its boxes.
    own: Vec<ScoredView>,
    /// The row texture on the photos it trained on, per (photo, detector) the mean over the
    /// folds that trained on it, filed under the fold that holds the photo out (see [`trained_on`]).
    trained: Vec<ScoredView>,
}

/// The runs of one label, averaged per held-out view.
struct Group {
    label: String,
    /// The optimized texture's best car scores.
    scores: Vec<ScoredView>,
    /// Its car's own box (None when a run lacks its boxes).
    own: Option<Vec<ScoredView>>,
    /// Its scores on the photos it trained on (None when a run has none).
    trained: Option<Vec<ScoredView>>,
    /// The detectors it trained against.
    white: Vec<String>,
}

/// Reads the run in `dir` with `texture` as its row: renamed to "optimized", while the other
/// textures of the run's own (its final texture when another was chosen, its snapshot means)
/// are left out; the rest are baselines the runs share.
fn read_run(dir: &Path, texture: &str) -> Result<Run, ExperimentError> {
    // The name a texture of the run takes in the table, or None to leave it out.
    let role = |t: String| -> Option<String> {
        if t == texture {
            Some(OPTIMIZED.to_string())
        } else if t == OPTIMIZED || is_snapshot_mean(&t) {
            None
        } else {
            Some(t)
        }
    };
    let rows: Vec<CrossvalRow> = read(&dir.join("crossval.csv"))?;
    let held: Vec<CrossvalRow> = rows
        .into_iter()
        .filter(|r| r.split == "held-out")
        .filter_map(|r| role(r.texture.clone()).map(|texture| CrossvalRow { texture, ..r }))
        .collect();
    if !held.iter().any(|r| r.texture == OPTIMIZED) {
        return Err(ExperimentError::Invalid(format!(
            "{}: no held-out scores of a texture named {texture}",
            dir.join("crossval.csv").display()
        )));
    }
    let held_out_of = |rows: Vec<ViewRow>| -> Vec<ScoredView> {
        rows.into_iter()
            .filter(|v| v.role == "held-out")
            .filter_map(|v| {
                role(v.texture).map(|texture| ScoredView {
                    fold: v.fold,
                    role: "held-out",
                    view: v.view,
                    texture,
                    seed: v.seed,
                    detector: v.detector,
                    score: v.score,
                })
            })
            .collect()
    };
    let held_out = |path: &Path| -> Result<Vec<ScoredView>, ExperimentError> { Ok(held_out_of(read(path)?)) };
    let rows: Vec<ViewRow> = read(&dir.join("crossval_views.csv"))?;
    let trained = trained_on(&rows, texture);
    let records = held_out_of(rows);
    let path = dir.join("crossval_anatomy.csv");
    let anatomy: Vec<BoxAnatomy> = if path.is_file() { read(&path)? } else { Vec::new() };
    let anatomy = anatomy
        .into_iter()
        .filter_map(|a| role(a.texture.clone()).map(|texture| BoxAnatomy { texture, ..a }))
        .collect();
    // A `plates` folder has each photo's own box already averaged over its rendered views.
    let (boxes, own_views) = (dir.join("crossval_boxes.csv"), dir.join("crossval_own_views.csv"));
    let own = if own_views.is_file() {
        held_out(&own_views)?
    } else if boxes.is_file() {
        let b: Vec<BoxRecord> = read(&boxes)?;
        let b: Vec<BoxRecord> =
            b.into_iter().filter_map(|x| role(x.texture.clone()).map(|texture| BoxRecord { texture, ..x })).collect();
        own_box_records(&records, &b)
    } else {
        Vec::new()
    };
    Ok(Run { held, records, anatomy, own, trained })
}

/// `texture`'s records on the photos it trained on: per (photo, detector) the mean best car
/// score over the folds that trained on the photo, filed as a held-out record of the fold that
/// holds the photo out (so it pairs with that fold's held-out scores) and named "optimized".
fn trained_on(rows: &[ViewRow], texture: &str) -> Vec<ScoredView> {
    let mut out = Vec::new();
    for h in rows.iter().filter(|r| r.role == "held-out" && r.texture == texture) {
        let of: Vec<f64> = rows
            .iter()
            .filter(|r| r.role == "train" && r.texture == texture && r.view == h.view && r.detector == h.detector)
            .map(|r| r.score as f64)
            .collect();
        if !of.is_empty() {
            out.push(ScoredView {
                fold: h.fold,
                role: "held-out",
                view: h.view.clone(),
                texture: OPTIMIZED.into(),
                seed: 0,
                detector: h.detector.clone(),
                score: (of.iter().sum::<f64>() / of.len() as f64) as f32,
            });
        }
    }
    out
}

/// The optimized texture's held-out records of several runs of one label, each (fold, view,
/// detector) averaged over the runs, renamed to `texture`. The runs must hold out the same views.
fn averaged(
    runs: &[&Run],
    dirs: &[&Path],
    texture: &str,
    of: fn(&Run) -> &[ScoredView],
) -> Result<Vec<ScoredView>, ExperimentError> {
    let mine = |r: &Run| -> Vec<(usize, String, String, f32)> {
        let mut v: Vec<_> = of(r)
            .iter()
            .filter(|x| x.texture == OPTIMIZED)
            .map(|x| (x.fold, x.view.clone(), x.detector.clone(), x.score))
            .collect();
        v.sort_by(|a, b| (a.0, &a.1, &a.2).cmp(&(b.0, &b.1, &b.2)));
        v
    };
    let first = mine(runs[0]);
    let mut sum: Vec<f64> = first.iter().map(|x| x.3 as f64).collect();
    for (r, dir) in runs.iter().zip(dirs).skip(1) {
        let other = mine(r);
        let same =
            other.len() == first.len() && other.iter().zip(&first).all(|(a, b)| (a.0, &a.1, &a.2) == (b.0, &b.1, &b.2));
        if !same {
            return Err(ExperimentError::Invalid(format!(
                "{} holds out other views, folds or detectors than {}: runs of one label must differ only in what was trained",
                dir.display(),
                dirs[0].display()
            )));
        }
        sum.iter_mut().zip(&other).for_each(|(s, o)| *s += o.3 as f64);
    }
    Ok(first
        .into_iter()
        .zip(sum)
        .map(|((fold, view, detector, _), s)| ScoredView {
            fold,
            role: "held-out",
            view,
            texture: texture.to_string(),
            seed: 0,
            detector,
            score: (s / runs.len() as f64) as f32,
        })
        .collect())
}

/// Builds the table from `runs` (a label and a `pav crossval` output folder each). Runs that
/// share a label (seeds of one config) make one row: each held-out view's score is averaged
/// over them before the paired bootstrap, so the row compares the method rather than one draw
/// of it. `against` names labels whose rows every other row is also paired with (a variant
/// against the config it varies).
pub fn table1(runs: &[(String, PathBuf)], against: &[String]) -> Result<Table1, ExperimentError> {
    let runs: Vec<(String, PathBuf, String)> =
        runs.iter().map(|(l, d)| (l.clone(), d.clone(), OPTIMIZED.into())).collect();
    table1_of(&runs, against)
}

/// [`table1`] with each run's row texture named: (label, folder, texture), the texture
/// "optimized" or another of the run's own, such as its snapshot mean.
pub fn table1_of(runs: &[(String, PathBuf, String)], against: &[String]) -> Result<Table1, ExperimentError> {
    if runs.is_empty() {
        return Err(ExperimentError::Invalid("name at least one `pav crossval` output folder".into()));
    }
    let read: Vec<Run> = runs.iter().map(|(_, d, t)| read_run(d, t)).collect::<Result<_, _>>()?;
    let runs: Vec<(String, PathBuf)> = runs.iter().map(|(l, d, _)| (l.clone(), d.clone())).collect();
    let labels = unique(runs.iter().map(|r| r.0.clone()));
    if let Some(a) = against.iter().find(|a| !labels.contains(a)) {
        return Err(ExperimentError::Invalid(format!(
            "--against {a}: no run has that label (labels: {})",
            labels.join(", ")
        )));
    }
    let mut baselines: Vec<Cell> = Vec::new();
    let mut spread = 0f64;
    for (i, run) in read.iter().enumerate() {
        for r in run.held.iter().filter(|r| r.texture != OPTIMIZED) {
            if i == 0 {
                baselines.push(Cell {
                    row: r.texture.clone(),
                    detector: r.detector.clone(),
                    white_box: false,
                    mean_score: r.mean_score,
                    p50: r.p50,
                    p50_min: r.p50,
                    p50_max: r.p50,
                    runs: 1,
                    images: r.images,
                });
            } else if let Some(b) = baselines.iter().find(|b| b.row == r.texture && b.detector == r.detector) {
                spread = spread.max((b.mean_score - r.mean_score).abs());
            }
        }
    }
    let mut anatomy: Vec<BoxAnatomy> = read[0].anatomy.iter().filter(|a| a.texture != OPTIMIZED).cloned().collect();
    let mut cells = Vec::new();
    let mut groups: Vec<Group> = Vec::new();
    for label in &labels {
        let idx: Vec<usize> = (0..runs.len()).filter(|&i| &runs[i].0 == label).collect();
        let group: Vec<&Run> = idx.iter().map(|&i| &read[i]).collect();
        let dirs: Vec<&Path> = idx.iter().map(|&i| runs[i].1.as_path()).collect();
        for r in group[0].held.iter().filter(|r| r.texture == OPTIMIZED) {
            let of_det: Vec<&CrossvalRow> = group
                .iter()
                .filter_map(|g| g.held.iter().find(|x| x.texture == OPTIMIZED && x.detector == r.detector))
                .collect();
            let n = of_det.len() as f64;
            cells.push(Cell {
                row: label.clone(),
                detector: r.detector.clone(),
                white_box: r.white_box,
                mean_score: of_det.iter().map(|x| x.mean_score).sum::<f64>() / n,
                p50: of_det.iter().map(|x| x.p50).sum::<f64>() / n,
                p50_min: of_det.iter().map(|x| x.p50).fold(f64::INFINITY, f64::min),
                p50_max: of_det.iter().map(|x| x.p50).fold(f64::NEG_INFINITY, f64::max),
                runs: of_det.len(),
                images: r.images,
            });
        }
        if group.iter().all(|g| !g.anatomy.is_empty()) {
            for det in unique(group[0].anatomy.iter().map(|a| a.detector.clone())) {
                let of: Vec<&BoxAnatomy> = group
                    .iter()
                    .flat_map(|g| g.anatomy.iter().filter(|a| a.texture == OPTIMIZED && a.detector == det))
                    .collect();
                anatomy.extend(mean_anatomy(label, &of));
            }
        }
        let white = unique(group[0].held.iter().filter(|r| r.white_box).map(|r| r.detector.clone()));
        let own = if group.iter().all(|g| !g.own.is_empty()) {
            Some(averaged(&group, &dirs, OPTIMIZED, |r| &r.own)?)
        } else {
            None
        };
        let scores = averaged(&group, &dirs, OPTIMIZED, |r| &r.records)?;
        let trained = if group.iter().all(|g| !g.trained.is_empty()) {
            Some(averaged(&group, &dirs, OPTIMIZED, |r| &r.trained)?)
        } else {
            None
        };
        groups.push(Group { label: label.clone(), scores, own, white, trained });
    }
    // Each label against the baselines and the `against` labels, over one kind of per-view score.
    let pair_all = |mine_of: &dyn Fn(&Group) -> Option<&Vec<ScoredView>>, baseline: &[ScoredView]| {
        let mut out = Vec::new();
        for g in &groups {
            let (label, white) = (&g.label, &g.white);
            let Some(mine) = mine_of(g) else { continue };
            let mut records = mine.clone();
            records.extend(baseline.iter().filter(|r| r.texture != OPTIMIZED && r.texture != "original").cloned());
            for a in against.iter().filter(|a| *a != label) {
                let theirs = groups.iter().find(|g| &g.label == a).and_then(mine_of);
                records.extend(theirs.into_iter().flatten().map(|r| ScoredView { texture: a.clone(), ..r.clone() }));
            }
            out.extend(paired(&records, white, OPTIMIZED).into_iter().map(|p| Difference::of(label, p)));
        }
        out
    };
    let differences = pair_all(&|g| Some(&g.scores), &read[0].records);
    let mut views = seeds_averaged(read[0].records.iter().filter(|r| r.texture != OPTIMIZED));
    views.extend(
        groups.iter().flat_map(|g| g.scores.iter().map(|r| ScoredView { texture: g.label.clone(), ..r.clone() })),
    );
    let own_box = if read[0].own.is_empty() { Vec::new() } else { pair_all(&|g| g.own.as_ref(), &read[0].own) };
    let (mut trained_cells, mut trained_on, mut generalization) = (Vec::new(), Vec::new(), Vec::new());
    for g in &groups {
        let Some(trained) = &g.trained else { continue };
        let as_difference = |p: Paired| Difference::of(&g.label, p);
        let mut records: Vec<ScoredView> =
            trained.iter().map(|r| ScoredView { texture: TRAINED_ON.into(), ..r.clone() }).collect();
        records.extend(g.scores.iter().cloned());
        generalization.extend(
            paired(&records, &g.white, OPTIMIZED).into_iter().filter(|p| p.against == TRAINED_ON).map(as_difference),
        );
        records.retain(|r| r.texture == TRAINED_ON);
        records.extend(read[0].records.iter().filter(|r| r.texture != OPTIMIZED && r.texture != "original").cloned());
        trained_on.extend(paired(&records, &g.white, TRAINED_ON).into_iter().map(as_difference));
        for det in unique(trained.iter().map(|r| r.detector.clone())) {
            // The held-out scores of the same photos as the trained-on ones.
            let of_det: Vec<&ScoredView> = trained.iter().filter(|r| r.detector == det).collect();
            let same = |r: &ScoredView| of_det.iter().any(|t| (t.fold, &t.view) == (r.fold, &r.view));
            let held: Vec<f64> =
                g.scores.iter().filter(|r| r.detector == det && same(r)).map(|r| r.score as f64).collect();
            let views = of_det.len();
            let t = of_det.iter().map(|r| r.score as f64).sum::<f64>() / views as f64;
            let h = held.iter().sum::<f64>() / held.len() as f64;
            let white_box = g.white.contains(&det);
            trained_cells.push(TrainedCell {
                row: g.label.clone(),
                detector: det,
                white_box,
                trained_on: t,
                held_out: h,
                views,
            });
        }
    }
    baselines.extend(cells);
    Ok(Table1 {
        cells: baselines,
        differences,
        own_box,
        baseline_spread: spread,
        anatomy,
        views,
        trained_cells,
        trained_on,
        generalization,
    })
}

/// `records` with each (fold, view, texture, detector)'s seeds averaged into one (seed 0), in
/// first-seen order.
fn seeds_averaged<'a>(records: impl Iterator<Item = &'a ScoredView>) -> Vec<ScoredView> {
    let mut out: Vec<(ScoredView, f64, usize)> = Vec::new();
    for r in records {
        let same =
            |o: &ScoredView| (o.fold, &o.view, &o.texture, &o.detector) == (r.fold, &r.view, &r.texture, &r.detector);
        match out.iter_mut().find(|(o, _, _)| same(o)) {
            Some((_, sum, n)) => (*sum, *n) = (*sum + r.score as f64, *n + 1),
            None => out.push((ScoredView { seed: 0, ..r.clone() }, r.score as f64, 1)),
        }
    }
    out.into_iter().map(|(r, sum, n)| ScoredView { score: (sum / n as f64) as f32, ..r }).collect()
}

/// Per held-out view, one table per detector that some row never trained against: a row per
/// view, a column per texture (baselines, then each label), so one sees which views a gap
/// between two rows comes from.
fn markdown_views(t: &Table1) -> String {
    let textures = unique(t.views.iter().map(|r| r.texture.clone()));
    let held_out = unique(
        t.cells
            .iter()
            .filter(|c| !c.white_box && t.differences.iter().any(|d| d.row == c.row))
            .map(|c| c.detector.clone()),
    );
    let mut s = String::new();
    for det in held_out {
        s.push_str(&format!(
            "\n### {det}\n\n| fold | view | {} |\n|---:|---|{}\n",
            textures.join(" | "),
            "---:|".repeat(textures.len())
        ));
        let of_det: Vec<&ScoredView> = t.views.iter().filter(|r| r.detector == det).collect();
        for (fold, view) in unique(of_det.iter().map(|r| (r.fold, r.view.clone()))) {
            s.push_str(&format!("| {fold} | {view} |"));
            for tex in &textures {
                match of_det.iter().find(|r| r.fold == fold && r.view == view && &r.texture == tex) {
                    Some(r) => s.push_str(&format!(" {:.3} |", r.score)),
                    None => s.push_str(" – |"),
                }
            }
            s.push('\n');
        }
    }
    s
}

impl Table1 {
    /// The tables in Markdown: mean best car score / P@0.5 (bold where the row's texture was
    /// trained against the column's detector), then one table of paired differences per baseline.
    pub fn markdown(&self) -> String {
        let dets = unique(self.cells.iter().map(|c| c.detector.clone()));
        let header = format!("|---|{}\n", "---:|".repeat(dets.len()));
        let mut s = format!("| texture (held-out views) | {} |\n{header}", dets.join(" | "));
        s.push_str(&grid(&unique(self.cells.iter().map(|c| c.row.clone())), &dets, |row, d| {
            let c = self.cells.iter().find(|c| c.row == row && c.detector == d)?;
            let range = if c.runs > 1 {
                format!(" ({:.0}–{:.0})", 100.0 * c.p50_min, 100.0 * c.p50_max)
            } else {
                String::new()
            };
            Some((format!("{:.3} / {:.0} %{range}", c.mean_score, 100.0 * c.p50), c.white_box))
        }));
        s.push_str(&markdown_differences(&self.differences, &dets, None));
        s
    }

    /// The trained-on section: each label's mean best car score on the photos it trained on
    /// and held out, then held-out − trained-on and trained-on − each baseline, paired over photos.
    fn markdown_trained(&self) -> String {
        let dets = unique(self.trained_cells.iter().map(|c| c.detector.clone()));
        let mut s =
            format!("| texture: trained on / held out | {} |\n|---|{}\n", dets.join(" | "), "---:|".repeat(dets.len()));
        s.push_str(&grid(&unique(self.trained_cells.iter().map(|c| c.row.clone())), &dets, |row, d| {
            let c = self.trained_cells.iter().find(|c| c.row == row && c.detector == d)?;
            Some((format!("{:.3} / {:.3}", c.trained_on, c.held_out), c.white_box))
        }));
        s.push_str(&markdown_differences(&self.generalization, &dets, Some("held out")));
        s.push_str(&markdown_differences(&self.trained_on, &dets, Some(TRAINED_ON)));
        s
    }
}

/// One table of paired differences per baseline or `against` label: a row per label, a column
/// per detector in `dets` (bold where the row trained against it); `mine` names the left side
/// of each difference (by default "optimized", or "row" against another label).
fn markdown_differences(diffs: &[Difference], dets: &[String], mine: Option<&str>) -> String {
    let header = format!("|---|{}\n", "---:|".repeat(dets.len()));
    let mut s = String::new();
    for against in unique(diffs.iter().map(|d| d.against.clone())) {
        let what = mine.unwrap_or(if diffs.iter().any(|d| d.row == against) { "row" } else { "optimized" });
        s.push_str(&format!("\n| {what} − {against} | {} |\n{header}", dets.join(" | ")));
        let rows = unique(diffs.iter().filter(|d| d.against == against).map(|d| d.row.clone()));
        s.push_str(&grid(&rows, dets, |row, d| {
            let p = diffs.iter().find(|x| x.row == row && x.detector == d && x.against == against)?;
            Some((format!("{:+.3} [{:+.3}, {:+.3}]", p.mean, p.lo, p.hi), p.white_box))
        }));
    }
    s
}

/// Markdown table rows: one per entry of `rows`, a cell per detector of `dets` from `cell` (its
/// text, bold when the flag is set), "–" where `cell` gives none.
fn grid(rows: &[String], dets: &[String], cell: impl Fn(&str, &str) -> Option<(String, bool)>) -> String {
    let mut s = String::new();
    for row in rows {
        s.push_str(&format!("| {row} |"));
        for d in dets {
            match cell(row, d) {
                Some((text, bold)) => {
                    let b = if bold { "**" } else { "" };
                    s.push_str(&format!(" {b}{text}{b} |"));
                }
                None => s.push_str(" – |"),
            }
        }
        s.push('\n');
    }
    s
}

/// `pav table1`: builds the table of `runs` (paired also with the rows labelled `against`) and
/// writes `table1.md`, `table1.csv`, `table1_paired.csv`, `table1_views.csv`, `table1_trained.csv`,
/// `table1_paired_trained.csv` and (when the runs wrote their boxes) `table1_anatomy.csv` and
/// `table1_paired_own_box.csv` into `out`; returns the Markdown.
pub fn table1_report(
    runs: &[(String, PathBuf, String)],
    against: &[String],
    out: &Path,
) -> Result<String, ExperimentError> {
    let t = table1_of(runs, against)?;
    super::create_dir(out)?;
    pav_core::table::write_csv(&out.join("table1.csv"), &t.cells)?;
    pav_core::table::write_csv(&out.join("table1_paired.csv"), &t.differences)?;
    let sources: Vec<String> = runs
        .iter()
        .map(|(l, d, t)| {
            let of = if t == OPTIMIZED { String::new() } else { format!(" ({t})") };
            format!("{l} = `{}`{of}", d.display())
        })
        .collect();
    let mut md = format!(
        "# Transfer over held-out views (the paper's Table I)\n\nRows: what the texture was trained against; columns: the detector it is scored on. A cell is the mean best car score / P@0.5 over the held-out views of every fold (bold: the row trained against that detector); runs sharing a label are averaged (P@0.5: their mean, lowest–highest in brackets). Baseline rows come from the first run; across runs their means differ by at most {:.4}. Differences: optimized − baseline per held-out view (runs of one label averaged per view first), mean [95 % paired-bootstrap interval]; an interval entirely below zero is a win with error bars.\n\nRuns: {}.\n\n{}",
        t.baseline_spread,
        sources.join("; "),
        t.markdown()
    );
    if !t.anatomy.is_empty() {
        pav_core::table::write_csv(&out.join("table1_anatomy.csv"), &t.anatomy)?;
        let mut a = t.anatomy.clone();
        // Grouped by detector, rows in table order (a stable sort keeps it).
        let dets = unique(a.iter().map(|x| x.detector.clone()));
        a.sort_by_key(|x| dets.iter().position(|d| *d == x.detector));
        md.push_str(&anatomy_section(&markdown_anatomy(&a), "Rows of several runs are their mean; images are pooled."));
    }
    pav_core::table::write_csv(&out.join("table1_views.csv"), &t.views)?;
    let per_view = markdown_views(&t);
    if !per_view.is_empty() {
        md.push_str(&format!("\n## Per held-out view, on the detectors a row never trained against\n\nBest car score per held-out view (`table1_views.csv`); random rows averaged over their seeds, a label over its runs.\n{per_view}"));
    }
    if !t.own_box.is_empty() {
        pav_core::table::write_csv(&out.join("table1_paired_own_box.csv"), &t.own_box)?;
        let dets = unique(t.cells.iter().map(|c| c.detector.clone()));
        md.push_str(&own_box_section(&markdown_differences(&t.own_box, &dets, None)));
    }
    if !t.trained_cells.is_empty() {
        pav_core::table::write_csv(&out.join("table1_trained.csv"), &t.trained_cells)?;
        let pairs: Vec<&Difference> = t.generalization.iter().chain(&t.trained_on).collect();
        pav_core::table::write_csv(&out.join("table1_paired_trained.csv"), &pairs)?;
        md.push_str(&format!("\n## On the photos each texture trained on\n\nEach photo trains in every fold but the one that holds it out. Per photo, a label's best car score averaged over the folds that trained on it (runs of a label averaged), next to the same photo held out (`table1_trained.csv`, `table1_paired_trained.csv`). Held out − trained-on is what a texture loses on a photo it has not seen; trained-on − a baseline says whether it beats that baseline even on the photos it was fitted to. Mean [95 % paired-bootstrap interval] over photos.\n\n{}", t.markdown_trained()));
    }
    super::write_markdown(out, "table1.md", &md)?;
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(fold: usize, role: &str, view: &str, texture: &str, score: f32) -> ViewRow {
        let (role, view, texture, detector) = (role.into(), view.into(), texture.into(), "d".into());
        ViewRow { fold, role, view, texture, seed: 0, detector, score }
    }

    #[test]
    fn a_photo_trained_on_in_several_folds_is_their_mean_filed_under_its_held_out_fold() {
        // Three photos, three folds: each photo held out once and trained on in the other two.
        let mut rows = Vec::new();
        for (f, v) in ["a", "b", "c"].into_iter().enumerate() {
            rows.push(row(f, "held-out", v, "mine", 0.9));
            rows.push(row(f, "held-out", v, "other", 0.5));
        }
        rows.extend([row(1, "train", "a", "mine", 0.2), row(2, "train", "a", "mine", 0.4)]);
        rows.extend([row(0, "train", "b", "mine", 0.1), row(2, "train", "b", "mine", 0.3)]);
        rows.push(row(1, "train", "a", "other", 0.8));
        let t = trained_on(&rows, "mine");
        let got: Vec<(usize, &str, f32)> = t.iter().map(|r| (r.fold, r.view.as_str(), r.score)).collect();
        assert_eq!(got.len(), 2, "c never trains on `mine`: {got:?}");
        assert!(got[0].0 == 0 && got[0].1 == "a" && (got[0].2 - 0.3).abs() < 1e-6, "{got:?}");
        assert!(got[1].0 == 1 && got[1].1 == "b" && (got[1].2 - 0.2).abs() < 1e-6, "{got:?}");
        assert!(t.iter().all(|r| r.texture == OPTIMIZED && r.role == "held-out"));
    }
}
