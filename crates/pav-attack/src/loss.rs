//! The paper's detector losses and the alternatives that decide detection: L1 over objectness,
//! L2 over target-class confidence, each with its exact gradient with respect to the detector's
//! raw outputs.
//!
//! A detector's outputs are first read as [`Predictions`] (objectness and class probabilities per
//! predicted box, and where each came from), so one loss serves every YOLO-style layout:
//! darknet heads (logits; the sigmoid is applied here) and YOLOX rows (probabilities already).
//!
//! A head without objectness (Ultralytics YOLOv8: class probabilities only) has no "is there an
//! object" output. There a prediction's objectness is its largest class probability, the
//! confidence the detector ranks and thresholds its boxes by, so L1 pushes down every object the
//! detector sees, whatever its class; and the detection score is the target class probability
//! itself (not objectness × confidence, which would square it when the car is the best class).
//! The gradient of that objectness goes to the class that holds the maximum.
//!
//! [`Reduce::Mean`] is the paper's: "boxes" are the predictions whose objectness reaches
//! `box_threshold`, "proposals" are those boxes whose most likely class is a target class; L1 is
//! the mean objectness over the boxes, L2 the mean target confidence over the proposals. The sets
//! are chosen on the values (no gradient through the choice); an empty set gives 0 and a zero
//! gradient, not 0/0. [`Reduce::TopK`] and [`Reduce::Softmax`] instead weight the strongest
//! predictions, since a detector reports a car when its single best box scores high: L1 over the
//! objectness values, L2 over the detection scores `objectness × target confidence`.
//!
//! [`Reduce::LogMax`] is RAUCA-E2E's loss: one term, `−log(1 − s*)` of the best target detection
//! score over all predictions, reported as L2 (L1 is 0). Without a weight a background car that
//! outscores the target holds the maximum and the step pushes nothing the texture can change;
//! [`Predictions::weigh`] multiplies each prediction's detection score by its box's IoU with the
//! car's box first, as RAUCA-E2E does (`loss.iou`). By default the weight is held constant: the
//! gradient goes through the scores, not the boxes, so a step lowers the car's scores and does
//! not move its boxes off the car. With `box_gradient` the weight is differentiated too:
//! [`DetectionLoss::terms_and_boxes`] also gives the loss's gradient with respect to each box
//! (the IoU's exact derivative, [`iou_and_grad`]), which a white box carries back through its
//! box outputs. Under the score reductions (top-k, softmax, log-max) the weight enters L2's
//! scores; the reported `max_score` stays the unweighted best score.
//!
//! [`ProposalSet::Scored`] changes the Mean's proposals to the set the digital metrics count: every
//! prediction whose detection score for a target class reaches `box_threshold`, whatever its most
//! likely class. The paper's set leaves out a box rated "truck 0.4, car 0.15", which P@0.5 and the
//! mean best car score still count as a car at 0.15 (`detect::decode::Proposals::target_detections`); in the
//! second half of a four-white-box crossval fold, 21 of DEIMv2's 127 steps had no paper proposal while its
//! best car score was ≥ 0.05, so L2 pushed nothing there.

use pav_detect::decode::{ScoreRule, ScoreSite};
use pav_detect::layout::Activation;
use pav_detect::nms::iou;

/// Sigmoid as `(1 + tanh(x/2))/2`, and its derivative `(1 − tanh²(x/2))/4`: both finite for every
/// finite logit, where `1/(1 + exp(−x))` makes a NaN gradient below x ≈ −88 in f32.
pub fn sigmoid(x: f32) -> (f32, f32) {
    let t = (0.5 * x).tanh();
    (0.5 + 0.5 * t, 0.25 * (1.0 - t * t))
}

/// The IoU of the xyxy boxes `a` and `b` (as [`iou`]) and its derivative with respect to `a`'s
/// corners. Where a corner of the overlap is shared by both boxes, the derivative is the one
/// that moves `a`'s side.
pub fn iou_and_grad(a: &[f32; 4], b: &[f32; 4]) -> (f32, [f32; 4]) {
    let v = iou(a, b);
    let (iw, ih) = (a[2].min(b[2]) - a[0].max(b[0]), a[3].min(b[3]) - a[1].max(b[1]));
    let (aw, ah) = (a[2] - a[0], a[3] - a[1]);
    let inter = iw.max(0.0) * ih.max(0.0);
    let area = |r: &[f32; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - inter;
    if union <= 0.0 {
        return (v, [0.0; 4]);
    }
    // ∂inter: a side of a inside b moves the overlap's side.
    let overlap = iw > 0.0 && ih > 0.0;
    let d_inter = if overlap {
        [
            if a[0] >= b[0] { -ih } else { 0.0 },
            if a[1] >= b[1] { -iw } else { 0.0 },
            if a[2] <= b[2] { ih } else { 0.0 },
            if a[3] <= b[3] { iw } else { 0.0 },
        ]
    } else {
        [0.0; 4]
    };
    let d_area = if aw > 0.0 && ah > 0.0 { [-ah, -aw, ah, aw] } else { [0.0; 4] };
    // IoU = inter / (area_a + area_b − inter).
    (v, [0, 1, 2, 3].map(|k| (d_inter[k] * union - inter * (d_area[k] - d_inter[k])) / (union * union)))
}

/// How the set of predictions becomes one number per term.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Reduce {
    /// The paper's means over thresholded sets.
    Mean,
    /// The mean of the k largest values (k = 1: the maximum).
    TopK(usize),
    /// `Σ softmax(v/τ)·v`: a smooth maximum with temperature τ.
    Softmax(f32),
    /// `−log(1 − s*)`, s* the best target detection score: one term, L2 (see the module doc).
    LogMax,
}

/// The largest score [`Reduce::LogMax`] takes: `−log(1 − s)` and its slope `1/(1 − s)` stay
/// finite (at most 9.2 and 10⁴) where a detector is certain.
const LOG_MAX_CAP: f32 = 1.0 - 1e-4;

/// Which predictions L2 averages over under [`Reduce::Mean`].
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProposalSet {
    /// The paper's: boxes (objectness ≥ the threshold) whose most likely class is a target.
    #[default]
    ArgMax,
    /// What the metrics count: predictions whose target detection score reaches the threshold.
    Scored,
}

/// The detector-loss settings.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectionLoss {
    /// Objectness from which a prediction counts as a box.
    pub box_threshold: f32,
    /// Target class indices (COCO car = 2).
    pub target: Vec<usize>,
    /// How the predictions are reduced.
    pub reduce: Reduce,
    /// L2's set under [`Reduce::Mean`].
    pub proposals: ProposalSet,
    /// Whether a white box weights scores by IoU with the car's box ([`Predictions::weigh`]).
    pub iou: bool,
    /// Whether that weight is differentiated with respect to the boxes (else held constant).
    pub box_gradient: bool,
}

/// L1 and L2 with the set sizes and the strongest target detection, for logs.
#[derive(Clone, Debug, PartialEq)]
pub struct LossTerms {
    /// The objectness term.
    pub l1: f32,
    /// The target-confidence term.
    pub l2: f32,
    /// Number of boxes (n_o: objectness ≥ the box threshold).
    pub boxes: usize,
    /// Number of target proposals (n_c: boxes whose best class is a target).
    pub proposals: usize,
    /// Highest detection score over all predictions (objectness × target confidence; the target
    /// probability alone for a head without objectness).
    pub max_score: f32,
}

/// Why outputs cannot be scored.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct HeadShapeError(String);

/// Objectness and class probabilities of every predicted box, read from a detector's raw
/// outputs where its description puts them ([`ScoreSite`]), as its [`ScoreRule`] says, with the
/// way back to those values.
#[derive(Clone, Debug)]
pub struct Predictions {
    classes: usize,
    rule: ScoreRule,
    obj: Vec<f32>,
    cls: Vec<f32>,
    at: Vec<ScoreSite>,
    /// Per prediction without an objectness, the class whose probability stands for it.
    best: Vec<usize>,
    /// Whether the head has objectness (false: objectness is the largest class probability and
    /// the detection score is the target probability alone).
    objectness: bool,
    /// Per prediction, the constant its detection score is weighted by in the loss (none: 1).
    weight: Option<Vec<f32>>,
    /// Per prediction, the weight's derivative with respect to its box (xyxy).
    weight_grad: Vec<[f32; 4]>,
}

/// A value through an activation that works on single values, and its derivative.
fn activate(a: Activation, x: f32) -> (f32, f32) {
    match a {
        Activation::Sigmoid => sigmoid(x),
        Activation::None | Activation::Softmax => (x, 1.0),
    }
}

impl Predictions {
    /// Every prediction of `raw` (a detector's outputs, as its white box orders them): its
    /// values at `sites`, read as `rule` says, for `classes` classes.
    pub fn read(raw: &[&[f32]], sites: &[ScoreSite], rule: &ScoreRule, classes: usize) -> Result<Self, HeadShapeError> {
        let fits = rule.width > 0 && classes + usize::from(rule.background.is_some()) == rule.width;
        let mut p = Predictions::empty(classes, rule.clone());
        let mut logits = vec![0f32; rule.width];
        for site in sites {
            let (o, first, step) = site.scores;
            let out = raw.get(o).ok_or_else(|| HeadShapeError(format!("no output {o} among {}", raw.len())))?;
            let last = first + step * rule.width.saturating_sub(1);
            if !fits || last >= out.len() {
                return Err(HeadShapeError(format!(
                    "{} values of output {o} do not hold {} class columns from {first} every {step}",
                    out.len(),
                    rule.width
                )));
            }
            let from = p.cls.len();
            if rule.activation == Activation::Softmax {
                logits.iter_mut().enumerate().for_each(|(j, l)| *l = out[first + j * step]);
                let m = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                let z: f32 = logits.iter().map(|x| (x - m).exp()).sum();
                p.cls.extend((0..classes).map(|k| (logits[rule.column(k)] - m).exp() / z));
            } else {
                p.cls.extend((0..classes).map(|k| activate(rule.activation, out[first + rule.column(k) * step]).0));
            }
            // The class holding objectness when there is none: ties to the first (every
            // activation keeps the order of a row's values).
            let row = &p.cls[from..];
            let k = (0..classes).fold(0, |m, k| if row[k] > row[m] { k } else { m });
            let obj = match (site.objectness, rule.objectness) {
                (Some((o, i)), Some(a)) => {
                    let v = raw.get(o).and_then(|r| r.get(i)).ok_or_else(|| {
                        HeadShapeError(format!("no objectness value {i} in output {o} of {}", raw.len()))
                    })?;
                    activate(a, *v).0
                }
                _ => row[k],
            };
            p.obj.push(obj);
            p.best.push(k);
            p.at.push(*site);
        }
        Ok(p)
    }

    /// No predictions yet, for heads of `classes` classes read as `rule` says.
    fn empty(classes: usize, rule: ScoreRule) -> Self {
        Predictions {
            classes,
            objectness: rule.objectness.is_some(),
            rule,
            obj: vec![],
            cls: vec![],
            at: vec![],
            best: vec![],
            weight: None,
            weight_grad: vec![],
        }
    }

    /// Prediction `i`'s most likely class among the non-empty `targets` (ties to the first) and
    /// its probability.
    fn best_target(&self, i: usize, targets: &[usize]) -> (usize, f32) {
        let c = self.classes;
        targets.iter().map(|&k| (k, self.cls[i * c + k])).fold((targets[0], f32::NEG_INFINITY), |m, t| {
            if t.1 > m.1 {
                t
            } else {
                m
            }
        })
    }

    /// The detection score of prediction `i` for a target probability `car`, and its derivatives
    /// with respect to objectness and that probability.
    fn score(&self, i: usize, car: f32) -> (f32, f32, f32) {
        let [p, q] = self.rule.powers;
        match (self.objectness, p == 1.0 && q == 1.0) {
            (true, true) => (self.obj[i] * car, car, self.obj[i]),
            (false, true) => (car, 0.0, 1.0),
            (with, false) => {
                // obj^p · car^q, its slopes finite where a factor is 0.
                let (o, c) = (if with { self.obj[i].max(0.0) } else { 1.0 }, car.max(0.0));
                let (op, cq) = (o.powf(p), c.powf(q));
                let slope = |v: f32, e: f32| if v > 0.0 { e * v.powf(e - 1.0) } else { 0.0 };
                (op * cq, if with { slope(o, p) * cq } else { 0.0 }, op * slope(c, q))
            }
        }
    }

    /// The detection score of prediction `i` and its derivatives, times the prediction's weight.
    fn weighted(&self, i: usize, car: f32) -> (f32, f32, f32) {
        let (s, d_obj, d_car) = self.score(i, car);
        match &self.weight {
            Some(w) => (w[i] * s, w[i] * d_obj, w[i] * d_car),
            None => (s, d_obj, d_car),
        }
    }

    /// Each prediction's best detection score over the `targets` classes (unweighted; 0 where
    /// none of them is among the head's classes).
    pub fn target_scores(&self, targets: &[usize]) -> Vec<f32> {
        let targets: Vec<usize> = targets.iter().copied().filter(|&k| k < self.classes).collect();
        if targets.is_empty() {
            return vec![0.0; self.len()];
        }
        (0..self.len()).map(|i| self.score(i, self.best_target(i, &targets).1).0).collect()
    }

    /// Weights each prediction's detection score in the loss by the IoU of its box (`boxes`, one
    /// per prediction in order, xyxy) with `car` (xyxy, the same pixels): see the module doc.
    pub fn weigh(&mut self, boxes: &[[f32; 4]], car: [f32; 4]) -> Result<(), HeadShapeError> {
        if boxes.len() != self.len() {
            return Err(HeadShapeError(format!("{} boxes for {} predictions", boxes.len(), self.len())));
        }
        let (w, g) = boxes
            .iter()
            .map(|b| if b.iter().all(|v| v.is_finite()) { iou_and_grad(b, &car) } else { (0.0, [0.0; 4]) })
            .unzip();
        self.weight = Some(w);
        self.weight_grad = g;
        Ok(())
    }

    /// Number of predicted boxes.
    pub fn len(&self) -> usize {
        self.obj.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.obj.is_empty()
    }

    /// Where class `k` of prediction `i` sits: (output, index).
    fn class_at(&self, i: usize, k: usize) -> (usize, usize) {
        let (o, first, step) = self.at[i].scores;
        (o, first + self.rule.column(k) * step)
    }

    /// The gradient with respect to the raw outputs `raw` of a loss whose gradients with respect
    /// to the probabilities are `dobj` (per box) and `dcls` (box, class, value).
    fn backprop(&self, raw: &[&[f32]], dobj: &[f32], dcls: &[(usize, usize, f32)]) -> Vec<Vec<f32>> {
        let mut g: Vec<Vec<f32>> = raw.iter().map(|r| vec![0f32; r.len()]).collect();
        // A prediction without objectness passes its objectness gradient to the class that holds it.
        let mut by_class: Vec<(usize, usize, f32)> = Vec::new();
        for (i, &d) in dobj.iter().enumerate() {
            if d == 0.0 {
                continue;
            }
            match (self.at[i].objectness, self.rule.objectness) {
                (Some((o, j)), Some(a)) => g[o][j] += d * activate(a, raw[o][j]).1,
                _ => by_class.push((i, self.best[i], d)),
            }
        }
        by_class.extend_from_slice(dcls);
        if self.rule.activation != Activation::Softmax {
            for (i, k, d) in by_class {
                let (o, j) = self.class_at(i, k);
                g[o][j] += d * activate(self.rule.activation, raw[o][j]).1;
            }
            return g;
        }
        // Through a softmax over the row: ∂p_k/∂z_j = p_k (δ_kj − p_j), every column of the row
        // (the background's too) receiving p_j (d_j − Σ_k d_k p_k).
        by_class.sort_by_key(|t| t.0);
        for row in by_class.chunk_by(|a, b| a.0 == b.0) {
            let i = row[0].0;
            let mut d = vec![0f32; self.classes];
            row.iter().for_each(|&(_, k, v)| d[k] += v);
            let s: f32 = (0..self.classes).map(|k| d[k] * self.cls[i * self.classes + k]).sum();
            let (o, first, step) = self.at[i].scores;
            let z: Vec<f32> = (0..self.rule.width).map(|j| raw[o][first + j * step]).collect();
            let m = z.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let e: f32 = z.iter().map(|x| (x - m).exp()).sum();
            for j in 0..self.rule.width {
                let pj = (z[j] - m).exp() / e;
                let dj = match self.rule.background {
                    Some(bg) if j == bg => 0.0,
                    Some(bg) if j > bg => d[j - 1],
                    _ => d[j],
                };
                g[o][first + j * step] += pj * (dj - s);
            }
        }
        g
    }
}

/// The mean of the `k` largest of the non-empty `v` (ties to the first) and its weights in `w`.
fn top_k(v: &[f32], k: usize, mut w: Vec<f32>) -> (f32, Vec<f32>) {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[b].total_cmp(&v[a]).then(a.cmp(&b)));
    let top = &idx[..k.clamp(1, v.len())];
    let n = top.len() as f32;
    top.iter().for_each(|&i| w[i] = 1.0 / n);
    (top.iter().map(|&i| v[i]).sum::<f32>() / n, w)
}

/// Weights of a reduction over `v`: the value and `∂value/∂v` (dense).
fn reduce(v: &[f32], how: Reduce) -> (f32, Vec<f32>) {
    let mut w = vec![0f32; v.len()];
    if v.is_empty() {
        return (0.0, w);
    }
    match how {
        Reduce::Mean => {
            let n = v.len() as f32;
            w.fill(1.0 / n);
            (v.iter().sum::<f32>() / n, w)
        }
        Reduce::TopK(k) => top_k(v, k, w),
        Reduce::LogMax => top_k(v, 1, w),
        Reduce::Softmax(tau) => {
            // Shifted by the maximum: exp never overflows, and the largest weight is exp(0) = 1.
            let m = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let e: Vec<f64> = v.iter().map(|&x| (((x - m) / tau) as f64).exp()).collect();
            let z: f64 = e.iter().sum();
            let s: f64 = e.iter().zip(v).map(|(e, &x)| e / z * x as f64).sum();
            // ∂/∂v_i Σ p_j v_j = p_i (1 + (v_i − s)/τ).
            for (i, &x) in v.iter().enumerate() {
                w[i] = (e[i] / z * (1.0 + (x as f64 - s) / tau as f64)) as f32;
            }
            (s as f32, w)
        }
    }
}

/// The gradient of the loss with respect to the boxes of weighted predictions: (prediction,
/// ∂loss/∂[x1, y1, x2, y2]).
pub type BoxGrads = Vec<(usize, [f32; 4])>;

impl DetectionLoss {
    /// The terms for `p` (read from `raw`), and the gradient of `L1 + beta·L2` with respect to each
    /// raw output.
    pub fn terms(
        &self,
        p: &Predictions,
        raw: &[&[f32]],
        beta: f32,
    ) -> Result<(LossTerms, Vec<Vec<f32>>), HeadShapeError> {
        self.terms_and_boxes(p, raw, beta).map(|(t, g, _)| (t, g))
    }

    /// As [`DetectionLoss::terms`], with the gradient with respect to the boxes that weighted
    /// `p` ([`Predictions::weigh`]; empty when nothing weighted it or `box_gradient` is off).
    pub fn terms_and_boxes(
        &self,
        p: &Predictions,
        raw: &[&[f32]],
        beta: f32,
    ) -> Result<(LossTerms, Vec<Vec<f32>>, BoxGrads), HeadShapeError> {
        let c = p.classes;
        let targets: Vec<usize> = self.target.iter().copied().filter(|&k| k < c).collect();
        if targets.is_empty() {
            return Err(HeadShapeError(format!("no target class among the model's {c} classes")));
        }
        let cls = |i: usize, k: usize| p.cls[i * c + k];
        // Per box: its best class, and its best target class with that class's confidence.
        let best =
            |i: usize| (0..c).fold((0, f32::NEG_INFINITY), |m, k| if cls(i, k) > m.1 { (k, cls(i, k)) } else { m });
        let n = p.len();
        let tk: Vec<(usize, f32)> = (0..n).map(|i| p.best_target(i, &targets)).collect();
        let mut max_score = 0f32;
        let (mut boxes, mut proposals) = (Vec::new(), Vec::new());
        for (i, (&o, &(k, car))) in p.obj.iter().zip(&tk).enumerate() {
            let score = p.score(i, car).0;
            max_score = max_score.max(score);
            if o >= self.box_threshold && o.is_finite() {
                boxes.push(i);
                let b = best(i).0;
                if self.proposals == ProposalSet::ArgMax && targets.contains(&b) {
                    proposals.push((i, b));
                }
            }
            if self.proposals == ProposalSet::Scored && score >= self.box_threshold && score.is_finite() {
                proposals.push((i, k));
            }
        }
        let mut dobj = vec![0f32; n];
        let mut dcls = Vec::new();
        // ∂loss/∂weight of the weighted scores read.
        let mut dweight: Vec<(usize, f32)> = Vec::new();
        let (l1, l2) = match self.reduce {
            Reduce::Mean => {
                let (l1, w1) = reduce(&boxes.iter().map(|&i| p.obj[i]).collect::<Vec<_>>(), Reduce::Mean);
                boxes.iter().zip(&w1).for_each(|(&i, &w)| dobj[i] += w);
                let (l2, w2) = reduce(&proposals.iter().map(|&(i, k)| cls(i, k)).collect::<Vec<_>>(), Reduce::Mean);
                proposals.iter().zip(&w2).for_each(|(&(i, k), &w)| dcls.push((i, k, beta * w)));
                (l1, l2)
            }
            Reduce::LogMax => {
                let scores: Vec<f32> = (0..n).map(|i| p.weighted(i, tk[i].1).0).collect();
                let (best, w) = reduce(&scores, Reduce::LogMax);
                match w.iter().position(|&x| x != 0.0) {
                    Some(i) if best.is_finite() => {
                        let s = best.clamp(0.0, LOG_MAX_CAP);
                        // d(−log(1 − s))/ds = 1/(1 − s); zero past the cap, where the value is held.
                        let slope = if best < LOG_MAX_CAP { 1.0 / (1.0 - s) } else { 0.0 };
                        let (_, d_obj, d_car) = p.weighted(i, tk[i].1);
                        dobj[i] += beta * slope * d_obj;
                        dcls.push((i, tk[i].0, beta * slope * d_car));
                        dweight.push((i, beta * slope * p.score(i, tk[i].1).0));
                        (0.0, -(1.0 - s).ln())
                    }
                    _ => (0.0, 0.0),
                }
            }
            how => {
                let (l1, w1) = reduce(&p.obj, how);
                w1.iter().enumerate().for_each(|(i, &w)| dobj[i] += w);
                let scores: Vec<f32> = (0..n).map(|i| p.weighted(i, tk[i].1).0).collect();
                let (l2, w2) = reduce(&scores, how);
                for (i, &w) in w2.iter().enumerate() {
                    if w != 0.0 {
                        let (_, d_obj, d_car) = p.weighted(i, tk[i].1);
                        dobj[i] += beta * w * d_obj;
                        dcls.push((i, tk[i].0, beta * w * d_car));
                        dweight.push((i, beta * w * p.score(i, tk[i].1).0));
                    }
                }
                (l1, l2)
            }
        };
        let grads = p.backprop(raw, &dobj, &dcls);
        let terms = LossTerms { l1, l2, boxes: boxes.len(), proposals: proposals.len(), max_score };
        let box_grads = if self.box_gradient && p.weight.is_some() {
            dweight.into_iter().map(|(i, d)| (i, p.weight_grad[i].map(|g| d * g))).collect()
        } else {
            Vec::new()
        };
        Ok((terms, grads, box_grads))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_detect::decode::{score_sites, RawOutput};
    use pav_detect::layout::Description;

    /// One batch-1 head map of 2 anchors × (5 + 3 classes) planes, flattened, with its `(H, W)`.
    type HeadMap = (Vec<f32>, (usize, usize));

    /// The predictions of the outputs `(name, shape, values)` as `desc` (TOML) describes them,
    /// for 3 classes.
    fn described(desc: &str, outs: &[(&str, Vec<usize>, &[f32])]) -> Result<Predictions, String> {
        let d: Description = toml::from_str(desc).map_err(|e| e.to_string())?;
        d.validate(3)?;
        let raws: Vec<RawOutput> = outs
            .iter()
            .map(|(n, s, v)| RawOutput { name: n.to_string(), shape: s.clone(), data: v.to_vec() })
            .collect();
        let sites = score_sites(&d, &raws, 64, 64, 3).map_err(|e| e.to_string())?;
        let raw: Vec<&[f32]> = outs.iter().map(|o| o.2).collect();
        Predictions::read(&raw, &sites, &ScoreRule::of(&d, 3), 3).map_err(|e| e.to_string())
    }

    /// Darknet planes: two anchors, logits.
    fn planes(m: &HeadMap) -> Result<Predictions, String> {
        let part = "output = ['h']\narrange = 'planes'\nper_level = true\n";
        let desc = format!("[[levels]]\nanchors = [[1, 1], [1, 1]]\n[boxes]\n{part}encoding = 'darknet'\n[objectness]\n{part}column = 4\nactivation = 'sigmoid'\n[scores]\n{part}column = 5\nactivation = 'sigmoid'\n");
        let (h, w) = m.1;
        described(&desc, &[("h", vec![1, m.0.len() / (h * w).max(1), h, w], &m.0)])
    }

    /// Rows (box, objectness, 3 classes) of probabilities.
    fn row_predictions(v: &[f32]) -> Predictions {
        let desc = "[boxes]\nencoding = 'xyxy'\n[objectness]\ncolumn = 4\n[scores]\ncolumn = 5\n";
        described(desc, &[("o", vec![v.len() / 8, 8], v)]).unwrap()
    }

    /// Class probabilities `[classes, N]`, class-major, without objectness.
    fn columns(v: &[f32], classes: usize) -> Result<Predictions, String> {
        let desc = "[boxes]\noutput = 'b'\nencoding = 'xyxy'\n[scores]\noutput = 's'\narrange = 'columns'\n";
        described(desc, &[("s", vec![classes, v.len() / classes], v)])
    }

    /// Query-major class logits `[Q, classes]`, without objectness.
    fn queries(v: &[f32], classes: usize) -> Result<Predictions, String> {
        let desc = "[boxes]\noutput = 'b'\nencoding = 'xyxy'\n[scores]\noutput = 's'\nactivation = 'sigmoid'\n";
        described(desc, &[("s", vec![v.len() / classes, classes], v)])
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

    fn loss(reduce: Reduce) -> DetectionLoss {
        DetectionLoss {
            box_threshold: 0.5,
            target: vec![2],
            reduce,
            proposals: ProposalSet::ArgMax,
            iou: false,
            box_gradient: false,
        }
    }

    /// Each reduction, and the mean over the metrics' set, for the gradient checks.
    fn every_loss() -> [DetectionLoss; 5] {
        let scored = DetectionLoss { proposals: ProposalSet::Scored, ..loss(Reduce::Mean) };
        [loss(Reduce::Mean), loss(Reduce::TopK(2)), loss(Reduce::Softmax(0.2)), scored, loss(Reduce::LogMax)]
    }

    fn eval(l: &DetectionLoss, m: &HeadMap, beta: f32) -> (LossTerms, Vec<Vec<f32>>) {
        let p = planes(m).unwrap();
        l.terms(&p, &[&m.0], beta).unwrap()
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
        // Objectness logits: 0 → 0.5 (a box, exactly on the threshold), 2 → 0.88, −5 → no box.
        let m = map([0.0, 2.0, -5.0, -5.0, 2.0, -5.0, -5.0, -5.0], [2, 1, 2, 0, 2, 0, 0, 0]);
        let (t, _) = eval(&loss(Reduce::Mean), &m, 1.0);
        assert_eq!((t.boxes, t.proposals), (3, 2));
        let s = |x: f32| 1.0 / (1.0 + (-x).exp());
        assert!((t.l1 - (s(0.0) + 2.0 * s(2.0)) / 3.0).abs() < 1e-6, "{}", t.l1);
        assert!((t.l2 - s(3.0)).abs() < 1e-6, "{}", t.l2);
        assert!((t.max_score - s(2.0) * s(3.0)).abs() < 1e-6);
        // Top-1: the largest objectness, and the largest objectness × car confidence.
        let (t, _) = eval(&loss(Reduce::TopK(1)), &m, 1.0);
        assert!((t.l1 - s(2.0)).abs() < 1e-6 && (t.l2 - t.max_score).abs() < 1e-6, "{t:?}");
        // A cold softmax is the maximum, a hot one the plain mean.
        let (t, _) = eval(&loss(Reduce::Softmax(1e-4)), &m, 1.0);
        assert!((t.l1 - s(2.0)).abs() < 1e-5 && (t.l2 - t.max_score).abs() < 1e-5, "{t:?}");
        let (t, _) = eval(&loss(Reduce::Softmax(1e6)), &m, 1.0);
        let mean_obj = [0.0, 2.0, -5.0, -5.0, 2.0, -5.0, -5.0, -5.0].iter().map(|&x| s(x)).sum::<f32>() / 8.0;
        assert!((t.l1 - mean_obj).abs() < 1e-5, "{t:?}");
        // RAUCA-E2E's shape: one term, −log(1 − best detection score), its gradient on that
        // prediction only: anchor 1, cell 0 (objectness s(2), car s(3)), whose objectness and car
        // logits sit at 32 + 4·4 and 32 + 7·4 of the map; slope 1/(1 − s) through each factor.
        let (t, g) = eval(&loss(Reduce::LogMax), &m, 1.0);
        assert!(t.l1 == 0.0 && (t.l2 + (1.0 - s(2.0) * s(3.0)).ln()).abs() < 1e-6, "{t:?}");
        let nonzero: Vec<usize> = (0..g[0].len()).filter(|&i| g[0][i] != 0.0).collect();
        assert_eq!(nonzero, [48, 60]);
        let slope = 1.0 / (1.0 - s(2.0) * s(3.0));
        let want_obj = slope * s(3.0) * s(2.0) * (1.0 - s(2.0));
        assert!((g[0][48] - want_obj).abs() < 1e-4, "{} vs {want_obj}", g[0][48]);
        // A certain detection (score past the cap) is held at the cap's value, with a zero slope.
        let (t, g) = eval(&loss(Reduce::LogMax), &(vec![1e4; 2 * 8 * 4], (2, 2)), 1.0);
        assert!((t.l2 + (1.0 - LOG_MAX_CAP).ln()).abs() < 1e-3 && g[0].iter().all(|v| *v == 0.0), "{t:?}");
    }

    #[test]
    fn gradient_matches_central_differences_for_every_reduction() {
        let (mut m, hw) = map([0.3, 2.0, -5.0, -5.0, 1.5, -5.0, -5.0, -5.0], [2, 1, 2, 0, 2, 0, 0, 0]);
        // Distinct logits so the sets and rankings do not change under the small steps below.
        for (i, v) in m.iter_mut().enumerate() {
            *v += 0.01 * (i % 7) as f32;
        }
        let beta = 0.7;
        for l in every_loss() {
            let how = l.reduce;
            let (_, g) = eval(&l, &(m.clone(), hw), beta);
            let total = |m: &[f32]| {
                let (t, _) = eval(&l, &(m.to_vec(), hw), beta);
                t.l1 as f64 + beta as f64 * t.l2 as f64
            };
            let eps = 1e-2;
            for i in 0..m.len() {
                let (mut p, mut q) = (m.clone(), m.clone());
                p[i] += eps;
                q[i] -= eps;
                let fd = (total(&p) - total(&q)) / (2.0 * eps as f64);
                assert!((fd - g[0][i] as f64).abs() < 1e-4, "{how:?} logit {i}: {} vs {fd}", g[0][i]);
            }
            if l.proposals == ProposalSet::ArgMax && how == Reduce::Mean {
                assert!(g[0].iter().filter(|v| **v != 0.0).count() == 5, "3 boxes and 2 proposals carry gradient");
            }
        }
    }

    #[test]
    fn scored_proposals_count_a_car_that_is_not_the_most_likely_class() {
        // Box 1 is most likely class 1 (logit 3) but rates car at logit 1: detection score
        // s(2)·s(1) = 0.64, a car for the metrics. The paper's set leaves it out; Scored keeps it,
        // and drops box 0, whose car score s(0)·s(3) = 0.48 is below the 0.5 threshold.
        let (mut m, hw) = map([0.0, 2.0, -5.0, -5.0, 2.0, -5.0, -5.0, -5.0], [2, 1, 2, 0, 2, 0, 0, 0]);
        m[(5 + 2) * 4 + 1] = 1.0;
        let s = |x: f32| 1.0 / (1.0 + (-x).exp());
        let (paper, _) = eval(&loss(Reduce::Mean), &(m.clone(), hw), 1.0);
        assert_eq!(paper.proposals, 2);
        assert!((paper.l2 - s(3.0)).abs() < 1e-6, "{paper:?}");
        let scored = DetectionLoss { proposals: ProposalSet::Scored, ..loss(Reduce::Mean) };
        let (t, g) = eval(&scored, &(m.clone(), hw), 1.0);
        assert_eq!((t.boxes, t.proposals, t.l1), (paper.boxes, 2, paper.l1));
        assert!((t.l2 - (s(1.0) + s(3.0)) / 2.0).abs() < 1e-6, "{t:?}");
        // Box 1's car logit now carries L2's gradient; box 0's car logit none.
        assert!(g[0][(5 + 2) * 4 + 1] > 0.0 && g[0][(5 + 2) * 4] == 0.0);
    }

    #[test]
    fn no_boxes_gives_zero_loss_and_zero_gradient() {
        let (t, g) = eval(&loss(Reduce::Mean), &map([-9.0; 8], [2; 8]), 1.0);
        assert_eq!((t.boxes, t.proposals, t.l1 + t.l2), (0, 0, 0.0));
        assert!(g[0].iter().all(|x| *x == 0.0));
        assert!(planes(&(vec![0.0; 5], (1, 1))).is_err());
    }

    #[test]
    fn saturated_values_stay_finite_for_every_reduction_and_layout() {
        // Logits at ±1e4 (darknet) and probabilities at exactly 0 and 1 (YOLOX).
        let m = map([1e4, -1e4, 1e4, -1e4, 1e4, 1e4, -1e4, -1e4], [2, 2, 0, 2, 1, 2, 2, 2]);
        let rows: Vec<f32> =
            (0..6).flat_map(|r| [0.0, 0.0, 0.0, 0.0, (r % 2) as f32, 0.0, (r % 3 == 0) as u8 as f32, 1.0]).collect();
        for how in [Reduce::Mean, Reduce::TopK(3), Reduce::Softmax(0.05), Reduce::Softmax(1e-6), Reduce::LogMax] {
            let (t, g) = eval(&loss(how), &m, 1.0);
            assert!(t.l1.is_finite() && t.l2.is_finite() && g[0].iter().all(|v| v.is_finite()), "{how:?} {t:?}");
            let (t, g) = loss(how).terms(&row_predictions(&rows), &[&rows], 1.0).unwrap();
            assert!(t.l1.is_finite() && t.l2.is_finite() && g[0].iter().all(|v| v.is_finite()), "{how:?} {t:?}");
        }
        // An empty output: zero terms.
        let p = row_predictions(&[]);
        let (t, _) = loss(Reduce::TopK(1)).terms(&p, &[&[]], 1.0).unwrap();
        assert_eq!((t.l1, t.l2), (0.0, 0.0));
    }

    /// Ultralytics scores `[3 classes, 4 predictions]`, class-major.
    fn v8_scores() -> Vec<f32> {
        vec![
            0.10, 0.70, 0.20, 0.05, // class 0
            0.20, 0.10, 0.30, 0.02, // class 1
            0.80, 0.15, 0.60, 0.01, // class 2 (the car)
        ]
    }

    #[test]
    fn a_head_without_objectness_uses_its_best_class_and_the_car_probability() {
        let s = v8_scores();
        let p = columns(&s, 3).unwrap();
        // Objectness = best class: 0.8, 0.7, 0.6, 0.05. Boxes ≥ 0.5: predictions 0, 1, 2; their
        // best classes are car, class 0, car.
        let (t, g) = loss(Reduce::Mean).terms(&p, &[&s], 2.0).unwrap();
        assert_eq!((t.boxes, t.proposals), (3, 2));
        assert!((t.l1 - (0.8 + 0.7 + 0.6) / 3.0).abs() < 1e-6 && (t.l2 - 0.7).abs() < 1e-6, "{t:?}");
        // The detection score is the car probability itself.
        assert!((t.max_score - 0.8).abs() < 1e-6, "{t:?}");
        // L1's gradient goes to each box's best class, L2's to the car entries of the proposals.
        let third = 1.0 / 3.0;
        assert!((g[0][8] - (third + 2.0 * 0.5)).abs() < 1e-6 && (g[0][1] - third).abs() < 1e-6, "{:?}", g[0]);
        assert_eq!((g[0][3], g[0][9], g[0][4]), (0.0, 0.0, 0.0));
        // Top-1: the largest best-class probability, and the largest car probability.
        let (t, g) = loss(Reduce::TopK(1)).terms(&p, &[&s], 1.0).unwrap();
        assert!((t.l1 - 0.8).abs() < 1e-6 && (t.l2 - 0.8).abs() < 1e-6, "{t:?}");
        assert!((g[0][8] - 2.0).abs() < 1e-6 && g[0].iter().filter(|v| **v != 0.0).count() == 1, "{:?}", g[0]);
        // Class rows that are not the config's classes are refused.
        assert!(columns(&s, 4).is_err());
    }

    #[test]
    fn a_head_without_objectness_has_exact_gradients_and_stays_finite() {
        // Distinct probabilities, away from ties and from the box threshold.
        let s = v8_scores();
        let beta = 0.7;
        for l in every_loss() {
            let how = l.reduce;
            let total = |v: &[f32]| {
                let (t, _) = l.terms(&columns(v, 3).unwrap(), &[v], beta).unwrap();
                t.l1 as f64 + beta as f64 * t.l2 as f64
            };
            let (_, g) = l.terms(&columns(&s, 3).unwrap(), &[&s], beta).unwrap();
            for i in 0..s.len() {
                let (mut a, mut b) = (s.clone(), s.clone());
                a[i] += 1e-3;
                b[i] -= 1e-3;
                let fd = (total(&a) - total(&b)) / 2e-3;
                assert!((fd - g[0][i] as f64).abs() < 1e-3, "{how:?} value {i}: {} vs {fd}", g[0][i]);
            }
            // Saturated (0 and 1 exactly), all-equal and empty outputs.
            for v in [vec![1.0; 12], vec![0.0; 12], vec![0.5; 12], vec![]] {
                let (t, g) = l.terms(&columns(&v, 3).unwrap(), &[&v], beta).unwrap();
                assert!(t.l1.is_finite() && t.l2.is_finite() && g[0].iter().all(|x| x.is_finite()), "{how:?} {t:?}");
            }
        }
    }

    #[test]
    fn yolox_rows_are_probabilities_with_identity_chain() {
        // Two rows, 3 classes: (box, obj, c0, c1, c2).
        let rows = vec![0.0, 0.0, 0.0, 0.0, 0.9, 0.1, 0.2, 0.7, 0.0, 0.0, 0.0, 0.0, 0.3, 0.6, 0.1, 0.3];
        let p = row_predictions(&rows);
        let (t, g) = loss(Reduce::Mean).terms(&p, &[&rows], 2.0).unwrap();
        // Row 0 is a box whose best class is the car (2); row 1 (0.3) is below the threshold.
        assert_eq!((t.boxes, t.proposals), (1, 1));
        assert!((t.l1 - 0.9).abs() < 1e-6 && (t.l2 - 0.7).abs() < 1e-6);
        assert!((t.max_score - 0.63).abs() < 1e-6);
        assert_eq!((g[0][4], g[0][7], g[0][12]), (1.0, 2.0, 0.0));
    }

    #[test]
    fn detr_queries_are_logits_without_objectness_with_exact_gradients() {
        // Four queries, 3 classes, query-major logits: the same probabilities as `v8_scores`
        // would give through the sigmoid, laid out per query.
        let logits: Vec<f32> = vec![0.3, -2.0, 1.4, 0.9, -1.1, 0.2, -0.6, 0.4, 0.1, -3.0, -2.5, -2.9];
        let p = queries(&logits, 3).unwrap();
        let prob = |x: f32| sigmoid(x).0;
        let (t, _) = loss(Reduce::Mean).terms(&p, &[&logits], 1.0).unwrap();
        // Best class per query: car (1.4), class 0 (0.9), class 1 (0.4), class 1 (−2.5).
        assert_eq!((t.boxes, t.proposals), (3, 1));
        assert!((t.max_score - prob(1.4)).abs() < 1e-6, "{t:?}");
        let beta = 0.7;
        for l in every_loss() {
            let how = l.reduce;
            let total = |v: &[f32]| {
                let (t, _) = l.terms(&queries(v, 3).unwrap(), &[v], beta).unwrap();
                t.l1 as f64 + beta as f64 * t.l2 as f64
            };
            let (_, g) = l.terms(&p, &[&logits], beta).unwrap();
            for i in 0..logits.len() {
                let (mut a, mut b) = (logits.clone(), logits.clone());
                a[i] += 1e-3;
                b[i] -= 1e-3;
                let fd = (total(&a) - total(&b)) / 2e-3;
                assert!((fd - g[0][i] as f64).abs() < 1e-3, "{how:?} value {i}: {} vs {fd}", g[0][i]);
            }
            // Saturated logits (±1e4: probabilities 0 and 1 exactly), all-equal and empty outputs.
            for v in [vec![1e4; 12], vec![-1e4; 12], vec![0.0; 12], vec![]] {
                let (t, g) = l.terms(&queries(&v, 3).unwrap(), &[&v], beta).unwrap();
                assert!(t.l1.is_finite() && t.l2.is_finite() && g[0].iter().all(|x| x.is_finite()), "{how:?} {t:?}");
            }
        }
        assert!(queries(&logits, 4).is_err());
    }

    #[test]
    fn an_iou_weight_leaves_a_background_car_out_of_the_maximum_with_an_exact_gradient() {
        // The DETR queries above: query 0 is the best car (logit 1.4) but its box lies off the
        // car; query 2 (car logit 0.1) overlaps it by a third, query 3 (−2.9) by two thirds.
        let logits: Vec<f32> = vec![0.3, -2.0, 1.4, 0.9, -1.1, 0.2, -0.6, 0.4, 0.1, -3.0, -2.5, -2.9];
        let car = [10.0, 10.0, 50.0, 30.0];
        let boxes = [[60.0, 0.0, 90.0, 20.0], [0.0, 0.0, 5.0, 5.0], [30.0, 10.0, 70.0, 30.0], [10.0, 10.0, 50.0, 40.0]];
        let prob = |x: f32| sigmoid(x).0;
        let weighed = |v: &[f32]| {
            let mut p = queries(v, 3).unwrap();
            p.weigh(&boxes, car).unwrap();
            p
        };
        let l = DetectionLoss { iou: true, ..loss(Reduce::LogMax) };
        let (t, g) = l.terms(&weighed(&logits), &[&logits], 1.0).unwrap();
        // IoUs: 0, 0, 20·20/(800 + 800 − 400) = 1/3, 800/1200 = 2/3.
        let want = prob(0.1) / 3.0;
        assert!(want > 2.0 / 3.0 * prob(-2.9));
        assert!((t.l2 + (1.0 - want).ln()).abs() < 1e-6, "{t:?} vs {want}");
        // The unweighted best score is still reported.
        assert!((t.max_score - prob(1.4)).abs() < 1e-6, "{t:?}");
        // Only query 2's car logit gets a gradient, exact by central differences.
        let nonzero: Vec<usize> = (0..12).filter(|&i| g[0][i] != 0.0).collect();
        assert_eq!(nonzero, [8], "{:?}", g[0]);
        let total = |v: &[f32]| l.terms(&weighed(v), &[v], 1.0).unwrap().0.l2 as f64;
        for i in 0..12 {
            let (mut a, mut b) = (logits.clone(), logits.clone());
            a[i] += 1e-3;
            b[i] -= 1e-3;
            let fd = (total(&a) - total(&b)) / 2e-3;
            assert!((fd - g[0][i] as f64).abs() < 1e-3, "value {i}: {} vs {fd}", g[0][i]);
        }
        // No box on the car: nothing to push. A box list of the wrong length is refused.
        let mut p = queries(&logits, 3).unwrap();
        p.weigh(&[[100.0, 100.0, 110.0, 110.0]; 4], car).unwrap();
        let (t, g) = l.terms(&p, &[&logits], 1.0).unwrap();
        assert!(t.l2 == 0.0 && g[0].iter().all(|&x| x == 0.0), "{t:?}");
        assert!(p.weigh(&boxes[..3], car).is_err());
    }

    /// Scores as a product of powers (FastestDet's obj^0.6 · cls^0.4) and scores through a softmax
    /// with a background column (SSD's): the loss's gradient by every raw value against central
    /// differences, for every reduction.
    #[test]
    fn powers_and_softmax_scores_have_exact_gradients() {
        let rows: Vec<f32> = vec![
            0.0, 0.0, 1.0, 1.0, 0.81, 0.2, 0.1, 0.7, //
            0.0, 0.0, 1.0, 1.0, 0.3, 0.6, 0.3, 0.1, //
            0.0, 0.0, 1.0, 1.0, 0.55, 0.1, 0.2, 0.45,
        ];
        let powers =
            "[boxes]\nencoding = 'xyxy'\n[objectness]\ncolumn = 4\npower = 0.6\n[scores]\ncolumn = 5\npower = 0.4\n";
        let logits: Vec<f32> = vec![0.2, -1.0, 0.4, 1.3, 1.1, 0.3, -0.2, 0.6, -0.4, 0.9, 0.1, 0.5];
        let softmax = "[boxes]\noutput = 'b'\nencoding = 'xyxy'\n[scores]\noutput = 's'\nactivation = 'softmax'\nbackground = 0\n";
        let cases: [(&str, &str, Vec<usize>, &[f32]); 2] =
            [(powers, "o", vec![3, 8], &rows), (softmax, "s", vec![3, 4], &logits)];
        let beta = 0.7;
        for (desc, name, shape, values) in cases {
            let p = |v: &[f32]| described(desc, &[(name, shape.clone(), v)]).unwrap();
            let first = p(values);
            // The detection score is the description's: 0.81^0.6 · 0.7^0.4 for the first row.
            if desc.contains("power") {
                assert!((first.target_scores(&[2])[0] - 0.81f32.powf(0.6) * 0.7f32.powf(0.4)).abs() < 1e-6);
            }
            for l in every_loss() {
                let total = |v: &[f32]| {
                    let (t, _) = l.terms(&p(v), &[v], beta).unwrap();
                    t.l1 as f64 + beta as f64 * t.l2 as f64
                };
                let (_, g) = l.terms(&first, &[values], beta).unwrap();
                for i in 0..values.len() {
                    let (mut a, mut b) = (values.to_vec(), values.to_vec());
                    a[i] += 1e-3;
                    b[i] -= 1e-3;
                    let fd = (total(&a) - total(&b)) / 2e-3;
                    assert!((fd - g[0][i] as f64).abs() < 2e-3, "{:?} value {i}: {} vs {fd}", l.reduce, g[0][i]);
                }
                assert!(g[0].iter().any(|x| x.abs() > 1e-3), "{:?}: no gradient", l.reduce);
            }
        }
    }

    /// The IoU's derivative by each corner against central differences (f64), for boxes that
    /// overlap in every arrangement (inside, across each side, around), and zero where they do not.
    #[test]
    fn iou_gradient_matches_central_differences() {
        let b = [10.0, 20.0, 50.0, 40.0];
        let cases = [
            [15.0, 25.0, 45.0, 35.0], // inside
            [0.0, 22.0, 30.0, 38.0],  // across the left side
            [30.0, 30.0, 60.0, 55.0], // across the bottom-right corner
            [5.0, 12.0, 58.0, 47.0],  // around
            [60.0, 0.0, 70.0, 10.0],  // apart
        ];
        for a in cases {
            let (v, g) = iou_and_grad(&a, &b);
            assert_eq!(v, iou(&a, &b));
            for k in 0..4 {
                let at = |d: f32| {
                    let mut m = a;
                    m[k] += d;
                    iou(&m, &b) as f64
                };
                let fd = (at(0.01) - at(-0.01)) / 0.02;
                assert!((fd - g[k] as f64).abs() < 1e-4, "{a:?} corner {k}: {} vs {fd}", g[k]);
            }
            if v == 0.0 {
                assert_eq!(g, [0.0; 4]);
            } else {
                assert!(g.iter().any(|x| x.abs() > 1e-3), "{a:?}: {g:?}");
            }
        }
    }

    /// With `box_gradient`, the weighted log-max and softmax give the loss's gradient by each
    /// box: against central differences of the loss with the weights recomputed from the moved
    /// box; without it, none.
    #[test]
    fn box_gradients_of_the_weighted_loss_match_central_differences() {
        let logits: Vec<f32> = vec![0.3, -2.0, 1.4, 0.9, -1.1, 0.2, -0.6, 0.4, 0.1, -3.0, -2.5, -2.9];
        let car = [10.0, 10.0, 50.0, 30.0];
        let boxes = [[60.0, 0.0, 90.0, 20.0], [0.0, 0.0, 5.0, 5.0], [30.0, 12.0, 70.0, 31.0], [12.0, 9.0, 49.0, 40.0]];
        for reduce in [Reduce::LogMax, Reduce::Softmax(0.1)] {
            let l = DetectionLoss { iou: true, box_gradient: true, ..loss(reduce) };
            let total = |b: &[[f32; 4]]| {
                let mut p = queries(&logits, 3).unwrap();
                p.weigh(b, car).unwrap();
                let t = l.terms(&p, &[&logits], 2.0).unwrap().0;
                t.l1 as f64 + 2.0 * t.l2 as f64
            };
            let mut p = queries(&logits, 3).unwrap();
            p.weigh(&boxes, car).unwrap();
            let (_, _, db) = l.terms_and_boxes(&p, &[&logits], 2.0).unwrap();
            assert!(!db.is_empty(), "{reduce:?}");
            let mut checked = 0;
            for i in 0..4 {
                let want = db.iter().filter(|(j, _)| *j == i).fold([0f32; 4], |mut a, (_, d)| {
                    (0..4).for_each(|k| a[k] += d[k]);
                    a
                });
                for k in 0..4 {
                    let at = |d: f32| {
                        let mut b = boxes;
                        b[i][k] += d;
                        total(&b)
                    };
                    let fd = (at(0.01) - at(-0.01)) / 0.02;
                    assert!(
                        (fd - want[k] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
                        "{reduce:?} box {i} corner {k}: {} vs {fd}",
                        want[k]
                    );
                    checked += usize::from(fd.abs() > 1e-4);
                }
            }
            assert!(checked >= 4, "{reduce:?}: only {checked} corners move the loss");
            let held = DetectionLoss { box_gradient: false, ..l.clone() };
            assert!(held.terms_and_boxes(&p, &[&logits], 2.0).unwrap().2.is_empty());
        }
    }
}
