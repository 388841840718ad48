//! Differentiable steps: one forward/adjoint pair for every step of the texture-to-detector
//! chain (texture lookup, shading, the view's render, EoT, zoom, the texture pyramid, the print
//! colour map, resampling, the white box's input defences), the chain that composes them, and
//! the check every pair passes.

use crate::rng::Rng;
use std::any::Any;
use std::time::Instant;

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
    /// Where the car's box (xyxy pixels) in the step's input lands in its output. The default
    /// keeps it, which is right for a step that moves no pixel; a step that draws the car says
    /// where it is.
    fn map_box(&self, _tape: &Self::Tape, car: Option<[f32; 4]>) -> Option<[f32; 4]> {
        car
    }
}

impl<S: Step + ?Sized> Step for &S {
    type Tape = S::Tape;
    type Error = S::Error;
    fn input_len(&self) -> usize {
        (**self).input_len()
    }
    fn output_len(&self) -> usize {
        (**self).output_len()
    }
    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, Self::Tape), Self::Error> {
        (**self).forward(x, rng)
    }
    fn adjoint(&self, tape: &Self::Tape, gy: &[f32], gx: &mut [f32]) {
        (**self).adjoint(tape, gy, gx)
    }
    fn map_box(&self, tape: &Self::Tape, car: Option<[f32; 4]>) -> Option<[f32; 4]> {
        (**self).map_box(tape, car)
    }
}

/// Why a chain's forward pass failed: the stage, and its step's error.
#[derive(Debug, thiserror::Error)]
#[error("{stage}: {source}")]
pub struct ChainError {
    /// The stage's name.
    pub stage: &'static str,
    /// The step's error.
    pub source: Box<dyn std::error::Error + Send + Sync>,
}

/// One stage's time in one pass of a chain.
#[derive(Clone, Debug, PartialEq)]
pub struct StageTime {
    /// The stage's name.
    pub stage: &'static str,
    /// Its forward pass, ms.
    pub forward_ms: f64,
    /// Its adjoint, ms (0 until the adjoint has run).
    pub adjoint_ms: f64,
}

/// What a chain's adjoint needs from its forward pass: each stage's tape, and the stages' times.
pub struct ChainTape {
    tapes: Vec<Box<dyn Any>>,
    /// Each stage's time, in the chain's order.
    pub times: Vec<StageTime>,
}

impl ChainTape {
    /// The summed forward time of the stages named `stages`, ms.
    pub fn forward_ms(&self, stages: &[&str]) -> f64 {
        self.times.iter().filter(|t| stages.contains(&t.stage)).map(|t| t.forward_ms).sum()
    }

    /// The summed adjoint time of every stage, ms.
    pub fn adjoint_ms(&self) -> f64 {
        self.times.iter().map(|t| t.adjoint_ms).sum()
    }
}

/// A step with its tape kept as `Any` and its error boxed, so that steps of different kinds
/// form one chain.
trait Link {
    fn stage(&self) -> &'static str;
    fn input_len(&self) -> usize;
    fn output_len(&self) -> usize;
    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, Box<dyn Any>), ChainError>;
    fn adjoint(&self, tape: &dyn Any, gy: &[f32], gx: &mut [f32]);
    fn map_box(&self, tape: &dyn Any, car: Option<[f32; 4]>) -> Option<[f32; 4]>;
}

struct Named<S> {
    stage: &'static str,
    step: S,
}

impl<S: Step> Named<S>
where
    S::Tape: 'static,
{
    fn tape<'t>(&self, tape: &'t dyn Any) -> &'t S::Tape {
        tape.downcast_ref().unwrap_or_else(|| panic!("{}: a tape from another step", self.stage))
    }
}

impl<S: Step> Link for Named<S>
where
    S::Tape: 'static,
    S::Error: Send + Sync + 'static,
{
    fn stage(&self) -> &'static str {
        self.stage
    }
    fn input_len(&self) -> usize {
        self.step.input_len()
    }
    fn output_len(&self) -> usize {
        self.step.output_len()
    }
    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, Box<dyn Any>), ChainError> {
        let (y, tape) = self.step.forward(x, rng).map_err(|e| ChainError { stage: self.stage, source: Box::new(e) })?;
        Ok((y, Box::new(tape)))
    }
    fn adjoint(&self, tape: &dyn Any, gy: &[f32], gx: &mut [f32]) {
        self.step.adjoint(self.tape(tape), gy, gx)
    }
    fn map_box(&self, tape: &dyn Any, car: Option<[f32; 4]>) -> Option<[f32; 4]> {
        self.step.map_box(self.tape(tape), car)
    }
}

/// Steps composed in order, each stage named and timed: itself a [`Step`] from the first
/// stage's input to the last one's output, whose adjoint runs the stages' adjoints in reverse.
#[derive(Default)]
pub struct Chain<'a> {
    links: Vec<Box<dyn Link + 'a>>,
}

impl<'a> Chain<'a> {
    /// A chain without stages: the identity.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends `step` as the stage `stage`.
    pub fn then<S: Step + 'a>(mut self, stage: &'static str, step: S) -> Self
    where
        S::Tape: 'static,
        S::Error: Send + Sync + 'static,
    {
        self.push(stage, step);
        self
    }

    /// Appends `step` as the stage `stage`.
    pub fn push<S: Step + 'a>(&mut self, stage: &'static str, step: S)
    where
        S::Tape: 'static,
        S::Error: Send + Sync + 'static,
    {
        self.append(Box::new(Named { stage, step }));
    }

    /// This chain followed by the stages of `rest`.
    pub fn and(mut self, rest: Chain<'a>) -> Self {
        rest.links.into_iter().for_each(|l| self.append(l));
        self
    }

    /// Appends `link`, which must read what the last stage writes.
    fn append(&mut self, link: Box<dyn Link + 'a>) {
        if let Some(last) = self.links.last() {
            let (out, inp) = (last.output_len(), link.input_len());
            assert_eq!(out, inp, "stage {} reads {inp} values, stage {} writes {out}", link.stage(), last.stage());
        }
        self.links.push(link);
    }

    /// The stages' names, in order.
    pub fn stages(&self) -> Vec<&'static str> {
        self.links.iter().map(|l| l.stage()).collect()
    }
}

impl Step for Chain<'_> {
    type Tape = ChainTape;
    type Error = ChainError;

    fn input_len(&self) -> usize {
        self.links.first().map_or(0, |l| l.input_len())
    }

    fn output_len(&self) -> usize {
        self.links.last().map_or(0, |l| l.output_len())
    }

    fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, ChainTape), ChainError> {
        let mut tape = ChainTape { tapes: Vec::with_capacity(self.links.len()), times: Vec::new() };
        // The first stage reads `x` itself; each later one what the stage before it wrote.
        let mut y: Option<Vec<f32>> = None;
        for link in &self.links {
            let t = Instant::now();
            let (next, tp) = link.forward(y.as_deref().unwrap_or(x), rng)?;
            let forward_ms = t.elapsed().as_secs_f64() * 1e3;
            tape.times.push(StageTime { stage: link.stage(), forward_ms, adjoint_ms: 0.0 });
            tape.tapes.push(tp);
            y = Some(next);
        }
        Ok((y.unwrap_or_else(|| x.to_vec()), tape))
    }

    fn adjoint(&self, tape: &ChainTape, gy: &[f32], gx: &mut [f32]) {
        self.backward(&tape.tapes, gy, gx);
    }

    fn map_box(&self, tape: &ChainTape, car: Option<[f32; 4]>) -> Option<[f32; 4]> {
        self.links.iter().zip(&tape.tapes).fold(car, |b, (link, tp)| link.map_box(tp.as_ref(), b))
    }
}

impl Chain<'_> {
    /// [`Step::adjoint`], recording each stage's adjoint time in `tape`.
    pub fn adjoint_timed(&self, tape: &mut ChainTape, gy: &[f32], gx: &mut [f32]) {
        let ms = self.backward(&tape.tapes, gy, gx);
        tape.times.iter_mut().zip(ms).for_each(|(t, ms)| t.adjoint_ms = ms);
    }

    /// The stages' adjoints in reverse, each adding into a zeroed buffer the size of its input
    /// and the first into `gx`; returns each stage's time, ms.
    fn backward(&self, tapes: &[Box<dyn Any>], gy: &[f32], gx: &mut [f32]) -> Vec<f64> {
        let mut ms = vec![0.0; self.links.len()];
        if self.links.is_empty() {
            accumulate(gx, gy.iter().copied());
            return ms;
        }
        // The last stage reads `gy` itself; each earlier one what the stage after it wrote.
        let mut g: Option<Vec<f32>> = None;
        for (i, (link, tp)) in self.links.iter().zip(tapes).enumerate().rev() {
            let t = Instant::now();
            let above = g.as_deref().unwrap_or(gy);
            if i == 0 {
                link.adjoint(tp.as_ref(), above, gx);
            } else {
                let mut below = vec![0f32; link.input_len()];
                link.adjoint(tp.as_ref(), above, &mut below);
                g = Some(below);
            }
            ms[i] = t.elapsed().as_secs_f64() * 1e3;
        }
        ms
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `y = a·x` on `n` values, with a box that scales by `a` too.
    struct Scale(f32, usize);

    impl Step for Scale {
        type Tape = ();
        type Error = std::convert::Infallible;
        fn input_len(&self) -> usize {
            self.1
        }
        fn output_len(&self) -> usize {
            self.1
        }
        fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
            Ok((x.iter().map(|v| v * self.0).collect(), ()))
        }
        fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
            accumulate(gx, gy.iter().map(|g| g * self.0));
        }
        fn map_box(&self, _: &(), car: Option<[f32; 4]>) -> Option<[f32; 4]> {
            car.map(|b| b.map(|v| v * self.0))
        }
    }

    /// `y = x²` value by value, failing on a negative input.
    struct Square(usize);

    #[derive(Debug, thiserror::Error)]
    #[error("negative input")]
    struct Negative;

    impl Step for Square {
        type Tape = Vec<f32>;
        type Error = Negative;
        fn input_len(&self) -> usize {
            self.0
        }
        fn output_len(&self) -> usize {
            self.0
        }
        fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, Vec<f32>), Negative> {
            if x.iter().any(|v| *v < 0.0) {
                return Err(Negative);
            }
            Ok((x.iter().map(|v| v * v).collect(), x.to_vec()))
        }
        fn adjoint(&self, x: &Vec<f32>, gy: &[f32], gx: &mut [f32]) {
            accumulate(gx, gy.iter().zip(x).map(|(g, v)| 2.0 * v * g));
        }
    }

    #[test]
    fn a_chain_composes_forward_adjoint_and_box_in_order() {
        let c = Chain::new().then("double", Scale(2.0, 3)).then("square", Square(3)).then("halve", Scale(0.5, 3));
        assert_eq!(c.stages(), ["double", "square", "halve"]);
        let (y, mut tape) = c.forward(&[1.0, 2.0, 3.0], &mut Rng::new(1)).unwrap();
        // (2x)²/2 = 2x², whose derivative is 4x.
        assert_eq!(y, [2.0, 8.0, 18.0]);
        let mut gx = vec![1.0; 3];
        c.adjoint_timed(&mut tape, &[1.0, 1.0, 1.0], &mut gx);
        assert_eq!(gx, [5.0, 9.0, 13.0], "the adjoint adds into gx");
        assert_eq!(tape.times.len(), 3);
        assert_eq!(c.map_box(&tape, Some([1.0, 2.0, 3.0, 4.0])), Some([1.0, 2.0, 3.0, 4.0]));
        let a = agreement(&c, &[0.3, 0.7, 1.1], 3, 1e-3, 3).unwrap();
        assert!(a.identity < 1e-3 && a.coordinates < 1e-2, "{a:?}");
        // Chains join, and an empty chain is the identity.
        let joined = Chain::new().then("double", Scale(2.0, 3)).and(Chain::new().then("double", Scale(2.0, 3)));
        assert_eq!(joined.forward(&[1.0, 0.0, -1.0], &mut Rng::new(1)).unwrap().0, [4.0, 0.0, -4.0]);
        let (y, tape) = Chain::new().forward(&[1.0, 2.0], &mut Rng::new(1)).unwrap();
        let mut gx = vec![0.0; 2];
        Chain::new().adjoint(&tape, &[3.0, 4.0], &mut gx);
        assert_eq!((y, gx), (vec![1.0, 2.0], vec![3.0, 4.0]));
    }

    #[test]
    fn a_failing_stage_is_named() {
        let c = Chain::new().then("shift", Scale(-1.0, 2)).then("square", Square(2));
        let e = c.forward(&[1.0, 2.0], &mut Rng::new(1)).err().unwrap();
        assert_eq!(e.to_string(), "square: negative input");
        assert!(e.source.downcast::<Negative>().is_ok());
    }

    #[test]
    #[should_panic(expected = "stage square reads 2 values, stage double writes 3")]
    fn stages_that_do_not_fit_are_refused() {
        let _ = Chain::new().then("double", Scale(2.0, 3)).then("square", Square(2));
    }
}
