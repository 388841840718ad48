//! The smoothing loss L_s: squared differences of vertically and horizontally neighbouring
//! texels, over all channels, either divided by the texel count (the authors' code) or summed
//! (the paper's Eq. 12, which grows with the texture size, so its γ must shrink with it).

/// How the squared differences are normalized.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SmoothNorm {
    /// Divided by the texel count (the authors' code).
    #[default]
    Mean,
    /// A plain sum (the paper's Eq. 12).
    Sum,
}

/// L_s of a `w × h` RGB interleaved texture, adding `weight·∂L_s/∂tex` into `grad`.
pub fn smoothness(tex: &[f32], w: usize, h: usize, norm: SmoothNorm, weight: f32, grad: &mut [f32]) -> f64 {
    let n = match norm {
        SmoothNorm::Mean => (w * h) as f64,
        SmoothNorm::Sum => 1.0,
    };
    let mut sum = 0f64;
    let mut pair = |a: usize, b: usize, grad: &mut [f32]| {
        let d = tex[a] - tex[b];
        sum += (d * d) as f64;
        let g = (2.0 * weight as f64 * d as f64 / n) as f32;
        grad[a] += g;
        grad[b] -= g;
    };
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let i = (y * w + x) * 3 + c;
                if x + 1 < w {
                    pair(i, i + 3, grad);
                }
                if y + 1 < h {
                    pair(i, i + w * 3, grad);
                }
            }
        }
    }
    sum / n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_is_zero_and_gradient_matches_finite_differences() {
        let (w, h) = (5, 4);
        let mut g = vec![0.0; w * h * 3];
        assert_eq!(smoothness(&vec![0.3; w * h * 3], w, h, SmoothNorm::Mean, 1.0, &mut g), 0.0);
        assert!(g.iter().all(|v| *v == 0.0));
        let tex: Vec<f32> = (0..w * h * 3).map(|i| ((i * 7919) % 97) as f32 / 97.0).collect();
        // One vertical step of 1 between two rows of a 2×2 one-value-per-channel texture: 2 pairs × 3 channels.
        let step: Vec<f32> = [0.0, 0.0, 1.0, 1.0].iter().flat_map(|v| [*v; 3]).collect();
        assert_eq!(smoothness(&step, 2, 2, SmoothNorm::Mean, 1.0, &mut [0.0; 12]), 6.0 / 4.0);
        assert_eq!(smoothness(&step, 2, 2, SmoothNorm::Sum, 1.0, &mut [0.0; 12]), 6.0);
        for norm in [SmoothNorm::Mean, SmoothNorm::Sum] {
            let mut grad = vec![0.0; tex.len()];
            let l0 = smoothness(&tex, w, h, norm, 1.0, &mut grad);
            assert!(l0 > 0.0);
            for i in [0, 7, 31, 59] {
                let eps = 1e-3;
                let (mut p, mut m) = (tex.clone(), tex.clone());
                p[i] += eps;
                m[i] -= eps;
                let mut scratch = vec![0.0; tex.len()];
                let fd = (smoothness(&p, w, h, norm, 1.0, &mut scratch)
                    - smoothness(&m, w, h, norm, 1.0, &mut scratch))
                    / (2.0 * eps as f64);
                assert!((fd - grad[i] as f64).abs() < 1e-3 * (1.0 + fd.abs()), "{norm:?} {i}: fd {fd} vs {}", grad[i]);
            }
        }
    }
}
