//! The held-out curve of a cross-validation (`pav crossval --curve-every N`): every fold's
//! texture snapshots scored on that fold's training and held-out photos, so one sees when the
//! held-out score stops following the training score (and whether stopping earlier would pay).
//! The pixel mean of a fold's late snapshots is a texture of its own ([`snapshot_mean`]), which
//! the cross-validation scores beside the final one: whether averaging the iterates would pay.

use super::table2::detect_view;
use super::ExperimentError;
use pav_attack::checkpoint::Average;
use pav_attack::optimize::snapshots;
use pav_attack::setup::Setup;
use pav_core::plot::{curves, Curve};
use pav_detect::Detector;
use std::collections::BTreeMap;
use std::path::Path;

/// What a cross-validation snapshots and scores.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CurveOptions {
    /// Snapshot every this many steps (0: no curve).
    pub every: u64,
    /// Also score each fold's [`snapshot_mean`] from this step, as a texture ([`snapshot_mean_name`]).
    pub mean_from: Option<u64>,
}

impl CurveOptions {
    /// Refuses a snapshot mean without snapshots to average.
    pub fn check(&self) -> Result<(), ExperimentError> {
        if self.mean_from.is_some() && self.every == 0 {
            return Err(ExperimentError::Invalid("a mean of snapshots needs snapshots: give --curve-every too".into()));
        }
        Ok(())
    }
}

/// The texture name under which a cross-validation scores [`snapshot_mean`] from step `from`.
pub fn snapshot_mean_name(from: u64) -> String {
    format!("{SNAPSHOT_MEAN}{from}")
}

/// Whether `texture` names a [`snapshot_mean`]: a texture of one run's own, not a baseline that
/// runs share.
pub fn is_snapshot_mean(texture: &str) -> bool {
    texture.strip_prefix(SNAPSHOT_MEAN).is_some_and(|s| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()))
}

const SNAPSHOT_MEAN: &str = "snapshot-mean-from-";

/// The pixel mean of the snapshots in `fold_dir` taken at step `from` or later, at `fs`'s atlas
/// size.
pub fn snapshot_mean(fold_dir: &Path, from: u64, fs: &Setup) -> Result<Vec<f32>, ExperimentError> {
    let mut sum = Average::default();
    for (_, path) in snapshots(fold_dir).into_iter().filter(|s| s.0 >= from) {
        sum.add(&fs.load_texture(&path)?);
    }
    sum.mean().ok_or_else(|| {
        ExperimentError::Invalid(format!("{}: no snapshot at or after step {from} to average", fold_dir.display()))
    })
}

/// One snapshot's best car score on one photo by one detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CurveRecord {
    /// Fold index.
    pub fold: usize,
    /// Optimizer steps done when the snapshot was taken.
    pub step: u64,
    /// Whether the fold's last snapshot (its final texture).
    pub last: bool,
    /// "train" or "held-out".
    #[serde(deserialize_with = "super::per_view::role")]
    pub role: super::per_view::FoldRole,
    /// Photo name.
    pub view: String,
    /// Detector name.
    pub detector: String,
    /// Best car score (0 without a car box).
    pub score: f32,
}

/// Scores the snapshots in `fold_dir` on `fs`'s training and held-out photos (synthetic and
/// rendered views are not scored: the curve is about photos).
pub fn score_snapshots(
    fold: usize,
    fold_dir: &Path,
    fs: &Setup,
    detectors: &mut [Box<dyn Detector>],
) -> Result<Vec<CurveRecord>, ExperimentError> {
    let shots = snapshots(fold_dir);
    let mut out = Vec::new();
    for (k, (step, path)) in shots.iter().enumerate() {
        let loaded = fs.load_texture(path)?;
        let tex = fs.scored(&loaded);
        for (role, views) in [("train", &fs.train), ("held-out", &fs.test)] {
            for v in views.iter() {
                for (d, im) in detect_view(v, Some(&tex), fs, detectors)?.into_iter().enumerate() {
                    out.push(CurveRecord {
                        fold,
                        step: *step,
                        last: k + 1 == shots.len(),
                        role,
                        view: v.name.clone(),
                        detector: detectors[d].name().to_string(),
                        score: im.best_score(),
                    });
                }
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
/// folds' final textures as one point at their mean final step; ordered by role, detector, then
/// steps before the end.
pub fn pool(records: &[CurveRecord]) -> Vec<CurvePoint> {
    let folds = records.iter().map(|r| r.fold).collect::<std::collections::BTreeSet<_>>().len();
    // (role, detector, last, step; 0 for last) → (sum, n, each fold's step)
    type Acc = (f64, usize, BTreeMap<usize, u64>);
    let mut acc: BTreeMap<(&'static str, &str, bool, u64), Acc> = BTreeMap::new();
    for r in records {
        // A fold's last snapshot counts only as the end: its step is not one every fold has.
        let e = acc.entry((r.role, r.detector.as_str(), r.last, if r.last { 0 } else { r.step })).or_default();
        e.0 += r.score as f64;
        e.1 += 1;
        e.2.insert(r.fold, r.step);
    }
    acc.into_iter()
        .filter(|(_, a)| a.2.len() == folds)
        .map(|((role, detector, last, step), (sum, n, steps))| CurvePoint {
            step: if last { steps.values().sum::<u64>() as f64 / steps.len() as f64 } else { step as f64 },
            last,
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
    let mut rows: Vec<(bool, f64)> = Vec::new();
    for p in points {
        if !rows.iter().any(|r| r.0 == p.last && (p.last || r.1 == p.step)) {
            rows.push((p.last, p.step));
        }
    }
    rows.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut md = format!(
        "| step | {} |\n|---:|{}\n",
        cols.iter().map(|(r, d)| format!("{r} {d}")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(cols.len())
    );
    for (last, step) in rows {
        md.push_str(&if last { format!("| end (mean {step:.0}) |") } else { format!("| {step:.0} |") });
        for (role, det) in &cols {
            let p = points
                .iter()
                .find(|p| p.role == *role && &p.detector == det && p.last == last && (last || p.step == step));
            md.push_str(&p.map_or(" – |".to_string(), |p| format!(" {:.3} |", p.mean)));
        }
        md.push('\n');
    }
    md
}

/// Draws the pooled curves into `path`: a colour per detector, held-out solid and training
/// dashed.
pub fn plot(path: &Path, points: &[CurvePoint], threshold: f32) -> Result<(), ExperimentError> {
    let detectors = pav_core::table::unique(points.iter().map(|p| p.detector.clone()));
    let mut lines: Vec<Curve> = Vec::new();
    for role in ["held-out", "train"] {
        for (c, det) in detectors.iter().enumerate() {
            let mut pts: Vec<(f64, f64)> =
                points.iter().filter(|p| p.role == role && &p.detector == det).map(|p| (p.step, p.mean)).collect();
            if pts.is_empty() {
                continue;
            }
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            lines.push(Curve { name: format!("{role} {det}"), colour: c, dashed: role == "train", points: pts });
        }
    }
    curves(path, "mean best car score of the snapshots, pooled over folds", &lines, Some(threshold as f64))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(fold: usize, step: u64, last: bool, role: &'static str, score: f32) -> CurveRecord {
        CurveRecord { fold, step, last, role, view: format!("v{fold}"), detector: "d".into(), score }
    }

    #[test]
    fn snapshot_means_are_told_from_baselines_by_name() {
        assert!(is_snapshot_mean(&snapshot_mean_name(100)) && is_snapshot_mean(&snapshot_mean_name(0)));
        for other in ["RAUCA_E2E", "optimized", "snapshot-mean-from-", "snapshot-mean-from-1x", "mean100"] {
            assert!(!is_snapshot_mean(other), "{other}");
        }
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
}
