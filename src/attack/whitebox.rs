//! The white-box detector side of a step: composite image → YOLOv3-tiny → L1 + β·L2, and the
//! exact gradient back to the composite's pixels.
//!
//! The network is the ONNX graph that `evaluate` runs (exported from the same darknet files), and
//! its input gradient is that graph differentiated (`detect::autodiff`), both run by ONNX Runtime
//! (`detect::ortgrad`). The resize from the composite to the network input is a fixed linear map
//! with its exact adjoint.

use super::config::DetectorSection;
use super::loss::{DetectionLoss, HeadMap, HeadShapeError};
use crate::detect::autodiff::{differentiate_with, AutodiffError, Kernels};
use crate::detect::darknet::cfg::YoloHead;
use crate::detect::darknet::{to_onnx, DarknetError, Network, Weights};
use crate::detect::ortgrad::{GradSession, Pass};
use crate::detect::DetectError;
use crate::image::resize::{Interpolation, Resampler};
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

/// YOLOv3-tiny with the paper's loss and its input gradient.
pub struct WhiteBox {
    session: Mutex<GradSession>,
    heads: Vec<YoloHead>,
    head_sizes: Vec<(usize, usize)>,
    loss: DetectionLoss,
    input: usize,
    resample: Resampler,
    composite: usize,
}

/// Errors of the white-box detector.
#[derive(Debug, thiserror::Error)]
pub enum WhiteBoxError {
    /// Model files.
    #[error("white-box detector: {0}")]
    Model(#[from] DarknetError),
    /// A graph without a gradient.
    #[error("white-box detector: {0}")]
    Autodiff(#[from] AutodiffError),
    /// ONNX Runtime.
    #[error("white-box detector: {0}")]
    Runtime(#[from] DetectError),
    /// Head maps that do not fit the cfg's heads.
    #[error("white-box detector: {0}")]
    Heads(#[from] HeadShapeError),
    /// A composite of another size than the one the detector was loaded for.
    #[error("white-box detector: a {got}-value composite, expected {expected}² RGB")]
    Size {
        /// Values given.
        got: usize,
        /// The composite side it was loaded for.
        expected: usize,
    },
    /// A network whose input is not square.
    #[error("white-box detector: non-square network input {0}x{1}")]
    NotSquare(usize, usize),
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
}

impl WhiteBox {
    /// Loads the darknet model for composites of `size × size` pixels.
    pub fn load(cfg: &DetectorSection, size: usize) -> Result<Self, WhiteBoxError> {
        Self::with_options(cfg, WhiteBoxOptions { composite: size, input: None, threads: 0 })
    }

    /// Loads the darknet model as `o` says.
    pub fn with_options(cfg: &DetectorSection, o: WhiteBoxOptions) -> Result<Self, WhiteBoxError> {
        let size = o.composite;
        let net = Network::from_file(&cfg.cfg)?;
        let w = Weights::from_file(&cfg.weights, &net)?;
        if net.width != net.height {
            return Err(WhiteBoxError::NotSquare(net.width, net.height));
        }
        let (iw, ih) = (o.input.unwrap_or(net.width), o.input.unwrap_or(net.height));
        let heads: Vec<YoloHead> = net.heads().into_iter().map(|(_, h)| h.clone()).collect();
        let model = to_onnx::export(&net, &w)?;
        let d = differentiate_with(&model, &[1, 3, ih as i64, iw as i64], Kernels::Fused)?;
        let head_sizes = d.outputs.iter().map(|(_, s)| (s[2] as usize, s[3] as usize)).collect();
        let session = GradSession::new("yolov3-tiny (white-box)", d, o.threads)?;
        let loss = DetectionLoss { box_threshold: cfg.box_threshold, target: cfg.target.clone() };
        let resample = Resampler::new(size, iw, Interpolation::Bilinear);
        Ok(WhiteBox { session: Mutex::new(session), heads, head_sizes, loss, input: iw, resample, composite: size })
    }

    /// Network input side.
    pub fn input_size(&self) -> usize {
        self.input
    }

    fn session(&self) -> std::sync::MutexGuard<'_, GradSession> {
        self.session.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The head maps of the `size × size` composite `img`, each with its `(H, W)`, and what the
    /// backward needs.
    fn heads_of(&self, s: &mut GradSession, img: &[f32], size: usize) -> Result<(Vec<HeadMap>, Pass), WhiteBoxError> {
        if size != self.composite || img.len() != size * size * 3 {
            return Err(WhiteBoxError::Size { got: img.len(), expected: self.composite });
        }
        let (maps, pass) = s.forward(self.resample.apply(img, 3))?;
        Ok((maps.into_iter().zip(self.head_sizes.iter().copied()).collect(), pass))
    }

    /// Loss of the `size × size` RGB composite `img` and its gradient for weight `beta` on L2.
    pub fn loss_and_grad(&self, img: &[f32], size: usize, beta: f32) -> Result<DetectorGrad, WhiteBoxError> {
        let t0 = Instant::now();
        let mut s = self.session();
        let (maps, pass) = self.heads_of(&mut s, img, size)?;
        let (loss, head_grads) = self.loss.yolo(&maps, &self.heads, beta)?;
        let forward_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let g = s.backward(&pass, head_grads)?;
        let grad = self.resample.adjoint(&g, 3);
        Ok(DetectorGrad { loss, grad, forward_ms, backward_ms: t1.elapsed().as_secs_f64() * 1e3 })
    }

    /// The loss terms of a composite, without gradients (for scoring).
    pub fn loss(&self, img: &[f32], size: usize) -> Result<DetectorLoss, WhiteBoxError> {
        let (maps, _) = self.heads_of(&mut self.session(), img, size)?;
        Ok(self.loss.yolo(&maps, &self.heads, 1.0)?.0)
    }
}
