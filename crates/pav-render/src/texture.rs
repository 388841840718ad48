//! Bilinear texture lookup as a fixed linear map (a gather) and its exact adjoint (a scatter).
//!
//! The geometry and poses are fixed, so each pixel's UV is known after rasterization: the DR
//! render is `I = G·T` for a sparse matrix `G` with four taps per covered pixel. The gradient of
//! any loss with respect to the texture is then `Gᵀ·∂L/∂I`, computed exactly by [`Gather::adjoint`].

use pav_core::rng::Rng;
use pav_core::step::Step;

/// Texel convention: `align_corners = True` as in PyTorch3D's `TexturesUV`. u = 0 and u = 1 are
/// the centres of the first and last columns; v = 1 is the top row; outside [0, 1] clamps.
#[derive(Clone, Debug, PartialEq)]
pub struct Gather {
    /// Texture width and height.
    pub tex_size: (usize, usize),
    /// Output pixel index of each sample.
    pub pixels: Vec<u32>,
    /// Four (texel index, weight) taps per sample; weights sum to 1.
    pub taps: Vec<[(u32, f32); 4]>,
}

impl Gather {
    /// Builds the map for `(pixel, uv)` samples on a `w × h` texture.
    pub fn new(samples: impl IntoIterator<Item = (u32, [f32; 2])>, w: usize, h: usize) -> Self {
        let (mut pixels, mut taps) = (Vec::new(), Vec::new());
        for (p, [u, v]) in samples {
            // Non-finite UVs (degenerate faces) fall back to the texture's first texel, never NaN.
            let u = if u.is_finite() { u.clamp(0.0, 1.0) } else { 0.0 };
            let v = if v.is_finite() { v.clamp(0.0, 1.0) } else { 0.0 };
            let x = u * (w - 1) as f32;
            let y = (1.0 - v) * (h - 1) as f32;
            let (x0, y0) = ((x.floor() as usize).min(w - 1), (y.floor() as usize).min(h - 1));
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            let (fx, fy) = (x - x0 as f32, y - y0 as f32);
            let t = |xx: usize, yy: usize| (yy * w + xx) as u32;
            taps.push([
                (t(x0, y0), (1.0 - fx) * (1.0 - fy)),
                (t(x1, y0), fx * (1.0 - fy)),
                (t(x0, y1), (1.0 - fx) * fy),
                (t(x1, y1), fx * fy),
            ]);
            pixels.push(p);
        }
        Gather { tex_size: (w, h), pixels, taps }
    }

    /// `out[pixel] = Σ w·tex[texel]` for `c`-channel interleaved data; pixels not covered are untouched.
    pub fn apply(&self, tex: &[f32], c: usize, out: &mut [f32]) {
        for (p, taps) in self.pixels.iter().zip(&self.taps) {
            let o = &mut out[*p as usize * c..(*p as usize + 1) * c];
            o.fill(0.0);
            for &(t, wgt) in taps {
                for k in 0..c {
                    o[k] += wgt * tex[t as usize * c + k];
                }
            }
        }
    }

    /// The adjoint: `grad_tex[texel] += Σ w·grad_out[pixel]`.
    pub fn adjoint(&self, grad_out: &[f32], c: usize, grad_tex: &mut [f32]) {
        for (p, taps) in self.pixels.iter().zip(&self.taps) {
            let g = &grad_out[*p as usize * c..(*p as usize + 1) * c];
            for &(t, wgt) in taps {
                for k in 0..c {
                    grad_tex[t as usize * c + k] += wgt * g[k];
                }
            }
        }
    }
}

/// The lookup as a step from an RGB texture to an RGB image as long as its last covered pixel;
/// pixels it does not cover are 0.
impl Step for Gather {
    type Tape = ();
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.tex_size.0 * self.tex_size.1 * 3
    }

    fn output_len(&self) -> usize {
        self.pixels.iter().max().map_or(0, |p| *p as usize + 1) * 3
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
        let mut y = vec![0f32; self.output_len()];
        self.apply(x, 3, &mut y);
        Ok((y, ()))
    }

    fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
        Gather::adjoint(self, gy, 3, gx);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(seed: &mut u64) -> f32 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn corners_hit_texel_centres_and_edges_clamp() {
        let tex: Vec<f32> = (0..6).map(|i| i as f32).collect(); // 3x2, one channel
        let g = Gather::new(
            [(0, [0.0, 1.0]), (1, [1.0, 0.0]), (2, [0.5, 0.5]), (3, [2.0, -1.0]), (4, [f32::NAN, 0.5])],
            3,
            2,
        );
        let mut out = vec![0.0; 5];
        g.apply(&tex, 1, &mut out);
        assert_eq!(&out[..4], &[0.0, 5.0, 2.5, 5.0]);
        assert!(out[4].is_finite());
    }

    #[test]
    fn adjoint_is_exact_and_matches_finite_differences() {
        let (w, h, c) = (7, 5, 3);
        let mut s = 42;
        let samples: Vec<(u32, [f32; 2])> = (0..40).map(|p| (p, [lcg(&mut s) * 1.2 - 0.1, lcg(&mut s)])).collect();
        let g = Gather::new(samples, w, h);
        let x: Vec<f32> = (0..w * h * c).map(|_| lcg(&mut s)).collect();
        let y: Vec<f32> = (0..40 * c).map(|_| lcg(&mut s) - 0.5).collect();
        let mut ax = vec![0.0; 40 * c];
        g.apply(&x, c, &mut ax);
        let mut aty = vec![0.0; w * h * c];
        g.adjoint(&y, c, &mut aty);
        // <Ax, y> = <x, Aᵀy>
        let lhs: f64 = ax.iter().zip(&y).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
        let rhs: f64 = x.iter().zip(&aty).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
        assert!((lhs - rhs).abs() < 1e-5 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
        // d/dx_i of L = <Ax, y> by central differences equals (Aᵀy)_i.
        for i in [0, 17, 50, w * h * c - 1] {
            let eps = 1e-2;
            let loss = |xx: &Vec<f32>| {
                let mut o = vec![0.0; 40 * c];
                g.apply(xx, c, &mut o);
                o.iter().zip(&y).map(|(a, b)| (*a as f64) * (*b as f64)).sum::<f64>()
            };
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += eps;
            xm[i] -= eps;
            let fd = (loss(&xp) - loss(&xm)) / (2.0 * eps as f64);
            assert!((fd - aty[i] as f64).abs() < 1e-4, "texel {i}: fd {fd} vs adjoint {}", aty[i]);
        }
    }
}
