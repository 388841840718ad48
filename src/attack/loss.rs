//! The paper's detector losses on YOLO head maps: L1 = mean objectness over the boxes, L2 = mean
//! target-class confidence over the proposals of the target class.
//!
//! "Boxes" are the predictions whose objectness reaches `box_threshold`; "proposals" are those
//! boxes whose most likely class is a target class. The sets are chosen on the values (no
//! gradient through the choice); an empty set gives 0, not 0/0.

use crate::detect::darknet::cfg::YoloHead;
use candle_core::{Result, Tensor};

/// Sigmoid as `(1 + tanh(x/2))/2`: finite with a finite gradient for every finite logit, where
/// `1/(1 + exp(−x))` overflows to a NaN gradient below x ≈ −88 in f32.
pub fn sigmoid(x: &Tensor) -> Result<Tensor> {
    (x * 0.5)?.tanh()?.affine(0.5, 0.5)
}

/// The detector-loss settings.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectionLoss {
    /// Objectness from which a prediction counts as a box.
    pub box_threshold: f32,
    /// Target class indices (COCO car = 2).
    pub target: Vec<usize>,
}

/// L1 and L2 with the set sizes and the strongest target detection, for logs.
#[derive(Debug)]
pub struct LossTerms {
    /// Mean objectness over the boxes (scalar tensor).
    pub l1: Tensor,
    /// Mean target-class confidence over the target proposals (scalar tensor).
    pub l2: Tensor,
    /// Number of boxes (n_o).
    pub boxes: usize,
    /// Number of target proposals (n_c).
    pub proposals: usize,
    /// Highest objectness × target confidence over all predictions (the detection score).
    pub max_score: f32,
}

impl DetectionLoss {
    /// L1 and L2 for batch-1 head maps `[1, A·(5+C), H, W]` of `heads`.
    pub fn yolo(&self, maps: &[Tensor], heads: &[YoloHead]) -> Result<LossTerms> {
        if maps.len() != heads.len() {
            candle_core::bail!("{} head maps for {} [yolo] heads", maps.len(), heads.len());
        }
        let (mut s1, mut s2): (Option<Tensor>, Option<Tensor>) = (None, None);
        let (mut boxes, mut proposals, mut max_score) = (0usize, 0usize, 0f32);
        let add = |acc: &mut Option<Tensor>, t: Tensor| -> Result<()> {
            *acc = Some(match acc.take() {
                None => t,
                Some(a) => (a + t)?,
            });
            Ok(())
        };
        for (map, head) in maps.iter().zip(heads) {
            let (b, ch, h, w) = map.dims4()?;
            let (a, c) = (head.anchors.len(), head.classes);
            if b != 1 || ch != a * (5 + c) {
                candle_core::bail!("head map {:?} does not fit {a} anchors × (5 + {c}) with batch 1", map.dims());
            }
            let t = map.reshape((a, 5 + c, h * w))?;
            let obj = sigmoid(&t.narrow(1, 4, 1)?)?.squeeze(1)?; // [A, HW]
            let cls = sigmoid(&t.narrow(1, 5, c)?)?; // [A, C, HW]
            let obj_v: Vec<Vec<f32>> = obj.to_dtype(candle_core::DType::F32)?.to_vec2()?;
            let cls_v: Vec<Vec<Vec<f32>>> = cls.to_dtype(candle_core::DType::F32)?.to_vec3()?;
            let (mut box_mask, mut prop_mask) = (vec![0f32; a * h * w], vec![0f32; a * c * h * w]);
            for ai in 0..a {
                for p in 0..h * w {
                    let o = obj_v[ai][p];
                    let (best, _) = (0..c).fold((0, f32::NEG_INFINITY), |m, k| {
                        if cls_v[ai][k][p] > m.1 {
                            (k, cls_v[ai][k][p])
                        } else {
                            m
                        }
                    });
                    for &k in &self.target {
                        if k < c {
                            max_score = max_score.max(o * cls_v[ai][k][p]);
                        }
                    }
                    if o >= self.box_threshold && o.is_finite() {
                        box_mask[ai * h * w + p] = 1.0;
                        boxes += 1;
                        if self.target.contains(&best) {
                            proposals += 1;
                            prop_mask[(ai * c + best) * h * w + p] = 1.0;
                        }
                    }
                }
            }
            let dev = map.device();
            let bm = Tensor::from_vec(box_mask, (a, h * w), dev)?.to_dtype(map.dtype())?;
            let pm = Tensor::from_vec(prop_mask, (a, c, h * w), dev)?.to_dtype(map.dtype())?;
            add(&mut s1, (obj * bm)?.sum_all()?)?;
            add(&mut s2, (cls * pm)?.sum_all()?)?;
        }
        let zero = || Tensor::new(0f32, &candle_core::Device::Cpu);
        let l1 = match s1 {
            Some(s) => (s / boxes.max(1) as f64)?,
            None => zero()?,
        };
        let l2 = match s2 {
            Some(s) => (s / proposals.max(1) as f64)?,
            None => zero()?,
        };
        Ok(LossTerms { l1, l2, boxes, proposals, max_score })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn head() -> YoloHead {
        YoloHead { anchors: vec![(10.0, 14.0), (23.0, 27.0)], classes: 3 }
    }

    /// A 2-anchor, 3-class, 2×2 head with chosen logits.
    fn map(obj: [f32; 8], cls_top: [usize; 8]) -> Tensor {
        let (a, c, hw) = (2, 3, 4);
        let mut v = vec![0f32; a * (5 + c) * hw];
        for i in 0..a * hw {
            let (ai, p) = (i / hw, i % hw);
            v[(ai * (5 + c) + 4) * hw + p] = obj[i];
            for k in 0..c {
                v[(ai * (5 + c) + 5 + k) * hw + p] = if k == cls_top[i] { 3.0 } else { -3.0 };
            }
        }
        Tensor::from_vec(v, (1, a * (5 + c), 2, 2), &Device::Cpu).unwrap()
    }

    #[test]
    fn sigmoid_is_finite_with_finite_gradient_at_extreme_logits() {
        let x = Var::from_vec(vec![-1e4f32, -100.0, 0.0, 100.0, 1e4], 5, &Device::Cpu).unwrap();
        let y = sigmoid(x.as_tensor()).unwrap();
        let v: Vec<f32> = y.to_vec1().unwrap();
        assert_eq!(v[0], 0.0);
        assert_eq!(v[2], 0.5);
        assert_eq!(v[4], 1.0);
        let g: Vec<f32> = y.sum_all().unwrap().backward().unwrap().get(x.as_tensor()).unwrap().to_vec1().unwrap();
        assert!(g.iter().all(|v| v.is_finite()), "{g:?}");
        assert!((g[2] - 0.25).abs() < 1e-6);
    }

    #[test]
    fn means_over_boxes_and_target_proposals() {
        let loss = DetectionLoss { box_threshold: 0.5, target: vec![2] };
        // Objectness logits: 0 → 0.5 (a box, exactly on the threshold), 2 → 0.88, −5 → no box.
        let m = map([0.0, 2.0, -5.0, -5.0, 2.0, -5.0, -5.0, -5.0], [2, 1, 2, 0, 2, 0, 0, 0]);
        let t = loss.yolo(&[m], &[head()]).unwrap();
        assert_eq!((t.boxes, t.proposals), (3, 2));
        let s = |x: f32| 1.0 / (1.0 + (-x).exp());
        let l1: f32 = t.l1.to_scalar().unwrap();
        assert!((l1 - (s(0.0) + 2.0 * s(2.0)) / 3.0).abs() < 1e-6, "{l1}");
        let l2: f32 = t.l2.to_scalar().unwrap();
        assert!((l2 - s(3.0)).abs() < 1e-6, "{l2}");
        assert!((t.max_score - s(2.0) * s(3.0)).abs() < 1e-6);
    }

    #[test]
    fn no_boxes_gives_zero_loss_and_zero_gradient() {
        let loss = DetectionLoss { box_threshold: 0.5, target: vec![2] };
        let v = Var::from_tensor(&map([-9.0; 8], [2; 8])).unwrap();
        let t = loss.yolo(&[v.as_tensor().clone()], &[head()]).unwrap();
        assert_eq!((t.boxes, t.proposals), (0, 0));
        let total = (&t.l1 + &t.l2).unwrap();
        assert_eq!(total.to_scalar::<f32>().unwrap(), 0.0);
        let g = total.backward().unwrap();
        let g: Vec<f32> = g.get(v.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        assert!(g.iter().all(|x| *x == 0.0));
    }
}
