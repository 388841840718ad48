//! The project's darknet → ONNX conversion of YOLOv3-tiny matches OpenCV DNN's own darknet reader
//! on real images: raw head logits to 1e-4, and decoded car scores to 1e-4 (one image with a
//! car, one without).

use crate::common;

use opencv::core::{Mat, Scalar, Size, Vector, CV_32F};
use opencv::prelude::*;
use opencv::{dnn, imgcodecs};
use pav::detect::config::OutputLayout;
use pav::detect::decode::decode;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::InputMap;
use pav::detect::DetectorConfig;
use pav_onnx::darknet::{Layer, Network};

fn model_dir() -> std::path::PathBuf {
    common::repo().join(".deps/models/yolov3-tiny")
}

fn mat_f32(m: &Mat) -> Vec<f32> {
    m.data_typed::<f32>().unwrap().to_vec()
}

#[test]
fn onnx_heads_match_opencv_darknet_reader() {
    let shared = common::shared_data();
    common::require_setup();
    let dir = model_dir();
    let mut cv =
        dnn::read_net_from_darknet(dir.join("yolov3-tiny.cfg"), &dir.join("yolov3-tiny.weights").to_string_lossy())
            .unwrap();
    cv.set_preferable_backend(dnn::DNN_BACKEND_OPENCV).unwrap();
    cv.set_preferable_target(dnn::DNN_TARGET_CPU).unwrap();
    let cfg = DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap();
    let mut ort = OnnxDetector::new(cfg.clone(), 1).unwrap();
    let images = ["fca/carla_dataset/train_new/data1.png", "das/smile.jpg"];
    for rel in images {
        let img = imgcodecs::imread(&*shared.join(rel).to_string_lossy(), imgcodecs::IMREAD_COLOR).unwrap();
        assert!(!img.empty(), "{rel} did not load");
        let blob = dnn::blob_from_image(&img, 1.0 / 255.0, Size::new(416, 416), Scalar::default(), true, false, CV_32F)
            .unwrap();
        cv.set_input(&blob, "", 1.0, Scalar::default()).unwrap();
        let mut outs: Vector<Mat> = Vector::new();
        let names: Vector<String> = Vector::from_iter(["conv_15", "conv_22", "yolo_16", "yolo_23"]);
        cv.forward(&mut outs, &names).unwrap();
        let raw = ort.infer(mat_f32(&blob), &pav::detect::preprocess::InputMap::identity(416, 416)).unwrap();
        for (k, head) in ["head0", "head1"].iter().enumerate() {
            let ours = raw.iter().find(|o| o.name == *head).unwrap();
            let theirs = mat_f32(&outs.get(k).unwrap());
            assert_eq!(ours.data.len(), theirs.len(), "{head} size");
            let worst = ours.data.iter().zip(&theirs).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
            eprintln!("{rel} {head}: max |onnx - opencv| = {worst:e}");
            assert!(worst < 1e-4, "{rel} {head}: max abs difference {worst}");
        }
        // OpenCV's [yolo] layers decode to rows (cx, cy, w, h, obj, obj·p(class)); our decoder
        // must give the same best car score from the raw heads.
        let id = InputMap { scale_x: 1.0, scale_y: 1.0, pad_x: 0.0, pad_y: 0.0, frame_w: 416.0, frame_h: 416.0 };
        let props = decode(&cfg.output, &raw, 416, 416, 80, &id).unwrap();
        let ours = props.best(&[2]).unwrap().score;
        let mut theirs = 0f32;
        for k in 2..4 {
            let m = mat_f32(&outs.get(k).unwrap());
            theirs = m.chunks(85).map(|r| r[5 + 2]).fold(theirs, f32::max);
        }
        eprintln!("{rel}: best car score ours {ours:.6}, opencv {theirs:.6}");
        if theirs > 0.0 {
            assert!((ours - theirs).abs() < 1e-4, "{rel}: car score {ours} vs OpenCV {theirs}");
        } else {
            // OpenCV zeroes the class scores of rows below its objectness cut; both say "no car".
            assert!(ours < 0.01, "{rel}: OpenCV sees no car, we score {ours}");
        }
    }
}

#[test]
fn shipped_config_anchors_match_the_cfg() {
    let dir = model_dir();
    if !dir.join("yolov3-tiny.cfg").exists() {
        common::require_setup();
    }
    let net = Network::from_file(&dir.join("yolov3-tiny.cfg")).unwrap();
    let cfg = DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap();
    let OutputLayout::Darknet { heads } = &cfg.output else { panic!("yolov3-tiny config must use the darknet layout") };
    let from_cfg: Vec<Vec<[f32; 2]>> = net
        .layers
        .iter()
        .filter_map(|l| match l {
            Layer::Yolo(h) => Some(h.anchors.iter().map(|&(w, h)| [w, h]).collect()),
            _ => None,
        })
        .collect();
    let from_toml: Vec<Vec<[f32; 2]>> = heads.iter().map(|h| h.anchors.clone()).collect();
    assert_eq!(from_toml, from_cfg);
    assert_eq!(cfg.class_names[2], "car");
}
