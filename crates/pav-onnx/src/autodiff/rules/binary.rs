//! Binary operators with numpy broadcasting: each operand's gradient summed back to its shape.

use super::{Back, Ctx};
use crate::autodiff::shapes::broadcast;
use crate::autodiff::AutodiffError;

/// `g` (negated for the subtrahend), summed back over broadcast axes.
pub(super) fn add_sub(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let ys = cx.shape[&n.outputs[0]].clone();
    for (i, v) in n.inputs.iter().enumerate() {
        if cx.live.contains(v) {
            let gi =
                if i == 1 && n.op_type == "Sub" { bw.tape.node("Neg", vec![g.clone()], vec![]) } else { g.clone() };
            let gv = bw.tape.unbroadcast(gi, &ys, &cx.shape[v]);
            bw.add(v, gv);
        }
    }
    Ok(())
}

/// Each factor gets `g` times the other, summed back over broadcast axes.
pub(super) fn mul(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let ys = cx.shape[&n.outputs[0]].clone();
    for (i, v) in n.inputs.iter().enumerate() {
        if cx.live.contains(v) {
            let other = bw
                .reuse(cx, &n.inputs[1 - i])
                .ok_or_else(|| cx.bad("a factor computed from constants alone; fold it into an initializer"))?;
            let gx = bw.tape.node("Mul", vec![g.clone(), other], vec![]);
            let gv = bw.tape.unbroadcast(gx, &ys, &cx.shape[v]);
            bw.add(v, gv);
        }
    }
    Ok(())
}

/// `y = a / b`: `∂a = g / b`, `∂b = −g·y / b`, summed back over broadcast axes.
pub(super) fn div(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    // y = a / b: ∂a = g / b, ∂b = −g·y / b.
    let ys = cx.shape[&n.outputs[0]].clone();
    let (a, b) = (&n.inputs[0], &n.inputs[1]);
    let bv = bw
        .reuse(cx, b)
        .ok_or_else(|| cx.bad("a divisor computed from constants alone; fold it into an initializer"))?;
    let gb = bw.tape.node("Div", vec![g.clone(), bv.clone()], vec![]);
    if cx.live.contains(a) {
        let ga = bw.tape.unbroadcast(gb.clone(), &ys, &cx.shape[a]);
        bw.add(a, ga);
    }
    if cx.live.contains(b) {
        let y = n.outputs[0].clone();
        bw.save(&y);
        let gy = bw.tape.node("Mul", vec![gb, y], vec![]);
        let neg = bw.tape.node("Neg", vec![gy], vec![]);
        let gv = bw.tape.unbroadcast(neg, &ys, &cx.shape[b]);
        bw.add(b, gv);
    }
    Ok(())
}

/// `Y = A·B`: `∂A = G·Bᵀ`, `∂B = Aᵀ·G`, summed over the batch axes each was broadcast on.
pub(super) fn matmul(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    // Y = A·B: ∂A = G·Bᵀ, ∂B = Aᵀ·G, each summed over the batch axes it was broadcast on.
    let ys = cx.shape[&n.outputs[0]].clone();
    let (a, b) = (&n.inputs[0], &n.inputs[1]);
    let dims = |v: &str| cx.shape.get(v).or_else(|| cx.consts.get(v).map(|c| &c.dims)).cloned().unwrap_or_default();
    let (sa, sb) = (dims(a), dims(b));
    let (ra, rb) = (sa.len(), sb.len());
    if rb == 1 {
        // A vector on the right: y[..] = Σ_k a[.., k]·b[k].
        let k = sb[0];
        let mut gk = ys.clone();
        gk.push(1);
        let g1 = bw.tape.reshape(g.clone(), &gk);
        if cx.live.contains(a) {
            let bv = bw
                .reuse(cx, b)
                .ok_or_else(|| cx.bad("an operand computed from constants alone; fold it into an initializer"))?;
            let row = bw.tape.reshape(bv, &[1, k]);
            let ga = bw.tape.node("MatMul", vec![g1.clone(), row], vec![]);
            bw.add(a, ga);
        }
        if cx.live.contains(b) {
            let av = bw
                .reuse(cx, a)
                .ok_or_else(|| cx.bad("an operand computed from constants alone; fold it into an initializer"))?;
            let m: i64 = sa[..ra - 1].iter().product();
            let af = bw.tape.reshape(av, &[m, k]);
            let gf = bw.tape.reshape(g1, &[m, 1]);
            let gb = bw.tape.matmul_t(af, gf, 0, true, 2);
            let gb = bw.tape.reshape(gb, &[k]);
            bw.add(b, gb);
        }
        return Ok(());
    }
    if cx.live.contains(a) {
        let bv = bw
            .reuse(cx, b)
            .ok_or_else(|| cx.bad("an operand computed from constants alone; fold it into an initializer"))?;
        let ga = bw.tape.matmul_t(g.clone(), bv, rb, false, 0);
        let mut gs = ys.clone();
        gs[ys.len() - 1] = sa[ra - 1];
        let ga = bw.tape.unbroadcast(ga, &gs, &sa);
        bw.add(a, ga);
    }
    if cx.live.contains(b) {
        let av = bw
            .reuse(cx, a)
            .ok_or_else(|| cx.bad("an operand computed from constants alone; fold it into an initializer"))?;
        let gb = bw.tape.matmul_t(av, g.clone(), 0, true, ra);
        let mut gs = broadcast(&sa[..ra - 2], &sb[..rb - 2]).unwrap_or_default();
        gs.extend([sb[rb - 2], sb[rb - 1]]);
        let gb = bw.tape.unbroadcast(gb, &gs, &sb);
        bw.add(b, gb);
    }
    Ok(())
}
