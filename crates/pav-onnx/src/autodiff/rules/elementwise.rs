//! Element-wise operators: each input value's gradient from its own output value.

use super::{Back, Ctx};
use crate::autodiff::shapes::{float, int};
use crate::autodiff::{AutodiffError, Kernels};
use crate::proto::{Attr, InitData, FLOAT};

/// The gradient passes unchanged.
pub(super) fn identity(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let x = cx.n.inputs[0].clone();
    bw.add(&x, g);
    Ok(())
}

/// `g` where the input is positive, else `alpha·g` (Relu: alpha 0).
pub(super) fn leaky_relu(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let alpha = if n.op_type == "Relu" { 0.0 } else { float(n, "alpha").unwrap_or(0.01) };
    // For alpha ≥ 0 the output has the input's sign, and saving the output leaves the
    // convolution before it free to fuse with the activation.
    let sign = if alpha >= 0.0 { n.outputs[0].clone() } else { x.clone() };
    bw.save(&sign);
    if cx.kernels == Kernels::Fused {
        let gx = bw.tape.fused("LeakyReluGrad", vec![sign, g], vec![("alpha", Attr::Float(alpha))]);
        bw.add(&x, gx);
        return Ok(());
    }
    let zero = bw.tape.scalar(0.0);
    let pos = bw.tape.node("Greater", vec![sign, zero.clone()], vec![]);
    let neg = if n.op_type == "Relu" {
        zero
    } else {
        let a = bw.tape.scalar(alpha);
        bw.tape.node("Mul", vec![g.clone(), a], vec![])
    };
    let gx = bw.tape.node("Where", vec![pos, g, neg], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g·y·(1 − y)`, from the saved output.
pub(super) fn sigmoid(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let y = n.outputs[0].clone();
    bw.save(&y);
    let one = bw.tape.scalar(1.0);
    let om = bw.tape.node("Sub", vec![one, y.clone()], vec![]);
    let d = bw.tape.node("Mul", vec![y, om], vec![]);
    let gx = bw.tape.node("Mul", vec![g, d], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `alpha·g` where `alpha·x + beta` lies strictly inside (0, 1), else 0 (HardSigmoid, which
/// PP-LCNet's squeeze-excitation uses; ONNX's defaults alpha 0.2, beta 0.5).
pub(super) fn hard_sigmoid(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let alpha = float(n, "alpha").unwrap_or(0.2);
    let y = n.outputs[0].clone();
    // The output is clamped to [0, 1]: strictly inside, the input was on the slope.
    bw.save(&y);
    let (zero, one) = (bw.tape.scalar(0.0), bw.tape.scalar(1.0));
    let above = bw.tape.node("Greater", vec![y.clone(), zero.clone()], vec![]);
    let below = bw.tape.node("Less", vec![y, one], vec![]);
    let slope = bw.tape.node("And", vec![above, below], vec![]);
    let a = bw.tape.scalar(alpha);
    let scaled = bw.tape.node("Mul", vec![g, a], vec![]);
    let gx = bw.tape.node("Where", vec![slope, scaled, zero], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g·c·x^(c−1)` for a constant scalar exponent `c`.
pub(super) fn pow(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let c = cx
        .consts
        .get(n.inputs[1].as_str())
        .and_then(|c| match &c.data {
            InitData::F32(v) if v.len() == 1 => Some(v[0]),
            _ => None,
        })
        .ok_or_else(|| cx.bad("only a constant scalar float exponent"))?;
    bw.save(&x);
    let d = if c == 2.0 {
        let two = bw.tape.scalar(2.0);
        bw.tape.node("Mul", vec![x.clone(), two], vec![])
    } else {
        let (e, k) = (bw.tape.scalar(c - 1.0), bw.tape.scalar(c));
        let p = bw.tape.node("Pow", vec![x.clone(), e], vec![]);
        bw.tape.node("Mul", vec![p, k], vec![])
    };
    let gx = bw.tape.node("Mul", vec![g, d], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g / (2·y)`, from the saved output.
pub(super) fn sqrt(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let y = n.outputs[0].clone();
    bw.save(&y);
    let half = bw.tape.scalar(0.5);
    let h = bw.tape.node("Mul", vec![g, half], vec![]);
    let slope = bw.tape.node("Div", vec![h, y.clone()], vec![]);
    // At 0 the slope is infinite: a score sqrt(σ(a)·σ(b)) of two saturated sigmoids is exactly 0
    // in f32, and ∞·0 would turn every gradient behind it into NaN. It passes nothing there.
    let zero = bw.tape.scalar(0.0);
    let positive = bw.tape.node("Greater", vec![y, zero.clone()], vec![]);
    let gx = bw.tape.node("Where", vec![positive, slope, zero], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g / x`.
pub(super) fn log(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let x = cx.n.inputs[0].clone();
    bw.save(&x);
    let gx = bw.tape.node("Div", vec![g, x.clone()], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `−g`.
pub(super) fn neg(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let x = cx.n.inputs[0].clone();
    let gx = bw.tape.node("Neg", vec![g], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g` where the input lies strictly inside the bounds, else 0.
pub(super) fn clip(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    // The gradient passes where the input lies strictly inside the bounds.
    bw.save(&x);
    let bound = |i: usize| n.inputs.get(i).filter(|v| !v.is_empty()).cloned();
    let mut keep: Option<String> = None;
    for (i, op) in [(1, "Greater"), (2, "Less")] {
        if let Some(v) = bound(i) {
            let c = bw.reuse(cx, &v).ok_or_else(|| cx.bad("bounds must be constants"))?;
            let m = bw.tape.node(op, vec![x.clone(), c], vec![]);
            keep = Some(match keep {
                Some(k) => bw.tape.node("And", vec![k, m], vec![]),
                None => m,
            });
        }
    }
    let gx = match keep {
        Some(k) => {
            let zero = bw.tape.scalar(0.0);
            bw.tape.node("Where", vec![k, g, zero], vec![])
        }
        None => g,
    };
    bw.add(&x, gx);
    Ok(())
}

/// A cast to float passes the gradient; to anything else it carries none.
pub(super) fn cast(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    if int(n, "to") != Some(FLOAT as i64) {
        return Err(cx.bad("a cast to anything but float carries no gradient"));
    }
    bw.add(&x, g);
    Ok(())
}

/// `g·y`, from the saved output `y = eˣ`.
pub(super) fn exp(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let (x, y) = (cx.n.inputs[0].clone(), cx.n.outputs[0].clone());
    bw.save(&y);
    let gx = bw.tape.node("Mul", vec![g, y], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// `g·(1 − y²)`, from the saved output `y = tanh x`.
pub(super) fn tanh(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let (x, y) = (cx.n.inputs[0].clone(), cx.n.outputs[0].clone());
    bw.save(&y);
    let one = bw.tape.scalar(1.0);
    let y2 = bw.tape.node("Mul", vec![y.clone(), y], vec![]);
    let d = bw.tape.node("Sub", vec![one, y2], vec![]);
    let gx = bw.tape.node("Mul", vec![g, d], vec![]);
    bw.add(&x, gx);
    Ok(())
}

/// Min and Max of the input and a constant that broadcasts into it: `g` where the input is the
/// one selected (strictly below, or above, the constant), else 0.
pub(super) fn min_max(cx: &Ctx, bw: &mut Back, g: String) -> Result<(), AutodiffError> {
    let n = cx.n;
    let x = n.inputs[0].clone();
    let [_, c] = n.inputs.as_slice() else {
        return Err(cx.bad("two operands: the input and a constant"));
    };
    if cx.live.contains(c) {
        return Err(cx.bad("the second operand must be a constant"));
    }
    let c = bw.reuse(cx, c).ok_or_else(|| cx.bad("the second operand must be a constant"))?;
    if cx.shape.get(&x) != cx.shape.get(&n.outputs[0]) {
        return Err(cx.bad("the constant must broadcast into the input, not the input into it"));
    }
    bw.save(&x);
    let op = if n.op_type == "Min" { "Less" } else { "Greater" };
    let keep = bw.tape.node(op, vec![x.clone(), c], vec![]);
    let zero = bw.tape.scalar(0.0);
    let gx = bw.tape.node("Where", vec![keep, g, zero], vec![]);
    bw.add(&x, gx);
    Ok(())
}
