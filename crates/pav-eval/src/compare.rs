//! A real capture beside its simulation: per detector, A_physical of both with the interval of
//! their difference, and the per-angle car scores side by side. A real table's zero is wherever
//! it homed, not where the simulated model faces the camera, so the angle offset between the two
//! is found first: the shift of the real angles that best matches the per-angle car scores.

use super::physical::{Accuracy, FrameRecord, Z95};
use std::path::{Path, PathBuf};

/// Why two runs could not be compared.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// `frames.csv` could not be read.
    #[error("{path}: {msg}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// A label has no frames, or no frame with an angle.
    #[error("{0}")]
    Missing(String),
}

/// One row of `frames.csv` as `pav-rig evaluate` writes it.
#[derive(serde::Deserialize)]
struct Row {
    video: String,
    frame: usize,
    time_s: f64,
    angle_deg: Option<f64>,
    detector: String,
    detected: bool,
    max_score: f32,
    file: String,
}

/// The frames an evaluation scored (its `frames.csv`).
pub fn read_frames(path: &Path) -> Result<Vec<FrameRecord>, CompareError> {
    let err = |msg: String| CompareError::Read { path: path.into(), msg };
    let mut r = csv::Reader::from_path(path).map_err(|e| err(e.to_string()))?;
    r.deserialize::<Row>()
        .map(|row| {
            let row = row.map_err(|e| err(e.to_string()))?;
            Ok(FrameRecord {
                video: row.video,
                frame: row.frame,
                time_s: row.time_s,
                angle_deg: row.angle_deg,
                detector: row.detector,
                detected: row.detected,
                max_score: row.max_score,
                x1: None,
                y1: None,
                x2: None,
                y2: None,
                file: row.file,
            })
        })
        .collect()
}

/// One angle sector of a comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct SectorPair {
    /// Sector start, degrees, in the simulation's angles.
    pub start_deg: f64,
    /// The real capture's frames in it (its angles shifted by the offset).
    pub real: Accuracy,
    /// The simulation's.
    pub sim: Accuracy,
    /// Mean best car score of the real frames (None when it has none).
    pub real_score: Option<f64>,
    /// Of the simulated frames.
    pub sim_score: Option<f64>,
}

/// One detector's comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectorComparison {
    /// The detector.
    pub detector: String,
    /// A_physical of the real capture.
    pub real: Accuracy,
    /// Of the simulation.
    pub sim: Accuracy,
    /// 95 % interval of real − simulated A_physical (Newcombe's hybrid score).
    pub difference: (f64, f64),
    /// Pearson correlation of the per-sector mean scores (None with fewer than three sectors
    /// holding both).
    pub correlation: Option<f64>,
    /// The sectors.
    pub sectors: Vec<SectorPair>,
}

/// A comparison of two labels of one evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// Degrees added to the real capture's angles to put them in the simulation's.
    pub offset_deg: f64,
    /// Whether the offset was found (not given).
    pub offset_found: bool,
    /// Per detector scored in both.
    pub detectors: Vec<DetectorComparison>,
}

/// Newcombe's hybrid score interval of `a − b` at `z`.
pub fn difference_interval(a: &Accuracy, b: &Accuracy, z: f64) -> Option<(f64, f64)> {
    let (pa, pb) = (a.rate()?, b.rate()?);
    let ((la, ua), (lb, ub)) = (a.wilson(z)?, b.wilson(z)?);
    let d = pa - pb;
    Some((d - ((pa - la).powi(2) + (ub - pb).powi(2)).sqrt(), d + ((ua - pa).powi(2) + (pb - lb).powi(2)).sqrt()))
}

fn pearson(pairs: &[(f64, f64)]) -> Option<f64> {
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let (mx, my) = (pairs.iter().map(|p| p.0).sum::<f64>() / n, pairs.iter().map(|p| p.1).sum::<f64>() / n);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    (sxx > 0.0 && syy > 0.0).then(|| sxy / (sxx * syy).sqrt())
}

/// Sector index of `angle` among `n` sectors.
fn sector(angle: f64, n: usize) -> usize {
    ((angle.rem_euclid(360.0) / (360.0 / n as f64)) as usize).min(n - 1)
}

/// Per sector: frames, detected and summed score of `records` with their angles shifted by
/// `offset`.
fn sectors<'a>(records: impl IntoIterator<Item = &'a FrameRecord>, n: usize, offset: f64) -> Vec<(Accuracy, f64)> {
    let mut out = vec![(Accuracy::default(), 0.0); n];
    for r in records {
        if let Some(a) = r.angle_deg {
            let s = &mut out[sector(a + offset, n)];
            s.0.total += 1;
            s.0.detected += usize::from(r.detected);
            s.1 += f64::from(r.max_score);
        }
    }
    out
}

/// The mean-score curves' correlation, pooled over detectors, with the real angles shifted by
/// `offset`.
fn agreement(real: &[&FrameRecord], sim: &[&FrameRecord], detectors: &[String], n: usize, offset: f64) -> f64 {
    let mut pairs = Vec::new();
    for d in detectors {
        let r = sectors(real.iter().copied().filter(|f| &f.detector == d), n, offset);
        let s = sectors(sim.iter().copied().filter(|f| &f.detector == d), n, 0.0);
        pairs.extend(
            r.iter()
                .zip(&s)
                .filter(|(a, b)| a.0.total > 0 && b.0.total > 0)
                .map(|(a, b)| (a.1 / a.0.total as f64, b.1 / b.0.total as f64)),
        );
    }
    pearson(&pairs).unwrap_or(f64::NEG_INFINITY)
}

/// Compares label `real` with label `sim` of `frames` in `n` angle sectors; the offset is
/// `offset_deg` when given, else the whole degree that best aligns the per-sector mean scores.
pub fn compare(
    frames: &[FrameRecord],
    real: &str,
    sim: &str,
    n: usize,
    offset_deg: Option<f64>,
) -> Result<Comparison, CompareError> {
    let n = n.clamp(1, 360);
    let pick = |label: &str| -> Result<Vec<&FrameRecord>, CompareError> {
        let v: Vec<&FrameRecord> = frames.iter().filter(|f| f.video == label).collect();
        let labels: std::collections::BTreeSet<&str> = frames.iter().map(|f| f.video.as_str()).collect();
        if v.is_empty() {
            return Err(CompareError::Missing(format!(
                "no frames labelled `{label}` (labels here: {})",
                labels.into_iter().collect::<Vec<_>>().join(", ")
            )));
        }
        if v.iter().all(|f| f.angle_deg.is_none()) {
            return Err(CompareError::Missing(format!(
                "`{label}` has no angles: evaluate it with its angle sidecar (or --period)"
            )));
        }
        Ok(v)
    };
    let (r, s) = (pick(real)?, pick(sim)?);
    let mut detectors: Vec<String> = r.iter().map(|f| f.detector.clone()).collect();
    detectors.sort();
    detectors.dedup();
    detectors.retain(|d| s.iter().any(|f| &f.detector == d));
    if detectors.is_empty() {
        return Err(CompareError::Missing(format!("no detector scored both `{real}` and `{sim}`")));
    }
    let (offset_deg, offset_found) = match offset_deg {
        Some(o) => (o, false),
        None => {
            // Ties (a flat curve) keep the smallest offset.
            let best = (0..360).map(f64::from).fold((0.0, f64::NEG_INFINITY), |best, o| {
                let a = agreement(&r, &s, &detectors, n, o);
                if a > best.1 + 1e-12 {
                    (o, a)
                } else {
                    best
                }
            });
            (best.0, true)
        }
    };
    let detectors = detectors
        .into_iter()
        .map(|d| {
            let rd: Vec<&FrameRecord> = r.iter().copied().filter(|f| f.detector == d).collect();
            let sd: Vec<&FrameRecord> = s.iter().copied().filter(|f| f.detector == d).collect();
            let (ra, sa) = (Accuracy::of(rd.iter().copied()), Accuracy::of(sd.iter().copied()));
            let (rs, ss) = (sectors(rd.iter().copied(), n, offset_deg), sectors(sd.iter().copied(), n, 0.0));
            let mean = |(a, sum): &(Accuracy, f64)| (a.total > 0).then(|| sum / a.total as f64);
            let sectors: Vec<SectorPair> = rs
                .iter()
                .zip(&ss)
                .enumerate()
                .map(|(k, (a, b))| SectorPair {
                    start_deg: k as f64 * 360.0 / n as f64,
                    real: a.0,
                    sim: b.0,
                    real_score: mean(a),
                    sim_score: mean(b),
                })
                .collect();
            let pairs: Vec<(f64, f64)> = sectors.iter().filter_map(|p| Some((p.real_score?, p.sim_score?))).collect();
            DetectorComparison {
                detector: d,
                difference: difference_interval(&ra, &sa, Z95).unwrap_or((f64::NAN, f64::NAN)),
                real: ra,
                sim: sa,
                correlation: pearson(&pairs),
                sectors,
            }
        })
        .collect();
    Ok(Comparison { offset_deg, offset_found, detectors })
}

/// The comparison as Markdown: the A_physical table, then the per-sector mean scores.
pub fn markdown(c: &Comparison, real: &str, sim: &str) -> String {
    let pct = |a: &Accuracy| a.rate().map_or("–".into(), |r| format!("{:.1}", 100.0 * r));
    let mut s = format!(
        "Real `{real}` beside simulated `{sim}`; the real angles shifted by {:+.0}° ({}).\n\n",
        c.offset_deg,
        if c.offset_found { "found: the shift that best matches the per-angle car scores" } else { "given" }
    );
    s += "| detector | real A % | simulated A % | real − simulated, pp [95 %] | per-angle score correlation |\n";
    s += "|---|---:|---:|---:|---:|\n";
    for d in &c.detectors {
        s += &format!(
            "| {} | {} ({}/{}) | {} ({}/{}) | {:+.1} [{:+.1}, {:+.1}] | {} |\n",
            d.detector,
            pct(&d.real),
            d.real.detected,
            d.real.total,
            pct(&d.sim),
            d.sim.detected,
            d.sim.total,
            100.0 * (d.real.rate().unwrap_or(0.0) - d.sim.rate().unwrap_or(0.0)),
            100.0 * d.difference.0,
            100.0 * d.difference.1,
            d.correlation.map_or("–".into(), |r| format!("{r:.2}"))
        );
    }
    s += "\nMean best car score per angle sector (real / simulated):\n\n| sector |";
    for d in &c.detectors {
        s += &format!(" {} |", d.detector);
    }
    s += "\n|---|";
    s += &"---:|".repeat(c.detectors.len());
    s += "\n";
    let n = c.detectors.first().map_or(0, |d| d.sectors.len());
    for k in 0..n {
        s += &format!("| {:.0}° |", c.detectors[0].sectors[k].start_deg);
        for d in &c.detectors {
            let p = &d.sectors[k];
            let f = |v: Option<f64>| v.map_or("–".into(), |v| format!("{v:.2}"));
            s += &format!(" {} / {} |", f(p.real_score), f(p.sim_score));
        }
        s += "\n";
    }
    s
}

/// The sectors as CSV rows (`detector,sector_deg,real_frames,real_detected,real_mean_score,
/// sim_frames,sim_detected,sim_mean_score`), with the header.
pub fn csv_rows(c: &Comparison) -> String {
    let mut s = String::from(
        "detector,sector_deg,real_frames,real_detected,real_mean_score,sim_frames,sim_detected,sim_mean_score\n",
    );
    let f = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.4}"));
    for d in &c.detectors {
        for p in &d.sectors {
            s += &format!(
                "{},{},{},{},{},{},{},{}\n",
                d.detector,
                p.start_deg,
                p.real.total,
                p.real.detected,
                f(p.real_score),
                p.sim.total,
                p.sim.detected,
                f(p.sim_score)
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(video: &str, angle: f64, score: f32) -> FrameRecord {
        FrameRecord { angle_deg: Some(angle), ..FrameRecord::scored(video, 0, "d", score) }
    }

    /// A car score that peaks twice a turn (side views) and has a bump at 60°.
    fn curve(a: f64) -> f32 {
        let r = a.to_radians();
        (0.5 + 0.3 * (2.0 * r).sin() + 0.15 * (r - 1.0).cos()) as f32
    }

    #[test]
    fn a_known_offset_is_found_and_undone() {
        for offset in [0.0, 37.0, 90.0, 250.0] {
            let mut frames: Vec<FrameRecord> =
                (0..72).map(|k| rec("sim", k as f64 * 5.0, curve(k as f64 * 5.0))).collect();
            // The real table homed `offset` degrees before the simulation's zero.
            frames.extend((0..72).map(|k| {
                let a = k as f64 * 5.0 + 2.0;
                rec("real", (a - offset).rem_euclid(360.0), curve(a))
            }));
            let c = compare(&frames, "real", "sim", 36, None).unwrap();
            let err = (c.offset_deg - offset + 180.0).rem_euclid(360.0) - 180.0;
            assert!(err.abs() <= 10.0, "offset {offset}: found {}", c.offset_deg);
            let d = &c.detectors[0];
            assert!(d.correlation.unwrap() > 0.9, "{:?}", d.correlation);
            assert_eq!((d.real.total, d.sim.total), (72, 72));
        }
    }

    #[test]
    fn missing_labels_and_angles_are_named() {
        let frames = vec![rec("a", 0.0, 0.7)];
        let e = compare(&frames, "a", "b", 12, None).unwrap_err().to_string();
        assert!(e.contains("`b`") && e.contains("labels here: a"), "{e}");
        let mut no_angle = rec("b", 0.0, 0.2);
        no_angle.angle_deg = None;
        let e = compare(&[rec("a", 0.0, 0.7), no_angle], "a", "b", 12, None).unwrap_err().to_string();
        assert!(e.contains("no angles"), "{e}");
    }

    #[test]
    fn the_difference_interval_is_newcombes() {
        // Newcombe (1998), example (c): 56/70 against 48/80 gives 0.2 [0.0524, 0.3339].
        let (a, b) = (Accuracy { detected: 56, total: 70 }, Accuracy { detected: 48, total: 80 });
        let (lo, hi) = difference_interval(&a, &b, Z95).unwrap();
        assert!((lo - 0.0524).abs() < 5e-4 && (hi - 0.3339).abs() < 5e-4, "{lo} {hi}");
    }
}
