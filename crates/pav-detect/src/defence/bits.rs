//! Feature squeezing by bit depth (Xu et al.): every level rounded to the nearest of `2^b` evenly
//! spaced levels. Rounding has no useful gradient, so the backward passes it straight through
//! (BPDA, the default).

use super::{DefenceError, DefenceUnit, Gradient};
use pav_core::image::Frame;

/// Feature squeezing by bit depth: `2^b` levels per channel (`b` from 1 to 8).
#[derive(Clone, Debug, serde::Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Bits {
    /// Bits kept.
    pub b: u32,
}

impl DefenceUnit for Bits {
    fn check(&self, _: usize, _: usize) -> Result<(), String> {
        if !(1..=8).contains(&self.b) {
            return Err(format!("b = {} must be 1 to 8 bits", self.b));
        }
        Ok(())
    }

    fn label(&self) -> String {
        format!("bits{}", self.b)
    }

    /// `round(x · (2^b − 1)) / (2^b − 1)` on `x = v / 255`, back to a level.
    fn apply(&self, img: &mut Frame, _: u64) -> Result<(), DefenceError> {
        assert!((1..=8).contains(&self.b), "bit depth {} must be 1 to 8", self.b);
        let steps = ((1u32 << self.b) - 1) as f64;
        let table: [u8; 256] =
            std::array::from_fn(|v| (((v as f64 / 255.0) * steps).round() / steps * 255.0).round() as u8);
        for v in &mut img.bgr {
            *v = table[*v as usize];
        }
        Ok(())
    }

    /// The same levels on the float input, without the 8-bit rounding after them.
    fn forward(&self, x: &mut [f32], _: usize, _: u64) -> Result<Gradient, DefenceError> {
        let steps = ((1u32 << self.b) - 1) as f32;
        x.iter_mut().for_each(|v| *v = (*v * steps).round() / steps);
        Ok(Gradient::Straight)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_depth_keeps_2_to_the_bits_levels_and_eight_bits_changes_nothing() {
        let squeeze = |f: &mut Frame, b: u32| Bits { b }.apply(f, 0).unwrap();
        let orig = Frame { width: 256, height: 1, bgr: (0..768).map(|i| (i / 3) as u8).collect() };
        let mut f = orig.clone();
        squeeze(&mut f, 8);
        assert_eq!(f.bgr, orig.bgr);
        for bits in 1..8 {
            let mut g = orig.clone();
            squeeze(&mut g, bits);
            let mut levels = g.bgr.clone();
            levels.sort();
            levels.dedup();
            assert_eq!(levels.len(), 1 << bits, "{bits} bits");
            assert_eq!((levels[0], *levels.last().unwrap()), (0, 255));
        }
        let mut one = orig.clone();
        squeeze(&mut one, 1);
        assert_eq!((one.bgr[127 * 3], one.bgr[128 * 3]), (0, 255));
        // On the float input: two bits, four levels.
        let mut x: Vec<f32> = (0..300).map(|i| i as f32 / 299.0).collect();
        assert!(matches!(Bits { b: 2 }.forward(&mut x, 10, 0), Ok(Gradient::Straight)));
        assert!(x.iter().all(|v| [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0].iter().any(|l| (v - l).abs() < 1e-6)));
    }
}
