//! Every differentiable step of the texture-to-detector chain implements one forward/adjoint
//! pair (`pav::step::Step`), and one check holds for each: the dot-product identity
//! `⟨J·d, g⟩ = ⟨d, Jᵀ·g⟩` along a random direction and the adjoint per coordinate, both against
//! central differences of the forward pass at the same random draw. The steps run on real data
//! where it exists: the paper's view of the e-tron on a CARLA photo with its scene's EoT and a
//! zoom, the print channel through Debian's CMYK profile.

use crate::common;

use pav::attack::config::OptimizeConfig;
use pav::attack::defended::Defended;
use pav::attack::pyramid::Pyramid;
use pav::attack::setup::Setup;
use pav::detect::defence::{Defence, Median};
use pav::image::resize::{Interpolation, Resampler};
use pav::print::channel::{PrintChannel, PrintConfig, Printing};
use pav::render::shade::Shading;
use pav::render::texture::Gather;
use pav::rng::Rng;
use pav::scene::eot::Eot;
use pav::scene::zoom::Zoom;
use pav::scene::{Effect, Scene};
use pav::step::{agreement, Chain, Step};

/// Values in [0.1, 0.9], away from the clamps' kinks.
fn values(n: usize, seed: u64) -> Vec<f32> {
    let mut r = Rng::new(seed);
    (0..n).map(|_| r.uniform(0.1, 0.9)).collect()
}

/// Asserts the check for `step` at `x` with finite-difference step `eps`, within `tol`.
fn holds<S: Step>(name: &str, step: &S, x: &[f32], eps: f32, tol: f64)
where
    S::Error: std::fmt::Debug,
{
    let a = agreement(step, x, 7, eps, 8).unwrap();
    eprintln!("{name}: identity {:.2e}, coordinates {:.2e}", a.identity, a.coordinates);
    assert!(a.identity < tol && a.coordinates < tol, "{name}: {a:?} (tolerance {tol})");
}

fn paper_setup(size: usize) -> Setup {
    common::real_data();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(1);
    cfg.views.test.clear();
    Setup::load(&cfg, Some(size)).unwrap()
}

#[test]
fn every_step_agrees_with_its_adjoint() {
    let s = paper_setup(128);
    let view = &s.train[0];
    let tex = values(s.tex_size * s.tex_size * 3, 1);
    let zoomed = Scene {
        lighting: s.scene.lighting,
        effects: s.scene.effects.iter().cloned().chain([Effect::Zoom { min: 0.7, max: 1.2 }]).collect(),
    };
    assert!(zoomed.effects.len() > 1, "the paper's scene lists its EoT");
    // The whole chain of one view: texture lookup and shading (linear in the texture), then EoT
    // and zoom. EoT's clamp to [0, 1] has kinks that a finite difference along a direction of
    // every texel crosses at a few pixels, so the nonlinear chains are differenced with a small
    // step, where f32 rounding bounds the agreement instead.
    let lit = Scene { lighting: s.scene.lighting, effects: vec![] };
    holds("view, lit", &view.chain(&lit), &tex, 1e-2, 1e-4);
    holds("view, EoT and zoom", &view.chain(&zoomed), &tex, 1e-4, 5e-3);
    // The optimizer's chain through the print channel: between the LUT's cell walls, a small step again.
    let channel = PrintChannel::open(&PrintConfig::default()).unwrap();
    let print = Printing { channel: &channel, texels: s.tex_size * s.tex_size, region: None };
    holds("print, view", &Chain::new().then("print", print).and(view.chain(&lit)), &tex, 1e-4, 5e-3);
    let img = values(view.size * view.size * 3, 2);
    holds("eot", &Eot { scene: &s.scene, active: &view.active, pixels: view.size * view.size }, &img, 1e-4, 5e-3);
    holds("zoom", &Zoom { scene: &zoomed, size: view.size }, &img, 1e-2, 1e-4);
    holds("resize bilinear", &Resampler::new(view.size, 96, Interpolation::Bilinear), &img, 1e-2, 1e-4);
    holds("resize antialias", &Resampler::new(view.size, 80, Interpolation::Antialias), &img, 1e-2, 1e-4);
    let pyramid = Pyramid::new(64, 4).unwrap();
    holds("pyramid", &pyramid, &values(pyramid.len(), 3), 1e-2, 1e-4);
    // The median picks one sample per window: its kinks are where two samples swap places, so
    // its input is distinct values at least 4.6·10⁻⁴ apart, further than any step moves them.
    let n = 3 * 24 * 24;
    let mut spread: Vec<f32> = (0..n).map(|i| 0.1 + 0.8 * i as f32 / n as f32).collect();
    let mut r = Rng::new(4);
    for i in (1..n).rev() {
        spread.swap(i, (r.next_u64() % (i as u64 + 1)) as usize);
    }
    let median = [Defence::Median(Median { k: 3 })];
    holds("median", &Defended { chain: &median, side: 24 }, &spread, 2e-4, 5e-3);
    // A texture lookup of its own: samples anywhere on a small texture.
    let mut r = Rng::new(5);
    let samples: Vec<(u32, [f32; 2])> = (0..500).map(|p| (p * 2, [r.uniform(0.0, 1.0), r.uniform(0.0, 1.0)])).collect();
    holds("gather", &Gather::new(samples, 17, 11), &values(17 * 11 * 3, 6), 1e-2, 1e-4);
    // Shading at some pixels of an image, as a view keeps it.
    let shading = Shading {
        mul: values(300, 10),
        add: values(300, 11),
        pixels: Some((0..300).map(|p| p * 3 + 1).collect()),
        image_pixels: 1000,
    };
    holds("shading", &shading, &values(3000, 12), 1e-2, 1e-4);
}

#[test]
fn the_print_colour_map_agrees_with_its_adjoint() {
    let channel = PrintChannel::open(&PrintConfig::default()).unwrap();
    // Trilinear between the LUT's nodes: kinks at every cell wall, so a small step again.
    holds("print", &Printing { channel: &channel, texels: 64 * 64, region: None }, &values(64 * 64 * 3, 8), 1e-5, 5e-3);
}

#[test]
fn a_wrong_adjoint_is_caught() {
    // The check is not vacuous: an adjoint off by a tenth on one value in a hundred fails it.
    struct Skewed(Resampler);
    impl Step for Skewed {
        type Tape = ();
        type Error = std::convert::Infallible;
        fn input_len(&self) -> usize {
            self.0.input_len()
        }
        fn output_len(&self) -> usize {
            self.0.output_len()
        }
        fn forward(&self, x: &[f32], rng: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
            self.0.forward(x, rng)
        }
        fn adjoint(&self, t: &(), gy: &[f32], gx: &mut [f32]) {
            Step::adjoint(&self.0, t, gy, gx);
            gx.iter_mut().step_by(100).for_each(|v| *v *= 1.1);
        }
    }
    let step = Skewed(Resampler::new(32, 24, Interpolation::Bilinear));
    let a = agreement(&step, &values(32 * 32 * 3, 9), 7, 1e-2, 8).unwrap();
    assert!(a.identity > 1e-4 || a.coordinates > 1e-2, "{a:?}");
}
