//! Evaluation reports: per-frame CSV (streamed), summary CSV/Markdown shaped like the paper's
//! Table V, and per-angle CSV.

use super::drift::{Drift, DriftLimits};
use super::physical::{angle_bins, Accuracy, FrameRecord, Z95};
use pav_core::table::unique;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Errors writing report files.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Settings that cannot make a report.
    #[error("{0}")]
    Options(String),
    /// The CSV writer failed.
    #[error("cannot write {path}: {source}")]
    Csv {
        /// File that failed.
        path: PathBuf,
        /// Why.
        source: csv::Error,
    },
    /// The file system failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// File or folder that failed.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A whole table could not be written.
    #[error(transparent)]
    Table(#[from] pav_core::table::TableError),
    /// Shards of a run that cannot be joined.
    #[error(transparent)]
    Shard(#[from] pav_run::shard::ShardError),
    /// A shard's file that cannot be read back.
    #[error("cannot read {path}: {why}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// A detector could not be copied to score frames at once.
    #[error(transparent)]
    Detector(#[from] pav_detect::DetectError),
    /// A chart could not be drawn.
    #[cfg(feature = "plot")]
    #[error(transparent)]
    Plot(#[from] pav_core::plot::PlotError),
}

fn csv_err(path: &Path, source: csv::Error) -> ReportError {
    ReportError::Csv { path: path.into(), source }
}

/// A file-system error on `path`, as a report error.
pub(crate) fn io_err(path: &Path, source: std::io::Error) -> ReportError {
    ReportError::Io { path: path.into(), source }
}

/// Streams [`FrameRecord`]s to CSV, flushing each row so an interrupted run keeps every frame.
pub(crate) struct FrameCsv {
    w: csv::Writer<std::fs::File>,
    path: PathBuf,
}

impl FrameCsv {
    /// Creates `path` (truncating).
    pub fn create(path: &Path) -> Result<Self, ReportError> {
        Ok(FrameCsv { w: csv::Writer::from_path(path).map_err(|e| csv_err(path, e))?, path: path.into() })
    }

    /// Appends and flushes one record.
    pub fn push(&mut self, r: &FrameRecord) -> Result<(), ReportError> {
        self.w.serialize(r).map_err(|e| csv_err(&self.path, e))?;
        self.w.flush().map_err(|e| io_err(&self.path, e))
    }
}

/// What was scored for one (video, detector) pair.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SummaryRow {
    /// Video label.
    pub video: String,
    /// Detector name.
    pub detector: String,
    /// Target classes, joined by `+`.
    pub classes: String,
    /// f_d / f_o.
    pub accuracy: Accuracy,
    /// Frames decoded from the video (all of them, scored or not).
    pub decoded_frames: usize,
    /// Frames the container declared.
    pub declared_frames: usize,
    /// Videos pooled into this row (they share its label).
    pub videos: usize,
    /// `complete`, or what cut the run short.
    pub status: String,
    /// How far the light of the still part of the scene drifted over the turn (none: fewer than
    /// two frames).
    #[serde(default)]
    pub drift: Option<Drift>,
}

impl SummaryRow {
    /// Whether its light drifted past the limits: its A_physical is then in doubt.
    pub fn drifted(&self) -> bool {
        self.drift.is_some_and(|d| d.flagged)
    }

    /// Its A_physical in %, marked `⚠` when the light drifted.
    fn rate_marked(&self) -> String {
        format!("{}{}", pct(self.accuracy.rate()), if self.drifted() { " ⚠" } else { "" })
    }
}

/// Settings printed with every report.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct ReportSettings {
    /// Score threshold for "detected".
    pub threshold: f32,
    /// Which frames were scored, short (`stride 4`, `even 44`).
    pub sampling: String,
    /// The same in words.
    pub sampling_text: String,
    /// Number of angle sectors.
    pub sectors: usize,
    /// Where angles came from, per video label.
    pub angle_sources: Vec<(String, String)>,
    /// The limits of the light's drift.
    pub drift: DriftLimits,
}

/// `value` with at least `digits` decimals, and more (up to four past them) until it no longer
/// prints as `limit` unless it is the limit: a drift of 4.96 % beside a 5 % limit prints as
/// 4.96, not 5.0.
fn beside(value: f64, limit: f64, digits: usize) -> String {
    (digits..=digits + 4)
        .map(|d| format!("{value:.d$}"))
        .find(|t| value == limit || t.parse::<f64>().is_ok_and(|r| r != limit && (r > limit) == (value > limit)))
        .unwrap_or_else(|| format!("{value}"))
}

fn pct(x: Option<f64>) -> String {
    x.map(|v| format!("{:.1}", 100.0 * v)).unwrap_or_else(|| "n/a".into())
}

/// Writes `summary.csv`.
pub(crate) fn write_summary_csv(path: &Path, rows: &[SummaryRow], s: &ReportSettings) -> Result<(), ReportError> {
    let mut w = csv::Writer::from_path(path).map_err(|e| csv_err(path, e))?;
    w.write_record([
        "video",
        "detector",
        "classes",
        "threshold",
        "sampling",
        "frames",
        "detected",
        "a_physical",
        "ci95_low",
        "ci95_high",
        "decoded_frames",
        "declared_frames",
        "videos",
        "status",
        "luminance_drift",
        "colour_drift",
        "drift_flag",
    ])
    .map_err(|e| csv_err(path, e))?;
    for r in rows {
        let ci = r.accuracy.wilson(Z95);
        let f = |x: Option<f64>| x.map(|v| format!("{v:.6}")).unwrap_or_default();
        w.write_record([
            r.video.clone(),
            r.detector.clone(),
            r.classes.clone(),
            s.threshold.to_string(),
            s.sampling.clone(),
            r.accuracy.total.to_string(),
            r.accuracy.detected.to_string(),
            f(r.accuracy.rate()),
            f(ci.map(|c| c.0)),
            f(ci.map(|c| c.1)),
            r.decoded_frames.to_string(),
            r.declared_frames.to_string(),
            r.videos.to_string(),
            r.status.clone(),
            f(r.drift.map(|d| d.luminance)),
            f(r.drift.map(|d| d.colour)),
            r.drifted().to_string(),
        ])
        .map_err(|e| csv_err(path, e))?;
    }
    w.flush().map_err(|e| io_err(path, e))
}

/// Writes `angles.csv`: accuracy per (video, detector, angle sector).
pub(crate) fn write_angles_csv(
    path: &Path,
    records: &[FrameRecord],
    rows: &[SummaryRow],
    bins: usize,
) -> Result<(), ReportError> {
    let mut w = csv::Writer::from_path(path).map_err(|e| csv_err(path, e))?;
    w.write_record(["video", "detector", "bin_start_deg", "bin_end_deg", "frames", "detected", "a_physical"])
        .map_err(|e| csv_err(path, e))?;
    for r in rows {
        let sel = records.iter().filter(|f| f.video == r.video && f.detector == r.detector);
        for b in angle_bins(sel, bins) {
            w.write_record([
                r.video.clone(),
                r.detector.clone(),
                format!("{}", b.start_deg),
                format!("{}", b.end_deg),
                b.accuracy.total.to_string(),
                b.accuracy.detected.to_string(),
                b.accuracy.rate().map(|v| format!("{v:.6}")).unwrap_or_default(),
            ])
            .map_err(|e| csv_err(path, e))?;
        }
    }
    w.flush().map_err(|e| io_err(path, e))
}

/// Renders the Markdown summary: settings, a Table-V-shaped matrix, details with 95 % CIs, angles.
pub(crate) fn summary_markdown(rows: &[SummaryRow], records: &[FrameRecord], s: &ReportSettings) -> String {
    let mut md = String::new();
    let videos = unique(rows.iter().map(|r| &r.video));
    let dets = unique(rows.iter().map(|r| &r.detector));
    let classes = unique(rows.iter().map(|r| &r.classes));
    let _ = writeln!(md, "# A_physical (frames with the car detected / frames scored)\n");
    let _ = writeln!(
        md,
        "Score threshold **{}**; target classes **{}**; {} scored.{}\n",
        s.threshold,
        classes.iter().map(|c| c.as_str()).collect::<Vec<_>>().join(", "),
        s.sampling_text,
        if rows.iter().any(|r| r.videos > 1) { " Videos that share a label are pooled into one row." } else { "" }
    );
    let _ = writeln!(md, "| Video | {} |", dets.iter().map(|d| d.as_str()).collect::<Vec<_>>().join(" | "));
    let _ = writeln!(md, "|---|{}", "---:|".repeat(dets.len()));
    for v in &videos {
        let cells: Vec<String> = dets
            .iter()
            .map(|d| {
                rows.iter()
                    .find(|r| &&r.video == v && &&r.detector == d)
                    .map(SummaryRow::rate_marked)
                    .unwrap_or_default()
            })
            .collect();
        let _ = writeln!(md, "| {v} | {} |", cells.join(" | "));
    }
    let drifted = rows.iter().any(SummaryRow::drifted);
    let _ = writeln!(
        md,
        "\nValues in %.{}\n",
        if drifted {
            " ⚠: the light of the scene around the car drifted past its limits over the turn (below)."
        } else {
            ""
        }
    );
    let _ = writeln!(md, "## Light over the turn\n");
    let _ = writeln!(
        md,
        "Over the still half of the scene (the cells that change least once each frame's level is taken out; docs/evaluate.md), per frame: the mean luminance's spread (5th to 95th percentile) as a share of its median, and the larger spread of the grey-world red and blue shares. Limits: {} % and {}.\n",
        beside(100.0 * s.drift.luminance, 100.0 * s.drift.luminance, 0),
        beside(s.drift.colour, s.drift.colour, 3)
    );
    let _ = writeln!(md, "| Video | Luminance drift % | Colour drift | Flag |");
    let _ = writeln!(md, "|---|---:|---:|---|");
    for v in &videos {
        let d = rows.iter().find(|r| &&r.video == v).and_then(|r| r.drift);
        let (l, c, flag) = match d {
            Some(d) => (
                beside(100.0 * d.luminance, 100.0 * s.drift.luminance, 1),
                beside(d.colour, s.drift.colour, 4),
                if d.flagged { "⚠ drifted" } else { "steady" },
            ),
            None => ("n/a".into(), "n/a".into(), "fewer than two frames"),
        };
        let _ = writeln!(md, "| {v} | {l} | {c} | {flag} |");
    }
    let _ = writeln!(md, "\n## Details\n");
    let _ = writeln!(md, "| Video | Detector | Videos | f_d | f_o | A_physical % | 95% CI (Wilson) | Status |");
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---|---|");
    for r in rows {
        let ci = r
            .accuracy
            .wilson(Z95)
            .map(|(l, h)| format!("{:.1}–{:.1}", 100.0 * l, 100.0 * h))
            .unwrap_or_else(|| "n/a".into());
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            r.video,
            r.detector,
            r.videos,
            r.accuracy.detected,
            r.accuracy.total,
            r.rate_marked(),
            ci,
            r.status
        );
    }
    let _ = writeln!(md, "\n## Per angle ({} sectors of {:.0}°)\n", s.sectors, 360.0 / s.sectors.max(1) as f64);
    for (v, src) in &s.angle_sources {
        let _ = writeln!(md, "Angles for **{v}**: {src}.\n");
    }
    for v in &videos {
        let _ = writeln!(md, "### {v}\n");
        let _ = writeln!(md, "| Sector | {} |", dets.iter().map(|d| d.as_str()).collect::<Vec<_>>().join(" | "));
        let _ = writeln!(md, "|---|{}", "---:|".repeat(dets.len()));
        let per_det: Vec<_> = dets
            .iter()
            .map(|d| angle_bins(records.iter().filter(|f| &&f.video == v && &&f.detector == d), s.sectors))
            .collect();
        for k in 0..s.sectors.max(1) {
            let b = &per_det[0][k];
            let cells: Vec<String> = per_det
                .iter()
                .map(|bins| {
                    let a = bins[k].accuracy;
                    if a.total == 0 {
                        "–".into()
                    } else {
                        format!("{} ({}/{})", pct(a.rate()), a.detected, a.total)
                    }
                })
                .collect();
            let _ = writeln!(md, "| {:.0}–{:.0}° | {} |", b.start_deg, b.end_deg, cells.join(" | "));
        }
        // Which sectors hold frames, when not all do: a part of a turn, or a sidecar with gaps.
        let held: Vec<String> = (0..s.sectors.max(1))
            .filter(|&k| per_det.iter().any(|bins| bins[k].accuracy.total > 0))
            .map(|k| format!("{:.0}–{:.0}°", per_det[0][k].start_deg, per_det[0][k].end_deg))
            .collect();
        if held.len() < s.sectors.max(1) {
            let _ = writeln!(md, "\nFrames in {} of {} sectors: {}.", held.len(), s.sectors.max(1), held.join(", "));
        }
        let _ = writeln!(md);
    }
    md
}

/// Writes `text` to `path`.
pub(crate) fn write_text(path: &Path, text: &str) -> Result<(), ReportError> {
    let mut f = std::fs::File::create(path).map_err(|e| io_err(path, e))?;
    f.write_all(text.as_bytes()).map_err(|e| io_err(path, e))
}

/// A plain-text summary table for the terminal.
pub fn summary_table(rows: &[SummaryRow], threshold: f32) -> String {
    let mut s = format!("A_physical at score threshold {threshold}\n");
    // Columns as wide as their longest entry (defended detectors have long names).
    let width = |min: usize, f: &dyn Fn(&SummaryRow) -> usize| rows.iter().map(f).max().unwrap_or(0).max(min);
    let (wv, wd, wc) = (
        width(20, &|r| r.video.chars().count()),
        width(16, &|r| r.detector.chars().count()),
        width(10, &|r| r.classes.chars().count()),
    );
    let _ = writeln!(
        s,
        "{:<wv$} {:<wd$} {:<wc$} {:>6} {:>6} {:>8}  {:<13} status",
        "video", "detector", "classes", "f_d", "f_o", "A %", "95% CI"
    );
    for r in rows {
        let ci = r
            .accuracy
            .wilson(Z95)
            .map(|(l, h)| format!("{:.1}-{:.1}", 100.0 * l, 100.0 * h))
            .unwrap_or_else(|| "n/a".into());
        let _ = writeln!(
            s,
            "{:<wv$} {:<wd$} {:<wc$} {:>6} {:>6} {:>8}  {:<13} {}",
            r.video,
            r.detector,
            r.classes,
            r.accuracy.detected,
            r.accuracy.total,
            r.rate_marked(),
            ci,
            if r.drifted() { format!("{}; the light drifted", r.status) } else { r.status.clone() }
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::beside;

    #[test]
    fn a_value_beside_its_limit_shows_which_side_it_falls() {
        assert_eq!(beside(4.96, 5.0, 1), "4.96");
        assert_eq!(beside(5.04, 5.0, 1), "5.04");
        assert_eq!(beside(4.9996, 5.0, 1), "4.9996");
        assert_eq!(beside(3.21, 5.0, 1), "3.2");
        assert_eq!(beside(5.0, 5.0, 0), "5");
        assert_eq!(beside(0.00996, 0.01, 4), "0.00996");
    }
}
