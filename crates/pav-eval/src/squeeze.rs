//! Feature squeezing as an attack detector (Xu et al., NDSS 2018) on scored frames or views: an
//! item is flagged when squeezing the detector's input (bit depth 4, a 3×3 median) moves its best
//! car score by more than a threshold. The threshold is given, or set so that a chosen share of
//! the legitimate items (the original paint) is flagged, as Xu et al. set theirs.

use super::physical::FrameRecord;
#[cfg(feature = "eval")]
use super::report::ReportError;
use pav_detect::defence::{chain_label, parse_chain, Defence};
use std::collections::{BTreeMap, HashMap};
#[cfg(feature = "eval")]
use std::path::Path;

/// The squeezers, as `--defence` specs: each detector is also scored behind each of them.
pub const SQUEEZERS: [&str; 2] = ["bits:b=4", "median:k=3"];

/// The squeezers as defence chains.
pub fn squeezers() -> Vec<Vec<Defence>> {
    SQUEEZERS.iter().map(|s| parse_chain(s).expect("the squeezers' specs are valid")).collect()
}

/// Their labels, the suffixes of the squeezed detectors' names (`bits4`, `median3`).
pub fn labels() -> Vec<String> {
    squeezers().iter().map(|c| chain_label(c)).collect()
}

/// Adds to `chains` each squeezer it does not have yet.
pub fn add_squeezers(chains: &mut Vec<Vec<Defence>>) {
    for q in squeezers() {
        if !chains.iter().any(|c| chain_label(c) == chain_label(&q)) {
            chains.push(q);
        }
    }
}

/// One item's squeeze gap for one detector: a video frame, or a view under a texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Gap<K> {
    /// What was scored (a frame: file and index; a view: its name and the texture's seed).
    pub key: K,
    /// The group a row of the table pools: a video label, or a texture.
    pub group: String,
    /// The undefended detector.
    pub detector: String,
    /// The largest change of the best car score under any squeezer.
    pub gap: f32,
    /// Whether the gap is above the detector's threshold.
    pub flagged: bool,
}

/// One frame's gap, as `squeeze.csv` lists it.
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

/// Flagged items per group and detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SqueezeRow {
    /// Video label or texture.
    pub group: String,
    /// The undefended detector.
    pub detector: String,
    /// Its threshold.
    pub threshold: f32,
    /// Items with every squeezer scored.
    pub items: usize,
    /// Of them, flagged.
    pub flagged: usize,
    /// Mean gap.
    pub mean_gap: f64,
}

/// For every (key, group, detector, best car score) whose detector was also scored behind every
/// squeezer on that key (named `DETECTOR+LABEL`, `labels` being the squeezers' chain labels),
/// the largest score change, in the order of `scores`.
pub fn gaps<K: Clone + Eq + std::hash::Hash>(scores: &[(K, &str, &str, f32)], labels: &[String]) -> Vec<Gap<K>> {
    let score: HashMap<(&K, &str), f32> = scores.iter().map(|(k, _, d, s)| ((k, *d), *s)).collect();
    let mut out = Vec::new();
    for (key, group, detector, s) in scores {
        let squeezed: Option<Vec<f32>> =
            labels.iter().map(|l| score.get(&(key, format!("{detector}+{l}").as_str())).copied()).collect();
        let Some(squeezed) = squeezed.filter(|q| !q.is_empty()) else { continue };
        let gap = squeezed.iter().map(|q| (q - s).abs()).fold(0.0, f32::max);
        out.push(Gap {
            key: key.clone(),
            group: group.to_string(),
            detector: detector.to_string(),
            gap,
            flagged: false,
        });
    }
    out
}

/// The gaps of evaluate's frames.
pub fn frame_gaps(records: &[FrameRecord], labels: &[String]) -> Vec<Gap<(String, String, usize)>> {
    let scores: Vec<_> = records
        .iter()
        .map(|r| ((r.video.clone(), r.file.clone(), r.frame), r.video.as_str(), r.detector.as_str(), r.max_score))
        .collect();
    gaps(&scores, labels)
}

/// A frame's gap as a row of `squeeze.csv`.
pub fn frame_row(g: &Gap<(String, String, usize)>) -> SqueezeFrame {
    SqueezeFrame {
        video: g.group.clone(),
        file: g.key.1.clone(),
        frame: g.key.2,
        detector: g.detector.clone(),
        gap: g.gap,
        flagged: g.flagged,
    }
}

/// Per detector, the threshold that flags at most `false_flags` of the items of the groups in
/// `clean` (the gap at that quantile; an item is flagged strictly above it). Detectors without a
/// clean item get none.
pub fn thresholds<K>(gaps: &[Gap<K>], clean: &[String], false_flags: f64) -> BTreeMap<String, f32> {
    let mut by: BTreeMap<String, Vec<f32>> = BTreeMap::new();
    for g in gaps.iter().filter(|g| clean.contains(&g.group)) {
        by.entry(g.detector.clone()).or_default().push(g.gap);
    }
    by.into_iter()
        .map(|(d, mut v)| {
            v.sort_by(f32::total_cmp);
            let i = (((1.0 - false_flags) * v.len() as f64 - 1e-9).ceil() as usize).clamp(1, v.len()) - 1;
            (d, v[i])
        })
        .collect()
}

/// Flags each item above its detector's threshold; returns the table per group and detector, in
/// first-seen order.
pub fn flag<K>(gaps: &mut [Gap<K>], thresholds: &BTreeMap<String, f32>) -> Vec<SqueezeRow> {
    let mut rows: Vec<SqueezeRow> = Vec::new();
    for g in gaps.iter_mut() {
        let Some(&t) = thresholds.get(&g.detector) else { continue };
        g.flagged = g.gap > t;
        let i = match rows.iter().position(|r| r.group == g.group && r.detector == g.detector) {
            Some(i) => i,
            None => {
                rows.push(SqueezeRow {
                    group: g.group.clone(),
                    detector: g.detector.clone(),
                    threshold: t,
                    items: 0,
                    flagged: 0,
                    mean_gap: 0.0,
                });
                rows.len() - 1
            }
        };
        rows[i].items += 1;
        rows[i].flagged += usize::from(g.flagged);
        rows[i].mean_gap += g.gap as f64;
    }
    for r in &mut rows {
        r.mean_gap /= r.items.max(1) as f64;
    }
    rows
}

/// How each detector's threshold on the squeezed score gap is set (`--squeeze-*`).
#[cfg(feature = "eval")]
#[derive(Clone, Debug, PartialEq)]
pub enum Thresholds {
    /// One threshold for every detector.
    Fixed(f32),
    /// Per detector, the gap that flags `false_flags` of the frames of the videos labelled
    /// `clean` (the original paint).
    Clean {
        /// Labels of the legitimate videos.
        clean: Vec<String>,
        /// Share of their frames flagged.
        false_flags: f64,
    },
}

#[cfg(feature = "eval")]
impl Thresholds {
    /// Refuses settings that cannot flag anything meaningful, or clean labels that no video has.
    pub fn check(&self, labels: &[&str]) -> Result<(), ReportError> {
        let bad = |s: String| Err(ReportError::Options(s));
        match self {
            Thresholds::Fixed(t) if !(0.0..=1.0).contains(t) => {
                bad(format!("--squeeze-threshold {t} must be a score change in [0, 1]"))
            }
            Thresholds::Fixed(_) => Ok(()),
            Thresholds::Clean { false_flags, .. } if !(0.0..1.0).contains(false_flags) => {
                bad(format!("--squeeze-false-flags {false_flags} must be a share in [0, 1)"))
            }
            Thresholds::Clean { clean, .. } => match clean.iter().find(|l| !labels.contains(&l.as_str())) {
                Some(l) => bad(format!("--squeeze-clean {l}: no video has that label (labels: {})", labels.join(", "))),
                None => Ok(()),
            },
        }
    }

    /// The setting in words, for `run.toml` and the report.
    pub fn setting(&self) -> String {
        match self {
            Thresholds::Fixed(t) => format!("threshold {t}"),
            Thresholds::Clean { clean, false_flags } => {
                format!("{false_flags} of the frames of {} flagged", clean.join(", "))
            }
        }
    }
}

/// Feature squeezing on evaluate's frames: the per-frame gaps, each detector's threshold and the
/// flagged shares per video label, written as `squeeze.csv` and `squeeze.md` in `dir`; returns
/// the Markdown.
#[cfg(feature = "eval")]
pub fn write_report(records: &[FrameRecord], how: &Thresholds, dir: &Path) -> Result<String, ReportError> {
    let mut gaps = frame_gaps(records, &labels());
    let thresholds = match how {
        Thresholds::Fixed(t) => gaps.iter().map(|g| (g.detector.clone(), *t)).collect(),
        Thresholds::Clean { clean, false_flags } => thresholds(&gaps, clean, *false_flags),
    };
    let rows = flag(&mut gaps, &thresholds);
    pav_core::table::write_csv(&dir.join("squeeze.csv"), &gaps.iter().map(frame_row).collect::<Vec<_>>())?;
    let md = format!(
        "# Feature squeezing as an attack detector\n\n{}\nPer-frame gaps: `squeeze.csv`.\n",
        markdown(&rows, "frame", &how.setting())
    );
    let path = dir.join("squeeze.md");
    std::fs::write(&path, &md).map_err(|source| ReportError::Io { path, source })?;
    Ok(md)
}

/// The table as Markdown (without a title): a row per detector, a column per group (flagged
/// share); `what` names the items ("frame", "view").
pub fn markdown(rows: &[SqueezeRow], what: &str, how: &str) -> String {
    let videos = pav_core::table::unique(rows.iter().map(|r| r.group.clone()));
    let mut md = format!(
        "A {what} is flagged when bit depth 4 or a 3×3 median moves the detector's best car score by more than its threshold ({how}).\n\n| detector | threshold | {} |\n|---|---:|{}\n",
        videos.iter().map(|v| format!("{v}: flagged")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(videos.len())
    );
    for d in pav_core::table::unique(rows.iter().map(|r| r.detector.clone())) {
        let t = rows.iter().find(|r| r.detector == d).map_or(0.0, |r| r.threshold);
        md.push_str(&format!("| {d} | {t:.3} |"));
        for v in &videos {
            match rows.iter().find(|r| &r.group == v && r.detector == d) {
                Some(r) => md.push_str(&format!(
                    " {:.1} % of {} (mean gap {:.3}) |",
                    100.0 * r.flagged as f64 / r.items.max(1) as f64,
                    r.items,
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
        FrameRecord::scored(video, frame, detector, score)
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
        let mut g = frame_gaps(&recs, &labels);
        assert_eq!(g.len(), 24);
        assert!(g.iter().all(|f| f.detector == "d"));
        assert!((g[20].gap - 0.5).abs() < 1e-6, "{:?}", g[20]);
        let t = thresholds(&g, &["original".to_string()], 0.05);
        // 5 % of 20 frames: one frame above the threshold, the 19th smallest gap (0.18).
        assert!((t["d"] - 0.18).abs() < 1e-6, "{t:?}");
        let rows = flag(&mut g, &t);
        assert_eq!((rows[0].group.as_str(), rows[0].items, rows[0].flagged), ("original", 20, 1));
        assert_eq!((rows[1].group.as_str(), rows[1].items, rows[1].flagged), ("camo", 4, 4));
        assert_eq!(frame_row(&g[20]).file, "camo.mp4");
        let md = markdown(&rows, "frame", "5 % of original");
        assert!(md.contains("| d | 0.180 | 5.0 % of 20 (mean gap 0.095) | 100.0 % of 4 (mean gap 0.500) |"), "{md}");
    }
}
