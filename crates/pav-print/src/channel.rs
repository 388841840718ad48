//! The print channel of an optimization: the soft proof sampled into a [`Lut3`] whose first three
//! channels are the printed colour and whose fourth is how far printing moves that colour
//! (ΔE2000), so one trilinear lookup and its adjoint give both the render's input and the gamut term.
use pav_core::rng::Rng;
use pav_core::step::Step;

use super::fit::Calibration;
use super::lut::Lut3;
use super::proof::{ProofError, RenderingIntent, SoftProof, DEFAULT_PROFILE};
use pav_core::colour::{delta_e2000_srgb, spread};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// `[print]` in an optimize config: the texture is seen by the detectors as this printer prints it.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PrintConfig {
    /// The printer's ICC output profile (default: Ghostscript's `default_cmyk.icc`).
    #[serde(default = "default_profile")]
    pub profile: PathBuf,
    /// Rendering intent of the way to the printer.
    #[serde(default)]
    pub intent: RenderingIntent,
    /// LittleCMS's black-point compensation on the way to the printer.
    #[serde(default)]
    pub black_point_compensation: bool,
    /// Nodes per axis of the sampled proof (the LUT has `lut_size³` nodes).
    #[serde(default = "lut_size")]
    pub lut_size: usize,
    /// Weight of the gamut term: the mean ΔE2000 over the region between a texel and its proof.
    #[serde(default)]
    pub gamut_weight: f32,
    /// A `pav print calibrate` file: its fitted map (printer + camera, measured from photos of
    /// pav's chart) replaces the profile.
    #[serde(default)]
    pub calibration: Option<PathBuf>,
}

impl PrintConfig {
    /// This table with a command line's printer options over it, each one where given.
    pub fn overridden(
        mut self,
        profile: Option<&Path>,
        intent: Option<RenderingIntent>,
        black_point_compensation: bool,
        calibration: Option<&Path>,
    ) -> Self {
        if let Some(f) = profile {
            self.profile = f.into();
        }
        if let Some(i) = intent {
            self.intent = i;
        }
        self.black_point_compensation |= black_point_compensation;
        if let Some(c) = calibration {
            self.calibration = Some(c.into());
        }
        self
    }
}

fn default_profile() -> PathBuf {
    DEFAULT_PROFILE.into()
}

fn lut_size() -> usize {
    33
}

impl Default for PrintConfig {
    fn default() -> Self {
        Self {
            profile: default_profile(),
            intent: RenderingIntent::default(),
            black_point_compensation: false,
            lut_size: lut_size(),
            gamut_weight: 0.0,
            calibration: None,
        }
    }
}

impl PrintConfig {
    /// Value checks with messages that say what to change.
    pub fn check(&self) -> Result<(), String> {
        if !(5..=129).contains(&self.lut_size) {
            return Err(format!("print.lut_size must be in 5..=129, got {}", self.lut_size));
        }
        if !(self.gamut_weight.is_finite() && self.gamut_weight >= 0.0) {
            return Err(format!("print.gamut_weight must be ≥ 0, got {}", self.gamut_weight));
        }
        Ok(())
    }
}

/// The soft proof as a differentiable step.
#[derive(Clone, Debug)]
pub struct PrintChannel {
    /// Channels 0–2: the printed sRGB colour; 3: ΔE2000 between input and print.
    pub lut: Lut3,
    /// Weight of the gamut term.
    pub gamut_weight: f32,
}

/// How far printing moves a texture's colours (ΔE2000 per texel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shift {
    /// Texels measured.
    pub texels: usize,
    /// Median ΔE2000.
    pub median: f64,
    /// 90th percentile.
    pub p90: f64,
    /// Share of texels that move by more than ΔE2000 5 (a difference anyone sees side by side).
    pub over5: f64,
}

impl std::fmt::Display for Shift {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} texels: ΔE2000 median {:.1}, p90 {:.1}; {:.0} % move by more than 5",
            self.texels,
            self.median,
            self.p90,
            100.0 * self.over5
        )
    }
}

impl PrintChannel {
    /// Samples the config's soft proof (or its calibration's map) into the LUT.
    pub fn open(cfg: &PrintConfig) -> Result<Self, ProofError> {
        if let Some(path) = &cfg.calibration {
            let c = Calibration::load(path)
                .map_err(|e| ProofError::Calibration { path: path.clone(), why: e.to_string() })?;
            return Ok(Self::from_map(cfg.lut_size, cfg.gamut_weight, |rgb| {
                rgb.iter().map(|p| c.map.apply(*p)).collect()
            }));
        }
        let proof = SoftProof::open(&cfg.profile, cfg.intent, cfg.black_point_compensation)?;
        Ok(Self::from_map(cfg.lut_size, cfg.gamut_weight, |rgb| proof.proof(rgb)))
    }

    /// Samples any colour map (sRGB → printed sRGB, many at once) into the LUT.
    pub fn from_map(n: usize, gamut_weight: f32, map: impl Fn(&[[f64; 3]]) -> Vec<[f64; 3]>) -> Self {
        let at = |i: usize| i as f64 / (n - 1) as f64;
        let nodes: Vec<[f64; 3]> = (0..n * n * n).map(|i| [at(i / (n * n)), at(i / n % n), at(i % n)]).collect();
        let printed = map(&nodes);
        let mut k = 0;
        let lut = Lut3::sample(n, 4, |rgb| {
            let p = printed[k];
            debug_assert_eq!(rgb, nodes[k]);
            k += 1;
            vec![p[0], p[1], p[2], delta_e2000_srgb(rgb, p)]
        });
        Self { lut, gamut_weight }
    }

    /// The texture (RGB interleaved) as printed.
    pub fn printed(&self, tex: &[f32]) -> Vec<f32> {
        let mut out = vec![0f32; tex.len()];
        let mut v = [0f32; 4];
        for (px, o) in tex.chunks_exact(3).zip(out.chunks_exact_mut(3)) {
            self.lut.eval(px, &mut v);
            o.copy_from_slice(&v[..3]);
        }
        out
    }

    /// The gamut term over `texels` (`gamut_weight ×` their mean ΔE2000 as printed; 0 without
    /// weight): a loss on the texture, whose gradient it adds into `grad`.
    pub fn gamut(&self, tex: &[f32], texels: &[u32], grad: &mut [f32]) -> f64 {
        let per = if texels.is_empty() { 0.0 } else { self.gamut_weight / texels.len() as f32 };
        if per == 0.0 {
            return 0.0;
        }
        let mut g4 = vec![0f32; tex.len() / 3 * 4];
        for &t in texels {
            g4[4 * t as usize + 3] = per;
        }
        self.lut.vjp(tex, &g4, grad, Some(texels));
        let mut v = [0f32; 4];
        let sum: f64 = texels
            .iter()
            .map(|&t| {
                self.lut.eval(&tex[3 * t as usize..3 * t as usize + 3], &mut v);
                v[3] as f64
            })
            .sum();
        per as f64 * sum
    }

    /// How far printing moves the texels where `mask` is set (every texel without a mask),
    /// ΔE2000 from the LUT.
    pub fn shift(&self, tex: &[f32], mask: Option<&[f32]>) -> Shift {
        let mut v = [0f32; 4];
        let de: Vec<f64> = tex
            .chunks_exact(3)
            .enumerate()
            .filter(|(i, _)| mask.is_none_or(|m| m[*i] > 0.5))
            .map(|(_, px)| {
                self.lut.eval(px, &mut v);
                v[3] as f64
            })
            .collect();
        let (median, p90, over5) = spread(&de, 5.0);
        Shift { texels: de.len(), median, p90, over5 }
    }
}

/// The texels of a region (1 per optimizable texel) as indices.
pub fn region_texels(region: &[f32]) -> Vec<u32> {
    region.iter().enumerate().filter(|(_, r)| **r > 0.5).map(|(i, _)| i as u32).collect()
}

/// Printing an RGB texture of `texels` texels, as a step (the gamut term, a loss of its own, is
/// [`PrintChannel::gamut`]).
pub struct Printing<'a> {
    /// The channel.
    pub channel: &'a PrintChannel,
    /// Texels in the texture.
    pub texels: usize,
    /// The texels whose gradient passes back (the optimizable region); `None`: every texel.
    pub region: Option<&'a [u32]>,
}

impl Step for Printing<'_> {
    /// The texture, where the map's Jacobian is taken.
    type Tape = Vec<f32>;
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.texels * 3
    }

    fn output_len(&self) -> usize {
        self.texels * 3
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, Vec<f32>), Self::Error> {
        Ok((self.channel.printed(x), x.to_vec()))
    }

    fn adjoint(&self, tex: &Vec<f32>, gy: &[f32], gx: &mut [f32]) {
        let mut g4 = vec![0f32; tex.len() / 3 * 4];
        for (g, o) in gy.chunks_exact(3).zip(g4.chunks_exact_mut(4)) {
            o[..3].copy_from_slice(g);
        }
        self.channel.lut.vjp(tex, &g4, gx, self.region);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::rng::Rng;

    #[test]
    fn the_sampled_proof_matches_littlecms_over_a_dense_sample_of_the_cube() {
        let cfg = PrintConfig::default();
        let channel = PrintChannel::open(&cfg).unwrap();
        let proof = SoftProof::open(&cfg.profile, cfg.intent, false).unwrap();
        let mut rng = Rng::new(42);
        let pts: Vec<[f64; 3]> =
            (0..20_000).map(|_| [rng.unit() as f64, rng.unit() as f64, rng.unit() as f64]).collect();
        let direct = proof.proof(&pts);
        let flat: Vec<f32> = pts.iter().flat_map(|p| p.map(|v| v as f32)).collect();
        let via_lut = channel.printed(&flat);
        let de: Vec<f64> = direct
            .iter()
            .zip(via_lut.chunks_exact(3))
            .map(|(d, l)| delta_e2000_srgb(*d, [l[0] as f64, l[1] as f64, l[2] as f64]))
            .collect();
        let (median, _, _) = spread(&de, 2.0);
        let max = de.iter().cloned().fold(0.0, f64::max);
        eprintln!(
            "LUT {}³ vs LittleCMS over {} colours: ΔE2000 median {median:.3}, max {max:.3}",
            cfg.lut_size,
            de.len()
        );
        assert!(median < 0.5 && max < 2.0, "LUT vs LittleCMS: median ΔE2000 {median:.3}, max {max:.3}");
    }

    #[test]
    fn the_gamut_term_is_the_weighted_mean_shift_and_its_gradient_lowers_it() {
        let channel = PrintChannel { gamut_weight: 2.0, ..PrintChannel::open(&PrintConfig::default()).unwrap() };
        let mut rng = Rng::new(7);
        let tex: Vec<f32> = (0..3 * 64).map(|_| rng.uniform(0.05, 0.95)).collect();
        let texels: Vec<u32> = (0..64).filter(|i| i % 2 == 0).collect();
        let mut grad = vec![0f32; tex.len()];
        let g = channel.gamut(&tex, &texels, &mut grad);
        let mut mask = vec![0f32; 64];
        texels.iter().for_each(|&t| mask[t as usize] = 1.0);
        let shift = channel.shift(&tex, Some(&mask));
        assert_eq!(shift.texels, 32);
        let mut v = [0f32; 4];
        let mean: f64 = texels
            .iter()
            .map(|&t| {
                channel.lut.eval(&tex[3 * t as usize..3 * t as usize + 3], &mut v);
                v[3] as f64
            })
            .sum::<f64>()
            / 32.0;
        assert!((g - 2.0 * mean).abs() < 1e-6, "{g} vs {}", 2.0 * mean);
        assert!(grad.chunks_exact(3).enumerate().all(|(i, g)| i % 2 == 0 || g == [0.0; 3]));
        // A small step against the gradient lowers the term.
        let stepped: Vec<f32> = tex.iter().zip(&grad).map(|(t, g)| t - 1e-3 * g.signum()).collect();
        let mut scratch = vec![0f32; tex.len()];
        let after = channel.gamut(&stepped, &texels, &mut scratch);
        assert!(after < g, "{after} ≥ {g}");
    }
}
