//! Reductions and averages: the gradient spread back over what was reduced.

use super::{Back, Ctx};
use crate::autodiff::shapes::{int, reduce_axes, reduced, window};
use crate::autodiff::AutodiffError;
use crate::proto::Attr;

/// `∂x = y ⊙ (g − Σ_axis g ⊙ y)`.
pub(super) fn softmax(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    // ∂x = y ⊙ (g − Σ_axis g ⊙ y).
    let r = cx.shape[&x].len() as i64;
    let axis = int(n, "axis").unwrap_or(-1);
    let axis = if axis < 0 { axis + r } else { axis };
    if cx.opset < 13 && axis != r - 1 {
        return Err(cx.bad("before opset 13 only the last axis"));
    }
    let y = n.outputs[0].clone();
    bw.save(&y);
    let gy = bw.tape.node("Mul", vec![g.clone(), y.clone()], vec![]);
    let a = bw.tape.i64s(vec![axis]);
    let s = bw.tape.node("ReduceSum", vec![gy, a], vec![("keepdims", Attr::Int(1))]);
    let d = bw.tape.node("Sub", vec![g, s], vec![]);
    let gx = bw.tape.node("Mul", vec![y, d], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g` expanded back over the reduced axes (divided by their size for the mean).
pub(super) fn reduce_mean_sum(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let xs = cx.shape[&x].clone();
    let axes = reduce_axes(n, cx.consts, xs.len());
    let kept = bw.tape.reshape(g, &reduced(&xs, &axes, true));
    let dims = bw.tape.i64s(xs.clone());
    let mut gx = bw.tape.node("Expand", vec![kept, dims], vec![]);
    if n.op_type == "ReduceMean" {
        let count: i64 = axes.iter().map(|&a| xs[a]).product();
        let k = bw.tape.scalar(1.0 / count as f32);
        gx = bw.tape.node("Mul", vec![gx, k], vec![]);
    }
    bw.add(&x, gx);
    Ok(())
}

/// `g` to every position equal to the maximum.
pub(super) fn reduce_max(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    // The gradient goes to the positions equal to the maximum (ties, of measure zero
    // for real inputs, each get it whole).
    let xs = cx.shape[&x].clone();
    let keep = reduced(&xs, &reduce_axes(n, cx.consts, xs.len()), true);
    let y = n.outputs[0].clone();
    bw.save(&x);
    bw.save(&y);
    let yk = bw.tape.reshape(y, &keep);
    let at = bw.tape.node("Equal", vec![x.clone(), yk], vec![]);
    let gk = bw.tape.reshape(g, &keep);
    let dims = bw.tape.i64s(xs);
    let ge = bw.tape.node("Expand", vec![gk, dims], vec![]);
    let zero = bw.tape.scalar(0.0);
    let gx = bw.tape.node("Where", vec![at, ge, zero], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g` spread evenly over each plane.
pub(super) fn global_average_pool(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let x = cx.n.inputs[0].clone();
    let xs = cx.shape[&x].clone();
    let dims = bw.tape.i64s(xs.clone());
    let e = bw.tape.node("Expand", vec![g, dims], vec![]);
    let k = bw.tape.scalar(1.0 / (xs[2] * xs[3]) as f32);
    let gx = bw.tape.node("Mul", vec![e, k], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// A transposed uniform convolution (padding counted, as the forward counts it).
pub(super) fn average_pool(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let (k, st, p) = window(n, None)?;
    if int(n, "count_include_pad").unwrap_or(0) == 0 && p.iter().any(|&v| v != 0) {
        return Err(cx.bad("padded windows must count the padding (count_include_pad = 1)"));
    }
    let (xs, ys) = (cx.shape[&x].clone(), cx.shape[&n.outputs[0]].clone());
    let c = xs[1];
    let w = bw.tape.f32s(vec![c, 1, k[0], k[1]], vec![1.0 / (k[0] * k[1]) as f32; (c * k[0] * k[1]) as usize]);
    let op = |i: usize| xs[2 + i] - (st[i] * (ys[2 + i] - 1) + k[i] - p[i] - p[i + 2]);
    let gx = bw.tape.node(
        "ConvTranspose",
        vec![g, w],
        vec![
            ("kernel_shape", Attr::Ints(k.to_vec())),
            ("strides", Attr::Ints(st.to_vec())),
            ("pads", Attr::Ints(p.to_vec())),
            ("group", Attr::Int(c)),
            ("output_padding", Attr::Ints(vec![op(0), op(1)])),
        ],
    );
    bw.add(&x, gx);
    Ok(())
}
