//! An X-Rite ColorChecker Classic (24 patches, 4 × 6) found in a photo by the four ArUco markers
//! (`DICT_4X4_50`, IDs 0–3) of a printed placement sheet around it: the sheet is rectified, the
//! checker's dark body located, its patch grid read from the rows and columns of bright pixels,
//! and its orientation taken as the one whose colours an affine map explains best.

use super::fit::{ColourMap, MapKind, Pair};
use super::photo::{median, median_colour, Homography, Photo, PhotoError};
use pav_core::colour::{delta_e2000_srgb, lab_d50_to_srgb};
use std::path::{Path, PathBuf};

/// Marker IDs of the placement sheet (any corner order).
pub const SHEET_IDS: [i32; 4] = [0, 1, 2, 3];
/// The dictionary of the placement sheet.
pub const SHEET_DICTIONARY: &str = "DICT_4X4_50";

/// Why the checker was not read.
#[derive(Debug, thiserror::Error)]
pub enum CheckerError {
    /// The photo or its markers.
    #[error(transparent)]
    Photo(Box<PhotoError>),
    /// The reference values.
    #[error("{path}: {why}")]
    Reference {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// Neither the marker sheet nor OpenCV's marker-less detector found the checker.
    #[error("{path}: no ColorChecker found, neither by its marker sheet ({markers}) nor by OpenCV's marker-less detector, mcc ({mcc})")]
    Neither {
        /// The file.
        path: PathBuf,
        /// Why the marker sheet did not give the checker.
        markers: String,
        /// Why mcc did not.
        mcc: String,
    },
    /// No 4 × 6 grid between the markers.
    #[error("{path}: no ColorChecker grid between the markers ({why})")]
    NoGrid {
        /// The file.
        path: PathBuf,
        /// What was found instead.
        why: String,
    },
}

impl From<PhotoError> for CheckerError {
    fn from(e: PhotoError) -> Self {
        CheckerError::Photo(Box::new(e))
    }
}

/// The 24 published CIELAB (D50) values, by row-major index (row 0: dark skin … bluish green;
/// row 3: white … black), from a CSV with columns `id,square,Lab_l,Lab_a,Lab_b`.
pub fn read_reference(path: &Path) -> Result<[[f64; 3]; 24], CheckerError> {
    let err = |why: String| CheckerError::Reference { path: path.into(), why };
    let mut rd = csv::Reader::from_path(path).map_err(|e| err(e.to_string()))?;
    let mut lab = [[f64::NAN; 3]; 24];
    for rec in rd.records() {
        let r = rec.map_err(|e| err(e.to_string()))?;
        let num = |i: usize| r.get(i).and_then(|v| v.trim().parse::<f64>().ok());
        let (Some(id), Some(l), Some(a), Some(b)) = (num(0), num(2), num(3), num(4)) else {
            return Err(err(format!("expected id,square,Lab_l,Lab_a,Lab_b, got {r:?}")));
        };
        let id = id as usize;
        if id >= 24 {
            return Err(err(format!("patch id {id} is not in 0..24")));
        }
        lab[id] = [l, a, b];
    }
    if lab.iter().any(|v| v[0].is_nan()) {
        return Err(err("fewer than 24 patches".into()));
    }
    Ok(lab)
}

/// Bands of a profile above half its maximum, as (start, end) index ranges.
fn bands(profile: &[f64]) -> Vec<(usize, usize)> {
    let max = profile.iter().cloned().fold(0.0, f64::max);
    let mut out = Vec::new();
    let mut start = None;
    for (i, v) in profile.iter().chain([&0.0]).enumerate() {
        match (start, *v > 0.5 * max) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    // Slivers are noise, not patches.
    let widest = out.iter().map(|(a, b)| b - a).max().unwrap_or(0);
    out.retain(|(a, b)| (b - a) * 3 >= widest);
    out
}

/// One photographed checker: the 24 colours by reference index.
#[derive(Clone, Debug)]
pub struct CheckerReading {
    /// Median colour of each patch's centre (sRGB, [0, 1]), by reference index.
    pub captured: [[f64; 3]; 24],
    /// Largest per-channel median absolute deviation of each.
    pub mad: [f64; 24],
}

/// Finds and reads the checker in `photo`; `reference_srgb` picks the orientation.
pub fn read_checker(
    photo: &Photo,
    path: &Path,
    reference_srgb: &[[f64; 3]; 24],
) -> Result<CheckerReading, CheckerError> {
    let markers = photo.chart_markers(SHEET_DICTIONARY, SHEET_IDS)?;
    let centre =
        |c: &[[f64; 2]; 4]| [c.iter().map(|p| p[0]).sum::<f64>() / 4.0, c.iter().map(|p| p[1]).sum::<f64>() / 4.0];
    let centres: Vec<[f64; 2]> = markers.iter().map(|(_, c)| centre(c)).collect();
    let mid = [centres.iter().map(|c| c[0]).sum::<f64>() / 4.0, centres.iter().map(|c| c[1]).sum::<f64>() / 4.0];
    // Each marker's corner nearest the middle is a corner of the sheet's placement rectangle.
    let mut inner: Vec<[f64; 2]> = markers
        .iter()
        .map(|(_, c)| {
            *c.iter()
                .min_by(|a, b| (a[0] - mid[0]).hypot(a[1] - mid[1]).total_cmp(&(b[0] - mid[0]).hypot(b[1] - mid[1])))
                .unwrap()
        })
        .collect();
    // Order them around the middle: by angle, starting top-left in the photo.
    inner.sort_by(|a, b| (a[1] - mid[1]).atan2(a[0] - mid[0]).total_cmp(&(b[1] - mid[1]).atan2(b[0] - mid[0])));
    let tl = (0..4).min_by(|&i, &j| (inner[i][0] + inner[i][1]).total_cmp(&(inner[j][0] + inner[j][1]))).unwrap();
    inner.rotate_left(tl);
    let side = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
    let (w, h) = (
        (side(inner[0], inner[1]) + side(inner[3], inner[2])) / 2.0,
        (side(inner[1], inner[2]) + side(inner[0], inner[3])) / 2.0,
    );
    let scale = 600.0 / w.max(h);
    let (rw, rh) = ((w * scale).round() as usize, (h * scale).round() as usize);
    let rect = [[0.0, 0.0], [rw as f64, 0.0], [rw as f64, rh as f64], [0.0, rh as f64]];
    let no_grid = |why: String| CheckerError::NoGrid { path: path.into(), why };
    let hm = Homography::fit(&rect, &inner).ok_or_else(|| no_grid("degenerate markers".into()))?;
    let mut img = vec![[0f64; 3]; rw * rh];
    for y in 0..rh {
        for x in 0..rw {
            let [px, py] = hm.apply([x as f64 + 0.5, y as f64 + 0.5]);
            img[y * rw + x] = photo.sample(px, py).unwrap_or([1.0; 3]);
        }
    }
    // The checker's body is the dark frame around the patches.
    let max_c = |p: &[f64; 3]| p[0].max(p[1]).max(p[2]);
    let dark: Vec<bool> = img.iter().map(|p| max_c(p) < 0.22).collect();
    let comp = largest_component(&dark, rw, rh).ok_or_else(|| no_grid("no dark checker body".into()))?;
    let [x0, y0, x1, y1] =
        pav_core::image::set_bounds(rw, comp.iter().copied()).ok_or_else(|| no_grid("no dark checker body".into()))?;
    // Bright pixels inside the body are patches.
    let body_level = {
        let mut v: Vec<f64> = (y0..y1)
            .flat_map(|y| (x0..x1).map(move |x| (x, y)))
            .filter(|&(x, y)| comp[y * rw + x])
            .map(|(x, y)| max_c(&img[y * rw + x]))
            .collect();
        median(&mut v)
    };
    let lit = |x: usize, y: usize| max_c(&img[y * rw + x]) > body_level + 0.12;
    let cols: Vec<f64> = (x0..x1).map(|x| (y0..y1).filter(|&y| lit(x, y)).count() as f64).collect();
    let rows: Vec<f64> = (y0..y1).map(|y| (x0..x1).filter(|&x| lit(x, y)).count() as f64).collect();
    let (bc, br) = (bands(&cols), bands(&rows));
    let (nc, nr) = (bc.len(), br.len());
    if !((nc == 4 && nr == 6) || (nc == 6 && nr == 4)) {
        return Err(no_grid(format!("{nc} columns × {nr} rows of patches")));
    }
    // Median of each cell's centre half.
    let mut cells = Vec::with_capacity(24);
    for &(ya, yb) in &br {
        for &(xa, xb) in &bc {
            let (cx0, cx1) = (x0 + xa + (xb - xa) / 4, x0 + xb - (xb - xa) / 4);
            let (cy0, cy1) = (y0 + ya + (yb - ya) / 4, y0 + yb - (yb - ya) / 4);
            let mut ch: [Vec<f64>; 3] = Default::default();
            for y in cy0..cy1.max(cy0 + 1) {
                for x in cx0..cx1.max(cx0 + 1) {
                    (0..3).for_each(|k| ch[k].push(img[y * rw + x][k]));
                }
            }
            cells.push(median_colour(ch));
        }
    }
    // Orientation: cell (r, c) of the nr × nc grid is reference patch index(r, c) under one of
    // four rotations; the right one is the one an affine map fits best.
    let index = |rot: usize, r: usize, c: usize| -> usize {
        let (rr, cc) = match rot {
            0 => (r, c),
            1 => (nr - 1 - r, nc - 1 - c),
            2 => (c, nr - 1 - r),
            _ => (nc - 1 - c, r),
        };
        rr * 6 + cc
    };
    let rots: &[usize] = if nr == 4 { &[0, 1] } else { &[2, 3] };
    let mut best: Option<(f64, usize)> = None;
    for &rot in rots {
        let mut captured = [[0.0; 3]; 24];
        for r in 0..nr {
            for c in 0..nc {
                captured[index(rot, r, c)] = cells[r * nc + c].0;
            }
        }
        let Some(m) = ColourMap::fit(MapKind::Affine, reference_srgb, &captured) else { continue };
        let err: f64 = (0..24).map(|i| delta_e2000_srgb(m.apply(reference_srgb[i]), captured[i])).sum();
        if best.is_none_or(|(e, _)| err < e) {
            best = Some((err, rot));
        }
    }
    let (_, rot) = best.ok_or_else(|| no_grid("no orientation fits".into()))?;
    let mut reading = CheckerReading { captured: [[0.0; 3]; 24], mad: [0.0; 24] };
    for r in 0..nr {
        for c in 0..nc {
            let i = index(rot, r, c);
            (reading.captured[i], reading.mad[i]) = cells[r * nc + c];
        }
    }
    Ok(reading)
}

/// The reference values as encoded sRGB (D50 → D65 by Bradford), clipped.
pub fn reference_srgb(lab: &[[f64; 3]; 24]) -> [[f64; 3]; 24] {
    lab.map(|l| lab_d50_to_srgb(l).map(|v| v.clamp(0.0, 1.0)))
}

/// The fit pairs of a reading: reference colour → photographed colour.
pub fn pairs(reading: &CheckerReading, reference_srgb: &[[f64; 3]; 24]) -> Vec<Pair> {
    (0..24)
        .map(|i| Pair {
            id: i,
            from: reference_srgb[i],
            to: reading.captured[i],
            clipped: reading.captured[i].iter().any(|v| *v >= 0.985),
            unreadable: reading.mad[i] > 0.05,
        })
        .collect()
}

/// The largest 4-connected component of a mask.
fn largest_component(mask: &[bool], w: usize, h: usize) -> Option<Vec<bool>> {
    let mut label = vec![0u32; mask.len()];
    let mut best = (0usize, 0u32);
    let mut next = 0u32;
    let mut stack = Vec::new();
    for start in 0..mask.len() {
        if !mask[start] || label[start] != 0 {
            continue;
        }
        next += 1;
        let mut size = 0;
        stack.push(start);
        label[start] = next;
        while let Some(p) = stack.pop() {
            size += 1;
            let (x, y) = (p % w, p / w);
            let mut push = |q: usize| {
                if mask[q] && label[q] == 0 {
                    label[q] = next;
                    stack.push(q);
                }
            };
            if x > 0 {
                push(p - 1);
            }
            if x + 1 < w {
                push(p + 1);
            }
            if y > 0 {
                push(p - w);
            }
            if y + 1 < h {
                push(p + w);
            }
        }
        if size > best.0 {
            best = (size, next);
        }
    }
    (best.0 > 0).then(|| label.iter().map(|l| *l == best.1).collect())
}

/// Which way a ColorChecker was found in a photo.
#[derive(Clone, Debug, PartialEq)]
pub enum FoundBy {
    /// The four markers of its placement sheet.
    Markers,
    /// OpenCV's marker-less detector, after the marker sheet failed for the reason given.
    Mcc {
        /// Why the marker sheet did not give the checker.
        markers: String,
    },
}

impl std::fmt::Display for FoundBy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FoundBy::Markers => write!(f, "found by its marker sheet"),
            FoundBy::Mcc { markers } => write!(f, "found by OpenCV's mcc (the marker sheet: {markers})"),
        }
    }
}

/// Finds and reads the checker in `photo`: by its marker sheet, and when that finds no checker
/// (no markers, other markers, or markers that do not frame it), by OpenCV's marker-less detector;
/// says which way it was found, or why neither found it.
pub fn find_checker(
    photo: &Photo,
    path: &Path,
    reference_srgb: &[[f64; 3]; 24],
) -> Result<(CheckerReading, FoundBy), CheckerError> {
    let markers = match read_checker(photo, path, reference_srgb) {
        Ok(r) => return Ok((r, FoundBy::Markers)),
        Err(CheckerError::Photo(e)) if matches!(*e, PhotoError::Load { .. }) => return Err(CheckerError::Photo(e)),
        Err(e @ (CheckerError::Photo(_) | CheckerError::NoGrid { .. })) => e.to_string(),
        Err(e) => return Err(e),
    };
    // The errors name the file; once is enough in the combined message.
    let markers = markers.strip_prefix(&format!("{}: ", path.display())).unwrap_or(&markers).to_string();
    let neither = |mcc: String| CheckerError::Neither { path: path.into(), markers: markers.clone(), mcc };
    match read_checker_mcc(photo) {
        Ok(Some(r)) => Ok((r, FoundBy::Mcc { markers: markers.clone() })),
        Ok(None) => Err(neither("it finds no ColorChecker Classic".into())),
        Err(e) => Err(neither(format!("it failed: {e}"))),
    }
}

/// Finds the checker without a marker sheet, by OpenCV's `mcc` detector (which reports the
/// patches in the chart's published order); None when it finds none.
pub fn read_checker_mcc(photo: &Photo) -> Result<Option<CheckerReading>, opencv::Error> {
    use opencv::mcc::{MCC_CCheckerDetector, MCC_TYPECHART};
    use opencv::prelude::*;
    let mut det = MCC_CCheckerDetector::create()?;
    if !det.process_def(photo.bgr(), MCC_TYPECHART::MCC24)? {
        return Ok(None);
    }
    let mut best = det.get_best_color_checker()?;
    let charts = best.get_charts_rgb()?;
    // Three rows per patch (one per channel: R, G, B), columns: size, mean, std, max, min.
    if charts.rows() != 72 {
        return Ok(None);
    }
    let mut reading = CheckerReading { captured: [[0.0; 3]; 24], mad: [0.0; 24] };
    for i in 0..24 {
        for c in 0..3 {
            let row = (3 * i + c) as i32;
            reading.captured[i][c] = *charts.at_2d::<f64>(row, 1)? / 255.0;
            // The standard deviation stands in for the median absolute deviation (≈ 1.48×).
            reading.mad[i] = reading.mad[i].max(*charts.at_2d::<f64>(row, 2)? / 255.0 / 1.4826);
        }
    }
    Ok(Some(reading))
}
