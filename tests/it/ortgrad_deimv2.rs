//! DEIMv2 (an int8 DETR) as a white box: its float surrogate (`detect::surrogate`) cut at the
//! class logits its post-processor reads, shapes folded (`detect::fold`), differentiated. The
//! loss without objectness (`attack::loss::Predictions::detr`) on a real photo, and descent on the
//! photo's pixels hides the car from the surrogate and from the int8 model it stands in for.

use crate::common;

use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::whitebox::{WhiteBox, WhiteBoxOptions};
use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav::image::Frame;

/// The frame as an RGB `size × size` composite in [0, 1] (nearest sampling is enough here).
fn composite(f: &Frame, size: usize) -> Vec<f32> {
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

/// The int8 model's best car score on an RGB composite.
fn int8_car(det: &mut OnnxDetector, img: &[f32], size: usize) -> f32 {
    let bgr: Vec<f32> = img.chunks(3).flat_map(|p| [p[2] * 255.0, p[1] * 255.0, p[0] * 255.0]).collect();
    let frame = Frame::from_levels(size, size, &bgr);
    det.propose(&frame).unwrap().best(det.target_classes()).map(|b| b.score).unwrap_or(0.0)
}

#[test]
fn deimv2_trains_as_a_named_surrogate_and_descent_hides_the_car() {
    let shared = common::real_data();
    let cfg = DetectorConfig::load(&common::detector_config("deimv2_atto_int8")).unwrap();
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: cfg.target_classes.clone(),
        reduce: Reduce::Mean,
        proposals: ProposalSet::ArgMax,
        iou: false,
        box_gradient: false,
    };
    let e = WhiteBox::load(&cfg, loss.clone(), 416).err().expect("refused").to_string();
    assert!(e.contains("surrogate = true"), "{e}");
    let o = WhiteBoxOptions { composite: 416, input: None, threads: 2, surrogate: true };
    let wb = WhiteBox::with_options(&cfg, loss, o).unwrap();
    let s = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12507.npz")).unwrap();
    let mut img = composite(&s.image, 416);
    let mut det = OnnxDetector::new(cfg.clone(), 1).unwrap();
    let g = wb.loss_and_grad(&img, 416, 1.0, None).unwrap();
    let before = (g.loss.max_score, int8_car(&mut det, &img, 416));
    eprintln!("photo: {:?}, int8 car {:.3}", g.loss, before.1);
    assert!(g.loss.max_score > 0.5 && g.loss.proposals > 0 && before.1 > 0.5, "{:?} {}", g.loss, before.1);
    assert!(g.grad.iter().all(|v| v.is_finite()) && g.grad.iter().any(|v| *v != 0.0));
    // Ten signed-gradient steps of 2/255 on every pixel: a digital attack on the photo itself.
    // Measured: surrogate 0.685 → 0.072, int8 0.688 → 0.057.
    for _ in 0..10 {
        let g = wb.loss_and_grad(&img, 416, 1.0, None).unwrap();
        img.iter_mut().zip(&g.grad).for_each(|(v, d)| *v = (*v - 2.0 / 255.0 * d.signum()).clamp(0.0, 1.0));
    }
    let after = (wb.loss(&img, 416).unwrap().max_score, int8_car(&mut det, &img, 416));
    eprintln!("car score, surrogate {:.3} → {:.3}, int8 {:.3} → {:.3}", before.0, after.0, before.1, after.1);
    assert!(after.0 < 0.5 * before.0 && after.1 < 0.5 * before.1, "{before:?} → {after:?}");
}
