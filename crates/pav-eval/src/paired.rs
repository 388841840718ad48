//! Two paints filmed on the same shots, frame by frame: per detector, the mean difference of the
//! best car score over frames that show the same pose, with its paired bootstrap interval. Where
//! both paints hide the car in every frame, A_physical is 0 % for both and cannot tell them
//! apart; the car score still can.

use super::digital::paired_bootstrap;
use super::physical::FrameRecord;
use std::fmt::Write;

/// Why frames could not be paired.
#[derive(Debug, thiserror::Error)]
pub enum PairError {
    /// A label is missing, or two labels filmed different numbers of shots.
    #[error("{0}")]
    Labels(String),
}

/// One label against the reference label, for one detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PairedRow {
    /// The label compared.
    pub label: String,
    /// The reference label.
    pub against: String,
    /// Detector.
    pub detector: String,
    /// Frame pairs (the same shot, the same frame).
    pub frames: usize,
    /// Frames of the pairs with the car detected, under the label.
    pub detected: usize,
    /// The same under the reference.
    pub detected_against: usize,
    /// Mean best car score under the label.
    pub score: f64,
    /// Under the reference.
    pub score_against: f64,
    /// Mean of the per-frame differences (label − reference).
    pub diff: f64,
    /// 2.5th percentile of its bootstrap.
    pub lo: f64,
    /// 97.5th percentile.
    pub hi: f64,
}

/// The labels of `records` in the order it first lists them.
fn labels(records: &[FrameRecord]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in records {
        if !out.contains(&r.video) {
            out.push(r.video.clone());
        }
    }
    out
}

/// The videos of `label` in the order `records` first lists them.
fn files<'a>(records: &'a [FrameRecord], label: &str) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for r in records.iter().filter(|r| r.video == label) {
        if !out.contains(&r.file.as_str()) {
            out.push(&r.file);
        }
    }
    out
}

/// Every other label of `records` against `against`, per detector. A frame is paired with the
/// frame of the same index in the reference's video at the same place among its label's videos
/// (the k-th video of each label films the same shot, as `pav-rig evaluate` lists them); frames
/// without a counterpart are left out. 10,000 bootstrap resamples of the frame pairs.
pub fn paired_frames(records: &[FrameRecord], against: &str) -> Result<Vec<PairedRow>, PairError> {
    let reference = files(records, against);
    if reference.is_empty() {
        let labels = labels(records);
        return Err(PairError::Labels(format!("no frames labelled `{against}` (labels: {})", labels.join(", "))));
    }
    let mut out = Vec::new();
    for label in labels(records).into_iter().filter(|l| l != against) {
        let mine = files(records, &label);
        if mine.len() != reference.len() {
            return Err(PairError::Labels(format!(
                "`{label}` has {} videos and `{against}` {}: frames are paired shot by shot, so both need the same shots",
                mine.len(),
                reference.len()
            )));
        }
        let detectors = {
            let mut d: Vec<&str> = Vec::new();
            for r in records.iter().filter(|r| r.video == label) {
                if !d.contains(&r.detector.as_str()) {
                    d.push(&r.detector);
                }
            }
            d
        };
        for det in detectors {
            let theirs: std::collections::HashMap<(&str, usize), &FrameRecord> = records
                .iter()
                .filter(|r| r.video == against && r.detector == det)
                .map(|r| ((r.file.as_str(), r.frame), r))
                .collect();
            let pairs: Vec<(&FrameRecord, &FrameRecord)> = records
                .iter()
                .filter(|r| r.video == label && r.detector == det)
                .filter_map(|r| {
                    let k = mine.iter().position(|f| *f == r.file)?;
                    theirs.get(&(reference[k], r.frame)).map(|t| (r, *t))
                })
                .collect();
            let d: Vec<f64> = pairs.iter().map(|(a, b)| a.max_score as f64 - b.max_score as f64).collect();
            let Some(iv) = paired_bootstrap(&d, 10_000, 7) else { continue };
            let n = pairs.len() as f64;
            out.push(PairedRow {
                label: label.clone(),
                against: against.into(),
                detector: det.into(),
                frames: pairs.len(),
                detected: pairs.iter().filter(|(a, _)| a.detected).count(),
                detected_against: pairs.iter().filter(|(_, b)| b.detected).count(),
                score: pairs.iter().map(|(a, _)| a.max_score as f64).sum::<f64>() / n,
                score_against: pairs.iter().map(|(_, b)| b.max_score as f64).sum::<f64>() / n,
                diff: iv.mean,
                lo: iv.lo,
                hi: iv.hi,
            });
        }
    }
    Ok(out)
}

/// The rows as Markdown: one table per reference label, a row per (label, detector).
pub fn markdown(rows: &[PairedRow]) -> String {
    let mut md = String::new();
    let Some(against) = rows.first().map(|r| r.against.as_str()) else {
        return "No frames to pair.\n".into();
    };
    let _ = writeln!(
        md,
        "# Frame by frame against `{against}`\n\nEach frame is paired with `{against}`'s frame of the same shot and index. Mean best car score, and the mean per-frame difference with its 95 % paired-bootstrap interval (10,000 resamples of the frame pairs); negative: the label hides the car better. Frames with the car detected of the pairs, under each.\n"
    );
    let _ = writeln!(md, "| label | detector | frame pairs | detected | detected ({against}) | car score | car score ({against}) | difference [95 %] |");
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {:.3} | {:.3} | {:+.3} [{:+.3}, {:+.3}] |",
            r.label, r.detector, r.frames, r.detected, r.detected_against, r.score, r.score_against, r.diff, r.lo, r.hi
        );
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(label: &str, file: &str, frame: usize, det: &str, score: f32) -> FrameRecord {
        FrameRecord { file: file.into(), ..FrameRecord::scored(label, frame, det, score) }
    }

    #[test]
    fn frames_pair_by_shot_and_index_and_their_difference_is_the_mean() {
        let mut r = Vec::new();
        // Two shots per label; the reference's files are named otherwise, in the same order.
        for (k, (a, b)) in [("e0.mp4", "ref_e0.mp4"), ("e20.mp4", "ref_e20.mp4")].iter().enumerate() {
            for f in 0..4 {
                let base = 0.1 * (f as f32 + 4.0 * k as f32) / 8.0;
                r.push(rec("pav", a, f, "yolo", base));
                r.push(rec("rauca", b, f, "yolo", base + 0.05 + 0.01 * f as f32));
            }
        }
        // A frame with no counterpart is left out.
        r.push(rec("pav", "e0.mp4", 9, "yolo", 0.9));
        let rows = paired_frames(&r, "rauca").unwrap();
        assert_eq!(rows.len(), 1);
        let p = &rows[0];
        assert_eq!((p.label.as_str(), p.frames, p.detected, p.detected_against), ("pav", 8, 0, 0));
        // Differences −0.05 − 0.01·f for f = 0..3 in both shots: mean −0.065.
        assert!((p.diff + 0.065).abs() < 1e-6, "{p:?}");
        assert!(p.lo <= p.diff && p.diff <= p.hi && p.hi < 0.0, "{p:?}");
        assert!((p.score_against - p.score - 0.065).abs() < 1e-6, "{p:?}");
        assert!(markdown(&rows).contains("| pav | yolo | 8 | 0 | 0 |"), "{}", markdown(&rows));
    }

    #[test]
    fn labels_that_cannot_be_paired_are_refused() {
        let r = vec![
            rec("pav", "a.mp4", 0, "yolo", 0.1),
            rec("pav", "b.mp4", 0, "yolo", 0.1),
            rec("rauca", "c.mp4", 0, "yolo", 0.2),
        ];
        let e = paired_frames(&r, "rauca").unwrap_err().to_string();
        assert!(e.contains("`pav` has 2 videos and `rauca` 1"), "{e}");
        let e = paired_frames(&r, "original").unwrap_err().to_string();
        assert!(e.contains("no frames labelled `original` (labels: pav, rauca)"), "{e}");
    }
}
