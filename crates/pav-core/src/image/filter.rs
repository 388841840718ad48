//! 8-bit image filters that change what a detector sees: median smoothing, bit-depth reduction,
//! JPEG re-compression, erased squares and Gaussian noise. Each works in place on a [`Frame`].

use super::Frame;
use crate::rng::Rng;

/// Each channel replaced by the median of its `k × k` neighbourhood (`k` odd), the border
/// replicated: OpenCV's `medianBlur`.
pub fn median(frame: &mut Frame, k: usize) {
    assert!(k % 2 == 1, "median window {k} must be odd");
    if k == 1 || frame.width == 0 || frame.height == 0 {
        return;
    }
    let (w, h, r) = (frame.width, frame.height, k / 2);
    let (pw, ph) = (w + 2 * r, h + 2 * r);
    let mut padded = vec![0u8; pw * ph];
    let mut window = vec![0u8; k * k];
    for c in 0..3 {
        for (py, row) in padded.chunks_exact_mut(pw).enumerate() {
            let y = py.saturating_sub(r).min(h - 1);
            let src = &frame.bgr[y * w * 3..(y + 1) * w * 3];
            for (px, v) in row.iter_mut().enumerate() {
                *v = src[px.saturating_sub(r).min(w - 1) * 3 + c];
            }
        }
        for y in 0..h {
            for x in 0..w {
                for (dy, chunk) in window.chunks_exact_mut(k).enumerate() {
                    let at = (y + dy) * pw + x;
                    chunk.copy_from_slice(&padded[at..at + k]);
                }
                let (_, m, _) = window.select_nth_unstable(k * k / 2);
                frame.bgr[(y * w + x) * 3 + c] = *m;
            }
        }
    }
}

/// Every level rounded to the nearest of `2^bits` evenly spaced levels of [0, 255] (Xu et al.'s
/// bit-depth squeezer: `round(x · (2^b − 1)) / (2^b − 1)` on `x = v / 255`).
pub fn reduce_bits(frame: &mut Frame, bits: u32) {
    assert!((1..=8).contains(&bits), "bit depth {bits} must be 1 to 8");
    let steps = ((1u32 << bits) - 1) as f64;
    let table: [u8; 256] =
        std::array::from_fn(|v| (((v as f64 / 255.0) * steps).round() / steps * 255.0).round() as u8);
    for v in &mut frame.bgr {
        *v = table[*v as usize];
    }
}

/// An axis-aligned square (or its part inside the image): left, top, right and bottom, exclusive.
pub type Rect = [usize; 4];

/// `n` squares of side `s` with centres uniform over a `w × h` image, clipped to it (DeVries and
/// Taylor's cutout), drawn from `rng`.
pub fn cutout_holes(w: usize, h: usize, n: usize, s: usize, rng: &mut Rng) -> Vec<Rect> {
    (0..n)
        .map(|_| {
            let cx = ((rng.unit() * w as f32) as usize).min(w.saturating_sub(1));
            let cy = ((rng.unit() * h as f32) as usize).min(h.saturating_sub(1));
            let (x0, y0) = ((cx + s / 2).saturating_sub(s), (cy + s / 2).saturating_sub(s));
            let (x1, y1) = ((cx + s / 2 + s % 2).min(w), (cy + s / 2 + s % 2).min(h));
            [x0, y0, x1, y1]
        })
        .collect()
}

/// Fills each rectangle with the grey level `fill`.
pub fn erase(frame: &mut Frame, rects: &[Rect], fill: u8) {
    let w = frame.width;
    for &[x0, y0, x1, y1] in rects {
        for y in y0..y1.min(frame.height) {
            frame.bgr[(y * w + x0) * 3..(y * w + x1.min(w)) * 3].fill(fill);
        }
    }
}

/// Adds independent Gaussian noise of standard deviation `sigma` levels to every sample, rounded
/// and clamped to a byte.
pub fn gaussian_noise(frame: &mut Frame, sigma: f32, rng: &mut Rng) {
    for v in &mut frame.bgr {
        *v = (*v as f32 + sigma * rng.normal()).round().clamp(0.0, 255.0) as u8;
    }
}

/// A JPEG encoder or decoder refused the image.
#[cfg(feature = "video")]
#[derive(Debug, thiserror::Error)]
#[error("JPEG re-compression at quality {quality}: {source}")]
pub struct JpegError {
    /// The quality asked for.
    pub quality: u8,
    /// OpenCV's error.
    pub source: opencv::Error,
}

/// The image encoded as a baseline JPEG of `quality` (1–100) and decoded again, by OpenCV's
/// `imencode`/`imdecode` (libjpeg, 4:2:0 chroma), as the JPEG defences of the literature do.
#[cfg(feature = "video")]
pub fn jpeg(frame: &mut Frame, quality: u8) -> Result<(), JpegError> {
    use opencv::core::{Mat, Vector};
    use opencv::prelude::*;
    let run = || -> opencv::Result<Vec<u8>> {
        let flat = Mat::from_slice(&frame.bgr)?;
        let src = flat.reshape(3, frame.height as i32)?;
        let mut buf = Vector::<u8>::new();
        let params = Vector::from_slice(&[opencv::imgcodecs::IMWRITE_JPEG_QUALITY, quality as i32]);
        opencv::imgcodecs::imencode(".jpg", &src, &mut buf, &params)?;
        let out = opencv::imgcodecs::imdecode(&buf, opencv::imgcodecs::IMREAD_COLOR)?;
        Ok(out.data_bytes()?.to_vec())
    };
    frame.bgr = run().map_err(|source| JpegError { quality, source })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize) -> Frame {
        Frame { width: w, height: h, bgr: (0..w * h * 3).map(|i| ((i * 97 + i / 5 * 13) % 256) as u8).collect() }
    }

    /// The median of a window computed the plain way: gather, sort, take the middle.
    fn median_at(f: &Frame, x: usize, y: usize, c: usize, k: usize) -> u8 {
        let r = k as isize / 2;
        let mut v: Vec<u8> = (-r..=r)
            .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| {
                let xx = (x as isize + dx).clamp(0, f.width as isize - 1) as usize;
                let yy = (y as isize + dy).clamp(0, f.height as isize - 1) as usize;
                f.bgr[(yy * f.width + xx) * 3 + c]
            })
            .collect();
        v.sort();
        v[v.len() / 2]
    }

    #[test]
    fn median_is_the_sorted_middle_of_each_replicated_window() {
        let f = ramp(13, 7);
        for k in [3, 5, 9] {
            let mut g = f.clone();
            median(&mut g, k);
            for y in 0..7 {
                for x in 0..13 {
                    for c in 0..3 {
                        assert_eq!(g.bgr[(y * 13 + x) * 3 + c], median_at(&f, x, y, c, k), "k {k} ({x}, {y}, {c})");
                    }
                }
            }
        }
    }

    #[test]
    fn bit_depth_keeps_2_to_the_bits_levels_and_eight_bits_changes_nothing() {
        let mut f = Frame { width: 256, height: 1, bgr: (0..768).map(|i| (i / 3) as u8).collect() };
        let orig = f.clone();
        reduce_bits(&mut f, 8);
        assert_eq!(f.bgr, orig.bgr);
        for bits in 1..8 {
            let mut g = orig.clone();
            reduce_bits(&mut g, bits);
            let mut levels = g.bgr.clone();
            levels.sort();
            levels.dedup();
            assert_eq!(levels.len(), 1 << bits, "{bits} bits");
            assert_eq!((levels[0], *levels.last().unwrap()), (0, 255));
        }
        let mut one = orig.clone();
        reduce_bits(&mut one, 1);
        assert_eq!((one.bgr[127 * 3], one.bgr[128 * 3]), (0, 255));
    }

    #[test]
    fn holes_are_squares_of_side_s_inside_the_image_and_only_they_change() {
        let mut rng = Rng::new(5);
        let holes = cutout_holes(50, 30, 40, 8, &mut rng);
        assert!(holes.iter().all(|r| r[2] <= 50 && r[3] <= 30 && r[2] - r[0] <= 8 && r[3] - r[1] <= 8));
        assert!(holes.iter().any(|r| r[2] - r[0] == 8 && r[3] - r[1] == 8));
        assert!(holes.iter().any(|r| r[0] == 0 || r[1] == 0 || r[2] == 50 || r[3] == 30), "some clipped");
        let f = ramp(50, 30);
        let mut g = f.clone();
        erase(&mut g, &holes[..1], 7);
        let [x0, y0, x1, y1] = holes[0];
        for y in 0..30 {
            for x in 0..50 {
                let inside = (x0..x1).contains(&x) && (y0..y1).contains(&y);
                let want = if inside {
                    [7; 3]
                } else {
                    [f.bgr[(y * 50 + x) * 3], f.bgr[(y * 50 + x) * 3 + 1], f.bgr[(y * 50 + x) * 3 + 2]]
                };
                assert_eq!(g.bgr[(y * 50 + x) * 3..(y * 50 + x) * 3 + 3], want);
            }
        }
    }

    #[test]
    fn noise_has_the_asked_spread_and_no_bias_away_from_the_clamps() {
        let mut f = Frame { width: 200, height: 200, bgr: vec![128; 120_000] };
        gaussian_noise(&mut f, 10.0, &mut Rng::new(1));
        let d: Vec<f64> = f.bgr.iter().map(|&v| v as f64 - 128.0).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
        assert!(mean.abs() < 0.1, "{mean}");
        // Rounding adds a uniform ±0.5 level: variance 100 + 1/12.
        assert!((sd - (100.0f64 + 1.0 / 12.0).sqrt()).abs() < 0.1, "{sd}");
    }
}
