//! Colour maps fitted to patch pairs (intended → photographed): an affine map, a second-order
//! polynomial and a smoothed 3D LUT, compared by CIEDE2000 on held-out patches; the best is kept
//! in a calibration file that the print channel can use in place of an ICC profile.

use super::lut::Lut3;
use pav_core::colour::{delta_e2000_srgb, spread};
use pav_core::geometry::linalg::Cholesky;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The kinds of map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MapKind {
    /// 3×3 matrix and offset (12 numbers).
    Affine,
    /// Second-order polynomial in r, g, b (30 numbers).
    Poly2,
    /// A 3D LUT with a smoothness penalty (nodes × 3 numbers).
    Lut,
}

const MODELS: [MapKind; 3] = [MapKind::Affine, MapKind::Poly2, MapKind::Lut];

/// A fitted map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColourMap {
    /// Its kind.
    pub model: MapKind,
    /// Affine and polynomial: one row of 3 per feature.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub coefficients: Vec<[f64; 3]>,
    /// LUT: nodes per axis.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lut_size: usize,
    /// LUT: node values, red slowest.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lut: Vec<[f64; 3]>,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Held-out CIEDE2000 of one model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    /// The model.
    pub model: MapKind,
    /// Median over held-out patches.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// Largest.
    pub max: f64,
}

fn features(m: MapKind, p: [f64; 3]) -> Vec<f64> {
    let [r, g, b] = p;
    match m {
        MapKind::Affine => vec![r, g, b, 1.0],
        MapKind::Poly2 => vec![1.0, r, g, b, r * r, g * g, b * b, r * g, r * b, g * b],
        MapKind::Lut => unreachable!("the LUT has no feature vector"),
    }
}

/// LUT nodes per axis for `n` patches: a coarse grid, the smoothness term filling its gaps.
fn lut_nodes(n: usize) -> usize {
    if n >= 200 {
        7
    } else {
        5
    }
}

impl ColourMap {
    /// Fits `model` to pairs (from, to), by least squares (with a small ridge, and for the LUT a
    /// smoothness penalty between neighbouring nodes).
    pub fn fit(model: MapKind, from: &[[f64; 3]], to: &[[f64; 3]]) -> Option<ColourMap> {
        match model {
            MapKind::Affine | MapKind::Poly2 => {
                let p = features(model, [0.0; 3]).len();
                let mut a = vec![0f64; p * p];
                let mut b = [vec![0f64; p], vec![0f64; p], vec![0f64; p]];
                for (x, y) in from.iter().zip(to) {
                    let f = features(model, *x);
                    for i in 0..p {
                        for j in 0..p {
                            a[i * p + j] += f[i] * f[j];
                        }
                        (0..3).for_each(|c| b[c][i] += f[i] * y[c]);
                    }
                }
                (0..p).for_each(|i| a[i * p + i] += 1e-6);
                let chol = Cholesky::factor(a, p)?;
                let cols: Vec<Vec<f64>> = b.into_iter().map(|b| chol.solve(b)).collect();
                Some(ColourMap {
                    model,
                    coefficients: (0..p).map(|i| [cols[0][i], cols[1][i], cols[2][i]]).collect(),
                    lut_size: 0,
                    lut: Vec::new(),
                })
            }
            MapKind::Lut => {
                let n = lut_nodes(from.len());
                let m = n * n * n;
                let mut a = vec![0f64; m * m];
                let mut b = [vec![0f64; m], vec![0f64; m], vec![0f64; m]];
                // Data term: trilinear weights of each patch.
                for (x, y) in from.iter().zip(to) {
                    let w = Lut3::node_weights(n, &x.map(|v| v as f32));
                    for &(wi, i) in &w {
                        for &(wj, j) in &w {
                            a[i * m + j] += (wi * wj) as f64;
                        }
                        (0..3).for_each(|c| b[c][i] += wi as f64 * y[c]);
                    }
                }
                // Smoothness: neighbouring nodes agree, weighted by the data per node.
                let lambda = 0.02 * from.len() as f64 / m as f64;
                let idx = |r: usize, g: usize, bb: usize| (r * n + g) * n + bb;
                for r in 0..n {
                    for g in 0..n {
                        for bb in 0..n {
                            let i = idx(r, g, bb);
                            for (dr, dg, db) in [(1, 0, 0), (0, 1, 0), (0, 0, 1)] {
                                let (r2, g2, b2) = (r + dr, g + dg, bb + db);
                                if r2 < n && g2 < n && b2 < n {
                                    let j = idx(r2, g2, b2);
                                    a[i * m + i] += lambda;
                                    a[j * m + j] += lambda;
                                    a[i * m + j] -= lambda;
                                    a[j * m + i] -= lambda;
                                }
                            }
                        }
                    }
                }
                (0..m).for_each(|i| a[i * m + i] += 1e-9);
                let chol = Cholesky::factor(a, m)?;
                let cols: Vec<Vec<f64>> = b.into_iter().map(|b| chol.solve(b)).collect();
                Some(ColourMap {
                    model,
                    coefficients: Vec::new(),
                    lut_size: n,
                    lut: (0..m).map(|i| [cols[0][i], cols[1][i], cols[2][i]]).collect(),
                })
            }
        }
    }

    /// The map at one colour, clipped to [0, 1].
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let out = match self.model {
            MapKind::Affine | MapKind::Poly2 => {
                let f = features(self.model, p);
                std::array::from_fn(|c| f.iter().zip(&self.coefficients).map(|(f, k)| f * k[c]).sum())
            }
            MapKind::Lut => Lut3::node_weights(self.lut_size, &p.map(|v| v as f32))
                .iter()
                .fold([0.0; 3], |acc, &(w, i)| std::array::from_fn(|c| acc[c] + w as f64 * self.lut[i][c])),
        };
        out.map(|v: f64| v.clamp(0.0, 1.0))
    }
}

/// Every patch's ΔE2000 when its fold is held out (`k` interleaved folds).
fn held_out(model: MapKind, from: &[[f64; 3]], to: &[[f64; 3]], k: usize) -> Option<Vec<f64>> {
    let mut de = vec![0f64; from.len()];
    for f in 0..k {
        let (tr, te): (Vec<usize>, Vec<usize>) = (0..from.len()).partition(|i| i % k != f);
        let pick = |v: &[[f64; 3]], ix: &[usize]| ix.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let m = ColourMap::fit(model, &pick(from, &tr), &pick(to, &tr))?;
        for i in te {
            de[i] = delta_e2000_srgb(m.apply(from[i]), to[i]);
        }
    }
    Some(de)
}

/// The fits compared and the one kept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// What the map turns intended colours into: "printer+camera" (pav's chart) or "camera" (a
    /// reference chart whose values are published).
    pub measures: String,
    /// The kept map, refitted on every usable patch.
    pub map: ColourMap,
    /// Held-out CIEDE2000 of every model (the kept one has the lowest median).
    pub held_out: Vec<Residual>,
    /// The bound on the kept model's held-out median that the fit had to meet.
    pub bound: f64,
    /// Whether the fit missed the bound and was kept anyway (`--force`).
    pub forced: bool,
    /// Patches fitted.
    pub patches: usize,
    /// Patches left out because a channel was over-exposed.
    pub clipped: Vec<usize>,
    /// Patches left out because their centre was not one colour.
    pub unreadable: Vec<usize>,
    /// The photos read.
    pub photos: Vec<PathBuf>,
    /// How the chart was found in each photo or frame read, where there is more than one way
    /// (a ColorChecker: by its marker sheet, or by OpenCV's mcc and why the sheet failed).
    #[serde(default)]
    pub found: Vec<String>,
}

/// Why a fit was not kept.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// Too few patches to fit and hold out.
    #[error("only {usable} usable patches ({clipped} clipped, {unreadable} unreadable): at least {need} are needed; lower the exposure or retake the photo")]
    TooFew {
        /// Usable patches.
        usable: usize,
        /// Clipped.
        clipped: usize,
        /// Unreadable.
        unreadable: usize,
        /// Needed.
        need: usize,
    },
    /// No model could be fitted (degenerate colours).
    #[error("no colour map could be fitted: the patches' colours are degenerate")]
    Degenerate,
    /// The best fit misses the bound.
    #[error("the best fit ({model:?}) leaves a held-out median ΔE2000 of {median:.2}, above the bound {bound}: check the photo's light and focus, or keep it with --force (the bound is written into the file)")]
    AboveBound {
        /// The best model.
        model: MapKind,
        /// Its held-out median.
        median: f64,
        /// The bound.
        bound: f64,
    },
    /// Reading or writing the file.
    #[error("{path}: {why}")]
    File {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
}

/// One patch's pair for a fit.
#[derive(Clone, Copy, Debug)]
pub struct Pair {
    /// Patch ID.
    pub id: usize,
    /// Intended (or reference) colour.
    pub from: [f64; 3],
    /// Photographed colour.
    pub to: [f64; 3],
    /// Over-exposed.
    pub clipped: bool,
    /// Not one colour.
    pub unreadable: bool,
}

impl Calibration {
    /// Compares the models on held-out patches and keeps the best; refuses a fit above `bound`
    /// unless `force`.
    pub fn fit(
        measures: &str,
        pairs: &[Pair],
        bound: f64,
        force: bool,
        photos: Vec<PathBuf>,
    ) -> Result<Calibration, FitError> {
        let usable: Vec<&Pair> = pairs.iter().filter(|p| !p.clipped && !p.unreadable).collect();
        let clipped: Vec<usize> = pairs.iter().filter(|p| p.clipped).map(|p| p.id).collect();
        let unreadable: Vec<usize> = pairs.iter().filter(|p| p.unreadable && !p.clipped).map(|p| p.id).collect();
        const NEED: usize = 16;
        if usable.len() < NEED {
            return Err(FitError::TooFew {
                usable: usable.len(),
                clipped: clipped.len(),
                unreadable: unreadable.len(),
                need: NEED,
            });
        }
        let from: Vec<[f64; 3]> = usable.iter().map(|p| p.from).collect();
        let to: Vec<[f64; 3]> = usable.iter().map(|p| p.to).collect();
        // Leave-one-out for small charts; five folds otherwise.
        let k = if from.len() <= 40 { from.len() } else { 5 };
        let mut held = Vec::new();
        for m in MODELS {
            // A model with more numbers than a fold's patches cannot be judged.
            let params = match m {
                MapKind::Affine => 4,
                MapKind::Poly2 => 10,
                MapKind::Lut => 0,
            };
            if params * 2 > from.len() - from.len() / k {
                continue;
            }
            if let Some(de) = held_out(m, &from, &to, k) {
                let (median, p90, _) = spread(&de, 0.0);
                held.push(Residual { model: m, median, p90, max: de.iter().cloned().fold(0.0, f64::max) });
            }
        }
        let best = *held.iter().min_by(|a, b| a.median.total_cmp(&b.median)).ok_or(FitError::Degenerate)?;
        let forced = best.median > bound;
        if forced && !force {
            return Err(FitError::AboveBound { model: best.model, median: best.median, bound });
        }
        let map = ColourMap::fit(best.model, &from, &to).ok_or(FitError::Degenerate)?;
        Ok(Calibration {
            measures: measures.into(),
            map,
            held_out: held,
            bound,
            forced,
            patches: from.len(),
            clipped,
            unreadable,
            photos,
            found: Vec::new(),
        })
    }

    /// The kept model's held-out residual.
    pub fn residual(&self) -> Residual {
        *self.held_out.iter().find(|r| r.model == self.map.model).expect("the kept model was scored")
    }

    /// Writes the calibration as TOML.
    pub fn save(&self, path: &Path) -> Result<(), FitError> {
        let text = toml::to_string(self).map_err(|e| FitError::File { path: path.into(), why: e.to_string() })?;
        std::fs::write(path, text).map_err(|e| FitError::File { path: path.into(), why: e.to_string() })
    }

    /// Reads a calibration written by [`Calibration::save`].
    pub fn load(path: &Path) -> Result<Calibration, FitError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| FitError::File { path: path.into(), why: e.to_string() })?;
        toml::from_str(&text)
            .map_err(|e| FitError::File { path: path.into(), why: format!("not a pav calibration: {e}") })
    }
}

/// A known print + camera map for the tests: desaturated, a warm cast, lifted blacks, a soft
/// shoulder.
#[cfg(test)]
pub(crate) fn known_print(p: [f64; 3]) -> [f64; 3] {
    let m = (p[0] + p[1] + p[2]) / 3.0;
    std::array::from_fn(|c| {
        let v = 0.8 * p[c] + 0.2 * m;
        (0.05 + 0.85 * v.powf(1.15) + [0.03, 0.0, -0.04][c] * v).clamp(0.0, 1.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::rng::Rng;

    #[test]
    fn each_model_recovers_a_smooth_map_and_the_best_is_kept() {
        let mut rng = Rng::new(9);
        let pairs: Vec<Pair> = (0..300)
            .map(|id| {
                let from = [0; 3].map(|_| rng.unit() as f64);
                Pair { id, from, to: known_print(from), clipped: false, unreadable: false }
            })
            .collect();
        let c = Calibration::fit("printer+camera", &pairs, 2.0, false, Vec::new()).unwrap();
        assert_eq!(c.held_out.len(), 3);
        let r = c.residual();
        assert!(r.median < 1.0, "{:?}", c.held_out);
        assert!(c.held_out.iter().all(|h| h.median >= r.median));
        let affine = c.held_out.iter().find(|h| h.model == MapKind::Affine).unwrap();
        assert!(affine.median > r.median, "a curved map should beat the affine one: {:?}", c.held_out);
        // Round trip through the file.
        let dir = tempfile::tempdir().unwrap();
        c.save(&dir.path().join("c.toml")).unwrap();
        let back = Calibration::load(&dir.path().join("c.toml")).unwrap();
        let p = [0.3, 0.6, 0.1];
        let (a, b) = (c.map.apply(p), back.map.apply(p));
        assert!((0..3).all(|i| (a[i] - b[i]).abs() < 1e-9));
    }

    #[test]
    fn a_fit_above_its_bound_is_refused_unless_forced_and_clipped_patches_are_left_out() {
        let mut rng = Rng::new(4);
        let pairs: Vec<Pair> = (0..60)
            .map(|id| {
                let from = [0; 3].map(|_| rng.unit() as f64);
                // Noise a map cannot explain.
                let to = [0; 3].map(|_| rng.unit() as f64);
                Pair { id, from, to, clipped: id % 10 == 0, unreadable: false }
            })
            .collect();
        let e = Calibration::fit("printer+camera", &pairs, 3.0, false, Vec::new()).unwrap_err();
        assert!(matches!(e, FitError::AboveBound { .. }), "{e}");
        let c = Calibration::fit("printer+camera", &pairs, 3.0, true, Vec::new()).unwrap();
        assert!(c.forced && c.bound == 3.0);
        assert_eq!(c.clipped, vec![0, 10, 20, 30, 40, 50]);
        assert_eq!(c.patches, 54);
        let few: Vec<Pair> = pairs.iter().take(20).map(|p| Pair { clipped: p.id % 2 == 0, ..*p }).collect();
        assert!(matches!(Calibration::fit("camera", &few, 3.0, true, Vec::new()), Err(FitError::TooFew { .. })));
    }
}
