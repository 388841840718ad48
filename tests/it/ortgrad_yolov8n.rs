//! YOLOv8n as a white box: the float surrogate of the int8 model (`detect::surrogate`), planned
//! from its description (`attack::outputs::Plan`): its output concatenates boxes and class
//! probabilities, so only the class piece is computed and differentiated. Its forward gives the
//! class probabilities of plain inference of the surrogate on real frames, and its input gradient
//! matches central differences of that forward.

use crate::common;

use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::outputs::Plan;
use pav::attack::whitebox::{WhiteBox, WhiteBoxOptions};
use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::prepare;
use pav::detect::DetectorConfig;
use pav_onnx::autodiff::{differentiate_with, Kernels};
use pav_onnx::proto::Model;
use pav_onnx::session::GradSession;
use pav_onnx::surrogate::dequantize;

fn config() -> DetectorConfig {
    DetectorConfig::load(&common::detector_config("yolov8n_int8")).unwrap()
}

fn surrogate() -> Model {
    dequantize(&Model::from_bytes(&std::fs::read(config().model).unwrap()).unwrap()).unwrap().0
}

/// The surrogate as its white box computes it without boxes: the class piece of its output.
fn class_branch() -> Model {
    let mut m = surrogate();
    let plan = Plan::new(&mut m, &config().output.describe(80), 640, 80, false, false).unwrap();
    assert_eq!((plan.graph_outputs.len(), plan.seeded), (1, 1), "{:?}", plan.graph_outputs);
    m
}

fn frame(name: &str) -> CarlaSample {
    CarlaSample::load(&common::real_data().join("fca/carla_dataset/test").join(name)).unwrap()
}

#[test]
fn the_class_branch_forward_equals_the_surrogate_on_real_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("float.onnx");
    std::fs::write(&path, surrogate().to_bytes()).unwrap();
    let mut plain = OnnxDetector::new(DetectorConfig { model: path, ..config() }, 2).unwrap();
    let branch = class_branch();
    // The box decoder (Softmax, Div, Sub) is gone with the boxes.
    assert!(branch.nodes.iter().all(|n| !["Softmax", "Div", "Sub"].contains(&n.op_type.as_str())));
    let d = differentiate_with(&branch, &[1, 3, 640, 640], Kernels::Fused).unwrap_or_else(|e| panic!("{e}"));
    let mut g = GradSession::new("yolov8n class branch", d, 2).unwrap();
    for name in ["data12503.npz", "data12510.npz"] {
        let (input, map) = prepare(&frame(name).image, &config().input).unwrap();
        let raw = plain.infer(input.clone(), &map).unwrap();
        let (outs, _) = g.forward(input).unwrap();
        // [1, 84, 8400]: rows 4.. are the 80 class probabilities.
        let n = 8400;
        assert_eq!((raw[0].data.len(), outs[0].len()), (84 * n, 80 * n));
        let worst = outs[0].iter().zip(&raw[0].data[4 * n..]).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        eprintln!("{name}: max |class branch − surrogate| = {worst:e}");
        assert!(worst < 1e-4, "{name}: {worst}");
    }
}

#[test]
fn the_class_branch_gradient_matches_central_differences() {
    let branch = class_branch();
    let input = prepare(&frame("data12503.npz").image, &config().input).unwrap().0;
    let d = differentiate_with(&branch, &[1, 3, 640, 640], Kernels::Fused).unwrap();
    let mut g = GradSession::new("yolov8n class branch", d, 2).unwrap();
    let (outs, pass) = g.forward(input.clone()).unwrap();
    // The car row (class 2) with weights in [−1, 1], which the losses read most; other rows' terms
    // would add f32 noise to the differences and little signal.
    let n = 8400;
    let w: Vec<f32> = (0..outs[0].len())
        .map(|i| if i / n == 2 { (i * 2654435761 % 2001) as f32 / 1000.0 - 1.0 } else { 0.0 })
        .collect();
    let grad = g.backward(&pass, vec![w.clone()]).unwrap();
    assert!(grad.iter().all(|v| v.is_finite()));
    let plane = 640 * 640;
    // The whole image, every pixel moved by a different amount.
    let dir = common::whole_image_direction(3 * plane);
    let an: f64 = grad.iter().zip(&dir).map(|(a, b)| *a as f64 * *b as f64).sum();
    // Inputs are in [0, 1] (YOLOX's are 0–255), so the steps are 1/255 of YOLOX's test. A 32×32
    // patch over the car at steps of 1e-3 disagreed by 40 % at every step size: the max-pools'
    // and the SiLU's kinks crowd a small patch. Over the whole image, as for YOLOX, the error is
    // first order in the step and is extrapolated away (measured: −12.077 analytic, −12.062 at
    // 4e-5, −12.067 at 1.2e-4).
    let fd = common::central_difference(&mut g, &w, &input, &dir, 4e-5, true);
    eprintln!("analytic {an:e}, extrapolated central difference {fd:e}");
    assert!((an - fd).abs() <= 1e-2 * an.abs().max(fd.abs()), "{an} vs {fd}");
}

#[test]
fn the_int8_model_trains_only_as_a_named_surrogate() {
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: config().target_classes.clone(),
        reduce: Reduce::Mean,
        proposals: ProposalSet::ArgMax,
        iou: false,
        box_gradient: false,
    };
    let e = WhiteBox::load(&config(), loss.clone(), 416).err().expect("refused").to_string();
    assert!(e.contains("surrogate = true"), "{e}");
    let o = WhiteBoxOptions { composite: 416, input: None, threads: 2, surrogate: true };
    let wb = WhiteBox::with_options(&config(), loss, o).unwrap();
    // A real photo, as a 416² composite: the car is found, and the loss and gradient are finite.
    let img = frame("data12503.npz").image;
    let comp = composite(&img, 416);
    let g = wb.loss_and_grad(&comp, 416, 1.0, None).unwrap();
    eprintln!("{:?}", g.loss);
    assert!(g.loss.max_score > 0.5 && g.loss.proposals > 0, "{:?}", g.loss);
    assert!(g.grad.iter().all(|v| v.is_finite()) && g.grad.iter().any(|v| *v != 0.0));
}

/// The frame as an RGB `size × size` composite in [0, 1] (nearest sampling is enough here).
fn composite(f: &pav::image::Frame, size: usize) -> Vec<f32> {
    let mut out = vec![0f32; size * size * 3];
    for y in 0..size {
        for x in 0..size {
            let (sx, sy) = (x * f.width / size, y * f.height / size);
            let p = (sy * f.width + sx) * 3;
            // Frames are BGR.
            for c in 0..3 {
                out[(y * size + x) * 3 + c] = f.bgr[p + 2 - c] as f32 / 255.0;
            }
        }
    }
    out
}
