//! A small seedable generator (SplitMix64): reproducible EoT draws and random textures whose
//! whole state is one `u64`, so a checkpoint can store it and a resumed run draws the same.

/// SplitMix64.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rng {
    /// The full generator state.
    pub state: u64,
}

impl Rng {
    /// A generator from `seed`.
    pub fn new(seed: u64) -> Self {
        Rng { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1) with 24 random bits.
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// Standard normal (Box–Muller on two uniform draws).
    pub fn normal(&mut self) -> f32 {
        let u = 1.0 - self.unit() as f64; // in (0, 1], so the logarithm is finite
        let v = self.unit() as f64;
        ((-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32
    }
}

/// FNV-1a over 64-bit items (bytes, or values' bits): a fast hash that is the same on every
/// build and release (the standard library's is not), to seed a draw from what it draws for.
pub fn fnv1a(items: impl IntoIterator<Item = u64>) -> u64 {
    items.into_iter().fold(0xcbf2_9ce4_8422_2325, |h, v| (h ^ v).wrapping_mul(0x0000_0100_0000_01b3))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproducible_and_roughly_uniform() {
        let (mut a, mut b) = (Rng::new(7), Rng::new(7));
        let xs: Vec<f32> = (0..10_000).map(|_| a.unit()).collect();
        assert!(xs.iter().zip((0..10_000).map(|_| b.unit())).all(|(x, y)| *x == y));
        assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        let mean = xs.iter().sum::<f32>() / xs.len() as f32;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        let below = xs.iter().filter(|x| **x < 0.1).count();
        assert!((900..1100).contains(&below), "{below}");
    }

    #[test]
    fn normal_draws_have_unit_variance_and_gaussian_tails() {
        let mut r = Rng::new(11);
        let n = 1_000_000;
        let z: Vec<f64> = (0..n).map(|_| r.normal() as f64).collect();
        let mean = z.iter().sum::<f64>() / n as f64;
        let var = z.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        let kurt = z.iter().map(|x| (x - mean).powi(4)).sum::<f64>() / n as f64 / (var * var);
        let beyond2 = z.iter().filter(|x| x.abs() > 2.0).count() as f64 / n as f64;
        assert!(mean.abs() < 0.005 && (var - 1.0).abs() < 0.005, "mean {mean}, variance {var}");
        assert!((kurt - 3.0).abs() < 0.03, "kurtosis {kurt}");
        assert!((beyond2 - 0.0455).abs() < 0.001, "P(|z| > 2) = {beyond2}");
    }
}
