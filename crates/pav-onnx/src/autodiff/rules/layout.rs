//! Operators that move values without changing them: the gradient moved back.

use super::{Back, Ctx};
use crate::autodiff::shapes::{
    const_ints, int, ints, resize_plan, slice_ranges, split_sizes, transpose_perm, ResizePlan,
};
use crate::autodiff::AutodiffError;
use crate::proto::Attr;

/// The gradient cut back to the unpadded extent.
pub(super) fn pad(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let xs = cx.shape[&x].clone();
    let p = const_ints(n, cx.consts, 1).or_else(|| ints(n, "pads")).unwrap_or_default();
    let r = xs.len();
    if p.iter().any(|&v| v < 0) {
        return Err(cx.bad("only non-negative pads"));
    }
    let ends: Vec<i64> = (0..r).map(|i| p[i] + xs[i]).collect();
    let gx = bw.tape.slice(&g, p[..r].to_vec(), ends, (0..r as i64).collect(), vec![1; r]);
    bw.add(&x, gx);
    Ok(())
}

/// `g` summed back over the expanded axes.
pub(super) fn expand(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let gx = bw.tape.unbroadcast(g, &cx.shape[&n.outputs[0]], &cx.shape[&x]);
    bw.add(&x, gx);
    Ok(())
}

/// `g` reshaped to the input's shape.
pub(super) fn reshape_like(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let x = cx.n.inputs[0].clone();
    let gx = bw.tape.reshape(g, &cx.shape[&x]);
    bw.add(&x, gx);
    Ok(())
}

/// `g` reshaped to the input's shape.
pub(super) fn reshape(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let x = cx.n.inputs[0].clone();
    let back = bw.tape.i64s(cx.shape[&x].clone());
    let gx = bw.tape.node("Reshape", vec![g, back], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// Each input gets its slice of `g` along the axis.
pub(super) fn concat(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let rank = cx.dims(&n.inputs[0]).len() as i64;
    let axis = int(n, "axis").unwrap_or(1);
    let axis = if axis < 0 { axis + rank } else { axis };
    let mut off = 0;
    for v in &n.inputs {
        // A constant part (a learned token, a fixed map) has no computed shape: its own dims.
        let len = cx.dims(v)[axis as usize];
        if cx.live.contains(v) {
            let gx = bw.tape.slice(&g, vec![off], vec![off + len], vec![axis], vec![1]);
            bw.add(v, gx);
        }
        off += len;
    }
    Ok(())
}

/// `g` spread back to the positions read (positive steps), zero elsewhere.
pub(super) fn slice(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    // Axis by axis: spread each read position to its step's slot, then pad to the
    // input's extent (or cut where the last step runs past it).
    let xs = cx.shape[&x].clone();
    let mut cur = cx.shape[&n.outputs[0]].clone();
    let mut gx = g;
    for (a, start, step, count) in slice_ranges(n, cx.consts, &xs)? {
        let rank = cur.len();
        if step > 1 {
            let mut six = cur.clone();
            six.insert(a + 1, 1);
            let six_c = bw.tape.i64s(six.clone());
            let r = bw.tape.node("Reshape", vec![gx, six_c], vec![]);
            let mut pads = vec![0; 2 * (rank + 1)];
            pads[rank + 1 + a + 1] = step - 1;
            let p = bw.tape.pad(&r, pads, 0.0);
            cur[a] = count * step;
            let back = bw.tape.i64s(cur.clone());
            gx = bw.tape.node("Reshape", vec![p, back], vec![]);
        }
        let room = xs[a] - start;
        if cur[a] > room {
            let (b, mut e) = (vec![0; rank], cur.clone());
            e[a] = room;
            let axes: Vec<i64> = (0..rank as i64).collect();
            gx = bw.tape.slice(&gx, b, e, axes, vec![1; rank]);
            cur[a] = room;
        }
        let mut pads = vec![0; 2 * rank];
        pads[a] = start;
        pads[rank + a] = xs[a] - start - cur[a];
        if pads.iter().any(|&q| q != 0) {
            gx = bw.tape.pad(&gx, pads, 0.0);
        }
        cur[a] = xs[a];
    }
    bw.add(&x, gx);
    Ok(())
}

/// `g` through the inverse permutation.
pub(super) fn transpose(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let perm = transpose_perm(n, cx.shape[&x].len());
    let mut inv = vec![0i64; perm.len()];
    for (i, &p) in perm.iter().enumerate() {
        inv[p as usize] = i as i64;
    }
    let gx = bw.tape.node("Transpose", vec![g], vec![("perm", Attr::Ints(inv))]);
    bw.add(&x, gx);
    Ok(())
}

/// Nearest upsampling by an integer factor: `g` summed over each block.
pub(super) fn resize(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let dims = &cx.shape[&x];
    let gx = match resize_plan(n, cx.consts, dims)? {
        // Each input pixel was copied into an f × f block: its gradient is the block's sum.
        ResizePlan::Nearest(f) => {
            let pooled = bw.tape.node(
                "AveragePool",
                vec![g],
                vec![("kernel_shape", Attr::Ints(vec![f, f])), ("strides", Attr::Ints(vec![f, f]))],
            );
            let area = bw.tape.scalar((f * f) as f32);
            bw.tape.node("Mul", vec![pooled, area], vec![])
        }
        // y = W_h · x · W_wᵀ per channel, so x̄ = W_hᵀ · ȳ · W_w.
        ResizePlan::Linear { out, weights: [wh, ww] } => {
            let (ih, iw) = (dims[2], dims[3]);
            let mut wht = vec![0f32; wh.len()];
            for o in 0..out[0] {
                for i in 0..ih {
                    wht[(i * out[0] + o) as usize] = wh[(o * ih + i) as usize];
                }
            }
            let wht = bw.tape.f32s(vec![ih, out[0]], wht);
            let ww = bw.tape.f32s(vec![out[1], iw], ww);
            let rows = bw.tape.node("MatMul", vec![wht, g], vec![]);
            bw.tape.node("MatMul", vec![rows, ww], vec![])
        }
    };
    bw.add(&x, gx);
    Ok(())
}

/// The outputs' gradients concatenated back (zeros for an output nothing reads).
pub(super) fn split(cx: &Ctx, bw: &mut Back, gs: Vec<Option<String>>) -> Result<(), AutodiffError> {
    let n = cx.n;
    let (axis, _) = split_sizes(n, cx.consts, &cx.shape[&n.inputs[0]])?;
    let mut parts = Vec::new();
    for (o, g) in n.outputs.iter().zip(gs) {
        parts.push(match g {
            Some(g) => g,
            None => {
                let (zero, dims) = (bw.tape.scalar(0.0), bw.tape.i64s(cx.shape[o].clone()));
                bw.tape.node("Expand", vec![zero, dims], vec![])
            }
        });
    }
    let gx = bw.tape.node("Concat", parts, vec![("axis", Attr::Int(axis as i64))]);
    bw.add(&n.inputs[0], gx);
    Ok(())
}
