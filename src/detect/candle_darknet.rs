//! A differentiable darknet network (YOLOv3-tiny) on candle, built from the same cfg and weights
//! (with batch norm folded) as the ONNX export, so white-box gradients and black-box evaluation
//! run the very same model.
//!
//! Two candle 0.11 pitfalls are avoided (measured, see DESIGN.md): `max_pool2d`'s backward is
//! wrong when kernel = stride, so pooling is a reshape + max; darknet's 2×2 stride-1 pool is a
//! replicate pad + maximum of four shifted views. Every op used has an exact backward.

use super::darknet::cfg::{Activation, Layer, Network};
use super::darknet::weights::Weights;
use candle_core::{DType, Device, Result, Tensor};

/// The network as candle tensors.
pub struct CandleDarknet {
    net: Network,
    /// (weight, bias as [1, C, 1, 1]) per layer index, for convolutions.
    convs: Vec<Option<(Tensor, Tensor)>>,
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
        let mut convs: Vec<Option<(Tensor, Tensor)>> = vec![None; net.layers.len()];
        for c in &weights.convs {
            let w = Tensor::from_vec(c.weight.clone(), (c.shape[0], c.shape[1], c.shape[2], c.shape[3]), device)?
                .to_dtype(dtype)?;
            let b = Tensor::from_vec(c.bias.clone(), (1, c.shape[0], 1, 1), device)?.to_dtype(dtype)?;
            convs[c.layer] = Some((w, b));
        }
        Ok(CandleDarknet { net, convs })
    }

    /// Raw head maps `[N, A·(5+C), H, W]` in `[yolo]` order for an NCHW input in [0, 1].
    pub fn forward(&self, x: &Tensor) -> Result<Vec<Tensor>> {
        let mut outs: Vec<Tensor> = Vec::with_capacity(self.net.layers.len());
        let mut heads = Vec::new();
        for (i, layer) in self.net.layers.iter().enumerate() {
            let prev = outs.last().unwrap_or(x);
            let y = match layer {
                Layer::Conv { stride, pad, activation, .. } => {
                    let (w, b) = self.convs[i]
                        .as_ref()
                        .ok_or_else(|| candle_core::Error::Msg(format!("no weights for layer {i}")))?;
                    let y = prev.conv2d(w, *pad, *stride, 1, 1)?.broadcast_add(b)?;
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
