//! The held-out curve of a cross-validation (`pav crossval --curve-every N`): every fold's
//! texture snapshots scored on that fold's training and held-out photos, so one sees when the
//! held-out score stops following the training score (and whether stopping earlier would pay),
//! and the pixel mean of the late snapshots (whether averaging the iterates would pay).

use super::table2::detect_view;
use super::ExperimentError;
use crate::attack::optimize::snapshots;
use crate::attack::setup::Setup;
use crate::detect::Detector;
use crate::plot::loss_curve;
use std::collections::BTreeMap;
use std::path::Path;

/// What a cross-validation snapshots and scores.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CurveOptions {
    /// Snapshot every this many steps (0: no curve).
    pub every: u64,
    /// Also score the pixel mean of each fold's snapshots from this step to its end.
    pub mean_from: Option<u64>,
}

/// One snapshot's best car score on one photo by one detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CurveRecord {
    /// Fold index.
    pub fold: usize,
    /// Optimizer steps done when the snapshot was taken (for a mean, the fold's last step).
    pub step: u64,
    /// Whether the fold's last snapshot (its final texture).
    pub last: bool,
    /// For the mean of the snapshots from this step on ([`CurveOptions::mean_from`]); empty for
    /// a snapshot.
    pub mean_from: Option<u64>,
    /// "train" or "held-out".
    pub role: &'static str,
    /// Photo name.
    pub view: String,
    /// Detector name.
    pub detector: String,
    /// Best car score (0 without a car box).
    pub score: f32,
}

/// Scores the snapshots in `fold_dir` on `fs`'s training and held-out photos (synthetic and
/// rendered views are not scored: the curve is about photos), and with `mean_from` their pixel
/// mean from that step on.
pub fn score_snapshots(
    fold: usize,
    fold_dir: &Path,
    mean_from: Option<u64>,
    fs: &Setup,
    detectors: &mut [Box<dyn Detector>],
) -> Result<Vec<CurveRecord>, ExperimentError> {
    let shots = snapshots(fold_dir);
    let mut out = Vec::new();
    let mut sum: Option<(Vec<f32>, usize)> = None;
    for (k, (step, path)) in shots.iter().enumerate() {
        let tex = fs.load_texture(path)?;
        out.extend(score_texture(fold, *step, k + 1 == shots.len(), None, &tex, fs, detectors)?);
        if mean_from.is_some_and(|m| *step >= m) {
            let (acc, n) = sum.get_or_insert_with(|| (vec![0.0; tex.len()], 0));
            acc.iter_mut().zip(&tex).for_each(|(a, t)| *a += t);
            *n += 1;
        }
    }
    if let Some(m) = mean_from {
        let (acc, n) = sum.ok_or_else(|| {
            ExperimentError::Invalid(format!("{}: no snapshot at or after step {m} to average", fold_dir.display()))
        })?;
        let mean: Vec<f32> = acc.iter().map(|a| a / n as f32).collect();
        let last = shots.last().map_or(0, |s| s.0);
        out.extend(score_texture(fold, last, false, Some(m), &mean, fs, detectors)?);
    }
    Ok(out)
}

fn score_texture(
    fold: usize,
    step: u64,
    last: bool,
    mean_from: Option<u64>,
    tex: &[f32],
    fs: &Setup,
    detectors: &mut [Box<dyn Detector>],
) -> Result<Vec<CurveRecord>, ExperimentError> {
    let mut out = Vec::new();
    for (role, views) in [("train", &fs.train), ("held-out", &fs.test)] {
        for v in views.iter() {
            for (d, im) in detect_view(v, Some(tex), fs, detectors)?.into_iter().enumerate() {
                out.push(CurveRecord {
                    fold,
                    step,
                    last,
                    mean_from,
                    role,
                    view: v.name.clone(),
                    detector: detectors[d].name().to_string(),
                    score: im.best_score(),
                });
            }
        }
    }
    Ok(out)
}

/// One point of the pooled curve: the mean over every fold's photos of one role.
#[derive(Clone, Debug, PartialEq)]
pub struct CurvePoint {
    /// Step, or for `last` the mean over folds of their final steps.
    pub step: f64,
    /// The folds' final textures (their final steps differ with their view counts).
    pub last: bool,
    /// The folds' snapshot means from this step on, at their mean final step.
    pub mean_from: Option<u64>,
    /// "train" or "held-out".
    pub role: &'static str,
    /// Detector name.
    pub detector: String,
    /// Mean best car score.
    pub mean: f64,
    /// Photos pooled (folds × photos of the role).
    pub n: usize,
}

/// Pools the records per (role, detector) at each step that every fold reached, plus the
/// folds' final textures and their snapshot means each as one point at their mean final step;
/// ordered by role, detector, then steps before the end, the means, the end.
pub fn pool(records: &[CurveRecord]) -> Vec<CurvePoint> {
    let folds = records.iter().map(|r| r.fold).collect::<std::collections::BTreeSet<_>>().len();
    // (role, detector, last, mean_from, step; 0 for last and means) → (sum, n, each fold's step)
    type Acc = (f64, usize, BTreeMap<usize, u64>);
    type Key<'a> = (&'static str, &'a str, bool, Option<u64>, u64);
    let mut acc: BTreeMap<Key, Acc> = BTreeMap::new();
    for r in records {
        // A fold's last snapshot counts only as the end: its step is not one every fold has.
        let at_end = r.last || r.mean_from.is_some();
        let e =
            acc.entry((r.role, r.detector.as_str(), r.last, r.mean_from, if at_end { 0 } else { r.step })).or_default();
        e.0 += r.score as f64;
        e.1 += 1;
        e.2.insert(r.fold, r.step);
    }
    acc.into_iter()
        .filter(|(_, a)| a.2.len() == folds)
        .map(|((role, detector, last, mean_from, step), (sum, n, steps))| CurvePoint {
            step: if last || mean_from.is_some() {
                steps.values().sum::<u64>() as f64 / steps.len() as f64
            } else {
                step as f64
            },
            last,
            mean_from,
            role,
            detector: detector.to_string(),
            mean: sum / n as f64,
            n,
        })
        .collect()
}

/// A Markdown table: one row per step, a column per (role, detector).
pub fn markdown(points: &[CurvePoint]) -> String {
    let mut cols: Vec<(&'static str, String)> = Vec::new();
    for role in ["held-out", "train"] {
        for p in points.iter().filter(|p| p.role == role) {
            if !cols.iter().any(|c| c.0 == role && c.1 == p.detector) {
                cols.push((role, p.detector.clone()));
            }
        }
    }
    // (0 snapshot, 1 end, 2 mean; the mean's first step; step), snapshots by step first
    let kind = |p: &CurvePoint| if p.mean_from.is_some() { 2u8 } else { p.last as u8 };
    let same = |r: &(u8, Option<u64>, f64), p: &CurvePoint| {
        r.0 == kind(p) && r.1 == p.mean_from && (r.0 != 0 || r.2 == p.step)
    };
    let mut rows: Vec<(u8, Option<u64>, f64)> = Vec::new();
    for p in points {
        if !rows.iter().any(|r| same(r, p)) {
            rows.push((kind(p), p.mean_from, p.step));
        }
    }
    rows.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.total_cmp(&b.2)));
    let mut md = format!(
        "| step | {} |\n|---:|{}\n",
        cols.iter().map(|(r, d)| format!("{r} {d}")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(cols.len())
    );
    for r in rows {
        let (k, from, step) = r;
        md.push_str(&match (k, from) {
            (0, _) => format!("| {step:.0} |"),
            (_, Some(m)) => format!("| mean of the snapshots from step {m} |"),
            _ => format!("| end (mean {step:.0}) |"),
        });
        for (role, det) in &cols {
            let p = points.iter().find(|p| p.role == *role && &p.detector == det && same(&r, p));
            md.push_str(&p.map_or(" – |".to_string(), |p| format!(" {:.3} |", p.mean)));
        }
        md.push('\n');
    }
    md
}

/// Draws the pooled curves (held-out and training, a line per detector) into `path`; snapshot
/// means are left to the table.
pub fn plot(path: &Path, points: &[CurvePoint], threshold: f32) -> Result<(), ExperimentError> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    // A mean of snapshots is not a point on the step axis: the table has it.
    for p in points.iter().filter(|p| p.mean_from.is_none()) {
        let name = format!("{} {}", p.role, p.detector);
        match series.iter_mut().find(|s| s.0 == name) {
            Some(s) => s.1.push((p.step, p.mean)),
            None => series.push((name, vec![(p.step, p.mean)])),
        }
    }
    series.iter_mut().for_each(|s| s.1.sort_by(|a, b| a.0.total_cmp(&b.0)));
    loss_curve(path, "mean best car score of the snapshots, pooled over folds", &series, 1, Some(threshold as f64))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(fold: usize, step: u64, last: bool, role: &'static str, score: f32) -> CurveRecord {
        CurveRecord { fold, step, last, mean_from: None, role, view: format!("v{fold}"), detector: "d".into(), score }
    }

    #[test]
    fn steps_every_fold_reached_are_pooled_and_the_final_textures_are_one_point() {
        // Fold 0 ran 120 steps, fold 1 ran 140: step 100 is in both, their ends differ.
        let r = [
            rec(0, 0, false, "held-out", 0.9),
            rec(1, 0, false, "held-out", 0.7),
            rec(0, 100, false, "held-out", 0.4),
            rec(1, 100, false, "held-out", 0.2),
            rec(0, 120, true, "held-out", 0.5),
            rec(1, 140, true, "held-out", 0.3),
            rec(1, 0, false, "train", 0.8),
        ];
        let p = pool(&r);
        let at = |step: f64, last: bool| p.iter().find(|q| q.role == "held-out" && q.last == last && q.step == step);
        assert!((at(0.0, false).unwrap().mean - 0.8).abs() < 1e-6);
        assert!((at(100.0, false).unwrap().mean - 0.3).abs() < 1e-6);
        let end = at(130.0, true).unwrap();
        assert!((end.mean - 0.4).abs() < 1e-6 && end.n == 2);
        // Neither fold's last step stands as a step of its own, and fold 0 has no training row.
        assert_eq!(p.len(), 3, "{p:?}");
        let md = markdown(&p);
        assert!(md.contains("| 100 | 0.300 |") && md.contains("| end (mean 130) | 0.400 |"), "{md}");
    }

    #[test]
    fn snapshot_means_pool_apart_from_the_end_and_stay_off_the_step_axis() {
        let mean =
            |fold, step, score| CurveRecord { mean_from: Some(100), ..rec(fold, step, false, "held-out", score) };
        let r = [
            rec(0, 100, false, "held-out", 0.4),
            rec(1, 100, false, "held-out", 0.2),
            rec(0, 120, true, "held-out", 0.5),
            rec(1, 140, true, "held-out", 0.3),
            mean(0, 120, 0.35),
            mean(1, 140, 0.15),
        ];
        let p = pool(&r);
        assert_eq!(p.len(), 3, "{p:?}");
        let m = p.iter().find(|q| q.mean_from == Some(100)).unwrap();
        assert!((m.mean - 0.25).abs() < 1e-6 && m.n == 2 && !m.last && m.step == 130.0, "{m:?}");
        let md = markdown(&p);
        let lines: Vec<&str> = md.lines().skip(2).collect();
        assert_eq!(
            lines,
            ["| 100 | 0.300 |", "| end (mean 130) | 0.400 |", "| mean of the snapshots from step 100 | 0.250 |"]
        );
    }
}
