//! One optimization step on real data: FCA's CARLA photos, the UV-mapped e-tron and each white-box
//! detector (YOLOv3-tiny, YOLOX-Nano), with and without the scene's zoom. The texture gradient (the differentiated ONNX graph, the
//! input transform's and the renderer's exact adjoints) must match finite differences of the
//! whole composite → detector → loss chain, and be zero off the region.

use crate::common;

use pav::attack::config::OptimizeConfig;
use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::setup::Setup;
use pav::attack::whitebox::{Ensemble, WhiteBox};
use pav::detect::defence::{Clip, Defence, Median};
use pav::detect::DetectorConfig;
use pav::rng::Rng;
use pav::scene::{Effect, Scene};
use pav::step::Step;

fn setup(size: usize, detector: &str) -> (OptimizeConfig, Setup, WhiteBox) {
    setup_defended(size, detector, &[])
}

fn setup_defended(size: usize, detector: &str, defence: &[Defence]) -> (OptimizeConfig, Setup, WhiteBox) {
    common::real_data();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(2);
    cfg.views.test.clear();
    let s = Setup::load(&cfg, Some(size)).unwrap();
    let mut d = DetectorConfig::load(&common::detector_config(detector)).unwrap();
    if !defence.is_empty() {
        d = d.defended(defence).unwrap();
    }
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: d.target_classes.clone(),
        reduce: Reduce::Mean,
        proposals: ProposalSet::ArgMax,
        iou: false,
        box_gradient: false,
    };
    let wb = WhiteBox::load(&d, loss, size).unwrap();
    (cfg, s, wb)
}

#[test]
fn texture_gradient_matches_finite_differences_through_yolov3_tiny() {
    check_chain("yolov3-tiny", None);
}

#[test]
fn texture_gradient_matches_finite_differences_through_yolox_nano() {
    check_chain("yolox_nano", None);
}

#[test]
fn texture_gradient_matches_finite_differences_through_a_zoom_out_and_yolov3_tiny() {
    check_chain("yolov3-tiny", Some(0.8));
}

/// An adaptive white box: YOLOX-Nano behind median smoothing (differentiated: each gradient to
/// the sample it picked) and feature norm clipping after its three backbone stages (rewritten
/// into the graph), the chain checked end to end as above.
#[test]
fn texture_gradient_matches_finite_differences_through_median_smoothing_and_clipping() {
    let clip = Defence::Clip(Clip { layers: ["781", "841", "886"].map(String::from).to_vec(), level: 1.0 });
    check_defended_chain("yolox_nano", None, &[Defence::Median(Median { k: 3 }), clip]);
}

#[test]
fn an_ensemble_sums_its_members_and_a_drawn_subset_keeps_the_loss_scale() {
    let (_, s, tiny) = setup(416, "yolov3-tiny");
    let (_, _, nano) = setup(416, "yolox_nano");
    let v = &s.train[1];
    let grey = vec![0.5f32; s.tex_size * s.tex_size * 3];
    let img = v.composite(&grey, &s.eval_scene());
    let (a, b) =
        (tiny.loss_and_grad(&img, v.size, 1.0, None).unwrap(), nano.loss_and_grad(&img, v.size, 1.0, None).unwrap());
    assert!(a.loss.l1 > 0.0 && b.loss.l1 > 0.0, "both should see the grey car: {:?} {:?}", a.loss, b.loss);
    let e = Ensemble { members: vec![(tiny, 1.0), (nano, 3.0)] };
    let close = |x: f32, y: f32| (x - y).abs() <= 1e-5 * (1.0 + y.abs());
    // All members: 1·a + 3·b. Only YOLOX-Nano: its weight scaled to the total 4, the other absent.
    let all = e.loss_and_grad(&img, v.size, 1.0, None).unwrap();
    assert!(close(all.sum.loss.l1, a.loss.l1 + 3.0 * b.loss.l1), "{:?}", all.sum.loss);
    let one = e.loss_and_grad_of(&[1], &img, v.size, 1.0, None).unwrap();
    assert!(close(one.sum.loss.l1, 4.0 * b.loss.l1) && close(one.sum.loss.l2, 4.0 * b.loss.l2), "{:?}", one.sum.loss);
    assert!(one.per_detector[0].is_none() && one.per_detector[1].as_ref() == Some(&b.loss));
    assert!(one.sum.grad.iter().zip(&b.grad).all(|(g, x)| close(*g, 4.0 * x)));
    assert!(all.sum.grad.iter().zip(a.grad.iter().zip(&b.grad)).all(|(g, (x, y))| close(*g, x + 3.0 * y)));
}

/// The chain texture → composite → (zoom by `zoom` at a fixed place) → detector → loss.
fn check_chain(detector: &str, zoom: Option<f32>) {
    check_defended_chain(detector, zoom, &[]);
}

fn check_defended_chain(detector: &str, zoom: Option<f32>, defence: &[Defence]) {
    let (_, s, wb) = setup_defended(416, detector, defence);
    let v = &s.train[1];
    eprintln!(
        "{}: car {:.1} % of the image, textured {:.1} %, c_mid {}",
        v.name,
        100.0 * v.coverage,
        100.0 * v.textured_share(),
        v.c_mid
    );
    assert!(v.textured_share() > 0.01);
    // A smooth colour pattern, rendered lit without EoT so the map is deterministic.
    let n = s.tex_size;
    let tex: Vec<f32> = (0..n * n * 3)
        .map(|i| {
            let (y, x, c) = ((i / 3 / n) as f32, (i / 3 % n) as f32, (i % 3) as f32);
            0.5 + 0.2 * (x * 0.031 + c).sin() * (y * 0.027 - c).cos()
        })
        .collect();
    let lit = Scene {
        lighting: s.scene.lighting,
        effects: zoom.map(|f| Effect::Zoom { min: f, max: f }).into_iter().collect(),
    };
    // The same draw (scale and place) every time the chain is evaluated.
    let chain = v.chain(&lit);
    let compose = |tex: &[f32]| chain.forward(tex, &mut Rng::new(11)).unwrap();
    let (img, tape) = compose(&tex);
    eprintln!("stages {:?}, the car at {:?}", chain.stages(), chain.map_box(&tape, None));
    let g = wb.loss_and_grad(&img, v.size, 1.0, None).unwrap();

    eprintln!("{:?}, forward {:.0} ms, backward {:.0} ms", g.loss, g.forward_ms, g.backward_ms);
    assert!(
        g.loss.boxes > 0 && g.loss.max_score > 0.3,
        "the car should be detected with a smooth texture: {:?}",
        g.loss
    );
    let mut grad = vec![0f32; tex.len()];
    chain.adjoint(&tape, &g.grad, &mut grad);
    assert!(grad.iter().all(|x| x.is_finite()));
    let region: std::collections::HashSet<u32> = s.region_values.iter().copied().collect();
    let off = grad.iter().enumerate().filter(|(i, x)| **x != 0.0 && !region.contains(&(*i as u32))).count();
    let on = grad.iter().enumerate().filter(|(i, x)| **x != 0.0 && region.contains(&(*i as u32))).count();
    eprintln!("{on} region values with gradient, {off} outside");
    assert!(on > 1000);
    // Bilinear taps at the region's border reach a few outside texels; they are never updated.
    assert!(off * 20 < on, "{off} gradients outside the region vs {on} inside");
    // Directional derivative along the gradient restricted to the region, against central
    // differences of the full chain.
    let dir: Vec<f32> = (0..tex.len()).map(|i| if region.contains(&(i as u32)) { grad[i] } else { 0.0 }).collect();
    let norm = dir.iter().map(|x| (*x as f64).powi(2)).sum::<f64>().sqrt();
    let loss_at = |t: f64| {
        let tt: Vec<f32> = tex.iter().zip(&dir).map(|(a, d)| a + (t * *d as f64 / norm) as f32).collect();
        let (im, _) = compose(&tt);
        let l = wb.loss(&im, v.size).unwrap();
        (l.l1 as f64 + l.l2 as f64, (l.boxes, l.proposals))
    };
    // The loss averages over the boxes above the threshold, so it jumps where a box crosses it;
    // the gradient is the derivative of the piece that holds t = 0. Differences are taken only
    // with steps that stay on that piece (the same boxes at ±ε as at 0), the largest two of a
    // halving sequence.
    let at_zero = loss_at(0.0).1;
    let steps: Vec<f64> = [0.01, 0.005, 0.0025, 0.00125, 0.000625]
        .into_iter()
        .filter(|eps| loss_at(*eps).1 == at_zero && loss_at(-eps).1 == at_zero)
        .take(2)
        .collect();
    assert!(
        steps.len() == 2 && steps[1] * 2.0 == steps[0],
        "no two halving steps keep the box set {at_zero:?}: {steps:?}"
    );
    // The chain also has kinks (leaky ReLU, max-pool), so the central difference approaches the
    // derivative linearly in ε: 0.27, 0.30, 0.32, 0.33 at ε = 0.05 … 0.005 for a backward
    // 0.343. Richardson's step 2·D(ε/2) − D(ε) cancels that first-order term.
    let fd = |eps: f64| (loss_at(eps).0 - loss_at(-eps).0) / (2.0 * eps);
    let (coarse, fine) = (fd(steps[0]), fd(steps[1]));
    let richardson = 2.0 * fine - coarse;
    eprintln!(
        "directional derivative: backward {norm:.5e}, central differences {coarse:.5e} (ε {}), {fine:.5e} (ε {}), extrapolated {richardson:.5e}",
        steps[0], steps[1]
    );
    assert!((fine - norm).abs() < 0.06 * norm, "backward {norm} vs finite difference {fine}");
    assert!((richardson - norm).abs() < 0.02 * norm, "backward {norm} vs extrapolated {richardson}");
}
