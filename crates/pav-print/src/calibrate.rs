//! `pav print calibrate`: photos (or a video) of pav's chart, or of a ColorChecker on its marker
//! sheet, read patch by patch and merged over the photos; the colour map fitted; the calibration
//! file, a per-patch CSV and a report image of intended, photographed and fitted swatches.

use super::chart::{Chart, ChartError};
use super::colorchecker::{find_checker, pairs as checker_pairs, read_reference, reference_srgb, CheckerError};
use super::fit::{Calibration, FitError, Pair};
use super::photo::{median, Photo, PhotoError};
use opencv::core::{Mat, Point, Rect, Scalar, CV_8UC3};
use opencv::imgproc;
use pav_core::colour::delta_e2000_srgb;
use pav_core::image::Frame;
use std::path::{Path, PathBuf};

/// Frames read from a video of the chart (evenly spaced).
const VIDEO_FRAMES: usize = 12;

/// Why a calibration failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// A photo of pav's chart.
    #[error(transparent)]
    Photo(Box<PhotoError>),
    /// A ColorChecker photo.
    #[error(transparent)]
    Checker(Box<CheckerError>),
    /// The chart files.
    #[error(transparent)]
    Chart(#[from] ChartError),
    /// The fit.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// A video of the chart.
    #[error(transparent)]
    Video(#[from] pav_core::video::VideoError),
    /// No frame of a video showed the chart.
    #[error("{path}: none of {tried} frames showed the whole chart; first problem: {first}")]
    NoFrame {
        /// The video.
        path: PathBuf,
        /// Frames tried.
        tried: usize,
        /// The first frame's error.
        first: String,
    },
    /// The patch table or the report image.
    #[error("{path}: {why}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
}

// Boxed: the photo errors carry paths and names, and every calibration step returns this error.
impl From<PhotoError> for CalibrateError {
    fn from(e: PhotoError) -> Self {
        CalibrateError::Photo(Box::new(e))
    }
}

impl From<CheckerError> for CalibrateError {
    fn from(e: CheckerError) -> Self {
        CalibrateError::Checker(Box::new(e))
    }
}

/// One patch's readings over the photos.
struct Merged {
    id: usize,
    from: [f64; 3],
    tos: Vec<[f64; 3]>,
    clipped: bool,
    unreadable: bool,
}

/// What to calibrate against.
pub enum Target<'a> {
    /// pav's chart (printer + camera).
    Chart(&'a Chart),
    /// A ColorChecker Classic with its published values (camera alone).
    ColorChecker {
        /// The reference CSV.
        reference: &'a Path,
    },
}

/// One patch of the result, for the CSV and the report.
#[derive(Clone, Debug, serde::Serialize)]
pub struct PatchRow {
    /// Patch ID.
    pub id: usize,
    /// Intended (or reference) sRGB, 0–255.
    pub intended: String,
    /// Photographed sRGB (median over photos), 0–255.
    pub captured: String,
    /// The fitted map's prediction, 0–255.
    pub fitted: String,
    /// ΔE2000 between prediction and photo (in-sample).
    pub delta_e: f64,
    /// Left out: "clipped", "unreadable" or "".
    pub left_out: &'static str,
}

fn hex(c: [f64; 3]) -> String {
    let [r, g, b] = c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
    format!("{r} {g} {b}")
}

fn video_ext(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["mp4", "mov", "avi", "mkv", "webm"].contains(&e.to_ascii_lowercase().as_str()))
}

/// The photos to read: each image, or evenly spaced frames of each video.
fn photos(paths: &[PathBuf]) -> Result<Vec<Result<Photo, PhotoError>>, CalibrateError> {
    let mut out = Vec::new();
    for p in paths {
        if !video_ext(p) {
            out.push(Photo::load(p));
            continue;
        }
        let mut rd = pav_core::video::VideoReader::open(p)?;
        let n = rd.info().declared_frames.max(1);
        let step = (n / VIDEO_FRAMES).max(1);
        while let Some((i, f)) = rd.read()? {
            if i % step == 0 {
                let m = pav_core::video::frame_to_mat(&f)
                    .map_err(|e| CalibrateError::Write { path: p.clone(), why: e.to_string() })?;
                out.push(Photo::from_mat(m, &p.with_extension(format!("frame{i}"))));
            }
        }
    }
    Ok(out)
}

/// Reads every photo, merges the patches (median over the photos that read them) and fits.
pub fn calibrate(
    target: Target,
    paths: &[PathBuf],
    bound: f64,
    force: bool,
) -> Result<(Calibration, Vec<PatchRow>), CalibrateError> {
    let shots = photos(paths)?;
    let tried = shots.len();
    let mut per_patch: Vec<Merged> = Vec::new();
    let mut first_err: Option<CalibrateError> = None;
    let mut read = 0;
    let mut found = Vec::new();
    let reference = match &target {
        Target::ColorChecker { reference } => Some(reference_srgb(&read_reference(reference)?)),
        Target::Chart(_) => None,
    };
    for shot in shots {
        let result: Result<Vec<Pair>, CalibrateError> =
            shot.map_err(CalibrateError::from).and_then(|photo| match &target {
                Target::Chart(chart) => Ok(photo
                    .read_chart(chart)?
                    .into_iter()
                    .map(|r| Pair {
                        id: r.id,
                        from: r.intended,
                        to: r.captured,
                        clipped: r.clipped,
                        unreadable: r.unreadable,
                    })
                    .collect()),
                Target::ColorChecker { .. } => {
                    let rs = reference.as_ref().expect("read above");
                    let (reading, by) = find_checker(&photo, photo.path(), rs)?;
                    found.push(format!("{}: {by}", photo.path().display()));
                    Ok(checker_pairs(&reading, rs))
                }
            });
        match result {
            Ok(pairs) => {
                read += 1;
                for p in pairs {
                    match per_patch.iter_mut().find(|e| e.id == p.id) {
                        Some(e) => {
                            e.tos.push(p.to);
                            e.clipped |= p.clipped;
                            e.unreadable |= p.unreadable;
                        }
                        None => per_patch.push(Merged {
                            id: p.id,
                            from: p.from,
                            tos: vec![p.to],
                            clipped: p.clipped,
                            unreadable: p.unreadable,
                        }),
                    }
                }
            }
            // A single photo's error is the error; a video skips frames that miss the chart.
            Err(e) if tried == 1 => return Err(e),
            Err(e) => {
                first_err.get_or_insert(e);
            }
        }
    }
    if read == 0 {
        let first = first_err.map(|e| e.to_string()).unwrap_or_default();
        return Err(CalibrateError::NoFrame { path: paths.first().cloned().unwrap_or_default(), tried, first });
    }
    let pairs: Vec<Pair> = per_patch
        .iter()
        .map(|m| Pair {
            id: m.id,
            from: m.from,
            to: std::array::from_fn(|c| median(&mut m.tos.iter().map(|t| t[c]).collect::<Vec<_>>())),
            clipped: m.clipped,
            unreadable: m.unreadable,
        })
        .collect();
    let measures = match target {
        Target::Chart(_) => "printer+camera",
        Target::ColorChecker { .. } => "camera",
    };
    let mut cal = Calibration::fit(measures, &pairs, bound, force, paths.to_vec())?;
    cal.found = found;
    let rows = pairs
        .iter()
        .map(|p| {
            let fitted = cal.map.apply(p.from);
            PatchRow {
                id: p.id,
                intended: hex(p.from),
                captured: hex(p.to),
                fitted: hex(fitted),
                delta_e: delta_e2000_srgb(fitted, p.to),
                left_out: if p.clipped {
                    "clipped"
                } else if p.unreadable {
                    "unreadable"
                } else {
                    ""
                },
            }
        })
        .collect();
    Ok((cal, rows))
}

/// Calibrates from `paths` as [`calibrate`] does and writes the fitted map to `out`, with the
/// per-patch CSV (`out` as .csv) and the report image (`out` as .png) beside it; returns the
/// calibration and those two files.
pub fn calibrate_to(
    target: Target,
    paths: &[PathBuf],
    bound: f64,
    force: bool,
    out: &Path,
) -> Result<(Calibration, [PathBuf; 2]), CalibrateError> {
    let (cal, rows) = calibrate(target, paths, bound, force)?;
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| CalibrateError::Write { path: dir.into(), why: e.to_string() })?;
    }
    cal.save(out)?;
    let csv = out.with_extension("csv");
    pav_core::table::write_csv(&csv, &rows)
        .map_err(|e| CalibrateError::Write { path: csv.clone(), why: e.to_string() })?;
    let png = out.with_extension("png");
    let r = cal.residual();
    let title = format!(
        "{}: {:?}, held-out dE2000 median {:.2}, p90 {:.2}, max {:.2} (swatches: intended | photo | fitted)",
        cal.measures, r.model, r.median, r.p90, r.max
    );
    report_image(&png, &rows, &title)?;
    Ok((cal, [csv, png]))
}

/// A report image: per patch, intended | photographed | fitted swatches and the ΔE2000, left-out
/// patches crossed.
pub fn report_image(path: &Path, rows: &[PatchRow], title: &str) -> Result<(), CalibrateError> {
    let err = |e: opencv::Error| CalibrateError::Write { path: path.into(), why: e.to_string() };
    let (sw, cell_w, cell_h, per_row) = (24, 3 * 24 + 56, 34, 8);
    let n_rows = rows.len().div_ceil(per_row);
    let (w, h) = (per_row * cell_w + 10, n_rows * cell_h + 40);
    let mut img = Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC3, Scalar::all(255.0)).map_err(err)?;
    let parse = |s: &str| -> Scalar {
        let v: Vec<f64> = s.split(' ').filter_map(|x| x.parse().ok()).collect();
        Scalar::new(v[2], v[1], v[0], 0.0)
    };
    let black = Scalar::all(0.0);
    imgproc::put_text(
        &mut img,
        title,
        Point::new(6, 22),
        imgproc::FONT_HERSHEY_SIMPLEX,
        0.55,
        black,
        1,
        imgproc::LINE_AA,
        false,
    )
    .map_err(err)?;
    for (k, r) in rows.iter().enumerate() {
        let (x, y) = ((k % per_row * cell_w + 6) as i32, (k / per_row * cell_h + 34) as i32);
        for (j, c) in [&r.intended, &r.captured, &r.fitted].iter().enumerate() {
            let rect = Rect::new(x + j as i32 * sw, y, sw, 24);
            imgproc::rectangle(&mut img, rect, parse(c), imgproc::FILLED, imgproc::LINE_8, 0).map_err(err)?;
        }
        let label = if r.left_out.is_empty() { format!("{:.1}", r.delta_e) } else { "out".into() };
        imgproc::put_text(
            &mut img,
            &label,
            Point::new(x + 3 * sw + 3, y + 17),
            imgproc::FONT_HERSHEY_PLAIN,
            1.0,
            black,
            1,
            imgproc::LINE_AA,
            false,
        )
        .map_err(err)?;
        if !r.left_out.is_empty() {
            imgproc::line(&mut img, Point::new(x, y), Point::new(x + 3 * sw, y + 24), black, 2, imgproc::LINE_8, 0)
                .map_err(err)?;
        }
    }
    let f = pav_core::video::mat_to_frame(&img)
        .map_err(|e| CalibrateError::Write { path: path.into(), why: e.to_string() })?;
    save_frame(path, &f)
}

fn save_frame(path: &Path, f: &Frame) -> Result<(), CalibrateError> {
    f.save_png(path).map_err(|e| CalibrateError::Write { path: path.into(), why: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chart::ChartSpec;
    use crate::fit::known_print;
    use crate::photo::Homography;
    use opencv::core::{Size, Vector, BORDER_CONSTANT};
    use opencv::imgcodecs;
    use opencv::prelude::*;
    use pav_core::rng::Rng;

    /// The effects a phone adds to a photo of a printed chart.
    struct Shot {
        blur: f64,
        gain: f64,
        crop_right: f64,
    }

    /// The chart printed through `known_print`, photographed at an angle with blur, vignetting,
    /// noise and JPEG.
    fn photograph(chart: &Chart, shot: &Shot, seed: u64) -> Mat {
        let page = chart.render().unwrap();
        let (pw, ph) = (page.cols() as f64, page.rows() as f64);
        // Printing: every page pixel through the map (the white paper too).
        let mut printed = page.clone();
        let mut cache = std::collections::HashMap::new();
        for px in printed.data_bytes_mut().unwrap().chunks_exact_mut(3) {
            let key = [px[0], px[1], px[2]];
            let out = *cache.entry(key).or_insert_with(|| {
                let o = known_print([px[2], px[1], px[0]].map(|v| v as f64 / 255.0));
                [o[2], o[1], o[0]].map(|v| (v * 255.0).round() as u8)
            });
            px.copy_from_slice(&out);
        }
        // A tilted view: the page's corners land on a skewed quadrilateral.
        let (w, h) = (1400, 1100);
        let quad = [[330.0, 60.0], [1080.0, 110.0], [1130.0, 1050.0], [270.0, 1010.0]];
        let hm = Homography::fit(&[[0.0, 0.0], [pw, 0.0], [pw, ph], [0.0, ph]], &quad).unwrap();
        let m = Mat::from_slice_2d(&[&hm.0[0..3], &hm.0[3..6], &hm.0[6..9]]).unwrap();
        let mut photo = Mat::default();
        imgproc::warp_perspective(
            &printed,
            &mut photo,
            &m,
            Size::new(w, h),
            imgproc::INTER_LINEAR,
            BORDER_CONSTANT,
            Scalar::all(70.0),
        )
        .unwrap();
        if shot.blur > 0.0 {
            let mut b = Mat::default();
            imgproc::gaussian_blur_def(&photo, &mut b, Size::new(0, 0), shot.blur).unwrap();
            photo = b;
        }
        // Vignetting (5 % at the corners), exposure, sensor noise.
        let mut rng = Rng::new(seed);
        let bytes = photo.data_bytes_mut().unwrap();
        let (cx, cy, r2) = (w as f64 / 2.0, h as f64 / 2.0, (w * w + h * h) as f64 / 4.0);
        for (i, px) in bytes.chunks_exact_mut(3).enumerate() {
            let (x, y) = ((i % w as usize) as f64, (i / w as usize) as f64);
            let v = shot.gain * (1.0 - 0.05 * ((x - cx).powi(2) + (y - cy).powi(2)) / r2);
            for c in px.iter_mut() {
                let n = (rng.unit() as f64 + rng.unit() as f64 - 1.0) * 3.0;
                *c = (*c as f64 * v + n).round().clamp(0.0, 255.0) as u8;
            }
        }
        if shot.crop_right > 0.0 {
            let keep = (w as f64 * (1.0 - shot.crop_right)) as i32;
            photo = Mat::roi(&photo, Rect::new(0, 0, keep, h)).unwrap().try_clone().unwrap();
        }
        let mut buf = Vector::<u8>::new();
        imgcodecs::imencode(".jpg", &photo, &mut buf, &Vector::from_slice(&[imgcodecs::IMWRITE_JPEG_QUALITY, 90]))
            .unwrap();
        imgcodecs::imdecode(&buf, imgcodecs::IMREAD_COLOR).unwrap()
    }

    fn chart() -> Chart {
        Chart::new(&ChartSpec { dpi: 100.0, ..Default::default() }).unwrap()
    }

    fn save(dir: &Path, name: &str, m: &Mat) -> PathBuf {
        let p = dir.join(name);
        imgcodecs::imwrite_def(&p, m).unwrap();
        p
    }

    #[test]
    fn the_chart_round_trip_recovers_a_known_print_and_camera_map() {
        let c = chart();
        let dir = tempfile::tempdir().unwrap();
        let photo = save(dir.path(), "a.png", &photograph(&c, &Shot { blur: 1.2, gain: 1.0, crop_right: 0.0 }, 1));
        let (cal, rows) = calibrate(Target::Chart(&c), &[photo], 5.0, false).unwrap();
        assert_eq!(rows.len(), c.patches.len());
        let mut rng = Rng::new(77);
        let de: Vec<f64> = (0..2000)
            .map(|_| {
                let x = [0; 3].map(|_| rng.unit() as f64);
                delta_e2000_srgb(cal.map.apply(x), known_print(x))
            })
            .collect();
        let (median, p90, _) = pav_core::colour::spread(&de, 2.0);
        eprintln!("round trip: {:?} kept; against the true map over 2000 colours ΔE2000 median {median:.2}, p90 {p90:.2}; held out {:?}", cal.map.model, cal.held_out);
        assert!(median < 2.0, "median ΔE2000 {median:.2} (p90 {p90:.2}) with {:?}", cal.held_out);
        let r = cal.residual();
        assert!(r.median < 2.0, "{:?}", cal.held_out);
        report_image(&dir.path().join("r.png"), &rows, "t").unwrap();
        // As `[print] calibration`, the fitted map is what the print channel applies.
        let file = dir.path().join("calibration.toml");
        cal.save(&file).unwrap();
        let cfg = crate::channel::PrintConfig { calibration: Some(file), ..Default::default() };
        let channel = crate::channel::PrintChannel::open(&cfg).unwrap();
        let xs: Vec<f32> = (0..3 * 500).map(|_| rng.unit()).collect();
        let printed = channel.printed(&xs);
        let de: Vec<f64> = xs
            .chunks_exact(3)
            .zip(printed.chunks_exact(3))
            .map(|(x, p)| {
                let want = cal.map.apply([x[0], x[1], x[2]].map(|v| v as f64));
                delta_e2000_srgb(want, [p[0], p[1], p[2]].map(|v| v as f64))
            })
            .collect();
        assert!(
            pav_core::colour::spread(&de, 1.0).0 < 0.3,
            "LUT of the calibration vs the calibration: {:?}",
            pav_core::colour::spread(&de, 1.0)
        );
    }

    #[test]
    fn a_video_of_the_chart_is_read_frame_by_frame_and_frames_without_it_are_skipped() {
        let c = chart();
        let dir = tempfile::tempdir().unwrap();
        let shots: Vec<Mat> =
            (0..4).map(|i| photograph(&c, &Shot { blur: 1.0, gain: 1.0, crop_right: 0.0 }, 10 + i)).collect();
        let (w, h) = (shots[0].cols() as usize, shots[0].rows() as usize);
        let path = dir.path().join("turntable.mp4");
        let mut wr = pav_core::video::VideoWriter::create(&path, ['a', 'v', 'c', '1'], 4.0, (w, h)).unwrap();
        let blank = Frame { width: w, height: h, bgr: vec![90; w * h * 3] };
        wr.write(&blank).unwrap();
        for m in &shots {
            wr.write(&pav_core::video::mat_to_frame(m).unwrap()).unwrap();
        }
        wr.finish().unwrap();
        let (cal, rows) = calibrate(Target::Chart(&c), &[path], 5.0, false).unwrap();
        assert_eq!(rows.len(), c.patches.len());
        assert!(cal.residual().median < 2.0, "{:?}", cal.held_out);
    }

    #[test]
    fn bad_photos_are_refused_with_what_went_wrong() {
        let c = chart();
        let dir = tempfile::tempdir().unwrap();
        let fit = |name: &str, m: &Mat| calibrate(Target::Chart(&c), &[save(dir.path(), name, m)], 5.0, false);
        // No chart at all.
        let blank = Mat::new_rows_cols_with_default(600, 800, CV_8UC3, Scalar::all(128.0)).unwrap();
        let e = fit("blank.png", &blank).unwrap_err();
        assert!(matches!(&e, CalibrateError::Photo(p) if matches!(**p, PhotoError::NoMarkers { .. })), "{e}");
        // Partly out of frame: the right-hand markers are cut off.
        let cut = photograph(&c, &Shot { blur: 0.0, gain: 1.0, crop_right: 0.3 }, 2);
        let e = fit("cut.png", &cut).unwrap_err();
        assert!(
            matches!(&e, CalibrateError::Photo(p) if matches!(&**p, PhotoError::MissingMarkers { missing, .. } if missing.len() == 2)),
            "{e}"
        );
        assert!(e.to_string().contains("out of frame"), "{e}");
        // Blur that smears the patches into each other.
        let blurred = photograph(&c, &Shot { blur: 9.0, gain: 1.0, crop_right: 0.0 }, 3);
        let e = fit("blur.png", &blurred).unwrap_err();
        assert!(
            matches!(&e, CalibrateError::Photo(p) if matches!(
                **p,
                PhotoError::Unreadable { .. } | PhotoError::MissingMarkers { .. } | PhotoError::NoMarkers { .. }
            )),
            "{e}"
        );
        // Over-exposed: the bright patches clip, are flagged and left out; the rest still fit.
        let bright = photograph(&c, &Shot { blur: 1.0, gain: 1.35, crop_right: 0.0 }, 4);
        let (cal, rows) = calibrate(Target::Chart(&c), &[save(dir.path(), "bright.png", &bright)], 5.0, true).unwrap();
        assert!(cal.clipped.len() > 20, "{} clipped", cal.clipped.len());
        assert_eq!(rows.iter().filter(|r| r.left_out == "clipped").count(), cal.clipped.len());
        assert_eq!(cal.patches + cal.clipped.len() + cal.unreadable.len(), c.patches.len());
        // A map from these readings is refused under a tight bound, kept with --force.
        let good = save(dir.path(), "good.png", &photograph(&c, &Shot { blur: 1.0, gain: 1.0, crop_right: 0.0 }, 5));
        let e = calibrate(Target::Chart(&c), std::slice::from_ref(&good), 0.05, false).unwrap_err();
        assert!(matches!(e, CalibrateError::Fit(FitError::AboveBound { .. })), "{e}");
        let (cal, _) = calibrate(Target::Chart(&c), &[good], 0.05, true).unwrap();
        assert!(cal.forced);
    }
}
