//! Differentiable steps: one forward/adjoint pair for every step of the texture-to-detector
//! chain (texture lookup, shading, the view's render, EoT, zoom, the texture pyramid, the print
//! colour map, resampling, the white box's input defences), and the check every pair passes.

use crate::rng::Rng;

/// A step `y = f(x)` with the exact adjoint of its Jacobian at the point its forward pass was
/// taken.
pub trait Step {
    /// What the adjoint needs from the forward pass (the draws of a random step, the input of a
    /// non-linear one).
    type Tape;
    /// Why a forward pass can fail.
    type Error: std::error::Error;
    /// Values the step reads.
    fn input_len(&self) -> usize;
    /// Values the step writes.
    fn output_len(&self) -> usize;
    /// `y = f(x)`; a random step draws from `rng`.
    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, Self::Tape), Self::Error>;
    /// Adds `Jᵀ·gy` into `gx`.
    fn adjoint(&self, tape: &Self::Tape, gy: &[f32], gx: &mut [f32]);
}

/// Adds `g` into `gx` value by value: how an adjoint accumulates a gradient it computed apart.
pub fn accumulate(gx: &mut [f32], g: impl IntoIterator<Item = f32>) {
    gx.iter_mut().zip(g).for_each(|(a, b)| *a += b);
}

/// How closely a step's adjoint agrees with its forward pass (relative errors).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Agreement {
    /// The dot-product identity `⟨J·d, g⟩ = ⟨d, Jᵀ·g⟩` along a random direction `d` for a random
    /// output gradient `g`, `J·d` by central differences.
    pub identity: f64,
    /// The worst per-coordinate error of `Jᵀ·g` against central differences of `⟨f(x), g⟩`, over
    /// the coordinates with the largest adjoint and a few drawn at random; relative to the
    /// adjoint's largest value.
    pub coordinates: f64,
}

fn dot(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum()
}

/// Checks `step` at `x`: every forward pass draws from `Rng::new(seed)`, so a random step is
/// differentiated at one draw; `eps` is the finite-difference step, `coords` how many
/// coordinates are checked one by one.
pub fn agreement<S: Step>(step: &S, x: &[f32], seed: u64, eps: f32, coords: usize) -> Result<Agreement, S::Error> {
    assert_eq!(x.len(), step.input_len(), "x has {} values, the step reads {}", x.len(), step.input_len());
    let mut draw = Rng::new(seed ^ 0x5eed);
    let d: Vec<f32> = (0..x.len()).map(|_| draw.uniform(-1.0, 1.0)).collect();
    let g: Vec<f32> = (0..step.output_len()).map(|_| draw.uniform(-1.0, 1.0)).collect();
    let (y, tape) = step.forward(x, &mut Rng::new(seed))?;
    assert_eq!(y.len(), step.output_len(), "the forward wrote {} values, the step says {}", y.len(), step.output_len());
    let mut adj = vec![0f32; x.len()];
    step.adjoint(&tape, &g, &mut adj);
    let along = |s: f32| -> Result<f64, S::Error> {
        let moved: Vec<f32> = x.iter().zip(&d).map(|(x, d)| x + s * d).collect();
        Ok(dot(&step.forward(&moved, &mut Rng::new(seed))?.0, &g))
    };
    let jd = (along(eps)? - along(-eps)?) / (2.0 * eps as f64);
    let dja = dot(&d, &adj);
    let identity = (jd - dja).abs() / jd.abs().max(dja.abs()).max(1e-12);
    let scale = adj.iter().fold(0f32, |m, v| m.max(v.abs())) as f64;
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|a, b| adj[*b].abs().total_cmp(&adj[*a].abs()));
    let mut picked: Vec<usize> = order.into_iter().take(coords.div_ceil(2)).collect();
    picked.extend((0..coords / 2).map(|_| (draw.next_u64() % x.len() as u64) as usize));
    let mut coordinates = 0f64;
    for k in picked {
        let at = |s: f32| -> Result<f64, S::Error> {
            let mut moved = x.to_vec();
            moved[k] += s;
            Ok(dot(&step.forward(&moved, &mut Rng::new(seed))?.0, &g))
        };
        let fd = (at(eps)? - at(-eps)?) / (2.0 * eps as f64);
        coordinates = coordinates.max((fd - adj[k] as f64).abs() / scale.max(1e-12));
    }
    Ok(Agreement { identity, coordinates })
}
