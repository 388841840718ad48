//! The evaluation's charts: car score against turntable angle per video, and A_physical bars
//! with their confidence intervals.

use super::physical::{FrameRecord, Z95};
use super::report::SummaryRow;
use pav_core::plot::{grouped_bars, polar_scores, Bar, BarSeries, PlotError, ScoreSeries};
use pav_core::table::unique;
use std::path::Path;

/// Polar plot of every detector's car score against the turntable angle in `video`.
pub fn polar_video(
    path: &Path,
    video: &str,
    detectors: &[&str],
    records: &[FrameRecord],
    threshold: f32,
) -> Result<(), PlotError> {
    let series: Vec<ScoreSeries> = detectors
        .iter()
        .map(|d| ScoreSeries {
            label: d.to_string(),
            points: records
                .iter()
                .filter(|r| r.video == video && r.detector == *d)
                .filter_map(|r| r.angle_deg.map(|a| (a, r.max_score as f64)))
                .collect(),
        })
        .collect();
    polar_scores(path, &format!("{video}: car score vs turntable angle"), &series, threshold as f64)
}

/// Grouped bars: A_physical (%) per detector, one bar per video, with 95 % Wilson whiskers.
pub fn accuracy_bars(path: &Path, rows: &[SummaryRow], threshold: f32) -> Result<(), PlotError> {
    let dets = unique(rows.iter().map(|r| r.detector.as_str()));
    let vids = unique(rows.iter().map(|r| r.video.as_str()));
    let series: Vec<BarSeries> = vids
        .iter()
        .map(|v| BarSeries {
            label: v.to_string(),
            bars: rows
                .iter()
                .filter(|r| r.video == *v)
                .filter_map(|r| {
                    Some(Bar {
                        group: dets.iter().position(|d| *d == r.detector)?,
                        value: 100.0 * r.accuracy.rate().unwrap_or(0.0),
                        whisker: r.accuracy.wilson(Z95).map(|(lo, hi)| (100.0 * lo, 100.0 * hi)),
                    })
                })
                .collect(),
        })
        .collect();
    let groups: Vec<String> = dets.iter().map(|d| d.to_string()).collect();
    grouped_bars(path, &format!("A_physical per detector (threshold {threshold})"), "A_physical [%]", &groups, &series)
}
