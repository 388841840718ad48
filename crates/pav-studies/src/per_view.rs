//! Every view's best car score under each texture, and what compares textures over them: the
//! paired bootstrap of per-view differences and the ASR over views whose original is detected.

use pav_core::table::unique;
use pav_detect::detected;
use pav_eval::digital::paired_bootstrap;

/// The best car score of one detector on one view under one texture.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ScoredView {
    /// Fold index.
    pub fold: usize,
    /// "train" or "held-out" in that fold.
    #[serde(deserialize_with = "role")]
    pub role: FoldRole,
    /// View name.
    pub view: String,
    /// "original", "random" or "optimized".
    pub texture: String,
    /// Random seed (0 for the others).
    pub seed: u64,
    /// Detector name.
    pub detector: String,
    /// Best car score (0 without a car box).
    pub score: f32,
}

/// A view's role in a fold, "train" or "held-out". A named type, since serde would otherwise
/// borrow a `&str` field from its input, which a `'static` one cannot be.
pub type FoldRole = &'static str;

/// A fold's role read back ("train" or "held-out"), as the static name records carry.
pub(crate) fn role<'de, D: serde::Deserializer<'de>>(d: D) -> Result<&'static str, D::Error> {
    let s = <String as serde::Deserialize>::deserialize(d)?;
    ["train", "held-out"]
        .into_iter()
        .find(|r| *r == s)
        .ok_or_else(|| serde::de::Error::custom(format!("role `{s}` is neither train nor held-out")))
}

/// Optimized against another texture on the held-out views of one detector: the per-view
/// difference of best car scores (optimized − other; below zero, the optimized texture hides the
/// car better), with its paired-bootstrap interval.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Paired {
    /// The texture compared.
    pub texture: String,
    /// Detector.
    pub detector: String,
    /// Whether it was a white box.
    pub white_box: bool,
    /// The other texture ("random" is each view's mean over its random seeds).
    pub against: String,
    /// Mean difference.
    pub mean: f64,
    /// 95 % interval, low end.
    pub lo: f64,
    /// 95 % interval, high end.
    pub hi: f64,
    /// Held-out views.
    pub views: usize,
}

/// The paired comparisons of texture `mine` with every other texture of `records`, per
/// detector, over held-out views (10,000 bootstrap resamples; a texture with several seeds
/// counts as each view's mean over them).
pub fn paired(records: &[ScoredView], white_box: &[String], mine: &str) -> Vec<Paired> {
    let held: Vec<&ScoredView> = records.iter().filter(|r| r.role == "held-out").collect();
    let mut out = Vec::new();
    for det in unique(held.iter().map(|r| r.detector.clone())) {
        let rows: Vec<&&ScoredView> = held.iter().filter(|r| r.detector == det).collect();
        let others = unique(rows.iter().map(|r| r.texture.clone()).filter(|t| t != mine));
        for other in others {
            let mut d = Vec::new();
            for o in rows.iter().filter(|r| r.texture == mine) {
                let theirs: Vec<f64> = rows
                    .iter()
                    .filter(|r| r.texture == other && r.fold == o.fold && r.view == o.view)
                    .map(|r| r.score as f64)
                    .collect();
                if !theirs.is_empty() {
                    d.push(o.score as f64 - theirs.iter().sum::<f64>() / theirs.len() as f64);
                }
            }
            if let Some(iv) = paired_bootstrap(&d, 10_000, 7) {
                out.push(Paired {
                    texture: mine.to_string(),
                    detector: det.clone(),
                    white_box: white_box.contains(&det),
                    against: other,
                    mean: iv.mean,
                    lo: iv.lo,
                    hi: iv.hi,
                    views: iv.n,
                });
            }
        }
    }
    out
}

/// ASR over the held-out views whose original paint is detected (a view the original already
/// misses is no success of a texture), per detector and texture; random textures pool their seeds.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ConditionalAsr {
    /// Detector.
    pub detector: String,
    /// Texture.
    pub texture: String,
    /// Share of the (view, seed) scorings below the threshold.
    pub asr: f64,
    /// Held-out views whose original is detected.
    pub views: usize,
}

/// [`ConditionalAsr`] for every detector and texture of `records` at `threshold`.
pub fn conditional_asr(records: &[ScoredView], threshold: f32) -> Vec<ConditionalAsr> {
    let held: Vec<&ScoredView> = records.iter().filter(|r| r.role == "held-out").collect();
    let mut out = Vec::new();
    for det in unique(held.iter().map(|r| r.detector.clone())) {
        let seen: Vec<(usize, &str)> = held
            .iter()
            .filter(|r| r.detector == det && r.texture == "original" && detected(r.score, threshold))
            .map(|r| (r.fold, r.view.as_str()))
            .collect();
        for tex in unique(held.iter().map(|r| r.texture.clone()).filter(|t| t != "original")) {
            let s: Vec<bool> = held
                .iter()
                .filter(|r| r.detector == det && r.texture == tex && seen.contains(&(r.fold, r.view.as_str())))
                .map(|r| !detected(r.score, threshold))
                .collect();
            if !s.is_empty() {
                let asr = s.iter().filter(|&&x| x).count() as f64 / s.len() as f64;
                out.push(ConditionalAsr { detector: det.clone(), texture: tex, asr, views: seen.len() });
            }
        }
    }
    out
}

/// The paired comparisons as a Markdown table: a row per detector, a column per other texture.
pub fn markdown_paired(p: &[Paired]) -> String {
    let against = unique(p.iter().map(|r| r.against.clone()));
    let mut s = format!(
        "| detector | {} |\n|---|{}\n",
        against.iter().map(|a| format!("vs {a}")).collect::<Vec<_>>().join(" | "),
        "---:|".repeat(against.len())
    );
    for det in unique(p.iter().map(|r| (r.detector.clone(), r.white_box))) {
        s.push_str(&format!("| {}{} |", det.0, if det.1 { " *" } else { "" }));
        for a in &against {
            match p.iter().find(|r| r.detector == det.0 && &r.against == a) {
                Some(r) => s.push_str(&format!(" {:+.3} [{:+.3}, {:+.3}] |", r.mean, r.lo, r.hi)),
                None => s.push_str(" – |"),
            }
        }
        s.push('\n');
    }
    s
}
