//! The paper's detector losses on YOLO head maps: L1 = mean objectness over the boxes, L2 = mean
//! target-class confidence over the proposals of the target class, with their exact gradient with
//! respect to the head logits.
//!
//! "Boxes" are the predictions whose objectness reaches `box_threshold`; "proposals" are those
//! boxes whose most likely class is a target class. The sets are chosen on the values (no
//! gradient through the choice); an empty set gives 0 and a zero gradient, not 0/0.

use crate::detect::darknet::cfg::YoloHead;

/// Sigmoid as `(1 + tanh(x/2))/2`, and its derivative `(1 − tanh²(x/2))/4`: both finite for every
/// finite logit, where `1/(1 + exp(−x))` makes a NaN gradient below x ≈ −88 in f32.
pub fn sigmoid(x: f32) -> (f32, f32) {
    let t = (0.5 * x).tanh();
    (0.5 + 0.5 * t, 0.25 * (1.0 - t * t))
}

/// One batch-1 head map `[A·(5+C), H, W]`, flattened, with its `(H, W)`.
pub type HeadMap = (Vec<f32>, (usize, usize));

/// The detector-loss settings.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectionLoss {
    /// Objectness from which a prediction counts as a box.
    pub box_threshold: f32,
    /// Target class indices (COCO car = 2).
    pub target: Vec<usize>,
}

/// L1 and L2 with the set sizes and the strongest target detection, for logs.
#[derive(Clone, Debug, PartialEq)]
pub struct LossTerms {
    /// Mean objectness over the boxes.
    pub l1: f32,
    /// Mean target-class confidence over the target proposals.
    pub l2: f32,
    /// Number of boxes (n_o).
    pub boxes: usize,
    /// Number of target proposals (n_c).
    pub proposals: usize,
    /// Highest objectness × target confidence over all predictions (the detection score).
    pub max_score: f32,
}

/// Why head maps cannot be scored.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct HeadShapeError(String);

impl DetectionLoss {
    /// L1 and L2 of the head maps, and the gradient of `L1 + beta·L2` with respect to each map.
    pub fn yolo(
        &self,
        maps: &[HeadMap],
        heads: &[YoloHead],
        beta: f32,
    ) -> Result<(LossTerms, Vec<Vec<f32>>), HeadShapeError> {
        if maps.len() != heads.len() {
            return Err(HeadShapeError(format!("{} head maps for {} [yolo] heads", maps.len(), heads.len())));
        }
        // First pass: the sets; second: the means and their gradient.
        let (mut boxes, mut proposals, mut max_score) = (0usize, 0usize, 0f32);
        let mut picked: Vec<Vec<(usize, Option<usize>)>> = Vec::new(); // per map: (objectness index, proposal class index)
        for ((map, (h, w)), head) in maps.iter().zip(heads) {
            let (a, c, hw) = (head.anchors.len(), head.classes, h * w);
            if map.len() != a * (5 + c) * hw {
                return Err(HeadShapeError(format!(
                    "a head map of {} values does not fit {a} anchors × (5 + {c}) × {h}×{w}",
                    map.len()
                )));
            }
            let mut here = Vec::new();
            for ai in 0..a {
                let base = ai * (5 + c) * hw;
                for p in 0..hw {
                    let o = sigmoid(map[base + 4 * hw + p]).0;
                    let cls = |k: usize| sigmoid(map[base + (5 + k) * hw + p]).0;
                    let (best, _) =
                        (0..c).fold((0, f32::NEG_INFINITY), |m, k| if cls(k) > m.1 { (k, cls(k)) } else { m });
                    for &k in self.target.iter().filter(|&&k| k < c) {
                        max_score = max_score.max(o * cls(k));
                    }
                    if o >= self.box_threshold && o.is_finite() {
                        boxes += 1;
                        let prop = self.target.contains(&best).then(|| base + (5 + best) * hw + p);
                        proposals += prop.is_some() as usize;
                        here.push((base + 4 * hw + p, prop));
                    }
                }
            }
            picked.push(here);
        }
        let (n1, n2) = (boxes.max(1) as f32, proposals.max(1) as f32);
        let (mut s1, mut s2) = (0f32, 0f32);
        let mut grads: Vec<Vec<f32>> = maps.iter().map(|(m, _)| vec![0f32; m.len()]).collect();
        for ((map, _), (here, g)) in maps.iter().zip(picked.iter().zip(&mut grads)) {
            for &(oi, prop) in here {
                let (o, d) = sigmoid(map[oi]);
                s1 += o;
                g[oi] += d / n1;
                if let Some(ci) = prop {
                    let (v, d) = sigmoid(map[ci]);
                    s2 += v;
                    g[ci] += beta * d / n2;
                }
            }
        }
        Ok((LossTerms { l1: s1 / n1, l2: s2 / n2, boxes, proposals, max_score }, grads))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head() -> YoloHead {
        YoloHead { anchors: vec![(10.0, 14.0), (23.0, 27.0)], classes: 3 }
    }

    /// A 2-anchor, 3-class, 2×2 head with chosen logits.
    fn map(obj: [f32; 8], cls_top: [usize; 8]) -> (Vec<f32>, (usize, usize)) {
        let (a, c, hw) = (2, 3, 4);
        let mut v = vec![0f32; a * (5 + c) * hw];
        for i in 0..a * hw {
            let (ai, p) = (i / hw, i % hw);
            v[(ai * (5 + c) + 4) * hw + p] = obj[i];
            for k in 0..c {
                v[(ai * (5 + c) + 5 + k) * hw + p] = if k == cls_top[i] { 3.0 } else { -3.0 };
            }
        }
        (v, (2, 2))
    }

    #[test]
    fn sigmoid_is_finite_with_finite_gradient_at_extreme_logits() {
        let v: Vec<(f32, f32)> = [-1e4f32, -100.0, 0.0, 100.0, 1e4].iter().map(|x| sigmoid(*x)).collect();
        assert_eq!((v[0].0, v[2].0, v[4].0), (0.0, 0.5, 1.0));
        assert!(v.iter().all(|(y, d)| y.is_finite() && d.is_finite() && *d >= 0.0), "{v:?}");
        assert!((v[2].1 - 0.25).abs() < 1e-6);
    }

    #[test]
    fn means_over_boxes_and_target_proposals() {
        let loss = DetectionLoss { box_threshold: 0.5, target: vec![2] };
        // Objectness logits: 0 → 0.5 (a box, exactly on the threshold), 2 → 0.88, −5 → no box.
        let m = map([0.0, 2.0, -5.0, -5.0, 2.0, -5.0, -5.0, -5.0], [2, 1, 2, 0, 2, 0, 0, 0]);
        let (t, _) = loss.yolo(&[m], &[head()], 1.0).unwrap();
        assert_eq!((t.boxes, t.proposals), (3, 2));
        let s = |x: f32| 1.0 / (1.0 + (-x).exp());
        assert!((t.l1 - (s(0.0) + 2.0 * s(2.0)) / 3.0).abs() < 1e-6, "{}", t.l1);
        assert!((t.l2 - s(3.0)).abs() < 1e-6, "{}", t.l2);
        assert!((t.max_score - s(2.0) * s(3.0)).abs() < 1e-6);
    }

    #[test]
    fn gradient_matches_central_differences() {
        let loss = DetectionLoss { box_threshold: 0.5, target: vec![2] };
        let (mut m, hw) = map([0.3, 2.0, -5.0, -5.0, 1.5, -5.0, -5.0, -5.0], [2, 1, 2, 0, 2, 0, 0, 0]);
        // Distinct logits so the sets do not change under the small steps below.
        for (i, v) in m.iter_mut().enumerate() {
            *v += 0.01 * (i % 7) as f32;
        }
        let beta = 0.7;
        let (_, g) = loss.yolo(&[(m.clone(), hw)], &[head()], beta).unwrap();
        let total = |m: &[f32]| {
            let (t, _) = loss.yolo(&[(m.to_vec(), hw)], &[head()], beta).unwrap();
            t.l1 as f64 + beta as f64 * t.l2 as f64
        };
        let eps = 1e-2;
        for i in 0..m.len() {
            let (mut p, mut q) = (m.clone(), m.clone());
            p[i] += eps;
            q[i] -= eps;
            let fd = (total(&p) - total(&q)) / (2.0 * eps as f64);
            assert!((fd - g[0][i] as f64).abs() < 1e-4, "logit {i}: {} vs {fd}", g[0][i]);
        }
        assert!(g[0].iter().filter(|v| **v != 0.0).count() == 5, "3 boxes and 2 proposals carry gradient");
    }

    #[test]
    fn no_boxes_gives_zero_loss_and_zero_gradient() {
        let loss = DetectionLoss { box_threshold: 0.5, target: vec![2] };
        let (t, g) = loss.yolo(&[map([-9.0; 8], [2; 8])], &[head()], 1.0).unwrap();
        assert_eq!((t.boxes, t.proposals, t.l1 + t.l2), (0, 0, 0.0));
        assert!(g[0].iter().all(|x| *x == 0.0));
        assert!(loss.yolo(&[(vec![0.0; 5], (1, 1))], &[head()], 1.0).is_err());
    }
}
