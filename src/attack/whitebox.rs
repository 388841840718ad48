//! The white-box detector side of a step: composite image → YOLOv3-tiny (candle) → L1 + β·L2,
//! and the exact gradient back to the composite's pixels.

use super::config::DetectorSection;
use super::loss::DetectionLoss;
use crate::detect::candle_darknet::CandleDarknet;
use crate::detect::darknet::cfg::YoloHead;
use crate::detect::darknet::{Network, Weights};
use crate::image::resize::{interpolation_matrix, Interpolation};
use candle_core::{DType, Device, Tensor, Var};
use std::time::Instant;

/// Loss values of one forward pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectorLoss {
    /// L1.
    pub l1: f32,
    /// L2.
    pub l2: f32,
    /// Number of boxes.
    pub boxes: usize,
    /// Number of target proposals.
    pub proposals: usize,
    /// Highest car score (objectness × class) of any prediction.
    pub max_score: f32,
}

impl DetectorLoss {
    fn of(t: &super::loss::LossTerms) -> candle_core::Result<Self> {
        Ok(DetectorLoss {
            l1: t.l1.to_scalar()?,
            l2: t.l2.to_scalar()?,
            boxes: t.boxes,
            proposals: t.proposals,
            max_score: t.max_score,
        })
    }
}

/// Gradient of `L1 + β·L2` with respect to the composite, with the two timings.
pub struct DetectorGrad {
    /// The loss terms.
    pub loss: DetectorLoss,
    /// ∂(L1 + β·L2)/∂image, interleaved RGB like the image.
    pub grad: Vec<f32>,
    /// Forward time (ms).
    pub forward_ms: f64,
    /// Backward time (ms).
    pub backward_ms: f64,
}

/// YOLOv3-tiny on candle with the paper's loss.
pub struct WhiteBox {
    model: CandleDarknet,
    heads: Vec<YoloHead>,
    loss: DetectionLoss,
    input: usize,
    /// Bilinear resize matrices (rows `input × size`, and its transpose) when size ≠ input.
    resize: Option<(usize, Tensor, Tensor)>,
}

/// Errors of the white-box detector.
#[derive(Debug, thiserror::Error)]
pub enum WhiteBoxError {
    /// Model files.
    #[error("white-box detector: {0}")]
    Model(#[from] crate::detect::darknet::DarknetError),
    /// Tensor maths.
    #[error("white-box detector: {0}")]
    Candle(#[from] candle_core::Error),
}

impl WhiteBox {
    /// Loads the darknet model for composites of `size × size` pixels.
    pub fn load(cfg: &DetectorSection, size: usize) -> Result<Self, WhiteBoxError> {
        let net = Network::from_file(&cfg.cfg)?;
        let w = Weights::from_file(&cfg.weights, &net)?;
        let model = CandleDarknet::new(net, &w, &Device::Cpu, DType::F32)?;
        let heads = model.heads();
        let (iw, ih) = model.input_size();
        if iw != ih {
            return Err(candle_core::Error::Msg(format!("non-square network input {iw}x{ih}")).into());
        }
        let resize = if size != iw {
            let a =
                Tensor::from_vec(interpolation_matrix(size, iw, Interpolation::Bilinear), (iw, size), &Device::Cpu)?;
            let at = a.t()?.contiguous()?;
            Some((size, a, at))
        } else {
            None
        };
        let loss = DetectionLoss { box_threshold: cfg.box_threshold, target: cfg.target.clone() };
        Ok(WhiteBox { model, heads, loss, input: iw, resize })
    }

    /// Network input side.
    pub fn input_size(&self) -> usize {
        self.input
    }

    /// HWC image tensor → `[1, 3, input, input]`.
    fn to_input(&self, hwc: &Tensor) -> candle_core::Result<Tensor> {
        let x = hwc.permute((2, 0, 1))?;
        let x = match &self.resize {
            Some((_, a, at)) => a.broadcast_matmul(&x)?.broadcast_matmul(at)?,
            None => x.contiguous()?,
        };
        x.unsqueeze(0)
    }

    /// Loss of the `size × size` RGB composite `img` and its gradient for weight `beta` on L2.
    pub fn loss_and_grad(&self, img: &[f32], size: usize, beta: f32) -> Result<DetectorGrad, WhiteBoxError> {
        let t0 = Instant::now();
        let x = Var::from_vec(img.to_vec(), (size, size, 3), &Device::Cpu)?;
        let maps = self.model.forward(&self.to_input(x.as_tensor())?)?;
        let t = self.loss.yolo(&maps, &self.heads)?;
        let total = (&t.l1 + (&t.l2 * beta as f64)?)?;
        let loss = DetectorLoss::of(&t)?;
        let forward_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let grads = total.backward()?;
        let grad = match grads.get(x.as_tensor()) {
            Some(g) => g.flatten_all()?.to_vec1()?,
            None => vec![0.0; img.len()],
        };
        Ok(DetectorGrad { loss, grad, forward_ms, backward_ms: t1.elapsed().as_secs_f64() * 1e3 })
    }

    /// The loss terms of a composite, without gradients (for scoring).
    pub fn loss(&self, img: &[f32], size: usize) -> Result<DetectorLoss, WhiteBoxError> {
        let x = Tensor::from_vec(img.to_vec(), (size, size, 3), &Device::Cpu)?;
        let t = self.loss.yolo(&self.model.forward(&self.to_input(&x)?)?, &self.heads)?;
        Ok(DetectorLoss::of(&t)?)
    }
}
