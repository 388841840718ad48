//! Convolution with a constant weight: the input gradient only.

use super::{Back, Ctx};
use crate::autodiff::shapes::{int, window};
use crate::autodiff::AutodiffError;
use crate::proto::{Attr, InitData};

/// A stride-1 ungrouped convolution: the flipped, transposed kernel; otherwise ConvTranspose.
pub(super) fn conv(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let w = cx.consts.get(n.inputs[1].as_str()).ok_or_else(|| cx.bad("the weight must be a constant"))?;
    let InitData::F32(wv) = &w.data else { return Err(cx.bad("the weight must be float")) };
    let (k, s, p) = window(n, Some([w.dims[2], w.dims[3]]))?;
    let group = int(n, "group").unwrap_or(1);
    let (xs, ys) = (&cx.shape[&x], &cx.shape[&n.outputs[0]]);
    let gx = if s == [1, 1] && group == 1 {
        // The flipped kernel with input and output channels swapped: [C, M, k, k].
        let (m, c, kh, kw) = (w.dims[0] as usize, w.dims[1] as usize, k[0] as usize, k[1] as usize);
        let mut flipped = vec![0f32; wv.len()];
        for mi in 0..m {
            for ci in 0..c {
                for i in 0..kh {
                    for j in 0..kw {
                        flipped[((ci * m + mi) * kh + kh - 1 - i) * kw + kw - 1 - j] =
                            wv[((mi * c + ci) * kh + i) * kw + j];
                    }
                }
            }
        }
        let wf = bw.tape.f32s(vec![c as i64, m as i64, k[0], k[1]], flipped);
        let pads = vec![k[0] - 1 - p[0], k[1] - 1 - p[1], k[0] - 1 - p[2], k[1] - 1 - p[3]];
        if pads.iter().any(|&q| q < 0) {
            return Err(cx.bad("pads larger than kernel − 1"));
        }
        bw.tape.node("Conv", vec![g, wf], vec![("kernel_shape", Attr::Ints(k.to_vec())), ("pads", Attr::Ints(pads))])
    } else {
        let wc = bw.tape.f32s(w.dims.clone(), wv.clone());
        // Rows and columns the forward never read stay out of the transposed output.
        let op = |i: usize| xs[2 + i] - (s[i] * (ys[2 + i] - 1) + k[i] - p[i] - p[i + 2]);
        let (oh, ow) = (op(0), op(1));
        if oh < 0 || ow < 0 || oh >= s[0] || ow >= s[1] {
            return Err(cx.bad("output shape the transposed convolution cannot reproduce"));
        }
        bw.tape.node(
            "ConvTranspose",
            vec![g, wc],
            vec![
                ("kernel_shape", Attr::Ints(k.to_vec())),
                ("strides", Attr::Ints(s.to_vec())),
                ("pads", Attr::Ints(p.to_vec())),
                ("group", Attr::Int(group)),
                ("output_padding", Attr::Ints(vec![oh, ow])),
            ],
        )
    };
    bw.add(&x, gx);
    Ok(())
}
