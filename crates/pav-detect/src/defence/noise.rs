//! Gaussian noise on the input (randomized smoothing's draw, without its vote). The rounding and
//! clamping have no useful gradient, so the backward passes it straight through (the default).

use super::{DefenceError, DefenceUnit, Gradient};
use pav_core::image::Frame;
use pav_core::rng::Rng;

/// Gaussian noise of standard deviation `sigma` levels (0–255 scale).
#[derive(Clone, Debug, serde::Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// Standard deviation in levels.
    pub sigma: f32,
    /// Seed of the draws (mixed with the image, as for cutout).
    #[serde(default)]
    pub seed: u64,
}

impl DefenceUnit for Noise {
    fn check(&self, _: usize, _: usize) -> Result<(), String> {
        let sigma = self.sigma;
        if !(sigma.is_finite() && sigma > 0.0 && sigma <= 255.0) {
            return Err(format!("sigma = {sigma} must be a level in (0, 255]"));
        }
        Ok(())
    }

    fn label(&self) -> String {
        let seeded = if self.seed == 0 { String::new() } else { format!("s{}", self.seed) };
        format!("noise{}{seeded}", self.sigma)
    }

    fn random(&self) -> bool {
        true
    }

    /// Independent noise on every sample, rounded and clamped to a byte.
    fn apply(&self, img: &mut Frame, draw: u64) -> Result<(), DefenceError> {
        let mut rng = Rng::new(self.seed ^ draw);
        for v in &mut img.bgr {
            *v = (*v as f32 + self.sigma * rng.normal()).round().clamp(0.0, 255.0) as u8;
        }
        Ok(())
    }

    /// The same noise on the float input, clamped to [0, 1] but not rounded.
    fn forward(&self, x: &mut [f32], _: usize, draw: u64) -> Result<Gradient, DefenceError> {
        let mut rng = Rng::new(self.seed ^ draw);
        x.iter_mut().for_each(|v| *v = (*v + self.sigma / 255.0 * rng.normal()).clamp(0.0, 1.0));
        Ok(Gradient::Straight)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_has_the_asked_spread_and_no_bias_away_from_the_clamps() {
        let mut f = Frame { width: 200, height: 200, bgr: vec![128; 120_000] };
        Noise { sigma: 10.0, seed: 1 }.apply(&mut f, 0).unwrap();
        let d: Vec<f64> = f.bgr.iter().map(|&v| v as f64 - 128.0).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
        assert!(mean.abs() < 0.1, "{mean}");
        // Rounding adds a uniform ±0.5 level: variance 100 + 1/12.
        assert!((sd - (100.0f64 + 1.0 / 12.0).sqrt()).abs() < 0.1, "{sd}");
    }
}
