//! Greedy per-class non-maximum suppression.

use super::{BBox, Detection};

/// Intersection over union of two xyxy boxes (0 when either is empty).
pub fn iou(a: &BBox, b: &BBox) -> f32 {
    let iw = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let ih = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let area = |r: &BBox| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - inter;
    if union > 0.0 {
        inter / union
    } else {
        0.0
    }
}

/// Keeps the highest-scoring box of each overlapping group (IoU > `thr`) within a class.
pub fn nms(mut dets: Vec<Detection>, thr: f32) -> Vec<Detection> {
    dets.sort_by(|a, b| b.score.total_cmp(&a.score));
    let mut keep: Vec<Detection> = Vec::new();
    for d in dets {
        if !keep.iter().any(|k| k.class_id == d.class_id && iou(&k.bbox, &d.bbox) > thr) {
            keep.push(d);
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suppresses_overlaps_within_class_only() {
        let d = |c, s, x| Detection { class_id: c, score: s, bbox: [x, 0.0, x + 10.0, 10.0] };
        let kept = nms(vec![d(2, 0.6, 1.0), d(2, 0.9, 0.0), d(7, 0.5, 0.0), d(2, 0.4, 50.0)], 0.45);
        assert_eq!(kept, vec![d(2, 0.9, 0.0), d(7, 0.5, 0.0), d(2, 0.4, 50.0)]);
        assert_eq!(iou(&[0.0, 0.0, 0.0, 0.0], &[0.0, 0.0, 0.0, 0.0]), 0.0);
    }
}
