//! PNG charts from plain data: scores on a polar dial, grouped bars with whiskers, labelled
//! lines, and optimization curves. Callers turn their records into these shapes.

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::path::Path;
use std::sync::Once;

/// Errors drawing a plot.
#[derive(Debug, thiserror::Error)]
#[error("plot {path}: {source}")]
pub struct PlotError {
    /// Output file.
    pub path: std::path::PathBuf,
    /// The drawing backend's error.
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

type R<T> = Result<T, Box<dyn std::error::Error + Send + Sync>>;

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

/// Colour `i` of the palette.
fn colour(i: usize) -> RGBColor {
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
    r.map_err(|source| PlotError { path: path.into(), source })
}

type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A white chart on `root` titled `caption`, with label areas of (x, y) pixels under and left
/// of the axes, over the ranges `x` and `y`.
fn chart<'a, 'b: 'a>(
    root: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    caption: &str,
    (x_area, y_area): (u32, u32),
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> R<Chart<'a, 'b>> {
    root.fill(&WHITE)?;
    Ok(ChartBuilder::on(root)
        .caption(caption, ("sans-serif", 22))
        .margin(15)
        .x_label_area_size(x_area)
        .y_label_area_size(y_area)
        .build_cartesian_2d(x, y)?)
}

/// Draws the legend box at `pos` and writes the image.
fn finish<'a, 'b: 'a>(
    ch: &mut Chart<'a, 'b>,
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    pos: SeriesLabelPosition,
) -> R<()> {
    ch.configure_series_labels().background_style(WHITE.mix(0.85)).border_style(BLACK).position(pos).draw()?;
    root.present()?;
    Ok(())
}

/// One series of scores by angle.
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

/// One bar of a [`BarSeries`].
pub struct Bar {
    /// Index of its group (a tick on the x axis).
    pub group: usize,
    /// Height.
    pub value: f64,
    /// Whisker (low, high), e.g. a confidence interval.
    pub whisker: Option<(f64, f64)>,
}

/// One colour of grouped bars.
pub struct BarSeries {
    /// Legend label.
    pub label: String,
    /// Its bars, drawn in this order.
    pub bars: Vec<Bar>,
}

/// Grouped bars on a 0–105 axis: one tick per group, one colour per series, with whiskers.
pub fn grouped_bars(
    path: &Path,
    caption: &str,
    y_desc: &str,
    groups: &[String],
    series: &[BarSeries],
) -> Result<(), PlotError> {
    fonts();
    wrap(
        path,
        (|| -> R<()> {
            let w = (220 * groups.len().max(1) + 200).max(700) as u32;
            let root = BitMapBackend::new(path, (w, 520)).into_drawing_area();
            let n = groups.len() as f64;
            let mut ch = chart(&root, caption, (40, 55), 0f64..n, 0f64..105f64)?;
            ch.configure_mesh()
                .disable_x_mesh()
                .x_labels(groups.len() * 2 + 1)
                .x_label_formatter(&|x| {
                    let k = x.floor() as usize;
                    if (x - k as f64 - 0.5).abs() < 0.26 && k < groups.len() {
                        groups[k].to_string()
                    } else {
                        String::new()
                    }
                })
                .y_desc(y_desc)
                .draw()?;
            let gw = 0.8 / series.len().max(1) as f64;
            for (si, s) in series.iter().enumerate() {
                let c = colour(si);
                let x0 = |b: &Bar| b.group as f64 + 0.1 + si as f64 * gw;
                ch.draw_series(
                    s.bars.iter().map(|b| Rectangle::new([(x0(b), 0.0), (x0(b) + gw * 0.9, b.value)], c.filled())),
                )?
                .label(s.label.clone())
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], c.filled()));
                for b in &s.bars {
                    if let Some((lo, hi)) = b.whisker {
                        let xm = x0(b) + gw * 0.45;
                        ch.draw_series(LineSeries::new([(xm, lo), (xm, hi)], BLACK.stroke_width(2)))?;
                    }
                }
            }
            finish(&mut ch, &root, SeriesLabelPosition::UpperRight)
        })(),
    )
}

/// One line of [`labelled_lines`]: points (x, y, label).
pub struct LabelledLine {
    /// Legend label.
    pub label: String,
    /// Points in drawing order, each with a text label.
    pub points: Vec<(f64, f64, String)>,
}

/// Lines with a labelled dot at every point, on a 0–105 y axis and an x axis from 0 to 1.1 × the
/// largest x.
pub fn labelled_lines(
    path: &Path,
    caption: &str,
    (x_desc, y_desc): (&str, &str),
    lines: &[LabelledLine],
) -> Result<(), PlotError> {
    fonts();
    let xmax = lines.iter().flat_map(|l| l.points.iter().map(|p| p.0)).fold(0.0, f64::max) * 1.1 + 1e-3;
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (900, 560)).into_drawing_area();
            let mut ch = chart(&root, caption, (45, 60), 0f64..xmax, 0f64..105f64)?;
            ch.configure_mesh().x_desc(x_desc).y_desc(y_desc).draw()?;
            for (i, l) in lines.iter().enumerate() {
                let c = colour(i);
                ch.draw_series(LineSeries::new(l.points.iter().map(|p| (p.0, p.1)), c.stroke_width(2)))?
                    .label(l.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                for (x, y, text) in &l.points {
                    let p = (*x, *y);
                    ch.draw_series(std::iter::once(Circle::new(p, 4, c.filled())))?;
                    ch.draw_series(std::iter::once(Text::new(text.clone(), p, ("sans-serif", 14))))?;
                }
            }
            finish(&mut ch, &root, SeriesLabelPosition::LowerRight)
        })(),
    )
}

/// A chart of values over steps on `root`: x from 0 to the largest step, y from 0 to 1.05 × the
/// largest finite value (each at least 1), with `threshold` as a dashed line.
fn step_chart<'a, 'b: 'a>(
    root: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    title: &str,
    points: impl Iterator<Item = (f64, f64)>,
    threshold: Option<f64>,
) -> R<Chart<'a, 'b>> {
    let (xmax, ymax) =
        points.fold((1.0f64, 1.0f64), |(x, y), p| (x.max(p.0), if p.1.is_finite() { y.max(p.1) } else { y }));
    let mut ch = chart(root, title, (45, 60), 0f64..xmax, 0f64..ymax * 1.05)?;
    ch.configure_mesh().x_desc("step").draw()?;
    if let Some(t) = threshold {
        ch.draw_series(DashedLineSeries::new([(0.0, t), (xmax, t)], 6, 4, BLACK.stroke_width(1)))?;
    }
    Ok(ch)
}

/// One line of [`curves`].
pub struct Curve {
    /// Legend entry.
    pub name: String,
    /// Colour index: lines that belong together share one.
    pub colour: usize,
    /// Dashed instead of solid.
    pub dashed: bool,
    /// (step, value) points, by step.
    pub points: Vec<(f64, f64)>,
}

/// Lines over steps, each with its own colour index and dash, and an optional dashed threshold.
pub fn curves(path: &Path, title: &str, lines: &[Curve], threshold: Option<f64>) -> Result<(), PlotError> {
    fonts();
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (900, 520)).into_drawing_area();
            let points = lines.iter().flat_map(|l| l.points.iter().copied());
            let mut ch = step_chart(&root, title, points, threshold)?;
            for l in lines {
                let c = colour(l.colour);
                let pts: Vec<(f64, f64)> = l.points.iter().copied().filter(|p| p.1.is_finite()).collect();
                let dashed = l.dashed;
                let style = c.stroke_width(if dashed { 2 } else { 3 });
                if dashed {
                    ch.draw_series(DashedLineSeries::new(pts, 8, 5, style))?
                } else {
                    ch.draw_series(LineSeries::new(pts, style))?
                }
                .label(l.name.as_str())
                .legend(move |(x, y)| {
                    let len = if dashed { 8 } else { 20 };
                    PathElement::new(vec![(x, y), (x + len, y)], style)
                });
            }
            finish(&mut ch, &root, SeriesLabelPosition::UpperRight)
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
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (900, 520)).into_drawing_area();
            let mut ch = step_chart(&root, title, series.iter().flat_map(|s| s.1.iter().copied()), threshold)?;
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

/// One point of an [`IntervalSeries`].
pub struct IntervalPoint {
    /// Where on the x axis.
    pub x: f64,
    /// The value.
    pub y: f64,
    /// Its interval (low, high), drawn as a whisker.
    pub interval: Option<(f64, f64)>,
    /// A text beside the point (empty: none).
    pub label: String,
}

/// One colour of [`intervals`]: points joined in x order.
pub struct IntervalSeries {
    /// Legend label.
    pub name: String,
    /// Its points.
    pub points: Vec<IntervalPoint>,
}

/// Values with their intervals against x, one colour per series, on a y axis that takes in
/// every whisker and zero (drawn dashed: a difference's sign is what one reads); with `log_x`
/// the x axis is logarithmic (its ticks still read in x's units), for costs spread over decades.
pub fn intervals(
    path: &Path,
    caption: &str,
    (x_desc, y_desc): (&str, &str),
    log_x: bool,
    series: &[IntervalSeries],
) -> Result<(), PlotError> {
    fonts();
    let fx = |x: f64| if log_x { x.max(1e-12).log10() } else { x };
    let all = || series.iter().flat_map(|s| &s.points);
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0f64, 0f64);
    for p in all() {
        (x0, x1) = (x0.min(fx(p.x)), x1.max(fx(p.x)));
        let (lo, hi) = p.interval.unwrap_or((p.y, p.y));
        (y0, y1) = (y0.min(lo.min(p.y)), y1.max(hi.max(p.y)));
    }
    if !x0.is_finite() {
        (x0, x1) = (0.0, 1.0);
    }
    let (dx, dy) = ((x1 - x0).max(1e-9) * 0.08, (y1 - y0).max(1e-9) * 0.08);
    wrap(
        path,
        (|| -> R<()> {
            let root = BitMapBackend::new(path, (900, 560)).into_drawing_area();
            let mut ch = chart(&root, caption, (45, 70), (x0 - dx)..(x1 + dx), (y0 - dy)..(y1 + dy))?;
            let tick = |v: &f64| {
                let x = if log_x { 10f64.powf(*v) } else { *v };
                if x >= 10.0 {
                    format!("{x:.0}")
                } else if x >= 0.1 {
                    format!("{x:.2}")
                } else {
                    format!("{x:.3}")
                }
            };
            ch.configure_mesh().x_desc(x_desc).y_desc(y_desc).x_label_formatter(&tick).draw()?;
            ch.draw_series(DashedLineSeries::new([(x0 - dx, 0.0), (x1 + dx, 0.0)], 6, 4, BLACK.stroke_width(1)))?;
            for (i, s) in series.iter().enumerate() {
                let c = colour(i);
                let mut pts: Vec<&IntervalPoint> = s.points.iter().collect();
                pts.sort_by(|a, b| a.x.total_cmp(&b.x));
                ch.draw_series(LineSeries::new(pts.iter().map(|p| (fx(p.x), p.y)), c.stroke_width(2)))?
                    .label(s.name.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                for p in pts {
                    let at = (fx(p.x), p.y);
                    if let Some((lo, hi)) = p.interval {
                        ch.draw_series(LineSeries::new([(at.0, lo), (at.0, hi)], c.stroke_width(1)))?;
                    }
                    ch.draw_series(std::iter::once(Circle::new(at, 4, c.filled())))?;
                    if !p.label.is_empty() {
                        // Beside the dot rather than on it.
                        let text = EmptyElement::at(at) + Text::new(p.label.clone(), (7, -16), ("sans-serif", 14));
                        ch.draw_series(std::iter::once(text))?;
                    }
                }
            }
            finish(&mut ch, &root, SeriesLabelPosition::UpperRight)
        })(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_of_one_colour_draw_solid_and_dashed_lines() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.png");
        let line = |dashed, y| Curve {
            name: if dashed { "train d" } else { "held-out d" }.into(),
            colour: 0,
            dashed,
            points: vec![(0.0, y), (100.0, y)],
        };
        curves(&path, "t", &[line(false, 0.2), line(true, 0.6)], Some(0.5)).unwrap();
        let img = crate::image::Rgb::load(&path).unwrap();
        assert_eq!((img.width, img.height), (900, 520));
        // Pixels in palette colour 0 per row: the solid line fills its rows, the dashed one
        // about 8 of every 13 pixels; the short legend entries add a few to other rows.
        let c0 = PALETTE[0];
        let want = [c0.0, c0.1, c0.2].map(|c| c as f32 / 255.0);
        let rows: Vec<usize> = (0..img.height)
            .map(|y| {
                (0..img.width)
                    .filter(|x| {
                        let p = &img.rgb[3 * (y * img.width + x)..][..3];
                        p.iter().zip(&want).all(|(a, b)| (a - b).abs() < 0.05)
                    })
                    .count()
            })
            .collect();
        let best = |ys: std::ops::Range<usize>| ys.map(|y| rows[y]).max().unwrap();
        let mid = img.height / 2;
        let (upper, lower) = (best(0..mid), best(mid..img.height));
        assert!(lower > 700, "the solid line at 0.2 spans the plot: {lower}");
        assert!(
            upper > 300 && (upper as f64) < 0.8 * lower as f64,
            "the dashed line at 0.6 has gaps: {upper} vs {lower}"
        );
    }
}
