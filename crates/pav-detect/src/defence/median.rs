//! Spatial smoothing: the median of each `k × k` window, as OpenCV's `medianBlur` (Xu et al.'s
//! median squeezer). Its backward is exact: each output sample's gradient goes to the input
//! sample its window picked.

use super::{DefenceError, DefenceUnit, Gradient};
use pav_core::image::Frame;

/// Spatial smoothing: the median of each `k × k` window (`k` odd, at least 3).
#[derive(Clone, Debug, serde::Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Median {
    /// Window side.
    pub k: usize,
}

impl DefenceUnit for Median {
    fn check(&self, width: usize, height: usize) -> Result<(), String> {
        let k = self.k;
        if k < 3 || k % 2 == 0 {
            return Err(format!("k = {k} must be odd and at least 3"));
        }
        if k > width.min(height) {
            return Err(format!("k = {k} is wider than the {width}x{height} input"));
        }
        Ok(())
    }

    fn label(&self) -> String {
        format!("median{}", self.k)
    }

    fn apply(&self, img: &mut Frame, _: u64) -> Result<(), DefenceError> {
        median_8bit(img, self.k);
        Ok(())
    }

    fn forward(&self, x: &mut [f32], side: usize, _: u64) -> Result<Gradient, DefenceError> {
        Ok(Gradient::Gather(median_float(x, side, self.k)))
    }
}

/// Each channel of an 8-bit frame replaced by the median of its `k × k` neighbourhood (`k` odd),
/// the border replicated: OpenCV's `medianBlur`.
fn median_8bit(frame: &mut Frame, k: usize) {
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

/// The median of each `k × k` window per plane of planar float samples (border replicated), in
/// place; returns, for each sample, the index of the input sample that is its median.
fn median_float(x: &mut [f32], side: usize, k: usize) -> Vec<u32> {
    let r = k as isize / 2;
    let plane = side * side;
    let src = x.to_vec();
    let mut from = vec![0u32; x.len()];
    let mut window: Vec<(f32, u32)> = Vec::with_capacity(k * k);
    for p in 0..x.len() / plane {
        for y in 0..side {
            for xx in 0..side {
                window.clear();
                for dy in -r..=r {
                    let yy = (y as isize + dy).clamp(0, side as isize - 1) as usize;
                    for dx in -r..=r {
                        let xs = (xx as isize + dx).clamp(0, side as isize - 1) as usize;
                        let j = p * plane + yy * side + xs;
                        window.push((src[j], j as u32));
                    }
                }
                let mid = window.len() / 2;
                let (_, m, _) = window.select_nth_unstable_by(mid, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                let i = p * plane + y * side + xx;
                x[i] = m.0;
                from[i] = m.1;
            }
        }
    }
    from
}

#[cfg(test)]
mod tests {
    use super::super::{from_frame, to_frame};
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
            median_8bit(&mut g, k);
            for y in 0..7 {
                for x in 0..13 {
                    for c in 0..3 {
                        assert_eq!(g.bgr[(y * 13 + x) * 3 + c], median_at(&f, x, y, c, k), "k {k} ({x}, {y}, {c})");
                    }
                }
            }
        }
    }

    /// The float median agrees with the 8-bit one on 8-bit levels.
    #[test]
    fn float_median_matches_the_frame_median() {
        let side = 12;
        let mut rng = pav_core::rng::Rng::new(6);
        let x: Vec<f32> = (0..3 * side * side).map(|_| (rng.unit() * 255.0).round() / 255.0).collect();
        let mut y = x.clone();
        median_float(&mut y, side, 5);
        let mut f = to_frame(&x, side);
        median_8bit(&mut f, 5);
        let mut z = vec![0f32; x.len()];
        from_frame(&f, &mut z);
        assert!(y.iter().zip(&z).all(|(a, b)| (a - b).abs() < 1e-6));
    }
}
