//! NanoDet-m's input gradient from its own ONNX file: the graph (bilinear up- and downsampling in
//! its feature pyramid, LeakyReLU, channel shuffles) differentiated, its forward equal to plain
//! inference on real photos, and its gradient equal to central differences along two directions.
#![cfg(feature = "eval")]

mod common;

use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::{prepare, InputMap};
use pav::detect::DetectorConfig;
use pav_onnx::autodiff::{differentiate_with, Kernels};
use pav_onnx::proto::{Dim, Model};
use pav_onnx::session::GradSession;

fn config() -> DetectorConfig {
    DetectorConfig::load(&common::repo().join("configs/detectors-wide/nanodet_m_416.toml")).unwrap()
}

/// The graph cut to its stride-8 class map `[1, 2704, 80]` (sigmoid probabilities), found by
/// shape, and that output's name.
fn class_map() -> (Model, String) {
    let mut m = Model::from_bytes(&std::fs::read(config().model).unwrap()).unwrap();
    let want = [1, 2704, 80].map(Dim::Fixed);
    let out = m.outputs.iter().find(|o| o.dims == want).expect("a [1, 2704, 80] output").clone();
    m.outputs = vec![out.clone()];
    m.prune();
    (m, out.name)
}

fn session(kernels: Kernels) -> GradSession {
    let d = differentiate_with(&class_map().0, &[1, 3, 416, 416], kernels).unwrap_or_else(|e| panic!("{e}"));
    GradSession::new("nanodet", d, 2).unwrap()
}

fn frame_input(name: &str) -> Vec<f32> {
    let sample = CarlaSample::load(&common::real_data().join("fca/carla_dataset/test").join(name)).unwrap();
    prepare(&sample.image, &config().input).unwrap().0
}

#[test]
fn forward_equals_plain_inference_on_real_photos() {
    let mut det = OnnxDetector::new(config(), 2).unwrap();
    let name = class_map().1;
    let mut g = session(Kernels::Fused);
    for photo in ["data12503.npz", "data12508.npz"] {
        let input = frame_input(photo);
        let raw = det.infer(input.clone(), &InputMap::identity(416, 416)).unwrap();
        let want = &raw.iter().find(|o| o.name == name).unwrap().data;
        let (outs, _) = g.forward(input).unwrap();
        assert_eq!(outs[0].len(), want.len());
        let worst = outs[0].iter().zip(want).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        eprintln!("{photo}: max |gradient graph − inference| = {worst:e}");
        assert!(worst < 1e-4, "{photo}: {worst}");
    }
}

#[test]
fn gradient_matches_central_differences_along_directions() {
    let input = frame_input("data12503.npz");
    let plane = 416 * 416;
    for kernels in [Kernels::Fused, Kernels::Onnx] {
        let mut g = session(kernels);
        let (outs, pass) = g.forward(input.clone()).unwrap();
        // A weighted sum of the class probabilities, as the losses read them.
        let w: Vec<f32> = (0..outs[0].len()).map(|i| ((i * 2654435761 % 2001) as f32 / 1000.0 - 1.0) * 1e-3).collect();
        let grad = g.backward(&pass, vec![w.clone()]).unwrap();
        assert!(grad.iter().all(|v| v.is_finite()));
        // The whole image, and a ramp across the car (left to right, opposite in red and blue).
        let ramp: Vec<f32> = (0..3 * plane)
            .map(|i| {
                let (c, y, x) = (i / plane, i % plane / 416, i % 416);
                if (150..260).contains(&y) && (90..330).contains(&x) {
                    (x as f32 / 416.0 - 0.5) * (c as f32 - 1.0)
                } else {
                    0.0
                }
            })
            .collect();
        // Steps in normalized input units (one is 57 levels). LeakyReLU and max-pool kinks make
        // the whole-image difference wander with the step (measured, fused kernels: 2.66, 2.56,
        // 2.43, 3.79 e-3 at 0.001, 0.003, 0.01, 0.03 against the graph's 2.50e-3), so it is taken
        // at 0.003 and allowed 4 %; along the ramp every step from 0.001 to 0.03 agrees to 2.5 %.
        for (k, d, eps, tol) in [(0, &common::whole_image_direction(3 * plane), 0.003f32, 4e-2), (1, &ramp, 0.01, 3e-2)]
        {
            let fd = common::central_difference(&mut g, &w, &input, d, eps, false);
            let an: f64 = grad.iter().zip(d.iter()).map(|(a, b)| *a as f64 * *b as f64).sum();
            eprintln!("{kernels:?} direction {k}: analytic {an:e}, central difference {fd:e}");
            assert!((an - fd).abs() <= tol * an.abs().max(fd.abs()), "{kernels:?} direction {k}: {an} vs {fd}");
        }
    }
}
