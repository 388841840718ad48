//! A detector config's keys mean one thing wherever pav reads them: `nms_iou` is the suppression
//! of every path that turns proposals into detections (eval-digital's and crossval's P@0.5 read
//! `studies::table2::detect_view`), with 0.5 when the key is absent; and each key of the input,
//! the output and the classes changes inference and the white box wherever it should.

use crate::common;

use pav::attack::config::OptimizeConfig;
use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::setup::Setup;
use pav::attack::whitebox::{WhiteBox, WhiteBoxOptions};
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav::studies::table2::detect_view;
use std::path::Path;

/// YOLOv3-tiny's config extended with `extra` (TOML keys), written into `dir`.
fn yolov3_tiny_with(dir: &Path, name: &str, extra: &str) -> std::path::PathBuf {
    let path = dir.join(format!("{name}.toml"));
    let base = common::detector_config("yolov3-tiny");
    std::fs::write(&path, format!("extends = {:?}\nname = {name:?}\n{extra}", base.display().to_string())).unwrap();
    path
}

#[test]
fn nms_iou_sets_the_suppression_of_the_detections_that_p50_scores() {
    common::real_data();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(2);
    cfg.views.test.clear();
    let setup = Setup::load_photos(&cfg, None).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let configs = [
        yolov3_tiny_with(tmp.path(), "absent", ""),
        yolov3_tiny_with(tmp.path(), "half", "nms_iou = 0.5\n"),
        yolov3_tiny_with(tmp.path(), "tight", "nms_iou = 0.05\n"),
        yolov3_tiny_with(tmp.path(), "loose", "nms_iou = 0.95\n"),
    ];
    let mut dets = pav::detect::load::load_detectors(&configs, &[], &[], 1).unwrap();
    assert_eq!(dets.iter().map(|d| d.nms_iou()).collect::<Vec<_>>(), [0.5, 0.5, 0.05, 0.95]);
    let mut counts = [0usize; 4];
    for view in &setup.train {
        let found = detect_view(view, None, &setup, &mut dets).unwrap();
        for (c, f) in counts.iter_mut().zip(&found) {
            *c += f.cars.len();
        }
        // The best box is the best box whatever the suppression.
        assert!(found.iter().all(|f| f.best_score() == found[0].best_score()));
    }
    eprintln!("car detections on {} photos: {counts:?}", setup.train.len());
    let [absent, half, tight, loose] = counts;
    assert_eq!(absent, half, "a config without nms_iou suppresses at 0.5");
    assert!(tight < half && half < loose, "suppression at 0.05, 0.5, 0.95 kept {tight}, {half}, {loose} boxes");
}

/// What one config reads on a real frame (inference) and on a 600² composite (the white box,
/// under the IoU-weighted log-max, so that boxes count too).
fn readings(path: &Path, frame: &pav::image::Frame, composite: &[f32], car: [f32; 4]) -> (Vec<f32>, [f32; 2]) {
    let cfg = DetectorConfig::load(path).unwrap();
    let p = OnnxDetector::new(cfg.clone(), 1).unwrap().propose(frame).unwrap();
    let eval: Vec<f32> = p.boxes.iter().flatten().chain(&p.scores).copied().collect();
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: cfg.target_classes.clone(),
        reduce: Reduce::LogMax,
        proposals: ProposalSet::ArgMax,
        iou: true,
        box_gradient: false,
    };
    let o = WhiteBoxOptions { composite: 600, input: None, threads: 1, surrogate: false };
    let g = WhiteBox::with_options(&cfg, loss, o).unwrap().loss_and_grad(composite, 600, 1.0, Some(car)).unwrap();
    (eval, [g.loss.l2, g.loss.max_score])
}

#[test]
fn every_input_output_and_class_key_changes_inference_and_the_white_box_where_it_should() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    // A wide frame, where a letterbox and a stretch differ.
    let frame = common::reference_image("turntable.mp4#0");
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train = cfg.views.train[1..2].to_vec();
    cfg.views.test.clear();
    let s = Setup::load_photos(&cfg, Some(600)).unwrap();
    let v = &s.train[0];
    let car = v.car_box.expect("the car is in view");
    let base = readings(&yolov3_tiny_with(tmp.path(), "base", ""), &frame, &v.photo, car);
    assert!(base.1[1] > 0.5, "the car is seen: {:?}", base.1);
    // (key, TOML, whether inference changes, whether the white box changes). The white box
    // scores square composites, so the letterbox's placement and padding never reach it; the
    // anchors (all halved) move its boxes and so the IoU weight.
    let cases = [
        ("input.width, input.height", "[input]\nwidth = 320\nheight = 320\n", true, true),
        ("input.channels", "[input]\nchannels = \"bgr\"\n", true, true),
        ("input.scale", "[input]\nscale = 0.0035\n", true, true),
        ("input.mean", "[input]\nmean = [0.1, 0.05, 0.0]\n", true, true),
        ("input.std", "[input]\nstd = [0.9, 1.0, 1.1]\n", true, true),
        ("input.interpolation", "[input]\ninterpolation = \"antialias\"\n", true, true),
        ("input.resize", "[input]\nresize = \"letterbox\"\n", true, false),
        ("output.heads", "[output]\nheads = [{ output = \"head0\", anchors = [[40, 41], [67, 84], [172, 160]] }, { output = \"head1\", anchors = [[5, 7], [11, 13], [18, 29]] }]\n", true, true),
        ("classes.target", "[classes]\ntarget = [\"truck\"]\n", false, true),
    ];
    for (key, toml, eval_changes, white_box_changes) in cases {
        let name = key.replace([',', ' ', '.'], "_");
        let (eval, wb) = readings(&yolov3_tiny_with(tmp.path(), &name, toml), &frame, &v.photo, car);
        eprintln!("{key}: white box {wb:?} (base {:?})", base.1);
        assert_eq!(eval != base.0, eval_changes, "{key}: inference changed: {}", eval != base.0);
        assert_eq!(wb != base.1, white_box_changes, "{key}: the white box changed: {}", wb != base.1);
    }
}

/// A white box's identity keys the rendered views' score file: the thread count leaves it as it
/// is (scores do not depend on it), while the composite size or another model changes it.
#[test]
fn a_white_box_identity_follows_what_its_scores_depend_on() {
    common::real_data();
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: vec![2],
        reduce: Reduce::LogMax,
        proposals: ProposalSet::ArgMax,
        iou: false,
        box_gradient: false,
    };
    let id = |name: &str, composite: usize, threads: usize| {
        let cfg = DetectorConfig::load(&common::detector_config(name)).unwrap();
        let loss = DetectionLoss { target: cfg.target_classes.clone(), ..loss.clone() };
        let o = WhiteBoxOptions { composite, input: None, threads, surrogate: false };
        WhiteBox::with_options(&cfg, loss, o).unwrap().identity().to_string()
    };
    let base = id("yolov3-tiny", 416, 0);
    assert_eq!(id("yolov3-tiny", 416, 1), base);
    assert_ne!(id("yolov3-tiny", 600, 0), base);
    assert_ne!(id("yolox_nano", 416, 0), base);
}

/// A white box's identity, which keys the cached scores of rendered views, is what its scores
/// depend on: the same model and settings under another name, from another folder, or with the
/// model's path spelled otherwise share it; another model or input size does not.
#[test]
fn a_white_boxs_identity_is_its_model_and_settings_not_its_name_or_folder() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let identity = |path: &Path| {
        let cfg = DetectorConfig::load(path).unwrap();
        let loss = DetectionLoss {
            box_threshold: 0.05,
            target: cfg.target_classes.clone(),
            reduce: Reduce::Mean,
            proposals: ProposalSet::ArgMax,
            iou: false,
            box_gradient: false,
        };
        WhiteBox::load(&cfg, loss, 416).unwrap().identity().to_string()
    };
    let shipped = identity(&common::detector_config("yolov3-tiny"));
    // Another folder, another name, the model by its absolute path.
    let model = DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap().model;
    let elsewhere = tmp.path().join("study/detectors");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let copied = yolov3_tiny_with(&elsewhere, "mine", &format!("model = {:?}\n", model.display().to_string()));
    assert_eq!(identity(&copied), shipped);
    let smaller = yolov3_tiny_with(tmp.path(), "smaller", "[input]\nwidth = 320\nheight = 320\n");
    assert_ne!(identity(&smaller), shipped);
    let other = tmp.path().join("other.toml");
    std::fs::write(
        &other,
        format!(
            "extends = {:?}\nname = \"yolov3-tiny\"\n",
            common::detector_config("yolox_nano").display().to_string()
        ),
    )
    .unwrap();
    assert_ne!(identity(&other), shipped);
}
