//! The scene's `zoom` effect on the whole composite, forward and exact backward: the detector sees
//! the view from a camera moved nearer or farther (input diversity). The composite is resampled
//! by a factor drawn from U(min, max) and placed at a random offset on a canvas of its own size:
//! grey where a smaller image leaves room, cropped where a larger one overflows.
//!
//! Unlike the pixel effects of `scene::eot` it moves pixels, so it runs after them, on the
//! clamped composite the detectors read.

use super::{Effect, Scene};
use pav_core::image::resize::{Interpolation, Resampler};
use pav_core::rng::Rng;
use pav_core::step::{accumulate, Step};

/// The canvas value where a zoomed-out composite leaves room (mid grey, as letterboxes are).
pub const FILL: f32 = 0.5;

/// One drawn zoom: what the backward pass needs.
#[derive(Clone)]
pub struct ZoomTape {
    resampler: Resampler,
    /// Side of the resampled composite.
    scaled: usize,
    /// Canvas position of the resampled composite's top-left pixel (negative: cropped).
    offset: (isize, isize),
}

impl std::fmt::Debug for ZoomTape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZoomTape").field("scaled", &self.scaled).field("offset", &self.offset).finish()
    }
}

impl ZoomTape {
    /// Side of the resampled composite before it is placed.
    pub fn scaled(&self) -> usize {
        self.scaled
    }

    /// Where a box (xyxy pixels) of the `size × size` composite lies on the zoomed canvas,
    /// clipped to it.
    pub fn map_box(&self, b: [f32; 4], size: usize) -> [f32; 4] {
        let k = self.scaled as f32 / size as f32;
        let (ox, oy) = (self.offset.0 as f32, self.offset.1 as f32);
        let clip = |v: f32| v.clamp(0.0, size as f32);
        [clip(b[0] * k + ox), clip(b[1] * k + oy), clip(b[2] * k + ox), clip(b[3] * k + oy)]
    }
}

/// The scene's zoom range, if it lists one.
pub fn range(scene: &Scene) -> Option<(f32, f32)> {
    scene.effects.iter().find_map(|e| match *e {
        Effect::Zoom { min, max } => Some((min, max)),
        _ => None,
    })
}

/// Zooms the `size × size` interleaved RGB `img` as the scene says, drawing from `rng`; a scene
/// without `zoom` draws nothing and returns `None`, leaving `img` as it is.
pub fn apply(scene: &Scene, img: &mut [f32], size: usize, rng: &mut Rng) -> Option<ZoomTape> {
    let (min, max) = range(scene)?;
    let s = rng.uniform(min, max);
    let scaled = ((size as f32 * s).round() as usize).max(1);
    let room = size as isize - scaled as isize;
    let mut pick = |room: isize| {
        let (lo, hi) = (room.min(0), room.max(0));
        lo + (rng.next_u64() % (hi - lo + 1) as u64) as isize
    };
    let offset = (pick(room), pick(room));
    let tape = ZoomTape { resampler: Resampler::new(size, scaled, Interpolation::Antialias), scaled, offset };
    let planar = tape.resampler.apply(img, 3);
    let plane = scaled * scaled;
    for (p, out) in img.chunks_exact_mut(3).enumerate() {
        match source(&tape, p % size, p / size) {
            Some(q) => (0..3).for_each(|c| out[c] = planar[c * plane + q]),
            None => out.fill(FILL),
        }
    }
    Some(tape)
}

/// Backward: `∂L/∂zoomed` → `∂L/∂composite`.
pub fn backward(tape: &ZoomTape, grad: &[f32], size: usize) -> Vec<f32> {
    let plane = tape.scaled * tape.scaled;
    let mut planar = vec![0f32; 3 * plane];
    for (p, g) in grad.chunks_exact(3).enumerate() {
        if let Some(q) = source(tape, p % size, p / size) {
            (0..3).for_each(|c| planar[c * plane + q] = g[c]);
        }
    }
    tape.resampler.adjoint(&planar, 3)
}

/// The resampled composite's pixel under canvas pixel (x, y), if any.
fn source(tape: &ZoomTape, x: usize, y: usize) -> Option<usize> {
    let (sx, sy) = (x as isize - tape.offset.0, y as isize - tape.offset.1);
    let n = tape.scaled as isize;
    ((0..n).contains(&sx) && (0..n).contains(&sy)).then(|| (sy * n + sx) as usize)
}

/// The scene's zoom as a step on a `size × size` RGB composite (the identity for a scene
/// without one).
pub struct Zoom<'a> {
    /// The scene whose zoom is drawn.
    pub scene: &'a Scene,
    /// The composite's side.
    pub size: usize,
}

impl Step for Zoom<'_> {
    type Tape = Option<ZoomTape>;
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.size * self.size * 3
    }

    fn output_len(&self) -> usize {
        self.size * self.size * 3
    }

    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, Option<ZoomTape>), Self::Error> {
        let mut y = x.to_vec();
        let tape = apply(self.scene, &mut y, self.size, rng);
        Ok((y, tape))
    }

    fn adjoint(&self, tape: &Option<ZoomTape>, gy: &[f32], gx: &mut [f32]) {
        match tape {
            Some(t) => accumulate(gx, backward(t, gy, self.size)),
            None => accumulate(gx, gy.iter().copied()),
        }
    }

    fn map_box(&self, tape: &Option<ZoomTape>, car: Option<[f32; 4]>) -> Option<[f32; 4]> {
        car.map(|b| tape.as_ref().map_or(b, |z| z.map_box(b, self.size)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(min: f32, max: f32) -> Scene {
        Scene::parse(&format!("[[effects]]\nkind = \"zoom\"\nmin = {min}\nmax = {max}\n"), "t").unwrap()
    }

    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut r = Rng::new(seed);
        (0..n).map(|_| r.unit()).collect()
    }

    #[test]
    fn backward_is_the_exact_adjoint_when_zooming_in_and_out() {
        let size = 37;
        let mut seen = (false, false);
        for seed in 0..12 {
            let x = noise(size * size * 3, seed);
            let y = noise(size * size * 3, seed + 100);
            let mut zx = x.clone();
            let tape = apply(&scene(0.5, 1.6), &mut zx, size, &mut Rng::new(seed)).unwrap();
            seen = (seen.0 || tape.scaled < size, seen.1 || tape.scaled > size);
            // ⟨A x, y⟩ = ⟨x, Aᵀ y⟩ for the linear part; the grey fill is the affine offset.
            let mut z0 = vec![0f32; x.len()];
            apply(&scene(0.5, 1.6), &mut z0, size, &mut Rng::new(seed));
            let lhs: f64 = zx.iter().zip(&z0).zip(&y).map(|((a, b), c)| ((a - b) * c) as f64).sum();
            let aty = backward(&tape, &y, size);
            let rhs: f64 = x.iter().zip(&aty).map(|(a, b)| (a * b) as f64).sum();
            assert!((lhs - rhs).abs() < 1e-3 * lhs.abs().max(1.0), "seed {seed}: {lhs} vs {rhs}");
        }
        assert!(seen.0 && seen.1, "draws covered both zooming out and in: {seen:?}");
    }

    #[test]
    fn a_unit_zoom_is_the_identity_and_a_scene_without_zoom_draws_nothing() {
        let size = 20;
        let x = noise(size * size * 3, 1);
        let mut z = x.clone();
        let tape = apply(&scene(1.0, 1.0), &mut z, size, &mut Rng::new(3)).unwrap();
        assert_eq!((tape.scaled, tape.offset), (size, (0, 0)));
        assert!(z.iter().zip(&x).all(|(a, b)| (a - b).abs() < 1e-6));
        let mut rng = Rng::new(5);
        let before = rng.state;
        assert!(apply(&Scene::default(), &mut z, size, &mut rng).is_none());
        assert_eq!(rng.state, before);
    }

    #[test]
    fn zooming_out_leaves_a_grey_border_and_keeps_the_mean_of_the_image() {
        let size = 40;
        let x = noise(size * size * 3, 2);
        let mut z = x.clone();
        let tape = apply(&scene(0.5, 0.5), &mut z, size, &mut Rng::new(9)).unwrap();
        assert_eq!(tape.scaled, 20);
        let grey = z.iter().filter(|v| **v == FILL).count();
        assert!(grey >= (size * size - 400) * 3, "{grey} grey values");
        let inner: f32 = z.iter().filter(|v| **v != FILL).sum::<f32>() / (400.0 * 3.0);
        let mean: f32 = x.iter().sum::<f32>() / x.len() as f32;
        assert!((inner - mean).abs() < 0.02, "{inner} vs {mean}");
    }

    #[test]
    fn a_box_follows_its_pixels_through_a_zoom() {
        // A white 10 × 6 block at (12, 20) on black, zoomed in and out: the mapped box holds the
        // pixels that stay brighter than half, to within the resampler's one-pixel blur.
        let size = 40;
        let b = [12.0, 20.0, 22.0, 26.0];
        for (s, seed) in [(0.6, 1), (1.3, 2), (1.0, 3)] {
            let mut img = vec![0f32; size * size * 3];
            for y in 20..26 {
                for x in 12..22 {
                    img[(y * size + x) * 3..(y * size + x) * 3 + 3].fill(1.0);
                }
            }
            let tape = apply(&scene(s, s), &mut img, size, &mut Rng::new(seed)).unwrap();
            let m = tape.map_box(b, size);
            for y in 0..size {
                for x in 0..size {
                    let bright = img[(y * size + x) * 3] > 0.5 && img[(y * size + x) * 3] != FILL;
                    let (cx, cy) = (x as f32 + 0.5, y as f32 + 0.5);
                    let inside = cx > m[0] - 1.0 && cx < m[2] + 1.0 && cy > m[1] - 1.0 && cy < m[3] + 1.0;
                    assert!(!bright || inside, "zoom {s}: bright ({x}, {y}) outside {m:?}");
                }
            }
            let k = tape.scaled as f32 / size as f32;
            assert!(((m[2] - m[0]) - 10.0 * k).abs() < 1e-4 || m[0] == 0.0 || m[2] == size as f32, "{m:?}");
        }
    }
}
