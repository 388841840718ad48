//! Resampling an 8-bit BGR [`Frame`]: OpenCV's bilinear and PIL's antialiased bilinear, bit for
//! bit, and the same filters as a linear map with its exact adjoint for differentiable pipelines.

use super::Frame;
use crate::rng::Rng;
use crate::step::{accumulate, Step};
use serde::Deserialize;

/// Resampling filter.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Default, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// 2-tap bilinear with half-pixel centres, no antialiasing (OpenCV `INTER_LINEAR`).
    #[default]
    Bilinear,
    /// Triangle filter widened by the downscale factor, two passes rounded to 8 bits
    /// (PIL `Image.resize(BILINEAR)`, torchvision on PIL images).
    Antialias,
    /// Each output pixel the mean of the source area it covers (OpenCV `INTER_AREA`; bilinear
    /// when enlarging, as OpenCV does).
    Area,
}

/// Source taps of one output sample: first source index and normalized weights.
#[derive(Clone)]
struct Taps {
    start: usize,
    weights: Vec<f64>,
}

/// Per-axis resampling table from `src` to `dst` samples.
fn axis_taps(src: usize, dst: usize, filter: Interpolation) -> Vec<Taps> {
    let scale = src as f64 / dst as f64;
    match filter {
        Interpolation::Bilinear => (0..dst)
            .map(|d| {
                // OpenCV: half-pixel centres, coordinates clamped to the edge.
                let f = ((d as f64 + 0.5) * scale - 0.5).max(0.0);
                let i0 = (f.floor() as usize).min(src - 1);
                let a = f - i0 as f64;
                if i0 + 1 < src {
                    Taps { start: i0, weights: vec![1.0 - a, a] }
                } else {
                    Taps { start: i0, weights: vec![1.0] }
                }
            })
            .collect(),
        Interpolation::Area if scale > 1.0 => (0..dst)
            .map(|d| {
                let (a, b) = (d as f64 * scale, (d as f64 + 1.0) * scale);
                let (lo, hi) = (a.floor() as usize, (b.ceil() as usize).min(src));
                let w: Vec<f64> = (lo..hi).map(|x| ((x + 1) as f64).min(b) - (x as f64).max(a)).collect();
                Taps { start: lo, weights: w.iter().map(|v| v / scale).collect() }
            })
            .collect(),
        Interpolation::Area => axis_taps(src, dst, Interpolation::Bilinear),
        Interpolation::Antialias => {
            // PIL: triangle filter of support `max(scale, 1)`, window truncated at the edges and renormalized.
            let fscale = scale.max(1.0);
            let support = fscale;
            (0..dst)
                .map(|d| {
                    let centre = (d as f64 + 0.5) * scale;
                    let lo = ((centre - support + 0.5) as i64).max(0) as usize;
                    let hi = ((centre + support + 0.5) as i64).min(src as i64) as usize;
                    let w: Vec<f64> =
                        (lo..hi).map(|x| (1.0 - ((x as f64 - centre + 0.5) / fscale).abs()).max(0.0)).collect();
                    let total: f64 = w.iter().sum();
                    Taps { start: lo, weights: w.iter().map(|v| v / total).collect() }
                })
                .collect()
        }
    }
}

/// Resizes an interleaved 3-channel u8 image to `nw × nh`, returning values on the 0–255 scale.
pub fn resize(frame: &Frame, nw: usize, nh: usize, filter: Interpolation) -> Vec<f32> {
    match filter {
        Interpolation::Bilinear | Interpolation::Area => resize_float(frame, nw, nh, filter),
        Interpolation::Antialias => resize_pil(frame, nw, nh),
    }
}

/// Separable bilinear or area resampling in f32 with one final rounding (OpenCV's result to
/// within 1 LSB).
fn resize_float(frame: &Frame, nw: usize, nh: usize, filter: Interpolation) -> Vec<f32> {
    resample(frame, &axis_taps(frame.width, nw, filter), &axis_taps(frame.height, nh, filter))
}

/// The window `[x, x + w) × [y, y + h)` (`[x, y, w, h]`) of [`resize`]`(frame, nw, nh,
/// Bilinear)`, computed alone and bit for bit the same: a page of a sheet too large to hold
/// whole.
pub fn resize_window(frame: &Frame, nw: usize, nh: usize, [x, y, w, h]: [usize; 4]) -> Vec<f32> {
    let xs = axis_taps(frame.width, nw, Interpolation::Bilinear);
    let ys = axis_taps(frame.height, nh, Interpolation::Bilinear);
    resample(frame, &xs[x..x + w], &ys[y..y + h])
}

/// The output samples whose taps are `xs` (columns) and `ys` (rows): the horizontal pass over
/// the source rows they read, then the vertical, then one rounding. Every resize and window of
/// one goes through here, so a window is exactly the part of the whole it covers.
fn resample(frame: &Frame, xs: &[Taps], ys: &[Taps]) -> Vec<f32> {
    let (w, nw, nh) = (frame.width, xs.len(), ys.len());
    let lo = ys.iter().map(|t| t.start).min().unwrap_or(0);
    let hi = ys.iter().map(|t| t.start + t.weights.len()).max().unwrap_or(0);
    let mut mid = vec![0f32; (hi - lo) * nw * 3];
    for y in lo..hi {
        let row = &frame.bgr[y * w * 3..(y + 1) * w * 3];
        for (dx, t) in xs.iter().enumerate() {
            for (k, &wt) in t.weights.iter().enumerate() {
                let p = &row[(t.start + k) * 3..(t.start + k) * 3 + 3];
                for c in 0..3 {
                    mid[((y - lo) * nw + dx) * 3 + c] += p[c] as f32 * wt as f32;
                }
            }
        }
    }
    let mut out = vec![0f32; nh * nw * 3];
    for (dy, t) in ys.iter().enumerate() {
        for (k, &wt) in t.weights.iter().enumerate() {
            let r = t.start + k - lo;
            let src = &mid[r * nw * 3..(r + 1) * nw * 3];
            for (o, s) in out[dy * nw * 3..(dy + 1) * nw * 3].iter_mut().zip(src) {
                *o += s * wt as f32;
            }
        }
    }
    out.iter_mut().for_each(|v| *v = v.round().clamp(0.0, 255.0));
    out
}

/// PIL's 8-bit resampler, on the 0–255 scale as floats (see [`resize_pil_u8`]).
fn resize_pil(frame: &Frame, nw: usize, nh: usize) -> Vec<f32> {
    resize_pil_u8(frame, nw, nh).into_iter().map(f32::from).collect()
}

/// PIL's 8-bit resampler: 22-bit fixed-point weights, horizontal pass rounded to 8 bits, then
/// vertical. The weights are non-negative and sum to about 2²², so a sum over 8-bit samples fits
/// an `i32`.
pub fn resize_pil_u8(frame: &Frame, nw: usize, nh: usize) -> Vec<u8> {
    const BITS: u32 = 22;
    let fixed = |taps: Vec<Taps>| -> Vec<(usize, Vec<i32>)> {
        taps.into_iter()
            .map(|t| (t.start, t.weights.iter().map(|&w| (w * (1u64 << BITS) as f64 + 0.5).floor() as i32).collect()))
            .collect()
    };
    let (w, h) = (frame.width, frame.height);
    let xs = fixed(axis_taps(w, nw, Interpolation::Antialias));
    let ys = fixed(axis_taps(h, nh, Interpolation::Antialias));
    let round = |acc: i32| ((acc + (1 << (BITS - 1))) >> BITS).clamp(0, 255) as u8;
    let mut mid = vec![0u8; h * nw * 3];
    for (row, out) in frame.bgr.chunks_exact(w * 3).zip(mid.chunks_exact_mut(nw * 3)) {
        for ((start, ks), o) in xs.iter().zip(out.chunks_exact_mut(3)) {
            let src = &row[start * 3..(start + ks.len()) * 3];
            let mut acc = [0i32; 3];
            for (p, &wt) in src.chunks_exact(3).zip(ks) {
                acc[0] += p[0] as i32 * wt;
                acc[1] += p[1] as i32 * wt;
                acc[2] += p[2] as i32 * wt;
            }
            o.copy_from_slice(&[round(acc[0]), round(acc[1]), round(acc[2])]);
        }
    }
    let stride = nw * 3;
    let mut out = vec![0u8; nh * stride];
    let mut acc = vec![0i32; stride];
    for ((start, ks), o) in ys.iter().zip(out.chunks_exact_mut(stride)) {
        acc.fill(0);
        for (k, &wt) in ks.iter().enumerate() {
            let src = &mid[(start + k) * stride..(start + k + 1) * stride];
            for (a, &v) in acc.iter_mut().zip(src) {
                *a += v as i32 * wt;
            }
        }
        for (o, &a) in o.iter_mut().zip(&acc) {
            *o = round(a);
        }
    }
    out
}

/// Resampling of square `src × src` images to `dst × dst` as a linear map with its exact adjoint,
/// from interleaved HWC (as images are stored) to planar CHW (as networks read them).
#[derive(Clone)]
pub struct Resampler {
    src: usize,
    dst: usize,
    taps: Vec<Taps>,
}

impl Resampler {
    /// The map for `filter`.
    pub fn new(src: usize, dst: usize, filter: Interpolation) -> Self {
        Resampler { src, dst, taps: axis_taps(src, dst, filter) }
    }

    /// Interleaved `src² × c` → planar `c × dst²`.
    pub fn apply(&self, img: &[f32], c: usize) -> Vec<f32> {
        let (s, d) = (self.src, self.dst);
        let mut rows = vec![0f32; s * d]; // one channel, resampled along x
        let mut out = vec![0f32; c * d * d];
        for ch in 0..c {
            rows.fill(0.0);
            for y in 0..s {
                for (dx, t) in self.taps.iter().enumerate() {
                    for (k, &w) in t.weights.iter().enumerate() {
                        rows[y * d + dx] += w as f32 * img[(y * s + t.start + k) * c + ch];
                    }
                }
            }
            let plane = &mut out[ch * d * d..(ch + 1) * d * d];
            for (dy, t) in self.taps.iter().enumerate() {
                for (k, &w) in t.weights.iter().enumerate() {
                    let src = &rows[(t.start + k) * d..(t.start + k + 1) * d];
                    for (o, v) in plane[dy * d..(dy + 1) * d].iter_mut().zip(src) {
                        *o += w as f32 * v;
                    }
                }
            }
        }
        out
    }

    /// The adjoint of [`Resampler::apply`]: planar `c × dst²` → interleaved `src² × c`.
    pub fn adjoint(&self, grad: &[f32], c: usize) -> Vec<f32> {
        let (s, d) = (self.src, self.dst);
        let mut rows = vec![0f32; s * d];
        let mut out = vec![0f32; s * s * c];
        for ch in 0..c {
            rows.fill(0.0);
            let plane = &grad[ch * d * d..(ch + 1) * d * d];
            for (dy, t) in self.taps.iter().enumerate() {
                for (k, &w) in t.weights.iter().enumerate() {
                    let dst = &mut rows[(t.start + k) * d..(t.start + k + 1) * d];
                    for (o, v) in dst.iter_mut().zip(&plane[dy * d..(dy + 1) * d]) {
                        *o += w as f32 * v;
                    }
                }
            }
            for y in 0..s {
                for (dx, t) in self.taps.iter().enumerate() {
                    let g = rows[y * d + dx];
                    for (k, &w) in t.weights.iter().enumerate() {
                        out[(y * s + t.start + k) * c + ch] += w as f32 * g;
                    }
                }
            }
        }
        out
    }
}

/// Resampling an interleaved RGB image to planar RGB, as a step.
impl Step for Resampler {
    type Tape = ();
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.src * self.src * 3
    }

    fn output_len(&self) -> usize {
        self.dst * self.dst * 3
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
        Ok((self.apply(x, 3), ()))
    }

    fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
        accumulate(gx, Resampler::adjoint(self, gy, 3));
    }

    fn map_box(&self, _: &(), car: Option<[f32; 4]>) -> Option<[f32; 4]> {
        let k = self.dst as f32 / self.src as f32;
        car.map(|b| b.map(|v| v * k))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_of_a_resize_is_that_part_of_the_whole_bit_for_bit() {
        let mut rng = crate::rng::Rng::new(7);
        let frame = Frame { width: 13, height: 9, bgr: (0..13 * 9 * 3).map(|_| (rng.unit() * 255.0) as u8).collect() };
        for (nw, nh) in [(40, 31), (7, 5), (13, 9)] {
            let whole = resize(&frame, nw, nh, Interpolation::Bilinear);
            for [x, y, w, h] in [[0, 0, nw, nh], [3, 2, 4, 3], [nw - 2, nh - 1, 2, 1]] {
                let win = resize_window(&frame, nw, nh, [x, y, w, h]);
                for r in 0..h {
                    let row = &whole[((y + r) * nw + x) * 3..((y + r) * nw + x + w) * 3];
                    assert_eq!(&win[r * w * 3..(r + 1) * w * 3], row, "{nw}×{nh} window {x},{y} {w}×{h} row {r}");
                }
            }
        }
    }

    #[test]
    fn bilinear_matches_opencv_half_pixel_convention() {
        // A 2-pixel ramp upsampled to 4: OpenCV gives 0, 64, 191, 255 for [0, 255].
        let f = Frame { width: 2, height: 1, bgr: vec![0, 0, 0, 255, 255, 255] };
        let t = resize(&f, 4, 1, Interpolation::Bilinear);
        let first: Vec<f32> = t.iter().step_by(3).copied().collect();
        assert_eq!(first, [0.0, 64.0, 191.0, 255.0]);
    }

    #[test]
    fn antialias_reproduces_pil_bilinear_downscale() {
        // 23x9 image (rows 4.. inverted) resized to 5x3; expected values from PIL 11 Image.resize(BILINEAR).
        let row: Vec<u8> = (0..23u32).map(|x| ((x * x * 7 + 13) % 256) as u8).collect();
        let bgr: Vec<u8> =
            (0..9).flat_map(|y| row.iter().flat_map(move |&v| [if y >= 4 { 255 - v } else { v }; 3])).collect();
        let f = Frame { width: 23, height: 9, bgr };
        let t: Vec<f32> = resize(&f, 5, 3, Interpolation::Antialias).into_iter().step_by(3).collect();
        let pil =
            [60.0, 113.0, 153.0, 133.0, 168.0, 150.0, 132.0, 119.0, 126.0, 114.0, 195.0, 142.0, 102.0, 122.0, 87.0];
        let worst = t.iter().zip(pil).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert_eq!(worst, 0.0, "got {t:?}");
        // Weights sum to one, so a flat image stays flat.
        let flat = Frame { width: 37, height: 11, bgr: vec![200; 37 * 11 * 3] };
        assert!(resize(&flat, 5, 3, Interpolation::Antialias).iter().all(|&v| v == 200.0));
    }
    #[test]
    fn resampler_reproduces_the_resize() {
        let (n, m) = (13, 5);
        let bgr: Vec<u8> = (0..n * n * 3).map(|i| ((i * 37) % 256) as u8).collect();
        let f = Frame { width: n, height: n, bgr };
        let direct = resize(&f, m, m, Interpolation::Bilinear);
        let r = Resampler::new(n, m, Interpolation::Bilinear);
        // Weights sum to one: a constant image stays constant.
        assert!(r.apply(&vec![1.0; n * n * 3], 3).iter().all(|v| (v - 1.0).abs() < 1e-6));
        let planar = r.apply(&f.bgr.iter().map(|v| *v as f32).collect::<Vec<_>>(), 3);
        for y in 0..m {
            for x in 0..m {
                for c in 0..3 {
                    let v = planar[(c * m + y) * m + x];
                    assert!((v.round() - direct[(y * m + x) * 3 + c]).abs() <= 1.0, "({x},{y},{c})");
                }
            }
        }
    }

    #[test]
    fn resampler_is_a_permutation_at_equal_size_and_its_adjoint_is_exact() {
        let img: Vec<f32> = (0..5 * 5 * 3).map(|i| ((i * 37) % 11) as f32).collect();
        let same = Resampler::new(5, 5, Interpolation::Bilinear).apply(&img, 3);
        for (i, v) in same.iter().enumerate() {
            let (ch, p) = (i / 25, i % 25);
            assert_eq!(*v, img[p * 3 + ch]);
        }
        let r = Resampler::new(13, 6, Interpolation::Bilinear);
        let x: Vec<f32> = (0..13 * 13 * 3).map(|i| ((i * 7919) % 101) as f32 / 50.0 - 1.0).collect();
        let y: Vec<f32> = (0..6 * 6 * 3).map(|i| ((i * 104729) % 97) as f32 / 48.0 - 1.0).collect();
        let lhs: f64 = r.apply(&x, 3).iter().zip(&y).map(|(a, b)| *a as f64 * *b as f64).sum();
        let rhs: f64 = x.iter().zip(r.adjoint(&y, 3)).map(|(a, b)| *a as f64 * b as f64).sum();
        assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
    }
}
