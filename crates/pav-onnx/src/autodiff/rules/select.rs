//! Selections: the gradient scattered back to where the values were read.

use super::{Back, Ctx};
use crate::autodiff::shapes::{const_ints, int, string};
use crate::autodiff::tape::Tape;
use crate::autodiff::AutodiffError;
use crate::proto::{Attr, FLOAT, INT64};

/// The values' gradient scattered back to where they were taken from.
pub(super) fn top_k(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    // The values' gradient goes back to where they were taken from.
    let xs = cx.shape[&x].clone();
    let a = int(n, "axis").unwrap_or(-1);
    let a = if a < 0 { a + xs.len() as i64 } else { a };
    let idx = n.outputs[1].clone();
    bw.save(&idx);
    let gx = bw.tape.scatter_add(&xs, idx, g, a);
    bw.add(&x, gx);
    Ok(())
}

/// `g` scattered (added) back to the positions read.
pub(super) fn gather_elements(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let xs = cx.shape[&x].clone();
    let a = int(n, "axis").unwrap_or(0);
    let a = if a < 0 { a + xs.len() as i64 } else { a };
    let idx = bw
        .reuse(cx, &n.inputs[1])
        .ok_or_else(|| cx.bad("indices computed from constants alone; fold them into an initializer"))?;
    let gx = bw.tape.scatter_add(&xs, idx, g, a);
    bw.add(&x, gx);
    Ok(())
}

/// `g` scattered (added) back to the constant indices read.
pub(super) fn gather(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let xs = cx.shape[&x].clone();
    let a = int(n, "axis").unwrap_or(0);
    let a = (if a < 0 { a + xs.len() as i64 } else { a }) as usize;
    let ind = const_ints(n, cx.consts, 1).ok_or_else(|| cx.bad("only constant indices"))?;
    let m = ind.len() as i64;
    let ind: Vec<i64> = ind.iter().map(|&i| if i < 0 { i + xs[a] } else { i }).collect();
    // The index axes as one of length m, then an index tensor broadcast along it.
    let mut gs = xs.clone();
    gs[a] = m;
    let g2 = bw.tape.reshape(g, &gs);
    let mut small = vec![1; xs.len()];
    small[a] = m;
    let idx = bw.tape.i64_tensor(small, ind);
    let dims = bw.tape.i64s(gs);
    let idx = bw.tape.node("Expand", vec![idx, dims], vec![]);
    let gx = bw.tape.scatter_add(&xs, idx, g2, a as i64);
    bw.add(&x, gx);
    Ok(())
}

/// Both gradients of bilinear, zero-padded sampling, from the four corners of every sample.
pub(super) fn grid_sample(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let mode = string(n, "mode").unwrap_or("bilinear".into());
    let padding = string(n, "padding_mode").unwrap_or("zeros".into());
    if mode != "bilinear" || padding != "zeros" || int(n, "align_corners").unwrap_or(0) != 0 {
        return Err(cx.bad("only bilinear sampling, zero padding and align_corners = 0"));
    }
    let grid = n.inputs[1].clone();
    bw.save(&x);
    bw.save(&grid);
    let (xs, gsh) = (cx.shape[&x].clone(), cx.shape[&grid].clone());
    let (gx, ggrid) = grid_sample_grad(&mut bw.tape, &x, &grid, &g, &xs, &gsh);
    if cx.live.contains(&x) {
        bw.add(&x, gx);
    }
    if cx.live.contains(&grid) {
        bw.add(&grid, ggrid);
    }
    Ok(())
}

/// The gradients of a bilinear, zero-padded `GridSample` (align_corners = 0) with respect to its
/// input `x` (`xs` = [N, C, H, W]) and its grid (`gs` = [N, Ho, Wo, 2]), from the output's `g`.
/// For each of the four corners around a sample: its weight, whether it lies inside the input,
/// its flat index; the input's gradient scatters g·weight onto the corners, the grid's sums
/// g·x(corner) times the weight's derivative, scaled by W/2 and H/2 (the grid spans [−1, 1]).
fn grid_sample_grad(tape: &mut Tape, x: &str, grid: &str, g: &str, xs: &[i64], gs: &[i64]) -> (String, String) {
    let (n, c, h, w) = (xs[0], xs[1], xs[2], xs[3]);
    let p = gs[1] * gs[2];
    let coord = |tape: &mut Tape, axis: i64, size: i64| {
        let sl = tape.slice(grid, vec![axis], vec![axis + 1], vec![3], vec![1]);
        let flat = tape.reshape(sl, &[n, 1, p]);
        let (one, half_size, half) = (tape.scalar(1.0), tape.scalar(size as f32 / 2.0), tape.scalar(0.5));
        let shifted = tape.node("Add", vec![flat, one], vec![]);
        let scaled = tape.node("Mul", vec![shifted, half_size], vec![]);
        let i = tape.node("Sub", vec![scaled, half], vec![]);
        let i0 = tape.node("Floor", vec![i.clone()], vec![]);
        let w1 = tape.node("Sub", vec![i, i0.clone()], vec![]);
        let one = tape.scalar(1.0);
        let w0 = tape.node("Sub", vec![one.clone(), w1.clone()], vec![]);
        let i1 = tape.node("Add", vec![i0.clone(), one], vec![]);
        [(i0, w0, -1.0f32), (i1, w1, 1.0f32)]
    };
    let xc = coord(tape, 0, w);
    let yc = coord(tape, 1, h);
    let inside = |tape: &mut Tape, v: &str, size: i64| {
        let (lo, hi) = (tape.scalar(-0.5), tape.scalar(size as f32 - 0.5));
        let a = tape.node("Greater", vec![v.into(), lo], vec![]);
        let b = tape.node("Less", vec![v.into(), hi], vec![]);
        tape.node("And", vec![a, b], vec![])
    };
    let gflat = tape.reshape(g.into(), &[n, c, p]);
    let xflat = tape.reshape(x.into(), &[n, c, h * w]);
    let cp = tape.i64s(vec![n, c, p]);
    let (mut idx_all, mut upd_all, mut dgx, mut dgy) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (yi, wy, sy) in &yc {
        for (xi, wx, sx) in &xc {
            let ok_x = inside(tape, xi, w);
            let ok_y = inside(tape, yi, h);
            let ok = tape.node("And", vec![ok_x, ok_y], vec![]);
            let okf = tape.node("Cast", vec![ok], vec![("to", Attr::Int(FLOAT as i64))]);
            let (z, wm1, hm1) = (tape.scalar(0.0), tape.scalar((w - 1) as f32), tape.scalar((h - 1) as f32));
            let xcl = tape.node("Clip", vec![xi.clone(), z.clone(), wm1], vec![]);
            let ycl = tape.node("Clip", vec![yi.clone(), z, hm1], vec![]);
            let wf = tape.scalar(w as f32);
            let row = tape.node("Mul", vec![ycl, wf], vec![]);
            let flat = tape.node("Add", vec![row, xcl], vec![]);
            let idx = tape.node("Cast", vec![flat], vec![("to", Attr::Int(INT64 as i64))]);
            let idx = tape.node("Expand", vec![idx, cp.clone()], vec![]);
            let wxy = tape.node("Mul", vec![wx.clone(), wy.clone()], vec![]);
            let weight = tape.node("Mul", vec![wxy, okf.clone()], vec![]);
            upd_all.push(tape.node("Mul", vec![gflat.clone(), weight], vec![]));
            idx_all.push(idx.clone());
            // Σ_c g·x(corner), then each coordinate's weight derivative (±1 times the other weight).
            let v = tape.node("GatherElements", vec![xflat.clone(), idx], vec![("axis", Attr::Int(2))]);
            let gv = tape.node("Mul", vec![gflat.clone(), v], vec![]);
            let one = tape.i64s(vec![1]);
            let sum = tape.node("ReduceSum", vec![gv, one], vec![("keepdims", Attr::Int(1))]);
            let s = tape.node("Mul", vec![sum, okf], vec![]);
            let (ksx, ksy) = (tape.scalar(*sx), tape.scalar(*sy));
            let ax = tape.node("Mul", vec![wy.clone(), ksx], vec![]);
            dgx.push(tape.node("Mul", vec![s.clone(), ax], vec![]));
            let ay = tape.node("Mul", vec![wx.clone(), ksy], vec![]);
            dgy.push(tape.node("Mul", vec![s, ay], vec![]));
        }
    }
    let idx = tape.node("Concat", idx_all, vec![("axis", Attr::Int(2))]);
    let upd = tape.node("Concat", upd_all, vec![("axis", Attr::Int(2))]);
    let gx = tape.scatter_add(&[n, c, h * w], idx, upd, 2);
    let gx = tape.reshape(gx, xs);
    let mut parts = Vec::new();
    for (d, size) in [(dgx, w), (dgy, h)] {
        let total = tape.node("Sum", d, vec![]);
        let k = tape.scalar(size as f32 / 2.0);
        let scaled = tape.node("Mul", vec![total, k], vec![]);
        parts.push(tape.reshape(scaled, &[n, gs[1], gs[2], 1]));
    }
    let ggrid = tape.node("Concat", parts, vec![("axis", Attr::Int(3))]);
    (gx, ggrid)
}
