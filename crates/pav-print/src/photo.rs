//! Reading a photographed chart: ArUco markers → homography from the page to the photo → the
//! median colour of each patch's centre, with the checks that keep a bad photo from turning
//! into a wrong calibration silently.

use super::chart::{dictionary, Chart, ChartError};
use opencv::core::{Point2f, Vector};
use opencv::prelude::*;
use opencv::{aruco, imgcodecs};
use pav_core::geometry::linalg::cholesky_solve;
use std::path::{Path, PathBuf};

/// The dictionaries tried when the chart's own finds nothing, to name what the photo shows.
const OTHER_DICTIONARIES: [&str; 4] = ["DICT_4X4_50", "DICT_5X5_50", "DICT_6X6_250", "DICT_ARUCO_ORIGINAL"];
/// A patch whose centre varies more than this (median absolute deviation, [0, 1] scale) is unreadable.
const MAX_MAD: f64 = 0.035;
/// A channel at or above this is clipped (over-exposed).
const CLIP: f64 = 0.985;

/// Why a photo could not be read.
#[derive(Debug, thiserror::Error)]
pub enum PhotoError {
    /// The image file.
    #[error("{path}: cannot read the image")]
    Load {
        /// The file.
        path: PathBuf,
    },
    /// No marker of any common dictionary.
    #[error("{path}: no ArUco marker found; photograph the whole chart, sharp and evenly lit")]
    NoMarkers {
        /// The file.
        path: PathBuf,
    },
    /// Markers of another dictionary.
    #[error("{path}: found {count} markers of {found}, none of {expected}: this is another chart than the one given")]
    WrongDictionary {
        /// The file.
        path: PathBuf,
        /// The dictionary found.
        found: String,
        /// The chart's dictionary.
        expected: String,
        /// Markers found.
        count: usize,
    },
    /// Markers of the right dictionary with other IDs.
    #[error("{path}: markers {ids:?} belong to another chart (this one has {expected:?})")]
    OtherChart {
        /// The file.
        path: PathBuf,
        /// IDs found.
        ids: Vec<i32>,
        /// The chart's IDs.
        expected: [i32; 4],
    },
    /// Some of the chart's markers are missing.
    #[error("{path}: markers {missing:?} not found (found {found:?}): the chart is partly out of frame, covered or too blurred")]
    MissingMarkers {
        /// The file.
        path: PathBuf,
        /// IDs found.
        found: Vec<i32>,
        /// IDs missing.
        missing: Vec<i32>,
    },
    /// Patches outside the photo.
    #[error("{path}: {outside} of {total} patches lie outside the photo: the chart is partly out of frame")]
    OutOfFrame {
        /// The file.
        path: PathBuf,
        /// Patches outside.
        outside: usize,
        /// Patches.
        total: usize,
    },
    /// Too many patches whose centre is not one colour.
    #[error("{path}: {unreadable} of {total} patches are not one colour at their centre (blur, glare or a misplaced chart): retake the photo sharp and without reflections")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// Patches unreadable.
        unreadable: usize,
        /// Patches.
        total: usize,
    },
    /// OpenCV.
    #[error("{path}: {source}")]
    Chart {
        /// The file.
        path: PathBuf,
        /// Why.
        source: Box<ChartError>,
    },
}

/// One patch as photographed.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PatchReading {
    /// The patch ID.
    pub id: usize,
    /// Intended colour, sRGB in [0, 1].
    pub intended: [f64; 3],
    /// The median photographed colour of its centre, sRGB in [0, 1].
    pub captured: [f64; 3],
    /// The largest per-channel median absolute deviation of its centre.
    pub mad: f64,
    /// A channel is over-exposed: left out of fits.
    pub clipped: bool,
    /// Its centre is not one colour: left out of fits.
    pub unreadable: bool,
}

/// A photo as an RGB image in [0, 1].
pub struct Photo {
    /// Width.
    pub width: usize,
    /// Height.
    pub height: usize,
    rgb: Vec<f32>,
    bgr8: Mat,
    path: PathBuf,
}

/// Markers found: ID and the four corners in photo pixels.
pub type Markers = Vec<(i32, [[f64; 2]; 4])>;

impl Photo {
    /// Reads an image file (any format OpenCV reads).
    pub fn load(path: &Path) -> Result<Photo, PhotoError> {
        let m = imgcodecs::imread(path, imgcodecs::IMREAD_COLOR).map_err(|_| PhotoError::Load { path: path.into() })?;
        if m.empty() {
            return Err(PhotoError::Load { path: path.into() });
        }
        Self::from_mat(m, path)
    }

    /// From an 8-bit BGR image.
    pub fn from_mat(m: Mat, path: &Path) -> Result<Photo, PhotoError> {
        let err = |e: opencv::Error| PhotoError::Chart { path: path.into(), source: Box::new(e.into()) };
        let (w, h) = (m.cols() as usize, m.rows() as usize);
        let rgb = m
            .data_bytes()
            .map_err(err)?
            .chunks_exact(3)
            .flat_map(|p| [p[2], p[1], p[0]].map(|v| v as f32 / 255.0))
            .collect();
        Ok(Photo { width: w, height: h, rgb, bgr8: m, path: path.into() })
    }

    /// The file it came from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The photo as OpenCV's 8-bit BGR image.
    pub fn bgr(&self) -> &Mat {
        &self.bgr8
    }

    /// The ArUco markers of `dict`.
    pub fn markers(&self, dict: &str) -> Result<Markers, PhotoError> {
        let err = |source: ChartError| PhotoError::Chart { path: self.path.clone(), source: Box::new(source) };
        let d = dictionary(dict).map_err(err)?;
        let mut corners: Vector<Vector<Point2f>> = Vector::new();
        let mut ids: Vector<i32> = Vector::new();
        aruco::detect_markers_def(&self.bgr8, &d, &mut corners, &mut ids).map_err(|e| err(e.into()))?;
        Ok(ids
            .iter()
            .zip(corners.iter())
            .map(|(id, c)| {
                (id, std::array::from_fn(|k| c.get(k).map(|p| [p.x as f64, p.y as f64]).unwrap_or([0.0; 2])))
            })
            .collect())
    }

    /// The chart's four markers, or the error that says what the photo shows instead.
    pub fn chart_markers(&self, dict: &str, expected: [i32; 4]) -> Result<Markers, PhotoError> {
        let found = self.markers(dict)?;
        let ours: Markers = found.iter().filter(|(id, _)| expected.contains(id)).cloned().collect();
        let path = self.path.clone();
        if ours.is_empty() {
            // Name what the photo shows: the dictionary with the most markers (a small dictionary
            // also matches parts of a larger one's markers, so the count decides).
            let mut best = (found.len(), dict.to_string());
            for other in OTHER_DICTIONARIES.iter().filter(|d| **d != dict) {
                let n = self.markers(other)?.len();
                if n > best.0 {
                    best = (n, other.to_string());
                }
            }
            return Err(match best {
                (0, _) => PhotoError::NoMarkers { path },
                (_, d) if d == dict => {
                    let mut ids: Vec<i32> = found.iter().map(|m| m.0).collect();
                    ids.sort();
                    PhotoError::OtherChart { path, ids, expected }
                }
                (count, found) => PhotoError::WrongDictionary { path, found, expected: dict.into(), count },
            });
        }
        let mut have: Vec<i32> = ours.iter().map(|m| m.0).collect();
        have.sort();
        have.dedup();
        if have.len() < 4 {
            let missing = expected.iter().filter(|id| !have.contains(id)).cloned().collect();
            return Err(PhotoError::MissingMarkers { path, found: have, missing });
        }
        Ok(ours)
    }

    /// Bilinear sample at photo pixel coordinates (pixel centres at integer + 0.5); None outside.
    pub fn sample(&self, x: f64, y: f64) -> Option<[f64; 3]> {
        let (fx, fy) = (x - 0.5, y - 0.5);
        if fx < 0.0 || fy < 0.0 || fx > (self.width - 1) as f64 || fy > (self.height - 1) as f64 {
            return None;
        }
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.width - 1), (y0 + 1).min(self.height - 1));
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        let at = |x: usize, y: usize, c: usize| self.rgb[(y * self.width + x) * 3 + c] as f64;
        Some(std::array::from_fn(|c| {
            (1.0 - ty) * ((1.0 - tx) * at(x0, y0, c) + tx * at(x1, y0, c))
                + ty * ((1.0 - tx) * at(x0, y1, c) + tx * at(x1, y1, c))
        }))
    }

    /// The median colour of the square `[x, x + s] × [y, y + s]` of a plane mapped into the photo by
    /// `h` (its centre half only), and the largest per-channel median absolute deviation; None
    /// when part of it lies outside the photo.
    pub fn read_square(&self, h: &Homography, x: f64, y: f64, s: f64) -> Option<([f64; 3], f64)> {
        const N: usize = 9;
        let mut vals: [Vec<f64>; 3] = Default::default();
        for i in 0..N {
            for j in 0..N {
                let u = x + s * (0.25 + 0.5 * (i as f64 + 0.5) / N as f64);
                let v = y + s * (0.25 + 0.5 * (j as f64 + 0.5) / N as f64);
                let [px, py] = h.apply([u, v]);
                let c = self.sample(px, py)?;
                (0..3).for_each(|k| vals[k].push(c[k]));
            }
        }
        Some(median_colour(vals))
    }

    /// Reads every patch of `chart`.
    pub fn read_chart(&self, chart: &Chart) -> Result<Vec<PatchReading>, PhotoError> {
        let l = &chart.layout;
        let markers = self.chart_markers(&l.dictionary, l.marker_ids)?;
        let mut src = Vec::new();
        let mut dst = Vec::new();
        for (id, corners) in &markers {
            let k = l.marker_ids.iter().position(|m| m == id).expect("filtered to the chart's IDs");
            src.extend(chart.marker_corners_mm(k));
            dst.extend(corners.iter().copied());
        }
        let h = Homography::fit(&src, &dst).ok_or_else(|| PhotoError::MissingMarkers {
            path: self.path.clone(),
            found: Vec::new(),
            missing: l.marker_ids.to_vec(),
        })?;
        let mut out = Vec::with_capacity(chart.patches.len());
        let mut outside = 0;
        for p in &chart.patches {
            let Some((captured, mad)) = self.read_square(&h, p.x_mm, p.y_mm, l.patch_mm) else {
                outside += 1;
                continue;
            };
            out.push(PatchReading {
                id: p.id,
                intended: p.rgb(),
                captured,
                mad,
                clipped: captured.iter().any(|v| *v >= CLIP),
                unreadable: mad > MAX_MAD,
            });
        }
        let total = chart.patches.len();
        if outside > 0 {
            return Err(PhotoError::OutOfFrame { path: self.path.clone(), outside, total });
        }
        let unreadable = out.iter().filter(|r| r.unreadable).count();
        if unreadable * 5 > total {
            return Err(PhotoError::Unreadable { path: self.path.clone(), unreadable, total });
        }
        Ok(out)
    }
}

/// The upper median of values (sorted in place).
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The per-channel median colour of samples and the largest per-channel median absolute
/// deviation: a patch's robust colour and how far it is from one colour.
pub fn median_colour(mut channels: [Vec<f64>; 3]) -> ([f64; 3], f64) {
    let mut med = [0.0; 3];
    let mut mad: f64 = 0.0;
    for (m, ch) in med.iter_mut().zip(channels.iter_mut()) {
        *m = median(ch);
        let mut dev: Vec<f64> = ch.iter().map(|v| (v - *m).abs()).collect();
        mad = mad.max(median(&mut dev));
    }
    (med, mad)
}

/// A plane-to-plane projective map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Homography(pub [f64; 9]);

impl Homography {
    /// The least-squares homography taking `src` to `dst` (at least four points, normalized for
    /// conditioning); None when the points are degenerate.
    pub fn fit(src: &[[f64; 2]], dst: &[[f64; 2]]) -> Option<Homography> {
        if src.len() < 4 || src.len() != dst.len() {
            return None;
        }
        let norm = |p: &[[f64; 2]]| {
            let n = p.len() as f64;
            let (mx, my) = (p.iter().map(|q| q[0]).sum::<f64>() / n, p.iter().map(|q| q[1]).sum::<f64>() / n);
            let d = p.iter().map(|q| (q[0] - mx).hypot(q[1] - my)).sum::<f64>() / n;
            let s = if d > 0.0 { std::f64::consts::SQRT_2 / d } else { 1.0 };
            [s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0]
        };
        let (ts, td) = (norm(src), norm(dst));
        let ap = |t: &[f64; 9], p: [f64; 2]| [t[0] * p[0] + t[2], t[4] * p[1] + t[5]];
        // Normal equations of the 8 unknowns with h33 = 1.
        let mut a = [[0f64; 9]; 8];
        for (s, d) in src.iter().zip(dst) {
            let ([x, y], [u, v]) = (ap(&ts, *s), ap(&td, *d));
            for row in [[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y, u], [0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y, v]] {
                for i in 0..8 {
                    for j in 0..9 {
                        a[i][j] += row[i] * row[j];
                    }
                }
            }
        }
        let h = cholesky_solve(a.iter().flat_map(|r| r[..8].to_vec()).collect(), a.iter().map(|r| r[8]).collect(), 8)?;
        let hn = [h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0];
        // H = Td⁻¹ · Hn · Ts.
        let tdi = [1.0 / td[0], 0.0, -td[2] / td[0], 0.0, 1.0 / td[4], -td[5] / td[4], 0.0, 0.0, 1.0];
        let m = mul3(&tdi, &mul3(&hn, &ts));
        (m[8].abs() > 1e-12).then(|| Homography(m.map(|v| v / m[8])))
    }

    /// Maps a point.
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let h = &self.0;
        let w = h[6] * p[0] + h[7] * p[1] + h[8];
        [(h[0] * p[0] + h[1] * p[1] + h[2]) / w, (h[3] * p[0] + h[4] * p[1] + h[5]) / w]
    }
}

fn mul3(a: &[f64; 9], b: &[f64; 9]) -> [f64; 9] {
    std::array::from_fn(|k| {
        let (i, j) = (k / 3, k % 3);
        (0..3).map(|t| a[i * 3 + t] * b[t * 3 + j]).sum()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_homography_is_recovered_from_its_points() {
        let h = Homography([1.2, 0.1, 30.0, -0.05, 0.9, 12.0, 1e-4, -2e-4, 1.0]);
        let src: Vec<[f64; 2]> = (0..12).map(|i| [(i % 4) as f64 * 50.0, (i / 4) as f64 * 70.0]).collect();
        let dst: Vec<[f64; 2]> = src.iter().map(|p| h.apply(*p)).collect();
        let g = Homography::fit(&src, &dst).unwrap();
        for p in [[10.0, 20.0], [150.0, 140.0]] {
            let (a, b) = (h.apply(p), g.apply(p));
            assert!((a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6, "{a:?} {b:?}");
        }
        assert!(Homography::fit(&src[..3], &dst[..3]).is_none());
    }
}
