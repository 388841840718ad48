//! Fused gradient operators for ONNX Runtime (domain `pav`), used by
//! [`Kernels::Fused`](super::autodiff::Kernels) gradient graphs: each replaces several element-wise
//! passes of its standard-ONNX rule by one, on ONNX Runtime's own thread pool.
//!
//! - `LeakyReluGrad(z, g; alpha)`: `g` where `z > 0`, else `alpha·g` (`z` may be the activation's
//!   input or, for `alpha ≥ 0`, its output: the sign is the same).
//! - `MaxPoolGrad(x, y, g; kernel_shape, strides, pads)`: each output's gradient goes to the first
//!   position of its window (row-major) that equals the window's maximum; padding never wins.

use crate::autodiff::PAV_DOMAIN;
use ort::operator::{
    BoxedKernel, ComputeContext, KernelContext, Operator, OperatorDomain, OperatorInput, OperatorOutput,
};
use ort::value::TensorElementType;

/// The domain with every pav operator, for a session builder's `with_operators`.
pub fn domain() -> ort::Result<OperatorDomain> {
    OperatorDomain::new(PAV_DOMAIN)?.add(LeakyReluGrad)?.add(MaxPoolGrad)
}

/// A pointer that parallel batches may share because each writes its own disjoint range.
#[derive(Clone, Copy)]
struct Shared(*mut f32);
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

impl Shared {
    /// `len` values from offset `at`; the caller owns that range alone.
    ///
    /// # Safety
    /// `at + len` is inside the buffer and no other batch touches the range.
    unsafe fn range<'a>(self, at: usize, len: usize) -> &'a mut [f32] {
        std::slice::from_raw_parts_mut(self.0.add(at), len)
    }
}

fn missing(what: &str) -> ort::Error {
    ort::Error::new(format!("pav operator: missing {what}"))
}

fn float_inputs(n: usize) -> Vec<OperatorInput> {
    (0..n).map(|_| OperatorInput::required(TensorElementType::Float32)).collect()
}

/// The backward of LeakyRelu (and of Relu, with `alpha = 0`).
pub struct LeakyReluGrad;

impl Operator for LeakyReluGrad {
    type Kernel<'attr> = BoxedKernel<'attr>;

    fn name(&self) -> &str {
        "LeakyReluGrad"
    }

    fn inputs(&self) -> impl IntoIterator<Item = OperatorInput> {
        float_inputs(2)
    }

    fn outputs(&self) -> impl IntoIterator<Item = OperatorOutput> {
        [OperatorOutput::required(TensorElementType::Float32)]
    }

    fn create_kernel<'attr>(&self, kctx: &KernelContext<'attr>) -> ort::Result<Self::Kernel<'attr>> {
        let alpha: f32 = kctx.get("alpha").unwrap_or(0.01);
        Ok(Box::new(move |ctx: &ComputeContext| {
            let z = ctx.input(0)?.ok_or_else(|| missing("input z"))?;
            let g = ctx.input(1)?.ok_or_else(|| missing("input g"))?;
            let (shape, z) = z.try_extract_tensor::<f32>()?;
            let (_, g) = g.try_extract_tensor::<f32>()?;
            if z.len() != g.len() {
                return Err(ort::Error::new("LeakyReluGrad: z and g differ in size"));
            }
            let mut out = ctx.output(0, shape.to_vec())?.ok_or_else(|| missing("output"))?;
            let (_, o) = out.try_extract_tensor_mut::<f32>()?;
            const CHUNK: usize = 1 << 16;
            let n = z.len();
            let dst = Shared(o.as_mut_ptr());
            ctx.par_for(n.div_ceil(CHUNK), n.div_ceil(CHUNK), move |b| {
                let (lo, hi) = (b * CHUNK, ((b + 1) * CHUNK).min(n));
                // SAFETY: batch b alone writes o[lo..hi], inside the output's n values.
                let o = unsafe { dst.range(lo, hi - lo) };
                for ((o, &z), &g) in o.iter_mut().zip(&z[lo..hi]).zip(&g[lo..hi]) {
                    *o = if z > 0.0 { g } else { alpha * g };
                }
            })
        }))
    }
}

/// The backward of MaxPool on NCHW tensors.
pub struct MaxPoolGrad;

impl Operator for MaxPoolGrad {
    type Kernel<'attr> = BoxedKernel<'attr>;

    fn name(&self) -> &str {
        "MaxPoolGrad"
    }

    fn inputs(&self) -> impl IntoIterator<Item = OperatorInput> {
        float_inputs(3)
    }

    fn outputs(&self) -> impl IntoIterator<Item = OperatorOutput> {
        [OperatorOutput::required(TensorElementType::Float32)]
    }

    fn create_kernel<'attr>(&self, kctx: &KernelContext<'attr>) -> ort::Result<Self::Kernel<'attr>> {
        let attr = |name: &str| -> ort::Result<Vec<i64>> {
            kctx.get::<Vec<i64>>(name).ok_or_else(|| missing(&format!("attribute {name}")))
        };
        let (k, s, p) = (attr("kernel_shape")?, attr("strides")?, attr("pads")?);
        if k.len() != 2 || s.len() != 2 || p.len() != 4 {
            return Err(ort::Error::new("MaxPoolGrad: needs 2-D kernel_shape, strides and pads"));
        }
        let (kh, kw, sh, sw, pt, pl) = (k[0], k[1], s[0], s[1], p[0], p[1]);
        Ok(Box::new(move |ctx: &ComputeContext| {
            let x = ctx.input(0)?.ok_or_else(|| missing("input x"))?;
            let y = ctx.input(1)?.ok_or_else(|| missing("input y"))?;
            let g = ctx.input(2)?.ok_or_else(|| missing("input g"))?;
            let (xs, x) = x.try_extract_tensor::<f32>()?;
            let (ys, y) = y.try_extract_tensor::<f32>()?;
            let (_, g) = g.try_extract_tensor::<f32>()?;
            if xs.len() != 4 || ys.len() != 4 || y.len() != g.len() {
                return Err(ort::Error::new("MaxPoolGrad: x, y and g must be NCHW with y and g alike"));
            }
            let (planes, h, w) = ((xs[0] * xs[1]) as usize, xs[2], xs[3]);
            let (oh, ow) = (ys[2], ys[3]);
            let mut out = ctx.output(0, xs.to_vec())?.ok_or_else(|| missing("output"))?;
            let (_, o) = out.try_extract_tensor_mut::<f32>()?;
            let dst = Shared(o.as_mut_ptr());
            let (hw, ohw) = ((h * w) as usize, (oh * ow) as usize);
            ctx.par_for(planes, planes, move |c| {
                // SAFETY: plane c alone writes o[c·hw..(c+1)·hw], inside the output.
                let o = unsafe { dst.range(c * hw, hw) };
                o.fill(0.0);
                let (xp, yp, gp) = (&x[c * hw..(c + 1) * hw], &y[c * ohw..(c + 1) * ohw], &g[c * ohw..(c + 1) * ohw]);
                for i in 0..oh {
                    for j in 0..ow {
                        let (m, gv) = (yp[(i * ow + j) as usize], gp[(i * ow + j) as usize]);
                        'window: for ky in 0..kh {
                            let iy = i * sh - pt + ky;
                            if iy < 0 || iy >= h {
                                continue;
                            }
                            for kx in 0..kw {
                                let ix = j * sw - pl + kx;
                                if ix >= 0 && ix < w && xp[(iy * w + ix) as usize] == m {
                                    o[(iy * w + ix) as usize] += gv;
                                    break 'window;
                                }
                            }
                        }
                    }
                }
            })
        }))
    }
}
