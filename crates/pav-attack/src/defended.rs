//! Input defences inside a white box, so that an attack can adapt to them (Athalye et al. 2018):
//! each works on the float model input as its 8-bit counterpart does on frames, with a backward
//! that is exact where the defence is differentiable (median smoothing routes each gradient to
//! the sample it picked; cutout stops it in the holes) and passes the gradient straight through
//! where it is not (BPDA: bit depth, JPEG, the rounding and clamping of noise). Random defences
//! draw afresh for every image, so training through them is Expectation over Transformation.

use pav_core::image::{filter, Frame};
use pav_core::rng::{fnv1a, Rng};
use pav_core::step::accumulate;
use pav_detect::defence::{Defence, DefenceError};

/// What a chain's backward needs from its forward, one entry per defence.
#[derive(Clone, Debug, Default)]
pub struct Tape(Vec<Step>);

#[derive(Clone, Debug)]
enum Step {
    /// The gradient passes unchanged.
    Straight,
    /// Each output sample's gradient goes to the input sample it copied.
    Gather(Vec<u32>),
    /// The gradient stops where the mask is set.
    Stop(Vec<bool>),
}

/// Applies the input defences of `chain` to `x`, three planes of `side × side` values in [0, 1]
/// (R, G, B), in order; model-side defences are skipped (the graph carries them).
fn forward(chain: &[Defence], x: &mut [f32], side: usize) -> Result<Tape, DefenceError> {
    forward_drawn(chain, x, side, None)
}

/// [`forward`] with every random defence drawing from `draw` instead of the image's hash.
fn forward_drawn(chain: &[Defence], x: &mut [f32], side: usize, draw: Option<u64>) -> Result<Tape, DefenceError> {
    let mut tape = Tape::default();
    for d in chain.iter().filter(|d| d.on_input()) {
        let draw = if d.random() { draw.unwrap_or_else(|| fnv1a(x.iter().map(|v| v.to_bits() as u64))) } else { 0 };
        tape.0.push(match *d {
            Defence::Median { k } => Step::Gather(median(x, side, k)),
            Defence::Bits { b } => {
                let steps = ((1u32 << b) - 1) as f32;
                x.iter_mut().for_each(|v| *v = (*v * steps).round() / steps);
                Step::Straight
            }
            Defence::Jpeg { .. } => {
                let mut f = to_frame(x, side);
                d.apply(&mut f, 0)?;
                from_frame(&f, x);
                Step::Straight
            }
            Defence::Cutout { n, s, fill, seed } => {
                let holes = filter::cutout_holes(side, side, n, s, &mut Rng::new(seed ^ draw));
                let mut mask = vec![false; side * side];
                for &[x0, y0, x1, y1] in &holes {
                    for y in y0..y1 {
                        mask[y * side + x0..y * side + x1].fill(true);
                    }
                }
                for plane in x.chunks_exact_mut(side * side) {
                    plane.iter_mut().zip(&mask).filter(|(_, m)| **m).for_each(|(v, _)| *v = fill as f32 / 255.0);
                }
                Step::Stop(mask)
            }
            Defence::Noise { sigma, seed } => {
                let mut rng = Rng::new(seed ^ draw);
                x.iter_mut().for_each(|v| *v = (*v + sigma / 255.0 * rng.normal()).clamp(0.0, 1.0));
                Step::Straight
            }
            Defence::Clip { .. } => unreachable!("model-side defences are filtered out above"),
        });
    }
    Ok(tape)
}

/// The gradient with respect to the chain's input from the gradient `g` of its output.
fn backward(tape: &Tape, g: &mut Vec<f32>) {
    for step in tape.0.iter().rev() {
        match step {
            Step::Straight => {}
            Step::Gather(from) => {
                let mut out = vec![0f32; g.len()];
                for (i, &j) in from.iter().enumerate() {
                    out[j as usize] += g[i];
                }
                *g = out;
            }
            Step::Stop(mask) => {
                for plane in g.chunks_exact_mut(mask.len()) {
                    plane.iter_mut().zip(mask).filter(|(_, m)| **m).for_each(|(v, _)| *v = 0.0);
                }
            }
        }
    }
}

/// The input defences of a chain on a `side × side` planar RGB model input, as a step. Its
/// adjoint is exact for median smoothing and cutout; the others pass the gradient straight
/// through (BPDA), which no finite difference confirms.
pub struct Defended<'a> {
    /// The chain (model-side defences are skipped).
    pub chain: &'a [Defence],
    /// The input's side.
    pub side: usize,
}

impl pav_core::step::Step for Defended<'_> {
    type Tape = Tape;
    type Error = DefenceError;

    fn input_len(&self) -> usize {
        3 * self.side * self.side
    }

    fn output_len(&self) -> usize {
        3 * self.side * self.side
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, Tape), DefenceError> {
        let mut y = x.to_vec();
        let tape = forward(self.chain, &mut y, self.side)?;
        Ok((y, tape))
    }

    fn adjoint(&self, tape: &Tape, gy: &[f32], gx: &mut [f32]) {
        let mut g = gy.to_vec();
        backward(tape, &mut g);
        accumulate(gx, g);
    }
}

/// Median of each `k × k` window per plane (border replicated), in place; returns, for each
/// sample, the index of the input sample that is its median.
fn median(x: &mut [f32], side: usize, k: usize) -> Vec<u32> {
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

/// Planar RGB in [0, 1] as an 8-bit BGR frame.
fn to_frame(x: &[f32], side: usize) -> Frame {
    let plane = side * side;
    let bgr = (0..plane).flat_map(|i| [2, 1, 0].map(|c| (x[c * plane + i] * 255.0).round().clamp(0.0, 255.0) as u8));
    Frame { width: side, height: side, bgr: bgr.collect() }
}

/// An 8-bit BGR frame back into planar RGB in [0, 1].
fn from_frame(f: &Frame, x: &mut [f32]) {
    let plane = f.width * f.height;
    for (i, px) in f.bgr.chunks_exact(3).enumerate() {
        for (c, &v) in [2, 1, 0].iter().zip(px) {
            x[c * plane + i] = v as f32 / 255.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planes(side: usize, seed: u64) -> Vec<f32> {
        let mut rng = Rng::new(seed);
        (0..3 * side * side).map(|_| rng.unit()).collect()
    }

    /// Σ w·defended(x) and its gradient, against central differences (median smoothing and
    /// cutout are piecewise linear: away from ties, the differences are exact).
    #[test]
    fn median_and_cutout_backward_match_finite_differences() {
        let side = 9;
        for chain in [
            vec![Defence::Median { k: 3 }],
            vec![Defence::Cutout { n: 2, s: 4, fill: 127, seed: 1 }],
            vec![Defence::Median { k: 5 }, Defence::Cutout { n: 1, s: 3, fill: 0, seed: 2 }],
        ] {
            let x = planes(side, 3);
            let w = planes(side, 4);
            // The draw held fixed: the derivative of one sampled transformation.
            let run = |x: &[f32]| -> (Vec<f32>, Tape) {
                let mut y = x.to_vec();
                let t = forward_drawn(&chain, &mut y, side, Some(7)).unwrap();
                (y, t)
            };
            let f = |x: &[f32]| -> f64 { run(x).0.iter().zip(&w).map(|(a, b)| *a as f64 * *b as f64).sum() };
            let tape = run(&x).1;
            let mut g = w.clone();
            backward(&tape, &mut g);
            let eps = 1e-3f32;
            let mut checked = 0;
            for i in (0..x.len()).step_by(7) {
                let (mut p, mut q) = (x.clone(), x.clone());
                p[i] += eps;
                q[i] -= eps;
                let same = |t: Tape| format!("{t:?}") == format!("{tape:?}");
                if !same(run(&p).1) || !same(run(&q).1) {
                    continue; // another sample became a median: not this point's derivative
                }
                let fd = (f(&p) - f(&q)) / (2.0 * eps as f64);
                assert!((fd as f32 - g[i]).abs() < 1e-3, "{chain:?} sample {i}: {} vs {fd}", g[i]);
                checked += 1;
            }
            assert!(checked > 20, "{chain:?}: only {checked} samples kept their draw and medians");
        }
    }

    #[cfg(feature = "video")]
    #[test]
    fn straight_through_defences_pass_the_gradient_and_change_the_forward() {
        let side = 16;
        let x = planes(side, 5);
        for d in [Defence::Bits { b: 2 }, Defence::Jpeg { q: 20 }, Defence::Noise { sigma: 10.0, seed: 0 }] {
            let mut y = x.clone();
            let tape = forward(std::slice::from_ref(&d), &mut y, side).unwrap();
            assert!(y.iter().zip(&x).any(|(a, b)| (a - b).abs() > 0.01), "{d:?} changed nothing");
            let mut g = x.clone();
            backward(&tape, &mut g);
            assert_eq!(g, x);
        }
        // Two bits: four levels.
        let mut y = x.clone();
        forward(&[Defence::Bits { b: 2 }], &mut y, side).unwrap();
        assert!(y.iter().all(|v| [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0].iter().any(|l| (v - l).abs() < 1e-6)));
    }

    /// The float median agrees with the 8-bit one on 8-bit levels.
    #[test]
    fn float_median_matches_the_frame_median() {
        let side = 12;
        let x: Vec<f32> = planes(side, 6).iter().map(|v| (v * 255.0).round() / 255.0).collect();
        let mut y = x.clone();
        forward(&[Defence::Median { k: 5 }], &mut y, side).unwrap();
        let mut f = to_frame(&x, side);
        filter::median(&mut f, 5);
        let mut z = vec![0f32; x.len()];
        from_frame(&f, &mut z);
        assert!(y.iter().zip(&z).all(|(a, b)| (a - b).abs() < 1e-6));
    }
}
