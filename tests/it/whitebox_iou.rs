//! `loss.iou` on real photos and the six white boxes: each prediction's box as the white box
//! reads it (decoded darknet and YOLOX outputs; the forward-only box outputs of the YOLOv8n and
//! DEIMv2 graphs; NanoDet's forward-only box maps; PicoDet cut before its NMS) agrees with evaluate's boxes, the view's car box agrees with the photo's label,
//! and the IoU-weighted log-max counts the car and not the rest of the street; differentiated
//! (`loss.box_gradient`), the weight's gradient through every box output is exact.

use crate::common;

use pav::attack::config::OptimizeConfig;
use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::setup::Setup;
use pav::attack::whitebox::{WhiteBox, WhiteBoxOptions};
use pav::detect::nms::iou;
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav::image::Frame;

fn check(detector: &str, surrogate: bool) {
    check_config(&common::detector_config(detector), surrogate)
}

/// The detector's name, two of FCA's training photos as views, and its config.
fn setup(config: &std::path::Path) -> (String, Setup, DetectorConfig) {
    common::real_data();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(2);
    cfg.views.test.clear();
    let s = Setup::load(&cfg, Some(416)).unwrap();
    (config.file_stem().unwrap().to_string_lossy().into_owned(), s, DetectorConfig::load(config).unwrap())
}

/// The detector as a white box under the IoU-weighted log-max.
fn white_box(d: &DetectorConfig, surrogate: bool, box_gradient: bool) -> WhiteBox {
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: d.target_classes.clone(),
        reduce: Reduce::LogMax,
        proposals: ProposalSet::ArgMax,
        iou: true,
        box_gradient,
    };
    WhiteBox::with_options(d, loss, WhiteBoxOptions { composite: 416, input: None, threads: 2, surrogate }).unwrap()
}

fn check_config(config: &std::path::Path, surrogate: bool) {
    let (detector, s, d) = setup(config);
    let wb = white_box(&d, surrogate, false);
    let mut det = OnnxDetector::new(d.clone(), 1).unwrap();
    for v in &s.train {
        let car = v.car_box.expect("the car is in view");
        let label = s.boxes[&v.name];
        assert!(iou(&car, &label) > 0.75, "{}: silhouette box {car:?} vs label {label:?}", v.name);
        let p = wb.predictions(&v.photo, v.size).unwrap();
        let (best_box, best) = p.iter().copied().fold(([0.0; 4], 0.0), |m, x| if x.1 > m.1 { x } else { m });
        let bgr: Vec<f32> = v.photo.chunks(3).flat_map(|p| [p[2] * 255.0, p[1] * 255.0, p[0] * 255.0]).collect();
        let eval = det.propose(&Frame::from_levels(v.size, v.size, &bgr)).unwrap().best(det.target_classes()).unwrap();
        eprintln!(
            "{detector} {}: white box best {best:.3} at {best_box:?}, evaluate {:.3} at {:?}, car {car:?}",
            v.name, eval.score, eval.bbox
        );
        assert!((best - eval.score).abs() < 0.1, "{}: white box {best} vs evaluate {}", v.name, eval.score);
        assert!(iou(&best_box, &eval.bbox) > 0.8, "{}: {best_box:?} vs {:?}", v.name, eval.bbox);
        assert!(iou(&best_box, &car) > 0.6, "{}: {best_box:?} vs the car {car:?}", v.name);
        // The loss is −log(1 − max IoU·s) over the boxes read here, with the car's box ...
        let want = p.iter().map(|(b, s)| iou(b, &car) * s).fold(0f32, f32::max);
        let g = wb.loss_and_grad(&v.photo, v.size, 1.0, Some(car)).unwrap();
        assert!((g.loss.l2 + (1.0 - want).ln()).abs() < 1e-4, "{}: {} vs {want}", v.name, g.loss.l2);
        assert!(want > 0.3 && g.grad.iter().any(|x| *x != 0.0), "{}: {want}", v.name);
        // ... and a box on the sky above the car weighs nothing the detector sees as a car there.
        let sky = [car[0], 0.0, car[2], (car[1] - 40.0).max(8.0)];
        let off = wb.loss_and_grad(&v.photo, v.size, 1.0, Some(sky)).unwrap();
        assert!(off.loss.l2 < 0.1 * g.loss.l2, "{}: {} on the sky vs {} on the car", v.name, off.loss.l2, g.loss.l2);
        // Without a car box the weight is off: the unweighted best score.
        let plain = wb.loss(&v.photo, v.size).unwrap();
        assert!((plain.l2 + (1.0 - best.min(1.0 - 1e-4)).ln()).abs() < 1e-3, "{}: {plain:?} vs {best}", v.name);
    }
}

#[test]
fn yolov3_tiny_boxes_weigh_the_car() {
    check("yolov3-tiny", false);
}

#[test]
fn yolox_nano_boxes_weigh_the_car() {
    check("yolox_nano", false);
}

#[test]
fn yolov8n_box_branch_runs_forward_only_and_weighs_the_car() {
    check("yolov8n_int8", true);
}

#[test]
fn deimv2_decoder_boxes_run_forward_only_and_weigh_the_car() {
    check("deimv2_atto_int8", true);
}

#[test]
fn nanodet_class_maps_score_and_its_box_maps_weigh_the_car() {
    check_config(&common::repo().join("configs/detectors-wide/nanodet_m_416.toml"), false);
}

#[test]
fn picodet_cut_before_its_nms_scores_and_weighs_the_car() {
    check_config(&common::repo().join("configs/detectors-wide/picodet_xs_320.toml"), false);
}

/// `loss.box_gradient`: the IoU weight differentiated through the box outputs. Along the part
/// of the gradient that the boxes add (the moving gradient minus the held one), central
/// differences of the loss follow the moving gradient and not the held one.
fn check_box_gradient(config: &std::path::Path, surrogate: bool) {
    let (detector, s, d) = setup(config);
    let (moving, held) = (white_box(&d, surrogate, true), white_box(&d, surrogate, false));
    let v = &s.train[1];
    let car = v.car_box.expect("the car is in view");
    let gm = moving.loss_and_grad(&v.photo, v.size, 1.0, Some(car)).unwrap();
    let gh = held.loss_and_grad(&v.photo, v.size, 1.0, Some(car)).unwrap();
    assert_eq!(gm.loss, gh.loss, "{detector}: the same forward");
    let diff: Vec<f64> = gm.grad.iter().zip(&gh.grad).map(|(a, b)| (a - b) as f64).collect();
    let norm = diff.iter().map(|x| x * x).sum::<f64>().sqrt();
    let along = |g: &[f32]| g.iter().zip(&diff).map(|(a, u)| *a as f64 * u / norm).sum::<f64>();
    let (want, held_says) = (along(&gm.grad), along(&gh.grad));
    let loss_at = |t: f64| {
        let img: Vec<f32> = v.photo.iter().zip(&diff).map(|(p, u)| p + (t * u / norm) as f32).collect();
        moving.loss_and_grad(&img, v.size, 1.0, Some(car)).unwrap().loss.l2 as f64
    };
    // Steps this small keep DEIMv2's top-k query selection as it is at 0 (at 0.01 and above its
    // differences jump between pieces); the other models are smooth there too.
    let fds: Vec<(f64, f64)> =
        [0.004, 0.001, 0.00025].iter().map(|&e| (e, (loss_at(e) - loss_at(-e)) / (2.0 * e))).collect();
    eprintln!(
        "{detector}: loss {:.4}, box part of the gradient {norm:.4e}; along it: moving {want:.4e}, held {held_says:.4e}, central differences {fds:?}",
        gm.loss.l2
    );
    assert!(
        norm > 1e-3 * gm.grad.iter().map(|x| (*x as f64).powi(2)).sum::<f64>().sqrt(),
        "{detector}: the boxes add nothing"
    );
    let fd = fds.last().unwrap().1;
    assert!((fd - want).abs() < 0.1 * (want - held_says).abs(), "{detector}: moving {want} vs central difference {fd}");
}

#[test]
fn box_gradients_through_yolov3_tiny_and_yolox_nano_decoders() {
    check_box_gradient(&common::detector_config("yolov3-tiny"), false);
    check_box_gradient(&common::detector_config("yolox_nano"), false);
}

#[test]
fn box_gradients_through_the_yolov8n_and_deimv2_box_branches() {
    check_box_gradient(&common::detector_config("yolov8n_int8"), true);
    check_box_gradient(&common::detector_config("deimv2_atto_int8"), true);
}

#[test]
fn box_gradients_through_nanodet_box_maps_and_picodet_before_its_nms() {
    check_box_gradient(&common::repo().join("configs/detectors-wide/nanodet_m_416.toml"), false);
    check_box_gradient(&common::repo().join("configs/detectors-wide/picodet_xs_320.toml"), false);
}
