//! PNG plots: detector score vs turntable angle (polar) and A_physical bars per detector.

use super::report::{unique, SummaryRow};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::path::Path;
use std::sync::Once;

/// Errors drawing a plot.
#[derive(Debug, thiserror::Error)]
#[error("plot {path}: {msg}")]
pub struct PlotError {
    /// Output file.
    pub path: String,
    /// Reason.
    pub msg: String,
}

type R<T> = Result<T, Box<dyn std::error::Error>>;

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Colour `i` of the report palette.
pub fn colour(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

fn fonts() {
    // The ab_glyph backend has no system font lookup: the family used must be registered.
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

fn wrap(path: &Path, r: R<()>) -> Result<(), PlotError> {
    r.map_err(|e| PlotError { path: path.display().to_string(), msg: e.to_string() })
}

type Chart<'a> = ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Draws the legend box at `pos` and writes the image.
fn finish(ch: &mut Chart<'_>, root: &DrawingArea<BitMapBackend<'_>, Shift>, pos: SeriesLabelPosition) -> R<()> {
    ch.configure_series_labels().background_style(WHITE.mix(0.85)).border_style(BLACK).position(pos).draw()?;
    root.present()?;
    Ok(())
}

/// One detector's scores by angle.
pub struct ScoreSeries {
    /// Legend label.
    pub label: String,
    /// (angle in degrees, score in [0, 1]) in frame order.
    pub points: Vec<(f64, f64)>,
}

/// Polar plot: radius = max car score, angle = turntable angle (0° up, clockwise); threshold ring.
pub fn polar_scores(path: &Path, title: &str, series: &[ScoreSeries], threshold: f64) -> Result<(), PlotError> {
    fonts();
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (760, 800)).into_drawing_area();
            root.fill(&WHITE)?;
            let mut ch = ChartBuilder::on(&root)
                .caption(title, ("sans-serif", 22))
                .margin(20)
                .build_cartesian_2d(-1.3f64..1.3f64, -1.3f64..1.3f64)?;
            let grey = BLACK.mix(0.2);
            let circle =
                |r: f64| (0..=360).map(move |d| (r * (d as f64).to_radians().sin(), r * (d as f64).to_radians().cos()));
            for r in [0.25, 0.5, 0.75, 1.0] {
                ch.draw_series(LineSeries::new(circle(r), grey))?;
                ch.draw_series(std::iter::once(Text::new(
                    format!("{r:.2}"),
                    (0.02, r + 0.02),
                    ("sans-serif", 13).into_font().color(&BLACK.mix(0.6)),
                )))?;
            }
            for k in 0..12 {
                let t = (k as f64 * 30.0).to_radians();
                ch.draw_series(LineSeries::new([(0.0, 0.0), (t.sin(), t.cos())], grey))?;
                ch.draw_series(std::iter::once(Text::new(
                    format!("{}°", k * 30),
                    (1.14 * t.sin() - 0.06, 1.14 * t.cos() + 0.03),
                    ("sans-serif", 15),
                )))?;
            }
            ch.draw_series(LineSeries::new(circle(threshold), BLACK.stroke_width(2)))?
                .label(format!("threshold {threshold}"))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
            for (i, s) in series.iter().enumerate() {
                let c = colour(i);
                let pts: Vec<(f64, f64)> =
                    s.points.iter().map(|&(a, r)| (r * a.to_radians().sin(), r * a.to_radians().cos())).collect();
                ch.draw_series(pts.iter().map(|&p| Circle::new(p, 2, c.filled())))?
                    .label(s.label.clone())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
            }
            finish(&mut ch, &root, SeriesLabelPosition::LowerRight)
        })(),
    )
}

/// Grouped bars: A_physical (%) per detector, one bar per video, with 95 % Wilson whiskers.
pub fn accuracy_bars(path: &Path, rows: &[SummaryRow], threshold: f32) -> Result<(), PlotError> {
    fonts();
    let dets = unique(rows.iter().map(|r| r.detector.as_str()));
    let vids = unique(rows.iter().map(|r| r.video.as_str()));
    wrap(
        path,
        (|| -> R<()> {
            let w = (220 * dets.len().max(1) + 200).max(700) as u32;
            let root = BitMapBackend::new(path, (w, 520)).into_drawing_area();
            root.fill(&WHITE)?;
            let n = dets.len() as f64;
            let mut ch = ChartBuilder::on(&root)
                .caption(format!("A_physical per detector (threshold {threshold})"), ("sans-serif", 22))
                .margin(15)
                .x_label_area_size(40)
                .y_label_area_size(55)
                .build_cartesian_2d(0f64..n, 0f64..105f64)?;
            let labels = dets.clone();
            ch.configure_mesh()
                .disable_x_mesh()
                .x_labels(dets.len() * 2 + 1)
                .x_label_formatter(&|x| {
                    let k = x.floor() as usize;
                    if (x - k as f64 - 0.5).abs() < 0.26 && k < labels.len() {
                        labels[k].to_string()
                    } else {
                        String::new()
                    }
                })
                .y_desc("A_physical [%]")
                .draw()?;
            let gw = 0.8 / vids.len().max(1) as f64;
            for (vi, v) in vids.iter().enumerate() {
                let c = colour(vi);
                let bars: Vec<_> = rows
                    .iter()
                    .filter(|r| r.video == *v)
                    .filter_map(|r| {
                        let di = dets.iter().position(|d| *d == r.detector)?;
                        let x0 = di as f64 + 0.1 + vi as f64 * gw;
                        Some((x0, r))
                    })
                    .collect();
                ch.draw_series(bars.iter().map(|(x0, r)| {
                    Rectangle::new([(*x0, 0.0), (x0 + gw * 0.9, 100.0 * r.accuracy.rate().unwrap_or(0.0))], c.filled())
                }))?
                .label(v.to_string())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], c.filled()));
                for (x0, r) in &bars {
                    if let Some((lo, hi)) = r.accuracy.wilson(super::physical::Z95) {
                        let xm = x0 + gw * 0.45;
                        ch.draw_series(LineSeries::new([(xm, 100.0 * lo), (xm, 100.0 * hi)], BLACK.stroke_width(2)))?;
                    }
                }
            }
            finish(&mut ch, &root, SeriesLabelPosition::UpperRight)
        })(),
    )
}

/// Accuracy-vs-time scatter: one series per (detector, input size), one point per stride.
pub fn tradeoff(path: &Path, rows: &[super::bench::Tradeoff]) -> Result<(), PlotError> {
    fonts();
    let keys = unique(rows.iter().map(|r| (r.detector.clone(), r.input.clone())));
    let tmax = rows.iter().map(|r| r.seconds).fold(0.0, f64::max) * 1.1 + 1e-3;
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (900, 560)).into_drawing_area();
            root.fill(&WHITE)?;
            let mut ch = ChartBuilder::on(&root)
                .caption("What accuracy costs in time (labels: stride)", ("sans-serif", 22))
                .margin(15)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(0f64..tmax, 0f64..105f64)?;
            ch.configure_mesh().x_desc("seconds per video").y_desc("A_physical [%]").draw()?;
            for (i, (d, inp)) in keys.iter().enumerate() {
                let c = colour(i);
                let pts: Vec<&super::bench::Tradeoff> =
                    rows.iter().filter(|r| &r.detector == d && &r.input == inp).collect();
                ch.draw_series(LineSeries::new(
                    pts.iter().map(|r| (r.seconds, 100.0 * r.a_physical)),
                    c.stroke_width(2),
                ))?
                .label(format!("{d} {inp}"))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                for r in pts {
                    let p = (r.seconds, 100.0 * r.a_physical);
                    ch.draw_series(std::iter::once(Circle::new(p, 4, c.filled())))?;
                    ch.draw_series(std::iter::once(Text::new(format!("{}", r.stride), p, ("sans-serif", 14))))?;
                }
            }
            finish(&mut ch, &root, SeriesLabelPosition::LowerRight)
        })(),
    )
}

/// Optimization curves over steps: named series of (step, value), each drawn faint per step with
/// its per-`window` running mean on top; `threshold` draws a dashed line for score series.
pub fn loss_curve(
    path: &Path,
    title: &str,
    series: &[(String, Vec<(f64, f64)>)],
    window: usize,
    threshold: Option<f64>,
) -> Result<(), PlotError> {
    fonts();
    let xmax = series.iter().flat_map(|s| s.1.iter().map(|p| p.0)).fold(1.0, f64::max);
    let ymax = series.iter().flat_map(|s| s.1.iter().map(|p| p.1)).filter(|v| v.is_finite()).fold(1.0, f64::max) * 1.05;
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (900, 520)).into_drawing_area();
            root.fill(&WHITE)?;
            let mut ch = ChartBuilder::on(&root)
                .caption(title, ("sans-serif", 22))
                .margin(15)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(0f64..xmax, 0f64..ymax)?;
            ch.configure_mesh().x_desc("step").draw()?;
            if let Some(t) = threshold {
                ch.draw_series(DashedLineSeries::new([(0.0, t), (xmax, t)], 6, 4, BLACK.stroke_width(1)))?;
            }
            for (i, (name, pts)) in series.iter().enumerate() {
                let c = colour(i);
                let finite: Vec<(f64, f64)> = pts.iter().copied().filter(|p| p.1.is_finite()).collect();
                ch.draw_series(LineSeries::new(finite.iter().copied(), c.mix(0.3).stroke_width(1)))?;
                let w = window.max(1);
                let smooth: Vec<(f64, f64)> = (0..finite.len())
                    .map(|k| {
                        let lo = k.saturating_sub(w - 1);
                        let s = &finite[lo..=k];
                        (finite[k].0, s.iter().map(|p| p.1).sum::<f64>() / s.len() as f64)
                    })
                    .collect();
                ch.draw_series(LineSeries::new(smooth, c.stroke_width(3)))?
                    .label(name.as_str())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3)));
            }
            finish(&mut ch, &root, SeriesLabelPosition::UpperRight)
        })(),
    )
}
