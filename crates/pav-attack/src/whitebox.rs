//! The white-box detector side of a step: composite image → detector → L1 + β·L2, and the exact
//! gradient back to the composite's pixels.
//!
//! A white box is the evaluated model itself: the ONNX file its detector config names (the same
//! one `evaluate` runs), differentiated as a graph (`pav_onnx::autodiff`) and run by ONNX Runtime
//! (`pav_onnx::session`). The input transform the config describes (resize, channel order, scale,
//! mean and std) is applied here with its exact adjoint. The outputs are read through the same
//! description evaluate decodes them by (`detect::layout::Description`, a preset's or a `custom`
//! one): its score and objectness values, with their activations and powers, become the loss's
//! predictions ([`Predictions::read`]), and under `loss.iou` its boxes, decoded with their exact
//! derivatives, weight each score by its overlap with the car. Where the outputs are final
//! detections, the description's `raw` values (those before the graph's post-processor) are
//! differentiated instead, the graph cut there. Only the outputs the loss reads are kept, and
//! those it does not differentiate (the boxes, unless `loss.box_gradient`) are computed forward
//! only.

use super::config::OptimizeConfig;
use super::defended::Defended;
use super::loss::{DetectionLoss, HeadShapeError, Predictions};
use super::outputs::{Plan, PlanError};
use pav_core::image::resize::Resampler;
use pav_core::rng::Rng;
use pav_core::step::{Chain, ChainTape, Step};
use pav_detect::config::{ChannelOrder, DetectorConfig, ExtraInput, ExtraValue};
use pav_detect::decode::{
    box_jacobians_described, decode_described, score_sites, BoxTerm, LayoutError, ScoreRule, ScoreSite,
};
use pav_detect::defence::{Defence, DefenceError};
use pav_detect::layout::{Description, Role};
use pav_detect::preprocess::InputMap;
use pav_detect::BBox;
use pav_detect::DetectError;
use pav_onnx::autodiff::{differentiate_first, AutodiffError, Kernels};
use pav_onnx::fold::fold_shapes;
use pav_onnx::proto::{Dim, Initializer, Model, ProtoError, ValueInfo, FLOAT};
use pav_onnx::session::{GradSession, Pass};
use pav_onnx::surrogate::dequantize;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

pub use super::loss::LossTerms as DetectorLoss;

/// Gradient of `L1 + β·L2` with respect to the composite, with the two timings.
pub struct DetectorGrad {
    /// The loss terms.
    pub loss: DetectorLoss,
    /// ∂(L1 + β·L2)/∂image, interleaved RGB like the image.
    pub grad: Vec<f32>,
    /// Forward time: resize, network, loss (ms).
    pub forward_ms: f64,
    /// Backward time: network gradient, resize adjoint (ms).
    pub backward_ms: f64,
}

/// A detector with the paper's loss and its input gradient.
pub struct WhiteBox {
    name: String,
    /// What its scores depend on, hashed ([`WhiteBox::identity`]).
    identity: String,
    session: Mutex<GradSession>,
    /// The description of the values differentiated.
    description: Description,
    /// Where each prediction's scores sit among the outputs, and how they are read.
    sites: Vec<ScoreSite>,
    rule: ScoreRule,
    classes: usize,
    /// The tensors the description reads and the graph outputs that compute them.
    plan: Plan,
    loss: DetectionLoss,
    input: usize,
    resample: Resampler,
    /// Model channel c reads RGB channel `channel[c]`, as `v·gain[c] + offset[c]` for v in [0, 1].
    channel: [usize; 3],
    gain: [f32; 3],
    offset: [f32; 3],
    composite: usize,
    /// Input defences trained through (`attack::defended`).
    defence: Vec<Defence>,
}

/// Errors of the white-box detector.
#[derive(Debug, thiserror::Error)]
pub enum WhiteBoxError {
    /// The detector config or its model file.
    #[error("white-box detector: {0}")]
    Config(#[from] DetectError),
    /// The model file is not an ONNX model pav reads.
    #[error("white-box detector {path}: {source}")]
    Model {
        /// The file.
        path: PathBuf,
        /// Why.
        source: ProtoError,
    },
    /// A graph without a gradient.
    #[error("white-box detector: {0}")]
    Autodiff(#[from] AutodiffError),
    /// A stage of the composite's way to the model input failed.
    #[error("white-box detector {detector}: {stage}: {why}")]
    Input {
        /// The detector.
        detector: String,
        /// The stage.
        stage: &'static str,
        /// Why.
        why: String,
    },
    /// ONNX Runtime refused the graphs, or their shapes could not be folded.
    #[error("white-box detector: {0}")]
    Onnx(#[from] pav_onnx::OnnxError),
    /// Outputs that do not fit the layout.
    #[error("white-box detector: {0}")]
    Heads(#[from] HeadShapeError),
    /// The outputs the description reads could not be planned.
    #[error("white-box detector: {0}")]
    Plan(#[from] PlanError),
    /// Outputs that do not fit the detector's description.
    #[error("white-box detector: {0}")]
    Layout(#[from] LayoutError),
    /// A composite of another size than the one the detector was loaded for.
    #[error("white-box detector: a {got}-value composite, expected {expected}² RGB")]
    Size {
        /// Values given.
        got: usize,
        /// The composite side it was loaded for.
        expected: usize,
    },
    /// A set-up pav has no white-box loss or input transform for.
    #[error("white-box detector {name}: {why}")]
    Unsupported {
        /// Detector name.
        name: String,
        /// What is missing.
        why: String,
    },
}

/// How a [`WhiteBox`] runs, beyond its config.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WhiteBoxOptions {
    /// Side of the composites it scores.
    pub composite: usize,
    /// Network input side (default: the cfg's).
    pub input: Option<usize>,
    /// ONNX Runtime threads per pass (0 = the runtime's default, the physical cores).
    pub threads: usize,
    /// Differentiate the float surrogate of a dynamically quantized model.
    pub surrogate: bool,
}

/// The extra inputs of `model` that are still inputs made neutral constants for a `side`² input:
/// a `scale_yx` of 1 leaves boxes in input pixels; a `size_wh` is the input's.
fn neutral_extras(model: &mut Model, extra: &[ExtraInput], side: usize) {
    for e in extra {
        if !model.inputs.iter().any(|v| v.name == e.name) {
            continue;
        }
        model.inputs.retain(|v| v.name != e.name);
        model.initializers.push(match e.value {
            ExtraValue::ScaleYx => Initializer::f32(&e.name, &[1, 2], vec![1.0, 1.0]),
            ExtraValue::SizeWh => Initializer::i64(&e.name, &[1, 2], vec![side as i64; 2]),
        });
    }
}

/// `model` cut to compute the values of `outputs` (each with the config key that names it), its
/// extra inputs made neutral constants (a `scale_yx` of 1 leaves boxes in input pixels; a
/// `size_wh` is the input's), its shapes folded for a `side`² input: a graph whose
/// post-processor (top-k, NMS) has no gradient, cut where that begins. `name`: the detector's.
pub fn cut_before_post(
    mut model: Model,
    outputs: &[(String, &str)],
    extra: &[ExtraInput],
    side: usize,
    name: &str,
) -> Result<Model, WhiteBoxError> {
    neutral_extras(&mut model, extra, side);
    if let Some((o, key)) = outputs.iter().find(|(o, _)| !model.nodes.iter().any(|n| n.outputs.contains(o))) {
        let why = format!("no value `{o}` (the config's `{key}`) in the graph");
        return Err(WhiteBoxError::Unsupported { name: name.into(), why });
    }
    model.outputs =
        outputs.iter().map(|(o, _)| ValueInfo { name: o.clone(), elem_type: FLOAT, dims: vec![] }).collect();
    model.prune();
    // The exported graph computes its reshapes from run-time shapes: fixed here.
    let x = model.inputs.first().map(|i| i.name.clone()).unwrap_or_default();
    Ok(fold_shapes(&model, &[(x.as_str(), vec![1, 3, side as i64, side as i64])], name)?.0)
}

impl WhiteBox {
    /// Loads the detector of `cfg` for composites of `size × size` pixels.
    pub fn load(cfg: &DetectorConfig, loss: DetectionLoss, size: usize) -> Result<Self, WhiteBoxError> {
        Self::with_options(cfg, loss, WhiteBoxOptions { composite: size, input: None, threads: 0, surrogate: false })
    }

    /// Loads the detector of `cfg` as `o` says.
    pub fn with_options(cfg: &DetectorConfig, loss: DetectionLoss, o: WhiteBoxOptions) -> Result<Self, WhiteBoxError> {
        let unsupported = |why: String| WhiteBoxError::Unsupported { name: cfg.name.clone(), why };
        let i = &cfg.input;
        // A square composite letterboxed into a square input is a plain resize.
        if i.width != i.height {
            return Err(unsupported(format!("a non-square input {}x{}", i.width, i.height)));
        }
        let side = o.input.unwrap_or(i.width);
        let bytes = std::fs::read(&cfg.model).map_err(|source| DetectError::ConfigRead {
            path: cfg.source.display().to_string(),
            what: format!("the model {}", cfg.model.display()),
            source,
        })?;
        let mut model =
            Model::from_bytes(&bytes).map_err(|source| WhiteBoxError::Model { path: cfg.model.clone(), source })?;
        let quantized = pav_detect::onnx::is_quantized(&model);
        if quantized && !o.surrogate {
            return Err(unsupported(
                "a dynamically quantized model has no gradient; set `surrogate = true` on its [[white_box]] to train against its float surrogate".into(),
            ));
        }
        if quantized {
            model = dequantize(&model).map_err(|e| unsupported(e.to_string()))?.0;
        }
        // A clipped detector is trained through its clipping: the rewrite is differentiable.
        pav_detect::defence::clip_graph(&mut model, &cfg.model_defence)?;
        // The image is the input the config names (else the first); the others get constants.
        if let Some(n) = &i.name {
            let k = model
                .inputs
                .iter()
                .position(|v| &v.name == n)
                .ok_or_else(|| unsupported(format!("the graph has no input `{n}` (the config's input.name)")))?;
            let x = model.inputs.remove(k);
            model.inputs.insert(0, x);
        }
        neutral_extras(&mut model, &i.extra, side);
        // As evaluate decodes: the config's class list; the loss checks the outputs against it.
        let classes = cfg.class_names.len();
        let description = cfg.output.gradient(classes).map_err(&unsupported)?;
        // Values the description names inside the graph: its post-processor (top-k, NMS) has no
        // gradient, so the graph is cut there. The boxes are read only under `loss.iou`.
        let mut named: Vec<(String, &str)> = Vec::new();
        for (role, part) in description.parts() {
            for n in part.output.iter().filter(|_| role != Role::Boxes || loss.iou) {
                if !named.iter().any(|(m, _)| m == n) {
                    named.push((n.clone(), role.table()));
                }
            }
        }
        if let Some(x) = model.inputs.first() {
            if x.dims.len() == 4 && x.dims[2..].iter().any(|d| matches!(d, Dim::Fixed(v) if *v != side as i64)) {
                return Err(unsupported(format!("the graph's input is fixed at {:?}, not {side}²", x.dims)));
            }
        }
        if named.iter().any(|(n, _)| !model.outputs.iter().any(|o| o.name == *n)) {
            model = cut_before_post(model, &named, &i.extra, side, &cfg.name)?;
        } else {
            // Described at its own outputs, a graph is folded alike: exports carry `Constant`
            // nodes and run-time shape arithmetic (Shape, Gather, Concat into a Reshape), which
            // have no derivative and need none once the input's size is fixed.
            let x = model.inputs.first().map(|i| i.name.clone()).unwrap_or_default();
            model = fold_shapes(&model, &[(x.as_str(), vec![1, 3, side as i64, side as i64])], &cfg.name)?.0;
        }
        // The outputs the loss differentiates (scores, objectness; the boxes too under
        // `loss.box_gradient`), then those it reads forward only (the boxes under `loss.iou`).
        let plan = Plan::new(&mut model, &description, side, classes, loss.iou, loss.box_gradient)?;
        let d = differentiate_first(&model, &[1, 3, side as i64, side as i64], Kernels::Fused, plan.seeded)?;
        let sites = score_sites(&description, &plan.located(), side, side, classes)?;
        let session = GradSession::new(&format!("{} (white-box)", cfg.name), d, o.threads)?;
        let channel = match i.channels {
            ChannelOrder::Rgb => [0, 1, 2],
            ChannelOrder::Bgr => [2, 1, 0],
        };
        let gain = [0, 1, 2].map(|c| 255.0 * i.scale / i.std[c]);
        let offset = [0, 1, 2].map(|c| -i.mean[c] / i.std[c]);
        // The model's bytes and every setting read above, and nothing that only names or locates
        // them: the same models under other names or in other folders share cached scores. The
        // thread count is left out too: it does not change a score.
        let settings = WhiteBoxOptions { threads: 0, ..o };
        let scored = DetectorConfig {
            name: String::new(),
            description: String::new(),
            model: PathBuf::new(),
            source: PathBuf::new(),
            bases: Vec::new(),
            ..cfg.clone()
        };
        let identity = pav_run::data::store::sha256_hex(
            format!("{}\n{scored:?}\n{loss:?}\n{settings:?}", pav_run::data::store::sha256_hex(&bytes)).as_bytes(),
        );
        Ok(WhiteBox {
            name: cfg.name.clone(),
            identity,
            session: Mutex::new(session),
            rule: ScoreRule::of(&description, classes),
            description,
            sites,
            classes,
            plan,
            loss,
            input: side,
            // The config's filter, as evaluate resizes (without its 8-bit rounding, which has no gradient).
            resample: Resampler::new(o.composite, side, i.interpolation),
            channel,
            gain,
            offset,
            composite: o.composite,
            defence: i.defence.clone(),
        })
    }

    /// The detector's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// A hash of what its scores depend on (the model's bytes, its description, the loss and load
    /// options): two white boxes of one identity score every image alike.
    pub fn identity(&self) -> &str {
        &self.identity
    }

    /// Network input side.
    pub fn input_size(&self) -> usize {
        self.input
    }

    fn session(&self) -> std::sync::MutexGuard<'_, GradSession> {
        self.session.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The composite to the model's input, as a chain of steps: resized to the input size,
    /// behind the config's input defences (when it has any), channels ordered and normalized.
    fn input_chain(&self) -> Chain<'_> {
        let mut c = Chain::new().then("resize", &self.resample);
        if self.defence.iter().any(Defence::on_input) {
            c.push("defences", Defended { chain: &self.defence, side: self.input });
        }
        let n = Normalize { channel: self.channel, gain: self.gain, offset: self.offset, side: self.input };
        c.then("normalize", n)
    }

    /// The model input of the `size × size` composite `img`, and what its adjoint needs.
    fn model_input(&self, img: &[f32], size: usize) -> Result<(Vec<f32>, ChainTape), WhiteBoxError> {
        if size != self.composite || img.len() != size * size * 3 {
            return Err(WhiteBoxError::Size { got: img.len(), expected: self.composite });
        }
        // The defences draw from the image itself, so the chain's generator is never read.
        self.input_chain().forward(img, &mut Rng::new(0)).map_err(|e| match e.source.downcast::<DefenceError>() {
            Ok(source) => DetectError::Defence { detector: self.name.clone(), source: *source }.into(),
            Err(source) => {
                WhiteBoxError::Input { detector: self.name.clone(), stage: e.stage, why: source.to_string() }
            }
        })
    }

    /// The adjoint of [`WhiteBox::model_input`] (of its forward that left `tape`).
    fn input_adjoint(&self, g: &[f32], tape: &ChainTape) -> Vec<f32> {
        let mut grad = vec![0f32; self.composite * self.composite * 3];
        self.input_chain().adjoint(tape, g, &mut grad);
        grad
    }

    /// Each prediction's box in composite pixels (xyxy), in the order [`Predictions`] reads them,
    /// decoded as evaluate decodes them; with `grad`, each with its derivative by every output
    /// value it reads (an empty list without).
    fn boxes(&self, outs: &[Vec<f32>], grad: bool) -> Result<Vec<(BBox, Vec<BoxTerm>)>, WhiteBoxError> {
        let k = self.input as f32 / self.composite as f32;
        let c = self.composite as f32;
        let map = InputMap { scale_x: k, scale_y: k, pad_x: 0.0, pad_y: 0.0, frame_w: c, frame_h: c };
        let raw = self.plan.raw(outs.to_vec());
        let (d, side) = (&self.description, self.input);
        Ok(if grad {
            box_jacobians_described(d, &raw, side, side, self.classes, &map)?
        } else {
            decode_described(d, &raw, side, side, self.classes, &map)?
                .boxes
                .into_iter()
                .map(|b| (b, Vec::new()))
                .collect()
        })
    }

    /// The loss terms of the outputs and their gradients, each score weighted by its box's IoU
    /// with `car` (composite pixels, xyxy) when the loss says so, that weight differentiated
    /// through the box outputs under `loss.box_gradient`.
    fn score(
        &self,
        outs: &[Vec<f32>],
        beta: f32,
        car: Option<[f32; 4]>,
    ) -> Result<(DetectorLoss, Vec<Vec<f32>>), WhiteBoxError> {
        let mut p = self.read(outs)?;
        let boxes = match (self.loss.iou, car) {
            (true, Some(car)) => {
                let boxes = self.boxes(outs, self.loss.box_gradient)?;
                p.weigh(&boxes.iter().map(|b| b.0).collect::<Vec<_>>(), car)?;
                boxes
            }
            _ => Vec::new(),
        };
        let raw: Vec<&[f32]> = outs.iter().map(|v| v.as_slice()).collect();
        let (terms, mut grads, box_grads) = self.loss.terms_and_boxes(&p, &raw, beta)?;
        for (i, d) in box_grads {
            for &(o, idx, db) in &boxes[i].1 {
                grads[o][idx] += (0..4).map(|k| d[k] * db[k]).sum::<f32>();
            }
        }
        Ok((terms, self.plan.scatter(grads)))
    }

    /// The differentiated outputs read as predictions.
    fn read(&self, outs: &[Vec<f32>]) -> Result<Predictions, HeadShapeError> {
        let raw: Vec<&[f32]> = outs.iter().map(|v| v.as_slice()).collect();
        Predictions::read(&raw, &self.sites, &self.rule, self.classes)
    }

    /// Each prediction's box in composite pixels and its unweighted detection score for the
    /// target classes, for checks and plots (boxes in outputs of their own are there under
    /// `loss.iou` only).
    pub fn predictions(&self, img: &[f32], size: usize) -> Result<Vec<([f32; 4], f32)>, WhiteBoxError> {
        let (outs, ..) = self.outputs(&mut self.session(), img, size)?;
        let scores = self.read(&outs)?.target_scores(&self.loss.target);
        Ok(self.boxes(&outs, false)?.into_iter().map(|b| b.0).zip(scores).collect())
    }

    fn outputs(
        &self,
        s: &mut GradSession,
        img: &[f32],
        size: usize,
    ) -> Result<(Vec<Vec<f32>>, Pass, ChainTape), WhiteBoxError> {
        let (x, tape) = self.model_input(img, size)?;
        let (outs, pass) = s.forward(x)?;
        Ok((self.plan.assemble(outs), pass, tape))
    }

    /// Loss of the `size × size` RGB composite `img` and its gradient for weight `beta` on L2;
    /// `car` is the car's box in the composite (xyxy), which `loss.iou` weights scores by.
    pub fn loss_and_grad(
        &self,
        img: &[f32],
        size: usize,
        beta: f32,
        car: Option<[f32; 4]>,
    ) -> Result<DetectorGrad, WhiteBoxError> {
        let t0 = Instant::now();
        let mut s = self.session();
        let (outs, pass, tape) = self.outputs(&mut s, img, size)?;
        let (loss, out_grads) = self.score(&outs, beta, car)?;
        let forward_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let g = s.backward(&pass, out_grads)?;
        let grad = self.input_adjoint(&g, &tape);
        Ok(DetectorGrad { loss, grad, forward_ms, backward_ms: t1.elapsed().as_secs_f64() * 1e3 })
    }

    /// The loss terms of a composite, without gradients (for scoring).
    pub fn loss(&self, img: &[f32], size: usize) -> Result<DetectorLoss, WhiteBoxError> {
        let (outs, ..) = self.outputs(&mut self.session(), img, size)?;
        Ok(self.score(&outs, 1.0, None)?.0)
    }
}

/// Several white-box detectors with weights: the loss is their weighted sum.
pub struct Ensemble {
    /// The detectors and their weights.
    pub members: Vec<(WhiteBox, f32)>,
}

/// One step's gradient over an ensemble, with each member's terms.
pub struct EnsembleGrad {
    /// The weighted sum over the members that took part: terms and gradient weighted (`boxes`,
    /// `proposals` summed; `max_score` the highest), times summed.
    pub sum: DetectorGrad,
    /// Each member's own terms, in member order; `None` for a member that sat the step out.
    pub per_detector: Vec<Option<DetectorLoss>>,
}

impl Ensemble {
    /// Loads the `[[white_box]]` detectors of `cfg` for composites of `size × size` pixels.
    pub fn load(cfg: &OptimizeConfig, size: usize) -> Result<Self, WhiteBoxError> {
        let members = cfg
            .white_box
            .iter()
            .map(|e| {
                let d = e.detector_config()?;
                let loss = DetectionLoss {
                    box_threshold: cfg.loss.box_threshold,
                    target: d.target_classes.clone(),
                    reduce: cfg.loss.reduce,
                    proposals: cfg.loss.proposals,
                    iou: cfg.loss.iou,
                    box_gradient: cfg.loss.box_gradient,
                };
                let o = WhiteBoxOptions {
                    composite: size,
                    input: None,
                    threads: cfg.optimizer.threads,
                    surrogate: e.surrogate,
                };
                Ok((WhiteBox::with_options(&d, loss, o)?, e.weight))
            })
            .collect::<Result<_, WhiteBoxError>>()?;
        Ok(Ensemble { members })
    }

    /// Weighted `L1 + β·L2` over all members and its gradient (`car` as for [`WhiteBox::loss_and_grad`]).
    pub fn loss_and_grad(
        &self,
        img: &[f32],
        size: usize,
        beta: f32,
        car: Option<[f32; 4]>,
    ) -> Result<EnsembleGrad, WhiteBoxError> {
        let all: Vec<usize> = (0..self.members.len()).collect();
        self.loss_and_grad_of(&all, img, size, beta, car)
    }

    /// Weighted `L1 + β·L2` over the members `drawn` (indices), their weights scaled so that they
    /// sum to the whole ensemble's: the loss keeps its scale whichever members take part.
    pub fn loss_and_grad_of(
        &self,
        drawn: &[usize],
        img: &[f32],
        size: usize,
        beta: f32,
        car: Option<[f32; 4]>,
    ) -> Result<EnsembleGrad, WhiteBoxError> {
        let mut sum = DetectorGrad {
            loss: DetectorLoss { l1: 0.0, l2: 0.0, boxes: 0, proposals: 0, max_score: 0.0 },
            grad: vec![0f32; img.len()],
            forward_ms: 0.0,
            backward_ms: 0.0,
        };
        let total: f32 = self.members.iter().map(|m| m.1).sum();
        let taking_part: f32 = drawn.iter().map(|&i| self.members[i].1).sum();
        let scale = total / taking_part;
        let mut per_detector = vec![None; self.members.len()];
        for &i in drawn {
            let (wb, weight) = &self.members[i];
            let w = weight * scale;
            let g = wb.loss_and_grad(img, size, beta, car)?;
            sum.grad.iter_mut().zip(&g.grad).for_each(|(a, b)| *a += w * b);
            let l = &mut sum.loss;
            l.l1 += w * g.loss.l1;
            l.l2 += w * g.loss.l2;
            l.boxes += g.loss.boxes;
            l.proposals += g.loss.proposals;
            l.max_score = l.max_score.max(g.loss.max_score);
            sum.forward_ms += g.forward_ms;
            sum.backward_ms += g.backward_ms;
            per_detector[i] = Some(g.loss);
        }
        Ok(EnsembleGrad { sum, per_detector })
    }

    /// The first member, which scores the per-view reports.
    pub fn first(&self) -> &WhiteBox {
        &self.members[0].0
    }
}

/// The config's channel order and normalization, as a step on a planar model input of
/// `side × side`: model channel c reads RGB channel `channel[c]` as `v·gain[c] + offset[c]`.
struct Normalize {
    channel: [usize; 3],
    gain: [f32; 3],
    offset: [f32; 3],
    side: usize,
}

impl Step for Normalize {
    type Tape = ();
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        3 * self.side * self.side
    }

    fn output_len(&self) -> usize {
        3 * self.side * self.side
    }

    fn forward(&self, rgb: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
        let plane = self.side * self.side;
        let mut x = vec![0f32; 3 * plane];
        for c in 0..3 {
            let src = &rgb[self.channel[c] * plane..(self.channel[c] + 1) * plane];
            let (g, o) = (self.gain[c], self.offset[c]);
            x[c * plane..(c + 1) * plane].iter_mut().zip(src).for_each(|(d, &v)| *d = v * g + o);
        }
        Ok((x, ()))
    }

    fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
        let plane = self.side * self.side;
        for c in 0..3 {
            let dst = &mut gx[self.channel[c] * plane..(self.channel[c] + 1) * plane];
            dst.iter_mut().zip(&gy[c * plane..(c + 1) * plane]).for_each(|(d, &v)| *d += v * self.gain[c]);
        }
    }
}
