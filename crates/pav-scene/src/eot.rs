//! Expectation over Transformation on the textured render, forward and exact backward.
//!
//! Every listed effect is affine per value (`x·a + b`), so one pass keeps each value's total
//! gain; the final clamp to [0, 1] passes the gradient only where it did not clip. Only the
//! pixels that reach the composite (P = 1) are transformed.

use super::{Effect, Per, Scene};
use pav_core::rng::Rng;
use pav_core::step::{accumulate, Step};

/// What the backward pass needs from one forward pass.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EotTape {
    /// Per transformed value: d out / d in (0 where the clamp clipped).
    pub gain: Vec<f32>,
}

/// Transforms `img` (`c` interleaved channels) in place at the pixels `active`, drawing from
/// `rng`, then clamps those values to [0, 1].
pub fn apply(scene: &Scene, img: &mut [f32], c: usize, active: &[u32], rng: &mut Rng) -> EotTape {
    let n = active.len() * c;
    let mut gain = vec![1f32; n];
    let mut vals: Vec<f32> = active.iter().flat_map(|&p| img[p as usize * c..(p as usize + 1) * c].to_vec()).collect();
    for e in &scene.effects {
        match *e {
            Effect::Contrast { min, max, per } => {
                let mut once = None;
                for (v, g) in vals.iter_mut().zip(gain.iter_mut()) {
                    let f = draw(per, &mut once, || rng.uniform(min, max));
                    *v *= f;
                    *g *= f;
                }
            }
            Effect::Brightness { min, max, per } => {
                let mut once = None;
                for v in vals.iter_mut() {
                    *v += draw(per, &mut once, || rng.uniform(min, max));
                }
            }
            Effect::Noise { amplitude } => {
                for v in vals.iter_mut() {
                    *v += amplitude * rng.uniform(-1.0, 1.0);
                }
            }
            // Moves pixels, not values: `scene::zoom`, on the whole composite.
            Effect::Zoom { .. } => {}
        }
    }
    for (i, (v, g)) in vals.iter().zip(gain.iter_mut()).enumerate() {
        // A NaN from upstream must not survive the clamp as a plausible value.
        let clipped = !(0.0..=1.0).contains(v);
        let out = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
        if clipped {
            *g = 0.0;
        }
        let (p, k) = (active[i / c] as usize, i % c);
        img[p * c + k] = out;
    }
    EotTape { gain }
}

/// One draw per value, or the same draw for the whole image.
fn draw(per: Per, once: &mut Option<f32>, mut sample: impl FnMut() -> f32) -> f32 {
    match per {
        Per::Pixel => sample(),
        Per::Image => *once.get_or_insert_with(sample),
    }
}

/// Backward: `grad` at the `active` pixels is multiplied by the tape's gains.
pub fn backward(tape: &EotTape, grad: &mut [f32], c: usize, active: &[u32]) {
    for (i, g) in tape.gain.iter().enumerate() {
        grad[active[i / c] as usize * c + i % c] *= g;
    }
}

/// A scene's EoT at a view's textured pixels, as a step on the view's RGB composite.
pub struct Eot<'a> {
    /// The scene whose effects are drawn.
    pub scene: &'a Scene,
    /// The pixels transformed.
    pub active: &'a [u32],
    /// Pixels in the composite.
    pub pixels: usize,
}

impl Step for Eot<'_> {
    type Tape = EotTape;
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.pixels * 3
    }

    fn output_len(&self) -> usize {
        self.pixels * 3
    }

    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, EotTape), Self::Error> {
        let mut y = x.to_vec();
        let tape = apply(self.scene, &mut y, 3, self.active, rng);
        Ok((y, tape))
    }

    fn adjoint(&self, tape: &EotTape, gy: &[f32], gx: &mut [f32]) {
        let mut g = gy.to_vec();
        backward(tape, &mut g, 3, self.active);
        accumulate(gx, g);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(toml: &str) -> Scene {
        Scene::parse(toml, "t").unwrap()
    }

    #[test]
    fn no_effects_only_clamps_and_touches_only_active_pixels() {
        let mut img = vec![0.5, 1.3, -0.2, 0.7];
        let tape = apply(&Scene::default(), &mut img, 1, &[0, 1, 2], &mut Rng::new(1));
        assert_eq!(img, vec![0.5, 1.0, 0.0, 0.7]);
        assert_eq!(tape.gain, vec![1.0, 0.0, 0.0]);
    }

    #[test]
    fn authors_eot_stays_in_range_with_gain_matching_finite_differences() {
        let s = scene(
            "[[effects]]\nkind=\"contrast\"\nmin=0.8\nmax=1.2\n[[effects]]\nkind=\"brightness\"\nmin=-0.1\nmax=0.1\n[[effects]]\nkind=\"noise\"\namplitude=0.1\n",
        );
        let base: Vec<f32> = (0..300).map(|i| (i as f32 * 0.37).sin() * 0.5 + 0.5).collect();
        let active: Vec<u32> = (0..100).collect();
        let mut img = base.clone();
        let tape = apply(&s, &mut img, 3, &active, &mut Rng::new(9));
        assert!(img.iter().all(|v| (0.0..=1.0).contains(v)));
        // Same draws (same seed), input nudged: the output moves by gain·ε where nothing clipped.
        let eps = 1e-3;
        let mut nudged: Vec<f32> = base.iter().map(|v| v + eps).collect();
        apply(&s, &mut nudged, 3, &active, &mut Rng::new(9));
        for i in 0..300 {
            let fd = (nudged[i] - img[i]) / eps;
            if tape.gain[i] > 0.0 && img[i] > 0.01 && img[i] < 0.99 {
                assert!((fd - tape.gain[i]).abs() < 1e-2, "value {i}: fd {fd} gain {}", tape.gain[i]);
                assert!((0.8..=1.2).contains(&tape.gain[i]));
            }
        }
        let mut grad = vec![1.0; 300];
        backward(&tape, &mut grad, 3, &active);
        assert_eq!(grad, tape.gain);
    }

    #[test]
    fn per_image_draws_once_and_nan_input_is_caught() {
        let s = scene("[[effects]]\nkind=\"contrast\"\nmin=0.5\nmax=1.0\nper=\"image\"\n");
        let mut img = vec![0.4; 6];
        img[5] = f32::NAN;
        let tape = apply(&s, &mut img, 3, &[0, 1], &mut Rng::new(3));
        assert!(tape.gain[..5].iter().all(|g| *g == tape.gain[0]));
        assert_eq!((img[5], tape.gain[5]), (0.0, 0.0));
    }
}
