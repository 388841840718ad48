//! The paper's Table I from `pav crossval` runs: a row per texture (the baselines, then one per
//! run: what it was trained against), a column per detector it is scored on, every cell over
//! held-out views; then each run's paired difference against every baseline, with its interval.

use super::per_view::{paired, Paired, ViewRecord};
use super::ExperimentError;
use crate::table::unique;
use std::path::{Path, PathBuf};

/// The texture a crossval optimizes; every other texture of its tables is a baseline.
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
    /// Car AP at IoU 0.5 over the held-out views.
    pub p50: f64,
    /// Held-out images scored (random textures count each seed).
    pub images: usize,
}

/// A run's optimized texture against a baseline, per detector, paired over held-out views.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Difference {
    /// The run's label.
    pub row: String,
    /// The baseline.
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

/// The transfer table of several runs.
#[derive(Clone, Debug)]
pub struct Table1 {
    /// Baseline rows (from the first run), then one row per run.
    pub cells: Vec<Cell>,
    /// Every run against every baseline.
    pub differences: Vec<Difference>,
    /// The largest difference of a baseline's held-out mean between runs: zero when the runs
    /// scored the same baselines on the same views.
    pub baseline_spread: f64,
}

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

/// Builds the table from `runs` (a label and a `pav crossval` output folder each).
pub fn table1(runs: &[(String, PathBuf)]) -> Result<Table1, ExperimentError> {
    if runs.is_empty() {
        return Err(ExperimentError::Invalid("name at least one `pav crossval` output folder".into()));
    }
    let mut cells = Vec::new();
    let mut differences = Vec::new();
    let mut baselines: Vec<Cell> = Vec::new();
    let mut spread = 0f64;
    for (i, (label, dir)) in runs.iter().enumerate() {
        let rows: Vec<CrossvalRow> = read(&dir.join("crossval.csv"))?;
        let held: Vec<&CrossvalRow> = rows.iter().filter(|r| r.split == "held-out").collect();
        if !held.iter().any(|r| r.texture == OPTIMIZED) {
            return Err(ExperimentError::Invalid(format!(
                "{}: no held-out scores of an optimized texture",
                dir.join("crossval.csv").display()
            )));
        }
        for r in &held {
            let cell = |row: &str| Cell {
                row: row.to_string(),
                detector: r.detector.clone(),
                white_box: r.white_box,
                mean_score: r.mean_score,
                p50: r.p50,
                images: r.images,
            };
            if r.texture == OPTIMIZED {
                cells.push(cell(label));
            } else if i == 0 {
                baselines.push(Cell { white_box: false, ..cell(&r.texture) });
            } else if let Some(b) = baselines.iter().find(|b| b.row == r.texture && b.detector == r.detector) {
                spread = spread.max((b.mean_score - r.mean_score).abs());
            }
        }
        let views: Vec<ViewRow> = read(&dir.join("crossval_views.csv"))?;
        let records: Vec<ViewRecord> = views
            .into_iter()
            .map(|v| ViewRecord {
                fold: v.fold,
                role: if v.role == "held-out" { "held-out" } else { "train" },
                view: v.view,
                texture: v.texture,
                seed: v.seed,
                detector: v.detector,
                score: v.score,
            })
            .collect();
        let white: Vec<String> = unique(held.iter().filter(|r| r.white_box).map(|r| r.detector.clone()));
        differences.extend(paired(&records, &white, OPTIMIZED).into_iter().filter(|p| p.against != "original").map(
            |p: Paired| Difference {
                row: label.clone(),
                against: p.against,
                detector: p.detector,
                white_box: p.white_box,
                mean: p.mean,
                lo: p.lo,
                hi: p.hi,
                views: p.views,
            },
        ));
    }
    baselines.extend(cells);
    Ok(Table1 { cells: baselines, differences, baseline_spread: spread })
}

impl Table1 {
    /// The tables in Markdown: mean best car score / P@0.5 (bold where the row's texture was
    /// trained against the column's detector), then one table of paired differences per baseline.
    pub fn markdown(&self) -> String {
        let dets = unique(self.cells.iter().map(|c| c.detector.clone()));
        let header = format!("|---|{}\n", "---:|".repeat(dets.len()));
        let mut s = format!("| texture (held-out views) | {} |\n{header}", dets.join(" | "));
        for row in unique(self.cells.iter().map(|c| c.row.clone())) {
            s.push_str(&format!("| {row} |"));
            for d in &dets {
                match self.cells.iter().find(|c| c.row == row && &c.detector == d) {
                    Some(c) => {
                        let b = if c.white_box { "**" } else { "" };
                        s.push_str(&format!(" {b}{:.3} / {:.0} %{b} |", c.mean_score, 100.0 * c.p50));
                    }
                    None => s.push_str(" – |"),
                }
            }
            s.push('\n');
        }
        for against in unique(self.differences.iter().map(|d| d.against.clone())) {
            s.push_str(&format!("\n| optimized − {against} | {} |\n{header}", dets.join(" | ")));
            for row in unique(self.differences.iter().map(|d| d.row.clone())) {
                s.push_str(&format!("| {row} |"));
                for d in &dets {
                    let hit =
                        self.differences.iter().find(|x| x.row == row && &x.detector == d && x.against == against);
                    match hit {
                        Some(x) => {
                            let p = x;
                            let b = if p.white_box { "**" } else { "" };
                            s.push_str(&format!(" {b}{:+.3} [{:+.3}, {:+.3}]{b} |", p.mean, p.lo, p.hi));
                        }
                        None => s.push_str(" – |"),
                    }
                }
                s.push('\n');
            }
        }
        s
    }
}

/// `pav table1`: builds the table of `runs` and writes `table1.md`, `table1.csv` and
/// `table1_paired.csv` into `out`; returns the Markdown.
pub fn table1_report(runs: &[(String, PathBuf)], out: &Path) -> Result<String, ExperimentError> {
    let t = table1(runs)?;
    super::create_dir(out)?;
    crate::table::write_csv(&out.join("table1.csv"), &t.cells)?;
    crate::table::write_csv(&out.join("table1_paired.csv"), &t.differences)?;
    let sources: Vec<String> = runs.iter().map(|(l, d)| format!("{l} = `{}`", d.display())).collect();
    let md = format!(
        "# Transfer over held-out views (the paper's Table I)\n\nRows: what the texture was trained against; columns: the detector it is scored on. A cell is the mean best car score / P@0.5 over the held-out views of every fold (bold: the row trained against that detector). Baseline rows come from the first run; across runs their means differ by at most {:.4}. Differences: optimized − baseline per held-out view, mean [95 % paired-bootstrap interval]; an interval entirely below zero is a win with error bars.\n\nRuns: {}.\n\n{}",
        t.baseline_spread,
        sources.join("; "),
        t.markdown()
    );
    super::write_markdown(out, "table1.md", &md)?;
    Ok(md)
}
