//! Feature squeezing as an attack detector (Xu et al., NDSS 2018) on scored frames: a frame is
//! flagged when squeezing the detector's input (bit depth 4, a 3×3 median) moves its best car
//! score by more than a threshold. The threshold is given, or set so that a chosen share of the
//! frames of legitimate videos (the original paint) is flagged, as Xu et al. set theirs.

use super::physical::FrameRecord;
use std::collections::{BTreeMap, HashMap};

/// The squeezers, as `--defence` specs: each detector is also scored behind each of them.
pub const SQUEEZERS: [&str; 2] = ["bits:b=4", "median:k=3"];

/// One frame's squeeze gap for one detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SqueezeFrame {
    /// Video label.
    pub video: String,
    /// The video's file name.
    pub file: String,
    /// Frame index.
    pub frame: usize,
    /// The undefended detector.
    pub detector: String,
    /// The largest change of the best car score under any squeezer.
    pub gap: f32,
    /// Whether the gap is above the detector's threshold.
    pub flagged: bool,
}

/// Flagged frames per video label and detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SqueezeRow {
    /// Video label.
    pub video: String,
    /// The undefended detector.
    pub detector: String,
    /// Its threshold.
    pub threshold: f32,
    /// Frames with every squeezer scored.
    pub frames: usize,
    /// Of them, flagged.
    pub flagged: usize,
    /// Mean gap.
    pub mean_gap: f64,
}

/// Per frame, every detector that was also scored behind every squeezer (named
/// `DETECTOR+LABEL`, `labels` being the squeezers' chain labels), with its largest score change.
/// Frames come in the order of `records`.
pub fn gaps(records: &[FrameRecord], labels: &[String]) -> Vec<SqueezeFrame> {
    let score: HashMap<(&str, &str, usize, &str), f32> = records
        .iter()
        .map(|r| ((r.video.as_str(), r.file.as_str(), r.frame, r.detector.as_str()), r.max_score))
        .collect();
    let mut out = Vec::new();
    for r in records {
        let squeezed: Option<Vec<f32>> = labels
            .iter()
            .map(|l| {
                score
                    .get(&(r.video.as_str(), r.file.as_str(), r.frame, format!("{}+{l}", r.detector).as_str()))
                    .copied()
            })
            .collect();
        let Some(squeezed) = squeezed.filter(|s| !s.is_empty()) else { continue };
        let gap = squeezed.iter().map(|s| (s - r.max_score).abs()).fold(0.0, f32::max);
        out.push(SqueezeFrame {
            video: r.video.clone(),
            file: r.file.clone(),
            frame: r.frame,
            detector: r.detector.clone(),
            gap,
            flagged: false,
        });
    }
    out
}

/// Per detector, the threshold that flags at most `false_flags` of the frames of the videos
/// labelled `clean` (the gap at that quantile; a frame is flagged strictly above it). Detectors
/// without a clean frame get none.
pub fn thresholds(frames: &[SqueezeFrame], clean: &[String], false_flags: f64) -> BTreeMap<String, f32> {
    let mut by: BTreeMap<String, Vec<f32>> = BTreeMap::new();
    for f in frames.iter().filter(|f| clean.contains(&f.video)) {
        by.entry(f.detector.clone()).or_default().push(f.gap);
    }
    by.into_iter()
        .map(|(d, mut g)| {
            g.sort_by(f32::total_cmp);
            let i = (((1.0 - false_flags) * g.len() as f64 - 1e-9).ceil() as usize).clamp(1, g.len()) - 1;
            (d, g[i])
        })
        .collect()
}

/// Flags each frame above its detector's threshold; returns the table per video label and
/// detector, in first-seen order.
pub fn flag(frames: &mut [SqueezeFrame], thresholds: &BTreeMap<String, f32>) -> Vec<SqueezeRow> {
    let mut rows: Vec<SqueezeRow> = Vec::new();
    for f in frames.iter_mut() {
        let Some(&t) = thresholds.get(&f.detector) else { continue };
        f.flagged = f.gap > t;
        let row = match rows.iter_mut().position(|r| r.video == f.video && r.detector == f.detector) {
            Some(i) => &mut rows[i],
            None => {
                rows.push(SqueezeRow {
                    video: f.video.clone(),
                    detector: f.detector.clone(),
                    threshold: t,
                    frames: 0,
                    flagged: 0,
                    mean_gap: 0.0,
                });
                rows.last_mut().expect("just pushed")
            }
        };
        row.frames += 1;
        row.flagged += usize::from(f.flagged);
        row.mean_gap += f.gap as f64;
    }
    for r in &mut rows {
        r.mean_gap /= r.frames.max(1) as f64;
    }
    rows
}

/// The table as Markdown: a row per detector, a column per video label (flagged share).
pub fn markdown(rows: &[SqueezeRow], how: &str) -> String {
    let videos = crate::table::unique(rows.iter().map(|r| r.video.clone()));
    let mut md = format!(
        "# Feature squeezing as an attack detector\n\nA frame is flagged when bit depth 4 or a 3×3 median moves the detector's best car score by more than its threshold ({how}). Per-frame gaps: `squeeze.csv`.\n\n| detector | threshold | {} |\n|---|---:|{}\n",
        videos.iter().map(|v| format!("{v}: flagged")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(videos.len())
    );
    for d in crate::table::unique(rows.iter().map(|r| r.detector.clone())) {
        let t = rows.iter().find(|r| r.detector == d).map_or(0.0, |r| r.threshold);
        md.push_str(&format!("| {d} | {t:.3} |"));
        for v in &videos {
            match rows.iter().find(|r| &r.video == v && r.detector == d) {
                Some(r) => md.push_str(&format!(
                    " {:.1} % of {} (mean gap {:.3}) |",
                    100.0 * r.flagged as f64 / r.frames.max(1) as f64,
                    r.frames,
                    r.mean_gap
                )),
                None => md.push_str(" – |"),
            }
        }
        md.push('\n');
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(video: &str, frame: usize, detector: &str, score: f32) -> FrameRecord {
        FrameRecord {
            video: video.into(),
            frame,
            time_s: 0.0,
            angle_deg: None,
            detector: detector.into(),
            detected: score >= 0.5,
            max_score: score,
            x1: None,
            y1: None,
            x2: None,
            y2: None,
            file: format!("{video}.mp4"),
        }
    }

    #[test]
    fn the_gap_is_the_largest_score_change_and_the_threshold_flags_the_asked_share() {
        let mut recs = Vec::new();
        // Clean frames: gaps 0.00, 0.01, …, 0.19; attacked frames: gap 0.5.
        for i in 0..20 {
            recs.push(rec("original", i, "d", 0.8));
            recs.push(rec("original", i, "d+bits4", 0.8 - 0.01 * i as f32));
            recs.push(rec("original", i, "d+median3", 0.8));
        }
        for i in 0..4 {
            recs.push(rec("camo", i, "d", 0.1));
            recs.push(rec("camo", i, "d+bits4", 0.2));
            recs.push(rec("camo", i, "d+median3", 0.6));
        }
        // A detector without both squeezers is not a squeezing detector.
        recs.push(rec("camo", 0, "e", 0.3));
        recs.push(rec("camo", 0, "e+bits4", 0.3));
        let labels = ["bits4".to_string(), "median3".to_string()];
        let mut g = gaps(&recs, &labels);
        assert_eq!(g.len(), 24);
        assert!(g.iter().all(|f| f.detector == "d"));
        assert!((g[20].gap - 0.5).abs() < 1e-6, "{:?}", g[20]);
        let t = thresholds(&g, &["original".to_string()], 0.05);
        // 5 % of 20 frames: one frame above the threshold, the 19th smallest gap (0.18).
        assert!((t["d"] - 0.18).abs() < 1e-6, "{t:?}");
        let rows = flag(&mut g, &t);
        assert_eq!((rows[0].video.as_str(), rows[0].frames, rows[0].flagged), ("original", 20, 1));
        assert_eq!((rows[1].video.as_str(), rows[1].frames, rows[1].flagged), ("camo", 4, 4));
        let md = markdown(&rows, "5 % of original");
        assert!(md.contains("| d | 0.180 | 5.0 % of 20 (mean gap 0.095) | 100.0 % of 4 (mean gap 0.500) |"), "{md}");
    }
}
