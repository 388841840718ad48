//! YOLOX-Nano's input gradient from its own ONNX file (`onnx_proto` reader, `detect::autodiff`,
//! `detect::ortgrad`): the forward gives the raw output of plain inference on real frames, and the
//! gradient matches central differences of that forward along several directions.

use crate::common;

use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::prepare;
use pav::detect::DetectorConfig;
use pav_onnx::autodiff::{differentiate_with, Kernels};
use pav_onnx::proto::Model;
use pav_onnx::session::GradSession;

fn config() -> DetectorConfig {
    DetectorConfig::load(&common::detector_config("yolox_nano")).unwrap()
}

fn session(kernels: Kernels) -> GradSession {
    let model = Model::from_bytes(&std::fs::read(config().model).unwrap()).unwrap_or_else(|e| panic!("{e}"));
    let d = differentiate_with(&model, &[1, 3, 416, 416], kernels).unwrap_or_else(|e| panic!("{e}"));
    GradSession::new("yolox_nano", d, 2).unwrap()
}

fn frame_input(name: &str) -> Vec<f32> {
    let shared = common::real_data();
    let sample = CarlaSample::load(&shared.join("fca/carla_dataset/test").join(name)).unwrap();
    prepare(&sample.image, &config().input).unwrap().0
}

#[test]
fn the_file_reads_as_the_graph_it_is() {
    let m = Model::from_bytes(&std::fs::read(config().model).unwrap()).unwrap();
    let count = |op: &str| m.nodes.iter().filter(|n| n.op_type == op).count();
    assert_eq!((m.opset, m.nodes.len(), m.inputs.len(), m.outputs.len()), (11, 369, 1, 1));
    assert_eq!((count("Conv"), count("Sigmoid"), count("Slice"), count("MaxPool")), (113, 110, 8, 3));
    let conv_weights: usize = m
        .initializers
        .iter()
        .filter_map(|i| match &i.data {
            pav_onnx::proto::InitData::F32(v) => Some(v.len()),
            _ => None,
        })
        .sum();
    // YOLOX-Nano has 0.91 M parameters.
    assert!((880_000..940_000).contains(&conv_weights), "{conv_weights}");
}

#[test]
fn forward_equals_plain_inference_on_real_frames() {
    let mut det = OnnxDetector::new(config(), 2).unwrap();
    let mut g = session(Kernels::Fused);
    for name in ["data12503.npz", "data12508.npz"] {
        let input = frame_input(name);
        let raw = det.infer(input.clone(), &pav::detect::preprocess::InputMap::identity(416, 416)).unwrap();
        let (outs, _) = g.forward(input).unwrap();
        assert_eq!(outs[0].len(), raw[0].data.len());
        let worst = outs[0].iter().zip(&raw[0].data).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        eprintln!("{name}: max |gradient graph − inference| = {worst:e}");
        assert!(worst < 1e-4, "{name}: {worst}");
    }
}

#[test]
fn gradient_matches_central_differences_along_directions() {
    let input = frame_input("data12503.npz");
    for kernels in [Kernels::Fused, Kernels::Onnx] {
        let mut g = session(kernels);
        let (outs, pass) = g.forward(input.clone()).unwrap();
        // A weighted sum of the objectness and class scores (columns 4..85 of the 85 per row), which
        // the losses read.
        let w: Vec<f32> = (0..outs[0].len())
            .map(|i| if i % 85 >= 4 { ((i * 2654435761 % 2001) as f32 / 1000.0 - 1.0) * 1e-3 } else { 0.0 })
            .collect();
        let grad = g.backward(&pass, vec![w.clone()]).unwrap();
        assert!(grad.iter().all(|v| v.is_finite()));
        let plane = 416 * 416;
        // The whole image, and a 64×64 patch of all three channels over the car.
        let dirs: Vec<Vec<f32>> =
            vec![
                common::whole_image_direction(3 * plane),
                (0..3 * plane)
                    .map(|i| {
                        if (176..240).contains(&(i % plane / 416)) && (170..234).contains(&(i % 416)) {
                            1.0
                        } else {
                            0.0
                        }
                    })
                    .collect(),
            ];
        // Across the whole image, the max-pools' kinks make the central difference's error first
        // order in ε, so it is extrapolated to ε → 0 from two steps. The extrapolation is good to
        // about a percent: on an AMD EPYC the graph gave −3.512e-4 against −3.496e-4 (0.4 %), so 2 % is allowed. On the
        // patch the difference is flat from ε = 0.03 to 0.3 (−1.563 to −1.573 e-5 against the
        // graph's −1.561e-5); a single channel's 24×24 patch had a derivative 20× smaller, at
        // the level of f32 rounding, whose difference drifted from 3.9 to 7.5 e-7 with ε.
        for (k, d, eps, tol) in [(0, &dirs[0], 0.01f32, 2e-2), (1, &dirs[1], 0.1, 3e-2)] {
            let fd = common::central_difference(&mut g, &w, &input, d, eps, k == 0);
            let an: f64 = grad.iter().zip(d).map(|(a, b)| *a as f64 * *b as f64).sum();
            eprintln!("{kernels:?} direction {k}: analytic {an:e}, central difference {fd:e}");
            assert!((an - fd).abs() <= tol * an.abs().max(fd.abs()), "{kernels:?} direction {k}: {an} vs {fd}");
        }
    }
}
