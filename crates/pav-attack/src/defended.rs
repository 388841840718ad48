//! Input defences inside a white box, so that an attack can adapt to them (Athalye et al. 2018):
//! the chain's float forward and backward, each defence's own (`pav_detect::defence::Unit`), as
//! one differentiable step.

use pav_core::rng::Rng;
use pav_core::step::accumulate;
use pav_detect::defence::{backward, forward, Defence, DefenceError, Tape};

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
        let tape = forward(self.chain, &mut y, self.side, None)?;
        Ok((y, tape))
    }

    fn adjoint(&self, tape: &Tape, gy: &[f32], gx: &mut [f32]) {
        let mut g = gy.to_vec();
        backward(tape, &mut g);
        accumulate(gx, g);
    }
}
