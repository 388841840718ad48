//! The input defences against an independent implementation on real images: FCA's 11 photos and
//! every eighth frame of the turntable fixture through `scripts/reference_defences.py` (OpenCV 5.0
//! and NumPy; `tests/reference/defences.tsv`). Median smoothing, bit-depth squeezing and JPEG must
//! give the reference's bytes exactly; Gaussian noise, whose draws differ, must change each image
//! as much, with the same bias and spread (clipping at 0 and 255 shapes both).

use crate::common;

use pav::detect::defence::{apply_chain, parse_chain};
use pav::image::Frame;
use sha2::{Digest, Sha256};

/// Mean absolute change, mean change and its standard deviation, in levels.
fn change(before: &Frame, after: &Frame) -> [f64; 3] {
    let d: Vec<f64> = after.bgr.iter().zip(&before.bgr).map(|(&a, &b)| a as f64 - b as f64).collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
    [d.iter().map(|x| x.abs()).sum::<f64>() / n, mean, sd]
}

#[test]
fn defences_match_opencv_and_numpy_on_photos_and_turntable_frames() {
    common::real_data();
    let text = std::fs::read_to_string(common::repo().join("tests/reference/defences.tsv")).unwrap();
    let mut current: Option<(String, Frame)> = None;
    let mut checked = 0;
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split('\t').collect();
        let (label, spec, digest) = (f[0], f[1], f[2]);
        let want: Vec<f64> = f[3..].iter().map(|v| v.parse().unwrap()).collect();
        if current.as_ref().is_none_or(|(l, _)| l != label) {
            current = Some((label.to_string(), common::reference_image(label)));
        }
        let image = &current.as_ref().unwrap().1;
        let mut out = image.clone();
        apply_chain(&parse_chain(spec).unwrap(), &mut out).unwrap();
        let got = change(image, &out);
        if digest == "-" {
            // Two independent draws: allow 5 standard errors of the difference of two means over
            // the image's samples (a wrong sigma or a biased generator misses by far more).
            let tol = 5.0 * std::f64::consts::SQRT_2 * want[2] / (out.bgr.len() as f64).sqrt() + 0.0001;
            for (k, what) in ["mean absolute change", "mean change", "spread"].iter().enumerate() {
                let (g, w) = (got[k], want[k]);
                assert!((g - w).abs() <= tol, "{label} {spec}: {what} {g:.4}, reference {w:.4} (tolerance {tol:.4})");
            }
        } else {
            let hex: String = Sha256::digest(&out.bgr).iter().map(|b| format!("{b:02x}")).collect();
            assert_eq!(
                hex, digest,
                "{label} {spec}: bytes differ (mean absolute change {:.4}, reference {:.4})",
                got[0], want[0]
            );
        }
        checked += 1;
    }
    assert_eq!(checked, 17 * 13);
}

/// Feature norm clipping in YOLOX-Nano after its three backbone stages (tensors 781, 841 and 886)
/// against `scripts/reference_clip.py` (the onnx package, ReduceL2/ReduceMean/Min instead of pav's
/// operators; `tests/reference/clip_yolox_nano.tsv`): the best car score on every image within
/// 1e-4 at each level (measured: 4e-6); at an infinite level, every proposal exactly as without clipping.
#[test]
fn feature_norm_clipping_matches_an_independent_rewrite() {
    use pav::detect::defence::{Clip, Defence};
    use pav::detect::onnx::OnnxDetector;
    use pav::detect::{Detector, DetectorConfig};
    common::real_data();
    let text = std::fs::read_to_string(common::repo().join("tests/reference/clip_yolox_nano.tsv")).unwrap();
    let plain_cfg = DetectorConfig::load(&common::detector_config("yolox_nano")).unwrap();
    let layers: Vec<String> = ["781", "841", "886"].map(String::from).to_vec();
    let mut plain = OnnxDetector::new(plain_cfg.clone(), 1).unwrap();
    let mut clipped = std::collections::BTreeMap::new();
    let (mut checked, mut worst) = (0, 0f32);
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split('\t').collect();
        let (label, level, want): (&str, f32, f32) = (f[0], f[1].parse().unwrap(), f[2].parse().unwrap());
        let det = clipped.entry(f[1].to_string()).or_insert_with(|| {
            let cfg = plain_cfg.defended(&[Defence::Clip(Clip { layers: layers.clone(), level })]).unwrap();
            OnnxDetector::new(cfg, 1).unwrap()
        });
        let image = common::reference_image(label);
        let props = det.propose(&image).unwrap();
        let got = props.best(det.target_classes()).map_or(0.0, |b| b.score);
        worst = worst.max((got - want).abs());
        assert!((got - want).abs() <= 1e-4, "{label} level {level}: car score {got:.6}, reference {want:.6}");
        if level.is_infinite() {
            assert_eq!(props, plain.propose(&image).unwrap(), "{label}: an infinite level changes nothing");
        }
        checked += 1;
    }
    eprintln!("{checked} image-levels, largest difference {worst:.6}");
    assert_eq!(checked, 17 * 4);
}
