//! A differentiable darknet network (YOLOv3-tiny) on candle, built from the same cfg and weights
//! (with batch norm folded) as the ONNX export, so white-box gradients and black-box evaluation
//! run the very same model.
//!
//! Two candle 0.11 pitfalls are avoided (measured, see DESIGN.md): `max_pool2d`'s backward is
//! wrong when kernel = stride, so pooling is a reshape + max; darknet's 2×2 stride-1 pool is a
//! replicate pad + maximum of four shifted views. Every op used has an exact backward.
//!
//! The weights never train here, so stride-1 convolutions run as [`FrozenConv`], whose backward
//! computes only the input gradient (DESIGN.md measured fwd+bwd 0.9 → 0.57 s at 416²).

use super::darknet::cfg::{Activation, Layer, Network};
use super::darknet::weights::Weights;
use candle_core::{CpuStorage, CustomOp1, DType, Device, Layout, Result, Shape, Tensor};
use std::sync::Arc;

/// A convolution with fixed weights (stride 1, square kernel, symmetric padding) whose backward
/// is the forward convolution of the output gradient with the flipped, transposed kernel: the
/// input gradient only, by the same im2col + GEMM path as the forward. Candle's stock backward
/// also builds the (unused) weight gradient and runs a direct transposed convolution.
pub struct FrozenConv {
    w: Tensor,
    w_flipped: Tensor,
    pad: usize,
}

impl FrozenConv {
    /// Wraps weight `w` `[out, in, k, k]` with padding `pad` (`pad ≤ k − 1`).
    pub fn new(w: &Tensor, pad: usize) -> Result<Self> {
        let (_, _, k, k2) = w.dims4()?;
        if k != k2 || pad > k - 1 {
            candle_core::bail!("frozen conv needs a square kernel and pad ≤ k−1, got {k}x{k2} pad {pad}");
        }
        let rev = Tensor::from_vec((0..k as u32).rev().collect::<Vec<_>>(), k, w.device())?;
        let w_flipped = w.index_select(&rev, 2)?.index_select(&rev, 3)?.transpose(0, 1)?.contiguous()?;
        Ok(FrozenConv { w: w.clone(), w_flipped, pad })
    }
}

impl CustomOp1 for FrozenConv {
    fn name(&self) -> &'static str {
        "frozen-conv2d"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let Some((a, b)) = layout.contiguous_offsets() else {
            candle_core::bail!("frozen conv: input is not contiguous");
        };
        let x = match storage {
            CpuStorage::F32(v) => Tensor::from_slice(&v[a..b], layout.shape(), &Device::Cpu)?,
            CpuStorage::F64(v) => Tensor::from_slice(&v[a..b], layout.shape(), &Device::Cpu)?,
            _ => candle_core::bail!("frozen conv: only f32 and f64 inputs"),
        };
        let y = x.conv2d(&self.w, self.pad, 1, 1, 1)?;
        let shape = y.shape().clone();
        let flat = y.flatten_all()?;
        let out = match y.dtype() {
            DType::F64 => CpuStorage::F64(flat.to_vec1()?),
            _ => CpuStorage::F32(flat.to_vec1()?),
        };
        Ok((out, shape))
    }

    fn bwd(&self, _arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let k = self.w.dim(2)?;
        Ok(Some(grad.conv2d(&self.w_flipped, k - 1 - self.pad, 1, 1, 1)?))
    }
}

/// One convolution's parameters: weight, bias as `[1, C, 1, 1]`, and the frozen op for stride 1.
struct Conv {
    w: Tensor,
    b: Tensor,
    frozen: Option<Arc<Box<dyn CustomOp1 + Send + Sync>>>,
}

/// The network as candle tensors.
pub struct CandleDarknet {
    net: Network,
    /// Per layer index, for convolutions.
    convs: Vec<Option<Conv>>,
    /// Whether stride-1 convolutions use [`FrozenConv`] when gradients flow.
    frozen: bool,
}

/// Darknet's leaky ReLU (slope 0.1) as max(x, 0.1·x).
fn leaky(x: &Tensor) -> Result<Tensor> {
    x.maximum(&(x * 0.1)?)
}

/// Darknet max-pooling: total padding size−1 (bottom/right first), out = (w + size − 1 − size)/stride + 1.
fn maxpool(x: &Tensor, size: usize, stride: usize) -> Result<Tensor> {
    let (b, c, h, w) = x.dims4()?;
    if size == stride && h % size == 0 && w % size == 0 {
        return x.reshape((b, c, h / size, size, w / size, size))?.max(5)?.max(3);
    }
    if stride != 1 {
        candle_core::bail!("darknet maxpool size {size} stride {stride} on {h}x{w} is not supported");
    }
    let pad = size - 1;
    let (lo, hi) = (pad / 2, pad - pad / 2);
    // Replicate padding acts as −∞ padding for a max: every window still holds a real pixel.
    let xp = x.pad_with_same(2, lo, hi)?.pad_with_same(3, lo, hi)?;
    let mut m: Option<Tensor> = None;
    for dy in 0..size {
        for dx in 0..size {
            let v = xp.narrow(2, dy, h)?.narrow(3, dx, w)?;
            m = Some(match m {
                None => v,
                Some(m) => m.maximum(&v)?,
            });
        }
    }
    m.ok_or_else(|| candle_core::Error::Msg("empty pool window".into()))
}

impl CandleDarknet {
    /// Uploads `weights` for `net` to `device` as `dtype`.
    pub fn new(net: Network, weights: &Weights, device: &Device, dtype: DType) -> Result<Self> {
        let mut convs: Vec<Option<Conv>> = (0..net.layers.len()).map(|_| None).collect();
        for c in &weights.convs {
            let w = Tensor::from_vec(c.weight.clone(), (c.shape[0], c.shape[1], c.shape[2], c.shape[3]), device)?
                .to_dtype(dtype)?;
            let b = Tensor::from_vec(c.bias.clone(), (1, c.shape[0], 1, 1), device)?.to_dtype(dtype)?;
            let frozen = match net.layers[c.layer] {
                Layer::Conv { stride: 1, pad, .. }
                    if device.is_cpu() && c.shape[2] == c.shape[3] && pad < c.shape[2] =>
                {
                    Some(Arc::new(Box::new(FrozenConv::new(&w, pad)?) as Box<dyn CustomOp1 + Send + Sync>))
                }
                _ => None,
            };
            convs[c.layer] = Some(Conv { w, b, frozen });
        }
        Ok(CandleDarknet { net, convs, frozen: true })
    }

    /// Uses candle's stock convolution backward instead of [`FrozenConv`] (for comparisons).
    pub fn with_stock_conv(mut self) -> Self {
        self.frozen = false;
        self
    }

    /// The `[yolo]` heads in output order (anchors and class count).
    pub fn heads(&self) -> Vec<super::darknet::cfg::YoloHead> {
        self.net.heads().into_iter().map(|(_, h)| h.clone()).collect()
    }

    /// Network input size (width, height) from the cfg.
    pub fn input_size(&self) -> (usize, usize) {
        (self.net.width, self.net.height)
    }

    /// Raw head maps `[N, A·(5+C), H, W]` in `[yolo]` order for an NCHW input in [0, 1].
    pub fn forward(&self, x: &Tensor) -> Result<Vec<Tensor>> {
        let mut outs: Vec<Tensor> = Vec::with_capacity(self.net.layers.len());
        let mut heads = Vec::new();
        for (i, layer) in self.net.layers.iter().enumerate() {
            let prev = outs.last().unwrap_or(x);
            let y = match layer {
                Layer::Conv { stride, pad, activation, .. } => {
                    let c = self.convs[i]
                        .as_ref()
                        .ok_or_else(|| candle_core::Error::Msg(format!("no weights for layer {i}")))?;
                    let y = match &c.frozen {
                        // Without gradients the op would only add copies.
                        Some(op) if self.frozen && prev.track_op() => prev.contiguous()?.apply_op1_arc(op.clone())?,
                        _ => prev.conv2d(&c.w, *pad, *stride, 1, 1)?,
                    };
                    let y = y.broadcast_add(&c.b)?;
                    match activation {
                        Activation::Leaky => leaky(&y)?,
                        Activation::Linear => y,
                    }
                }
                Layer::MaxPool { size, stride } => maxpool(prev, *size, *stride)?,
                Layer::Upsample { stride } => {
                    let (_, _, h, w) = prev.dims4()?;
                    prev.upsample_nearest2d(h * stride, w * stride)?
                }
                Layer::Route { layers } => {
                    let parts: Vec<&Tensor> = layers.iter().map(|&l| &outs[l]).collect();
                    if parts.len() == 1 {
                        parts[0].clone()
                    } else {
                        Tensor::cat(&parts, 1)?
                    }
                }
                Layer::Yolo(_) => {
                    heads.push(prev.clone());
                    prev.clone()
                }
            };
            outs.push(y);
        }
        Ok(heads)
    }
}
