//! Adam on the texture, restricted to the optimizable texels and projected back into range.

use serde::{Deserialize, Serialize};

/// Adam state for one parameter vector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    /// Learning rate.
    pub lr: f32,
    /// First-moment decay.
    pub beta1: f32,
    /// Second-moment decay.
    pub beta2: f32,
    /// Denominator guard.
    pub eps: f32,
    /// Steps taken.
    pub t: u64,
    /// First moments.
    pub m: Vec<f32>,
    /// Second moments.
    pub v: Vec<f32>,
}

impl Adam {
    /// Fresh state for `n` parameters (PyTorch's defaults β = (0.9, 0.999), ε = 1e-8).
    pub fn new(n: usize, lr: f32) -> Self {
        Adam { lr, beta1: 0.9, beta2: 0.999, eps: 1e-8, t: 0, m: vec![0.0; n], v: vec![0.0; n] }
    }

    /// One step on the entries `idx` of `x`, then clamps them to `[lo, hi]` (the entries outside
    /// `idx` are neither read nor moved, and their moments stay zero).
    pub fn step(&mut self, x: &mut [f32], grad: &[f32], idx: &[u32], (lo, hi): (f32, f32)) {
        self.t += 1;
        let bc1 = 1.0 - (self.beta1 as f64).powi(self.t as i32);
        let bc2 = 1.0 - (self.beta2 as f64).powi(self.t as i32);
        let step = (self.lr as f64 / bc1) as f32;
        let bc2_sqrt = bc2.sqrt() as f32;
        for &i in idx {
            let i = i as usize;
            let g = grad[i];
            self.m[i] = self.beta1 * self.m[i] + (1.0 - self.beta1) * g;
            self.v[i] = self.beta2 * self.v[i] + (1.0 - self.beta2) * g * g;
            let denom = self.v[i].sqrt() / bc2_sqrt + self.eps;
            x[i] = (x[i] - step * self.m[i] / denom).clamp(lo, hi);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_lr_and_reaches_a_quadratic_minimum_inside_the_box() {
        // Adam's first step is lr·sign(g) whatever the gradient's size.
        let mut a = Adam::new(3, 0.01);
        let mut x = vec![0.5, 0.5, 0.5];
        a.step(&mut x, &[1e-3, -3.0, 100.0], &[0, 1], (0.0, 1.0));
        assert!((x[0] - 0.49).abs() < 1e-6 && (x[1] - 0.51).abs() < 1e-6 && x[2] == 0.5, "{x:?}");
        // Minimize (x − 0.3)² and (y − 2)²: x reaches 0.3, y stops at the bound 1 − 1e-4.
        let mut a = Adam::new(2, 0.05);
        let mut x = vec![0.9, 0.1];
        for _ in 0..500 {
            let g = [2.0 * (x[0] - 0.3), 2.0 * (x[1] - 2.0)];
            a.step(&mut x, &g, &[0, 1], (1e-4, 1.0 - 1e-4));
        }
        assert!((x[0] - 0.3).abs() < 1e-3, "{x:?}");
        assert_eq!(x[1], 1.0 - 1e-4);
    }
}
