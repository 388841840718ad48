//! Attributes, constant inputs and static shapes of the operators the rules cover.

use super::AutodiffError;
use crate::proto::{Attr, InitData, Initializer, Node};
use std::collections::HashMap;

pub(super) fn ints(n: &Node, key: &str) -> Option<Vec<i64>> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Ints(v) => Some(v.clone()),
        _ => None,
    })
}

pub(super) fn int(n: &Node, key: &str) -> Option<i64> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Int(v) => Some(*v),
        _ => None,
    })
}

pub(super) fn float(n: &Node, key: &str) -> Option<f32> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Float(v) => Some(*v),
        _ => None,
    })
}

pub(super) fn string(n: &Node, key: &str) -> Option<String> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Str(v) => Some(v.clone()),
        _ => None,
    })
}

/// Kernel, strides and pads `[top, left, bottom, right]` of a 2-D window.
pub(super) type Window = ([i64; 2], [i64; 2], [i64; 4]);

/// The [`Window`] of a 2-D Conv or MaxPool.
pub(super) fn window(n: &Node, kernel: Option<[i64; 2]>) -> Result<Window, AutodiffError> {
    let bad = |msg: String| AutodiffError::Settings { node: n.name.clone(), op: n.op_type.clone(), msg };
    let k = match (ints(n, "kernel_shape"), kernel) {
        (Some(k), _) if k.len() == 2 => [k[0], k[1]],
        (None, Some(k)) => k,
        _ => return Err(bad("needs a 2-D kernel_shape".into())),
    };
    let s = ints(n, "strides").unwrap_or(vec![1, 1]);
    let p = ints(n, "pads").unwrap_or(vec![0; 4]);
    if s.len() != 2 || p.len() != 4 {
        return Err(bad("needs 2-D strides and pads".into()));
    }
    if ints(n, "dilations").is_some_and(|d| d.iter().any(|&v| v != 1)) {
        return Err(bad("dilations other than 1".into()));
    }
    if string(n, "auto_pad").is_some_and(|a| a != "NOTSET") {
        return Err(bad("auto_pad is not covered; give explicit pads".into()));
    }
    Ok((k, [s[0], s[1]], [p[0], p[1], p[2], p[3]]))
}

/// The constant int64 tensor a node reads as input `i`, if it is one.
pub(super) fn const_ints(n: &Node, consts: &HashMap<&str, &Initializer>, i: usize) -> Option<Vec<i64>> {
    n.inputs.get(i).filter(|s| !s.is_empty()).and_then(|s| consts.get(s.as_str())).and_then(|c| match &c.data {
        InitData::I64(v) => Some(v.clone()),
        _ => None,
    })
}

/// What a `Slice` reads along each axis it cuts: `(axis, start, step, count)`, normalized
/// against the input shape `x`.
pub(super) fn slice_ranges(
    n: &Node,
    consts: &HashMap<&str, &Initializer>,
    x: &[i64],
) -> Result<Vec<(usize, i64, i64, i64)>, AutodiffError> {
    let bad = |msg: &str| AutodiffError::Settings { node: n.name.clone(), op: "Slice".into(), msg: msg.into() };
    let (starts, ends) = match (const_ints(n, consts, 1), const_ints(n, consts, 2)) {
        (Some(s), Some(e)) => (s, e),
        // Opset < 10 keeps the bounds in attributes.
        _ => match (ints(n, "starts"), ints(n, "ends")) {
            (Some(s), Some(e)) => (s, e),
            _ => return Err(bad("starts and ends must be constants")),
        },
    };
    let axes =
        const_ints(n, consts, 3).or_else(|| ints(n, "axes")).unwrap_or_else(|| (0..starts.len() as i64).collect());
    let steps = const_ints(n, consts, 4).unwrap_or(vec![1; starts.len()]);
    if axes.len() != starts.len() || ends.len() != starts.len() || steps.len() != starts.len() {
        return Err(bad("starts, ends, axes and steps differ in length"));
    }
    let mut out = Vec::new();
    for i in 0..starts.len() {
        let a = if axes[i] < 0 { axes[i] + x.len() as i64 } else { axes[i] };
        if a < 0 || a as usize >= x.len() {
            return Err(bad("an axis outside the input's rank"));
        }
        if steps[i] <= 0 {
            return Err(bad("only positive steps"));
        }
        let len = x[a as usize];
        let norm = |v: i64| if v < 0 { (v + len).max(0) } else { v.min(len) };
        let (b, e, st) = (norm(starts[i]), norm(ends[i]), steps[i]);
        out.push((a as usize, b, st, if e > b { (e - b + st - 1) / st } else { 0 }));
    }
    Ok(out)
}

/// A `Split`'s axis and the sizes of its outputs along it, against the input shape `x`.
pub(super) fn split_sizes(
    n: &Node,
    consts: &HashMap<&str, &Initializer>,
    x: &[i64],
) -> Result<(usize, Vec<i64>), AutodiffError> {
    let bad = |msg: String| AutodiffError::Settings { node: n.name.clone(), op: "Split".into(), msg };
    let axis = int(n, "axis").unwrap_or(0);
    let axis = if axis < 0 { axis + x.len() as i64 } else { axis };
    if axis < 0 || axis as usize >= x.len() {
        return Err(bad(format!("axis {axis} for rank {}", x.len())));
    }
    let len = x[axis as usize];
    let parts = n.outputs.len() as i64;
    // Opset ≥ 13 gives the sizes as an input, older opsets as an attribute; none: equal parts.
    let sizes = match const_ints(n, consts, 1).or_else(|| ints(n, "split")) {
        Some(s) => s,
        None if n.inputs.get(1).is_some_and(|i| !i.is_empty()) => return Err(bad("sizes must be a constant".into())),
        None if parts > 0 && len % parts == 0 => vec![len / parts; parts as usize],
        None => return Err(bad(format!("{len} does not split into {parts} equal parts"))),
    };
    if sizes.len() != n.outputs.len() || sizes.iter().sum::<i64>() != len || sizes.iter().any(|&s| s < 0) {
        return Err(bad(format!("sizes {sizes:?} for an axis of {len} and {parts} outputs")));
    }
    Ok((axis as usize, sizes))
}

/// The target shape of a `Reshape` with a constant shape (0 copies, −1 takes the rest).
pub(super) fn reshape_target(
    n: &Node,
    consts: &HashMap<&str, &Initializer>,
    x: &[i64],
) -> Result<Vec<i64>, AutodiffError> {
    let bad = |msg: String| AutodiffError::Settings { node: n.name.clone(), op: "Reshape".into(), msg };
    let t = const_ints(n, consts, 1).ok_or_else(|| bad("the shape must be a constant".into()))?;
    let mut out: Vec<i64> =
        t.iter().enumerate().map(|(i, &d)| if d == 0 { x.get(i).copied().unwrap_or(0) } else { d }).collect();
    let total: i64 = x.iter().product();
    let known: i64 = out.iter().filter(|&&d| d != -1).product();
    match out.iter().filter(|&&d| d == -1).count() {
        0 => {}
        1 if known > 0 && total % known == 0 => {
            if let Some(d) = out.iter_mut().find(|d| **d == -1) {
                *d = total / known;
            }
        }
        _ => return Err(bad(format!("cannot reshape {x:?} to {t:?}"))),
    }
    if out.iter().product::<i64>() != total {
        return Err(bad(format!("cannot reshape {x:?} to {t:?}")));
    }
    Ok(out)
}

/// A `Transpose`'s permutation (default: reversed axes).
pub(super) fn transpose_perm(n: &Node, rank: usize) -> Vec<i64> {
    ints(n, "perm").unwrap_or_else(|| (0..rank as i64).rev().collect())
}

/// Numpy broadcasting of two shapes, or `None` when they do not broadcast.
pub(super) fn broadcast(a: &[i64], b: &[i64]) -> Option<Vec<i64>> {
    let r = a.len().max(b.len());
    let at = |s: &[i64], i: usize| if i + s.len() >= r { s[i + s.len() - r] } else { 1 };
    (0..r)
        .map(|i| match (at(a, i), at(b, i)) {
            (x, y) if x == y || y == 1 => Some(x),
            (1, y) => Some(y),
            _ => None,
        })
        .collect()
}

/// A reduction's axes (attribute, or constant input 1 from opset 13 on), normalized and sorted;
/// none given: every axis.
pub(super) fn reduce_axes(n: &Node, consts: &HashMap<&str, &Initializer>, rank: usize) -> Vec<usize> {
    let axes = ints(n, "axes").or_else(|| const_ints(n, consts, 1));
    let mut a: Vec<usize> = match axes {
        Some(v) if !v.is_empty() => v.iter().map(|&a| if a < 0 { a + rank as i64 } else { a } as usize).collect(),
        _ => (0..rank).collect(),
    };
    a.sort_unstable();
    a.dedup();
    a
}

/// A reduction's output shape: the axes kept as 1 (`keepdims`, the default) or dropped.
pub(super) fn reduced(x: &[i64], axes: &[usize], keep: bool) -> Vec<i64> {
    (0..x.len()).filter(|i| keep || !axes.contains(i)).map(|i| if axes.contains(&i) { 1 } else { x[i] }).collect()
}

/// The axes an `Unsqueeze` or `Squeeze` names (attribute before opset 13, constant input after).
pub(super) fn squeeze_axes(n: &Node, consts: &HashMap<&str, &Initializer>) -> Option<Vec<i64>> {
    ints(n, "axes").or_else(|| const_ints(n, consts, 1))
}

/// Static output shapes of `n` from its input shapes.
pub(super) fn infer(
    n: &Node,
    shape: &HashMap<String, Vec<i64>>,
    consts: &HashMap<&str, &Initializer>,
) -> Result<Vec<i64>, AutodiffError> {
    let get = |i: usize| -> Result<Vec<i64>, AutodiffError> {
        let name = n.inputs.get(i).ok_or_else(|| AutodiffError::Graph(format!("{} lacks input {i}", n.name)))?;
        shape
            .get(name)
            .or_else(|| consts.get(name.as_str()).map(|c| &c.dims))
            .cloned()
            .ok_or_else(|| AutodiffError::Graph(format!("{} reads unknown value `{name}`", n.name)))
    };
    let bad = |msg: String| AutodiffError::Settings { node: n.name.clone(), op: n.op_type.clone(), msg };
    let x = get(0)?;
    Ok(match n.op_type.as_str() {
        // Split: the input's shape here; each output's is cut from it by `split_sizes`.
        "Identity" | "LeakyRelu" | "Relu" | "Sigmoid" | "HardSigmoid" | "Split" | "Pow" | "Sqrt" | "Log"
        | "Softmax" | "Cast" | "Clip" | "Neg" | "Exp" | "Tanh" => x,
        "Add" | "Mul" | "Sub" | "Div" | "Min" | "Max" => {
            let y = get(1)?;
            broadcast(&x, &y).ok_or_else(|| bad(format!("operands {x:?} and {y:?} do not broadcast")))?
        }
        "MatMul" if get(1)?.len() == 1 => {
            let y = get(1)?;
            if x.len() < 2 || x[x.len() - 1] != y[0] {
                return Err(bad(format!("operands {x:?} and {y:?} do not multiply")));
            }
            x[..x.len() - 1].to_vec()
        }
        "MatMul" => {
            let y = get(1)?;
            let (r, q) = (x.len(), y.len());
            if r < 2 || q < 2 || x[r - 1] != y[q - 2] {
                return Err(bad(format!("operands {x:?} and {y:?}: only matrices (rank ≥ 2) that multiply")));
            }
            let mut out =
                broadcast(&x[..r - 2], &y[..q - 2]).ok_or_else(|| bad("batch axes do not broadcast".into()))?;
            out.extend([x[r - 2], y[q - 1]]);
            out
        }
        "ReduceMean" | "ReduceSum" => {
            reduced(&x, &reduce_axes(n, consts, x.len()), int(n, "keepdims").unwrap_or(1) != 0)
        }
        "Unsqueeze" => {
            let axes = squeeze_axes(n, consts).ok_or_else(|| bad("axes must be constants".into()))?;
            let rank = (x.len() + axes.len()) as i64;
            let mut at: Vec<i64> = axes.iter().map(|&a| if a < 0 { a + rank } else { a }).collect();
            at.sort_unstable();
            let mut out = x.clone();
            for a in at {
                out.insert(a as usize, 1);
            }
            out
        }
        "Squeeze" => {
            let r = x.len() as i64;
            let axes: Vec<i64> = squeeze_axes(n, consts)
                .map(|v| v.iter().map(|&a| if a < 0 { a + r } else { a }).collect())
                .unwrap_or_else(|| (0..r).filter(|&i| x[i as usize] == 1).collect());
            (0..r).filter(|i| !axes.contains(i)).map(|i| x[i as usize]).collect()
        }
        "Pad" => {
            let p = const_ints(n, consts, 1)
                .or_else(|| ints(n, "pads"))
                .ok_or_else(|| bad("pads must be constants".into()))?;
            if p.len() != 2 * x.len() || string(n, "mode").is_some_and(|m| m != "constant") {
                return Err(bad("only constant-mode pads on every axis".into()));
            }
            (0..x.len()).map(|i| x[i] + p[i] + p[i + x.len()]).collect()
        }
        "GlobalAveragePool" => vec![x[0], x[1], 1, 1],
        "ReduceMax" => reduced(&x, &reduce_axes(n, consts, x.len()), int(n, "keepdims").unwrap_or(1) != 0),
        "TopK" => {
            let k = const_ints(n, consts, 1)
                .and_then(|k| k.first().copied())
                .ok_or_else(|| bad("k must be a constant".into()))?;
            let a = int(n, "axis").unwrap_or(-1);
            let a = if a < 0 { a + x.len() as i64 } else { a } as usize;
            let mut out = x.clone();
            out[a] = k;
            out
        }
        "Gather" => {
            let ind = get(1)?;
            let a = int(n, "axis").unwrap_or(0);
            let a = if a < 0 { a + x.len() as i64 } else { a } as usize;
            x[..a].iter().chain(&ind).chain(&x[a + 1..]).copied().collect()
        }
        "GatherElements" => get(1)?,
        "Expand" => {
            let to = const_ints(n, consts, 1).ok_or_else(|| bad("the shape must be a constant".into()))?;
            broadcast(&x, &to).ok_or_else(|| bad(format!("{x:?} does not expand to {to:?}")))?
        }
        "Tile" => {
            let r = const_ints(n, consts, 1).ok_or_else(|| bad("repeats must be constants".into()))?;
            x.iter().zip(&r).map(|(a, b)| a * b).collect()
        }
        "GridSample" => {
            let grid = get(1)?;
            vec![x[0], x[1], grid[1], grid[2]]
        }
        "Flatten" => {
            let a = int(n, "axis").unwrap_or(1);
            let a = if a < 0 { a + x.len() as i64 } else { a } as usize;
            vec![x[..a].iter().product(), x[a..].iter().product()]
        }
        "Conv" => {
            let w = get(1)?;
            let (k, s, p) = window(n, Some([w[2], w[3]]))?;
            let out = |i: usize| (x[2 + i] + p[i] + p[i + 2] - k[i]) / s[i] + 1;
            vec![x[0], w[0], out(0), out(1)]
        }
        "MaxPool" | "AveragePool" => {
            let (k, s, p) = window(n, None)?;
            // ceil_mode only where it agrees with floor: the windows end exactly at the edge.
            let fits = |i: usize| (x[2 + i] + p[i] + p[i + 2] - k[i]) % s[i] == 0;
            if int(n, "ceil_mode").is_some_and(|c| c != 0) && !(fits(0) && fits(1)) {
                return Err(bad("ceil_mode where it adds a partial window".into()));
            }
            let out = |i: usize| (x[2 + i] + p[i] + p[i + 2] - k[i]) / s[i] + 1;
            vec![x[0], x[1], out(0), out(1)]
        }
        "Resize" => match resize_plan(n, consts, &x)? {
            ResizePlan::Nearest(f) => vec![x[0], x[1], x[2] * f, x[3] * f],
            ResizePlan::Linear { out, .. } => vec![x[0], x[1], out[0], out[1]],
        },
        "Slice" => {
            let mut out = x.clone();
            for (a, _, _, count) in slice_ranges(n, consts, &x)? {
                out[a] = count;
            }
            out
        }
        "Reshape" => reshape_target(n, consts, &x)?,
        "Transpose" => {
            let perm = transpose_perm(n, x.len());
            if perm.len() != x.len() {
                return Err(bad(format!("perm {perm:?} for rank {}", x.len())));
            }
            perm.iter().map(|&p| x[p as usize]).collect()
        }
        "Concat" => {
            let axis = int(n, "axis").ok_or_else(|| bad("needs an axis".into()))?;
            let axis = if axis < 0 { axis + x.len() as i64 } else { axis } as usize;
            let mut out = x.clone();
            out[axis] = (0..n.inputs.len()).map(|i| get(i).map(|s| s[axis])).sum::<Result<i64, _>>()?;
            out
        }
        _ => return Err(AutodiffError::Unsupported { node: n.name.clone(), op: n.op_type.clone() }),
    })
}

/// What a Resize does on the two spatial axes.
pub(super) enum ResizePlan {
    /// Nearest neighbour by one integer factor on both axes.
    Nearest(i64),
    /// Linear interpolation to `out` (height, width); `weights[a]` is axis a's `[out × in]`
    /// matrix of interpolation weights, so the output is `W_h · X · W_wᵀ` per channel.
    Linear { out: [i64; 2], weights: [Vec<f32>; 2] },
}

/// The plan of a 4-D Resize with constant scales or sizes: nearest by equal integer factors, or
/// linear by any factors under the `half_pixel`, `pytorch_half_pixel`, `align_corners` or
/// `asymmetric` coordinate transformation (source coordinates clamped to the input, as ONNX
/// Runtime clamps them).
pub(super) fn resize_plan(
    n: &Node,
    consts: &HashMap<&str, &Initializer>,
    x: &[i64],
) -> Result<ResizePlan, AutodiffError> {
    let bad = |msg: String| AutodiffError::Settings { node: n.name.clone(), op: "Resize".into(), msg };
    let mode = string(n, "mode").unwrap_or_else(|| "nearest".into());
    let from = |i: usize| {
        n.inputs.get(i).filter(|s| !s.is_empty()).and_then(|s| consts.get(s.as_str())).filter(|c| c.data.len() == 4)
    };
    // Per axis: the output size and the scale the coordinates are mapped by.
    let (out, f): (Vec<i64>, Vec<f64>) = match (from(2), from(3)) {
        (Some(c), _) => match &c.data {
            // The product in f32, as ONNX Runtime takes it: 3 × (5/3 as f32) is 5, not 4.
            InitData::F32(v) => v.iter().zip(x).map(|(&s, &d)| ((d as f32 * s).floor() as i64, s as f64)).unzip(),
            _ => return Err(bad("scales must be 4 constant floats".into())),
        },
        (None, Some(c)) => match &c.data {
            InitData::I64(v) => v.iter().zip(x).map(|(&a, &b)| (a, a as f64 / b as f64)).unzip(),
            _ => return Err(bad("sizes must be 4 constant integers".into())),
        },
        _ => return Err(bad("needs constant scales or sizes".into())),
    };
    if x.len() != 4 || out[0] != x[0] || out[1] != x[1] {
        return Err(bad(format!("only the two spatial axes of a 4-D tensor may be resized, got {f:?}")));
    }
    match mode.as_str() {
        "nearest" => {
            let k = f[2].round() as i64;
            if f[2] != f[3] || (f[2] - k as f64).abs() > 1e-9 || k < 1 {
                return Err(bad(format!("nearest: only equal integer spatial factors, got {f:?}")));
            }
            Ok(ResizePlan::Nearest(k))
        }
        "linear" => {
            let ctm = string(n, "coordinate_transformation_mode").unwrap_or_else(|| "half_pixel".into());
            let axis = |a: usize| -> Result<Vec<f32>, AutodiffError> {
                let (len_in, len_out, s) = (x[a], out[a], f[a]);
                if len_out < 1 {
                    return Err(bad(format!("an output of {len_out} on axis {a}")));
                }
                let mut w = vec![0f32; (len_out * len_in) as usize];
                for o in 0..len_out {
                    let src = match ctm.as_str() {
                        "half_pixel" => (o as f64 + 0.5) / s - 0.5,
                        "pytorch_half_pixel" if len_out > 1 => (o as f64 + 0.5) / s - 0.5,
                        "pytorch_half_pixel" => 0.0,
                        "align_corners" if len_out > 1 => o as f64 * (len_in - 1) as f64 / (len_out - 1) as f64,
                        "align_corners" => 0.0,
                        "asymmetric" => o as f64 / s,
                        other => return Err(bad(format!("linear with coordinate_transformation_mode = {other}"))),
                    };
                    let src = src.clamp(0.0, (len_in - 1) as f64);
                    let i0 = src.floor() as i64;
                    let i1 = (i0 + 1).min(len_in - 1);
                    let t = (src - i0 as f64) as f32;
                    w[(o * len_in + i0) as usize] += 1.0 - t;
                    w[(o * len_in + i1) as usize] += t;
                }
                Ok(w)
            };
            Ok(ResizePlan::Linear { out: [out[2], out[3]], weights: [axis(2)?, axis(3)?] })
        }
        other => Err(bad(format!("mode = {other} (nearest and linear have rules)"))),
    }
}
