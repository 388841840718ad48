//! Digital-world metrics of the paper's Table II over a set of images with one car each.
//!
//! ASR = 1 − (images where some car detection scores above the threshold) / images, as the
//! authors compute it. P@0.5 is the car class's average precision at IoU 0.5 (COCO's
//! 101-point interpolation), which is what the authors report under that name.

use pav_detect::nms::iou;
use pav_detect::BBox;

/// Car detections on one image and its ground-truth box.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ImageDetections {
    /// Ground-truth car box (None: no box known; the image counts only for ASR).
    pub gt: Option<BBox>,
    /// (score, box) of every car detection after NMS.
    pub cars: Vec<(f32, BBox)>,
}

impl ImageDetections {
    /// The best car score (0 without a car detection).
    pub fn best_score(&self) -> f32 {
        self.cars.iter().map(|c| c.0).fold(0.0, f32::max)
    }

    /// Whether a car is detected at `threshold` (`detect::detected`).
    pub fn car_detected(&self, threshold: f32) -> bool {
        self.cars.iter().any(|(s, _)| pav_detect::detected(*s, threshold))
    }
}

/// Attack success rate at `threshold` (None for no images).
pub fn asr(images: &[ImageDetections], threshold: f32) -> Option<f64> {
    if images.is_empty() {
        return None;
    }
    let detected = images.iter().filter(|i| i.car_detected(threshold)).count();
    Some(1.0 - detected as f64 / images.len() as f64)
}

/// A mean difference with its 95 % paired-bootstrap interval.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Interval {
    /// Mean of the differences.
    pub mean: f64,
    /// 2.5th percentile of the resampled means.
    pub lo: f64,
    /// 97.5th percentile of the resampled means.
    pub hi: f64,
    /// Number of paired units (views).
    pub n: usize,
}

/// The mean of per-unit differences `d` with a 95 % percentile interval from `resamples`
/// bootstrap resamples of the units (drawn with replacement from `seed`); None for no units.
pub fn paired_bootstrap(d: &[f64], resamples: usize, seed: u64) -> Option<Interval> {
    if d.is_empty() {
        return None;
    }
    let n = d.len();
    let mut rng = pav_core::rng::Rng::new(seed);
    let mut means: Vec<f64> = (0..resamples.max(1))
        .map(|_| (0..n).map(|_| d[(rng.next_u64() % n as u64) as usize]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    let at = |q: f64| means[((q * (means.len() - 1) as f64).round() as usize).min(means.len() - 1)];
    Some(Interval { mean: d.iter().sum::<f64>() / n as f64, lo: at(0.025), hi: at(0.975), n })
}

/// Car AP at IoU 0.5 over the images with a ground-truth box (None when there are none).
pub fn ap50(images: &[ImageDetections]) -> Option<f64> {
    let with_gt: Vec<&ImageDetections> = images.iter().filter(|i| i.gt.is_some()).collect();
    if with_gt.is_empty() {
        return None;
    }
    let mut dets: Vec<(f32, usize, BBox)> =
        with_gt.iter().enumerate().flat_map(|(k, im)| im.cars.iter().map(move |(s, b)| (*s, k, *b))).collect();
    dets.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut matched = vec![false; with_gt.len()];
    let (mut tp, mut fp) = (0usize, 0usize);
    let mut pr = Vec::with_capacity(dets.len());
    for (_, k, b) in dets {
        let gt = with_gt[k].gt.unwrap_or_default();
        if !matched[k] && iou(&b, &gt) >= 0.5 {
            matched[k] = true;
            tp += 1;
        } else {
            fp += 1;
        }
        pr.push((tp as f64 / with_gt.len() as f64, tp as f64 / (tp + fp) as f64));
    }
    // Precision envelope (non-increasing from the right), sampled at 101 recall levels.
    for i in (0..pr.len().saturating_sub(1)).rev() {
        pr[i].1 = pr[i].1.max(pr[i + 1].1);
    }
    let mut sum = 0.0;
    for r in 0..=100 {
        let r = r as f64 / 100.0;
        sum += pr.iter().find(|(rec, _)| *rec >= r - 1e-12).map(|p| p.1).unwrap_or(0.0);
    }
    Some(sum / 101.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bootstrap_interval_brackets_the_mean_and_shrinks_with_agreement() {
        let d: Vec<f64> = (0..11).map(|i| -0.1 + 0.02 * (i as f64 - 5.0)).collect();
        let iv = paired_bootstrap(&d, 4000, 3).unwrap();
        assert!((iv.mean + 0.1).abs() < 1e-12 && iv.lo < iv.mean && iv.mean < iv.hi, "{iv:?}");
        // All below zero: the interval excludes zero. Equal differences: a zero-width interval.
        assert!(iv.hi < 0.0);
        let same = paired_bootstrap(&[0.25; 5], 100, 1).unwrap();
        assert_eq!((same.lo, same.hi), (0.25, 0.25));
        // One large win among ties: the interval reaches zero.
        let mut one = vec![0.0; 10];
        one[3] = -0.5;
        let iv = paired_bootstrap(&one, 4000, 3).unwrap();
        assert!(iv.lo < iv.mean && iv.hi == 0.0, "{iv:?}");
        assert!(paired_bootstrap(&[], 10, 1).is_none());
    }

    fn im(gt: BBox, cars: &[(f32, BBox)]) -> ImageDetections {
        ImageDetections { gt: Some(gt), cars: cars.to_vec() }
    }

    #[test]
    fn asr_counts_images_with_a_car_at_or_above_threshold() {
        let b = [0.0, 0.0, 10.0, 10.0];
        // A score equal to the threshold is a detection (`detect::detected`), as in A_physical.
        let ims = [im(b, &[(0.7, b)]), im(b, &[(0.4, b)]), im(b, &[]), im(b, &[(0.5, b)])];
        assert_eq!(asr(&ims, 0.5), Some(0.5));
        assert_eq!(asr(&ims, 0.3), Some(0.25));
        assert_eq!(asr(&[], 0.5), None);
    }

    #[test]
    fn ap50_perfect_missing_and_ranked() {
        let g = [0.0, 0.0, 10.0, 10.0];
        let off = [20.0, 20.0, 30.0, 30.0];
        assert_eq!(ap50(&[im(g, &[(0.9, g)]), im(g, &[(0.8, g)])]), Some(1.0));
        assert_eq!(ap50(&[im(g, &[]), im(g, &[(0.8, off)])]), Some(0.0));
        // One hit ranked below one false positive: precision 0.5 up to recall 0.5, then nothing.
        let ap = ap50(&[im(g, &[(0.6, g)]), im(g, &[(0.9, off)])]).unwrap();
        assert!((ap - 0.5 * 51.0 / 101.0).abs() < 1e-9, "{ap}");
        // A duplicate of a matched box is a false positive.
        let ap = ap50(&[im(g, &[(0.9, g), (0.8, g)])]).unwrap();
        assert!((ap - 1.0).abs() < 1e-9);
        assert!((iou(&g, &[5.0, 0.0, 15.0, 10.0]) - 1.0 / 3.0).abs() < 1e-6);
    }
}
