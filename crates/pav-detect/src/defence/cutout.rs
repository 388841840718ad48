//! Cutout (DeVries and Taylor) as an input defence: squares of the input filled with grey, their
//! centres drawn afresh for each image. Its backward is exact: the gradient stops in the squares.

use super::{DefenceError, DefenceUnit, Gradient};
use pav_core::image::Frame;
use pav_core::rng::Rng;

/// Cutout: `n` squares of side `s` input pixels, centres drawn per image, filled with `fill`.
#[derive(Clone, Debug, serde::Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Cutout {
    /// Squares per image.
    pub n: usize,
    /// Their side in input pixels.
    pub s: usize,
    /// Grey level they are filled with (0–255).
    #[serde(default = "mid_grey")]
    pub fill: u8,
    /// Seed of the draws (mixed with the image, so a frame always gets the same squares).
    #[serde(default)]
    pub seed: u64,
}

fn mid_grey() -> u8 {
    127
}

/// An axis-aligned square (or its part inside the image): left, top, right and bottom, exclusive.
type Rect = [usize; 4];

/// `n` squares of side `s` with centres uniform over a `w × h` image, clipped to it, drawn from
/// `rng`.
fn holes(w: usize, h: usize, n: usize, s: usize, rng: &mut Rng) -> Vec<Rect> {
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

impl DefenceUnit for Cutout {
    fn check(&self, width: usize, height: usize) -> Result<(), String> {
        let (n, s) = (self.n, self.s);
        if n == 0 || s == 0 {
            return Err(format!("n = {n} and s = {s} must be positive"));
        }
        if s > width.max(height) {
            return Err(format!("s = {s} is larger than the {width}x{height} input"));
        }
        Ok(())
    }

    fn label(&self) -> String {
        let seeded = if self.seed == 0 { String::new() } else { format!("s{}", self.seed) };
        format!("cutout{}x{}{seeded}", self.n, self.s)
    }

    fn random(&self) -> bool {
        true
    }

    fn apply(&self, img: &mut Frame, draw: u64) -> Result<(), DefenceError> {
        let w = img.width;
        for [x0, y0, x1, y1] in holes(img.width, img.height, self.n, self.s, &mut Rng::new(self.seed ^ draw)) {
            for y in y0..y1.min(img.height) {
                img.bgr[(y * w + x0) * 3..(y * w + x1.min(w)) * 3].fill(self.fill);
            }
        }
        Ok(())
    }

    fn forward(&self, x: &mut [f32], side: usize, draw: u64) -> Result<Gradient, DefenceError> {
        let mut mask = vec![false; side * side];
        for [x0, y0, x1, y1] in holes(side, side, self.n, self.s, &mut Rng::new(self.seed ^ draw)) {
            for y in y0..y1 {
                mask[y * side + x0..y * side + x1].fill(true);
            }
        }
        for plane in x.chunks_exact_mut(side * side) {
            plane.iter_mut().zip(&mask).filter(|(_, m)| **m).for_each(|(v, _)| *v = self.fill as f32 / 255.0);
        }
        Ok(Gradient::Stop(mask))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holes_are_squares_of_side_s_inside_the_image_and_only_they_change() {
        let mut rng = Rng::new(5);
        let all = holes(50, 30, 40, 8, &mut rng);
        assert!(all.iter().all(|r| r[2] <= 50 && r[3] <= 30 && r[2] - r[0] <= 8 && r[3] - r[1] <= 8));
        assert!(all.iter().any(|r| r[2] - r[0] == 8 && r[3] - r[1] == 8));
        assert!(all.iter().any(|r| r[0] == 0 || r[1] == 0 || r[2] == 50 || r[3] == 30), "some clipped");
        let f = Frame { width: 50, height: 30, bgr: (0..4500).map(|i| ((i * 97 + i / 5 * 13) % 256) as u8).collect() };
        let mut g = f.clone();
        // One square drawn from seed 5, as `holes` drew it first.
        Cutout { n: 1, s: 8, fill: 7, seed: 5 }.apply(&mut g, 0).unwrap();
        let [x0, y0, x1, y1] = all[0];
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
}
