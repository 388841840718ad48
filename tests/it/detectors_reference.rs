//! Real detectors on the real CARLA samples reproduce the reference car scores of
//! derived_test_labels.tsv (computed independently with onnxruntime; that reference resized with
//! PIL's antialiased bilinear filter, which `interpolation = "antialias"` reproduces bit for bit).

use crate::common;

use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav::image::resize::Interpolation;

/// Max score of the target class on every sample, with the config's preprocessing optionally overridden.
fn scores(detector: &str, interpolation: Option<Interpolation>) -> Vec<(String, f32, f32)> {
    let shared = common::real_data();
    let mut cfg = DetectorConfig::load(&common::detector_config(detector)).unwrap();
    if let Some(i) = interpolation {
        cfg.input.interpolation = i;
    }
    let mut det = OnnxDetector::new(cfg, 1).unwrap();
    let column = format!("car_score_{detector}");
    let mut out = Vec::new();
    for (npz, cols) in common::reference_labels(&shared) {
        let s = CarlaSample::load(&npz).unwrap();
        let want: f32 = cols[&column].parse().unwrap();
        let got = det.propose(&s.image).unwrap().best(det.target_classes()).map(|b| b.score).unwrap_or(0.0);
        out.push((npz.file_name().unwrap().to_string_lossy().into_owned(), got, want));
    }
    out
}

/// Scores must match the reference within `tol` under the reference's resize, and detection
/// decisions at 0.5 must agree under both resizes wherever the reference is over 0.1 from 0.5.
fn check(detector: &str, tol: f32) {
    let rows = scores(detector, Some(Interpolation::Antialias));
    let shipped = scores(detector, None);
    for ((f, got, want), (_, got_cfg, _)) in rows.iter().zip(&shipped) {
        assert!((got - want).abs() <= tol, "{detector} {f}: score {got:.4}, reference {want:.3}");
        if (want - 0.5).abs() > 0.1 {
            assert_eq!(*got >= 0.5, *want >= 0.5, "{detector} {f}: {got:.3} vs reference {want:.3}");
            assert_eq!(
                *got_cfg >= 0.5,
                *want >= 0.5,
                "{detector} {f} (config resize): {got_cfg:.3} vs reference {want:.3}"
            );
        }
    }
}

// Tolerances: a separate Python run (PIL resize + onnxruntime 1.31.1, this machine) gives our
// scores to 1e-4 on every sample. The TSV differs from that by up to 0.016 for the two YOLOs and
// by up to 0.115 for the int8 DETR, whose dynamically quantized kernels amplify small numeric
// differences between onnxruntime builds and CPUs.

#[test]
fn yolox_nano_matches_reference_scores() {
    check("yolox_nano", 0.02);
}

#[test]
fn yolov8n_int8_matches_reference_scores() {
    check("yolov8n_int8", 0.02);
}

#[test]
fn deimv2_atto_int8_matches_reference_scores() {
    check("deimv2_atto_int8", 0.12);
}
