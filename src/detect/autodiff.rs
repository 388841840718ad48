//! Input gradients of ONNX graphs, as ONNX graphs: from a frozen-weight inference graph, a forward
//! graph that also outputs what the backward needs, and a backward graph from the gradients of the
//! outputs (and those saved tensors) to the gradient of the input. ONNX Runtime then runs both
//! ([`crate::detect::ortgrad`]), with the kernels it runs inference with.
//!
//! Each supported operator has one backward rule, exact for its forward:
//! - `Conv`: the input gradient of a stride-1 convolution is the convolution of the output gradient
//!   with the flipped, transposed kernel (ONNX Runtime's fast convolution path); other strides and
//!   groups use `ConvTranspose`.
//! - `MaxPool`: the gradient goes to the first position of each window (row-major) that equals the
//!   window's maximum, as PyTorch routes it; padded positions never win.
//! - `LeakyRelu`, `Relu`, `Sigmoid`, `Add`, `Mul`, `Concat`, nearest `Resize` by an integer factor,
//!   `Identity`: their derivatives, element by element.
//! - `Split` (constant sizes or equal parts): the outputs' gradients concatenated back, zeros for
//!   an output nothing reads.
//! - `Slice` (constant bounds, positive steps): the gradient spread back to the positions read and
//!   zero elsewhere; `Reshape` (constant shape) and `Transpose`: the inverse reshape and
//!   permutation.
//!
//! Shapes are fixed at differentiation time (batch 1, the given input size).

use super::onnx_proto::{Attr, Dim, InitData, Initializer, Model, Node, ValueInfo, FLOAT};
use std::collections::{HashMap, HashSet};

/// Why a graph cannot be differentiated.
#[derive(Debug, thiserror::Error)]
pub enum AutodiffError {
    /// An operator without a backward rule.
    #[error("node `{node}`: operator {op} has no backward rule in pav (supported: {SUPPORTED})")]
    Unsupported {
        /// Node name.
        node: String,
        /// Operator.
        op: String,
    },
    /// A supported operator with settings the rule does not cover.
    #[error("node `{node}` ({op}): {msg}")]
    Settings {
        /// Node name.
        node: String,
        /// Operator.
        op: String,
        /// What is not covered.
        msg: String,
    },
    /// The graph itself is inconsistent (an unknown value, a wrong input count).
    #[error("graph: {0}")]
    Graph(String),
}

/// The custom operator domain of [`Kernels::Fused`] gradient graphs.
pub const PAV_DOMAIN: &str = "pav";

/// How the backward of element-wise-heavy operators is written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Kernels {
    /// Standard ONNX operators only: runs on any ONNX runtime and execution provider.
    #[default]
    Onnx,
    /// pav's fused operators (domain `pav`: `LeakyReluGrad`, `MaxPoolGrad`, one pass each instead of
    /// several), which the session must register (`detect::gradops`); CPU only.
    Fused,
}

/// The operators with a backward rule.
pub const SUPPORTED: &str =
    "Conv, MaxPool, LeakyRelu, Relu, Sigmoid, Add, Mul, Concat, Split, Resize (nearest), Slice, Reshape, Transpose, Identity";

/// A graph and its gradient graphs.
#[derive(Clone, Debug)]
pub struct Differentiated {
    /// The inference graph with fixed shapes and the saved tensors as extra outputs.
    pub forward: Model,
    /// Inputs: the saved tensors and `grad_<output>` for each output; output: `grad_<input>`.
    pub backward: Model,
    /// The graph's input.
    pub input: String,
    /// Its shape.
    pub input_shape: Vec<i64>,
    /// The original outputs, in order, with their shapes.
    pub outputs: Vec<(String, Vec<i64>)>,
    /// The tensors the backward reads from the forward, in the order the forward outputs them
    /// after the original outputs (the graph input is never among them).
    pub saved: Vec<String>,
    /// Whether the backward also reads the graph input itself.
    pub saves_input: bool,
}

/// Name of the gradient input that seeds `output`'s gradient.
pub fn grad_name(value: &str) -> String {
    format!("grad_{value}")
}

fn ints(n: &Node, key: &str) -> Option<Vec<i64>> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Ints(v) => Some(v.clone()),
        _ => None,
    })
}

fn int(n: &Node, key: &str) -> Option<i64> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Int(v) => Some(*v),
        _ => None,
    })
}

fn float(n: &Node, key: &str) -> Option<f32> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Float(v) => Some(*v),
        _ => None,
    })
}

fn string(n: &Node, key: &str) -> Option<String> {
    n.attrs.iter().find(|(k, _)| k == key).and_then(|(_, a)| match a {
        Attr::Str(v) => Some(v.clone()),
        _ => None,
    })
}

/// Kernel, strides and pads `[top, left, bottom, right]` of a 2-D window.
type Window = ([i64; 2], [i64; 2], [i64; 4]);

/// The [`Window`] of a 2-D Conv or MaxPool.
fn window(n: &Node, kernel: Option<[i64; 2]>) -> Result<Window, AutodiffError> {
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
    if string(n, "auto_pad").is_some_and(|a| a != "NOTSET") || int(n, "ceil_mode").is_some_and(|c| c != 0) {
        return Err(bad("auto_pad and ceil_mode are not covered; give explicit pads".into()));
    }
    Ok((k, [s[0], s[1]], [p[0], p[1], p[2], p[3]]))
}

/// The constant int64 tensor a node reads as input `i`, if it is one.
fn const_ints(n: &Node, consts: &HashMap<&str, &Initializer>, i: usize) -> Option<Vec<i64>> {
    n.inputs.get(i).filter(|s| !s.is_empty()).and_then(|s| consts.get(s.as_str())).and_then(|c| match &c.data {
        InitData::I64(v) => Some(v.clone()),
        _ => None,
    })
}

/// What a `Slice` reads along each axis it cuts: `(axis, start, step, count)`, normalized
/// against the input shape `x`.
fn slice_ranges(
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
fn split_sizes(n: &Node, consts: &HashMap<&str, &Initializer>, x: &[i64]) -> Result<(usize, Vec<i64>), AutodiffError> {
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
fn reshape_target(n: &Node, consts: &HashMap<&str, &Initializer>, x: &[i64]) -> Result<Vec<i64>, AutodiffError> {
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
fn transpose_perm(n: &Node, rank: usize) -> Vec<i64> {
    ints(n, "perm").unwrap_or_else(|| (0..rank as i64).rev().collect())
}

/// Builds the backward graph node by node, with unique names and its own constants.
struct Tape {
    nodes: Vec<Node>,
    inits: Vec<Initializer>,
    count: usize,
}

impl Tape {
    fn fresh(&mut self, what: &str) -> String {
        self.count += 1;
        format!("bw{}_{what}", self.count)
    }
    fn node(&mut self, op: &str, inputs: Vec<String>, attrs: Vec<(&str, Attr)>) -> String {
        let out = self.fresh(&op.to_lowercase());
        self.nodes.push(Node {
            op_type: op.into(),
            name: out.clone(),
            inputs,
            outputs: vec![out.clone()],
            attrs: attrs.into_iter().map(|(k, a)| (k.to_string(), a)).collect(),
            domain: String::new(),
        });
        out
    }
    fn fused(&mut self, op: &str, inputs: Vec<String>, attrs: Vec<(&str, Attr)>) -> String {
        let out = self.node(op, inputs, attrs);
        if let Some(n) = self.nodes.last_mut() {
            n.domain = PAV_DOMAIN.into();
        }
        out
    }
    fn f32s(&mut self, dims: Vec<i64>, v: Vec<f32>) -> String {
        let name = self.fresh("const");
        self.inits.push(Initializer { name: name.clone(), dims, data: InitData::F32(v) });
        name
    }
    fn i64s(&mut self, v: Vec<i64>) -> String {
        let name = self.fresh("const");
        self.inits.push(Initializer { name: name.clone(), dims: vec![v.len() as i64], data: InitData::I64(v) });
        name
    }
    fn scalar(&mut self, v: f32) -> String {
        self.f32s(vec![], vec![v])
    }
    fn slice(&mut self, x: &str, starts: Vec<i64>, ends: Vec<i64>, axes: Vec<i64>, steps: Vec<i64>) -> String {
        let (s, e, a, st) = (self.i64s(starts), self.i64s(ends), self.i64s(axes), self.i64s(steps));
        self.node("Slice", vec![x.into(), s, e, a, st], vec![])
    }
    fn pad(&mut self, x: &str, pads: Vec<i64>, value: f32) -> String {
        let (p, v) = (self.i64s(pads), self.scalar(value));
        self.node("Pad", vec![x.into(), p, v], vec![])
    }
}

/// Static output shapes of `n` from its input shapes.
fn infer(
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
        "Identity" | "LeakyRelu" | "Relu" | "Sigmoid" | "Split" => x,
        "Add" | "Mul" => {
            let y = get(1)?;
            if x != y && !y.is_empty() && y.iter().product::<i64>() != 1 {
                return Err(bad(format!("operands {x:?} and {y:?}: only equal shapes or a scalar")));
            }
            x
        }
        "Conv" => {
            let w = get(1)?;
            let (k, s, p) = window(n, Some([w[2], w[3]]))?;
            let out = |i: usize| (x[2 + i] + p[i] + p[i + 2] - k[i]) / s[i] + 1;
            vec![x[0], w[0], out(0), out(1)]
        }
        "MaxPool" => {
            let (k, s, p) = window(n, None)?;
            let out = |i: usize| (x[2 + i] + p[i] + p[i + 2] - k[i]) / s[i] + 1;
            vec![x[0], x[1], out(0), out(1)]
        }
        "Resize" => {
            let f = resize_factor(n, consts, &x)?;
            vec![x[0], x[1], x[2] * f, x[3] * f]
        }
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

/// The integer factor of a nearest-neighbour Resize (the same on both spatial axes).
fn resize_factor(n: &Node, consts: &HashMap<&str, &Initializer>, x: &[i64]) -> Result<i64, AutodiffError> {
    let bad = |msg: String| AutodiffError::Settings { node: n.name.clone(), op: "Resize".into(), msg };
    if string(n, "mode").as_deref() != Some("nearest") {
        return Err(bad("only mode = nearest".into()));
    }
    let from = |i: usize| n.inputs.get(i).filter(|s| !s.is_empty()).and_then(|s| consts.get(s.as_str()));
    let f = match (from(2), from(3)) {
        (Some(c), _) => match &c.data {
            InitData::F32(v) if v.len() == 4 => v.iter().map(|&s| s as f64).collect::<Vec<_>>(),
            _ => return Err(bad("scales must be 4 constant floats".into())),
        },
        (None, Some(c)) => match &c.data {
            InitData::I64(v) if v.len() == 4 => v.iter().zip(x).map(|(&a, &b)| a as f64 / b as f64).collect(),
            _ => return Err(bad("sizes must be 4 constant integers".into())),
        },
        _ => return Err(bad("needs constant scales or sizes".into())),
    };
    let k = f[2].round() as i64;
    if f[0] != 1.0 || f[1] != 1.0 || f[2] != f[3] || (f[2] - k as f64).abs() > 1e-9 || k < 1 {
        return Err(bad(format!("only equal integer spatial factors, got {f:?}")));
    }
    Ok(k)
}

/// The gradient of a max-pool whose windows tile the input (kernel = stride `b`):
/// SpaceToDepth lays every window position out at once, a cumulative count keeps the first
/// position equal to the maximum, and DepthToSpace puts the routed gradient back. Measured on
/// YOLOv3-tiny at 416² (2 threads): the backward graph 191 → 93 ms against per-position slices and
/// pads (ONNX Runtime's Pad alone took 94 ms).
fn tiled_pool_grad(tape: &mut Tape, x: &str, y: &str, g: &str, b: i64, ys: &[i64]) -> String {
    let windows = tape.node("SpaceToDepth", vec![x.into()], vec![("blocksize", Attr::Int(b))]);
    // [b², C, Ho, Wo]: position (dy, dx) of every window, in row-major order.
    let split = tape.i64s(vec![b * b, ys[1], ys[2], ys[3]]);
    let windows = tape.node("Reshape", vec![windows, split], vec![]);
    let eq = tape.node("Equal", vec![windows, y.into()], vec![]);
    let count = tape.node("Cast", vec![eq.clone()], vec![("to", Attr::Int(FLOAT as i64))]);
    let axis = tape.i64s(vec![0]);
    let seen = tape.node("CumSum", vec![count, axis], vec![]);
    let one = tape.scalar(1.0);
    let first_seen = tape.node("Equal", vec![seen, one], vec![]);
    let first = tape.node("And", vec![eq, first_seen], vec![]);
    let zero = tape.scalar(0.0);
    let routed = tape.node("Where", vec![first, g.into(), zero], vec![]);
    let joined = tape.i64s(vec![1, b * b * ys[1], ys[2], ys[3]]);
    let routed = tape.node("Reshape", vec![routed, joined], vec![]);
    tape.node("DepthToSpace", vec![routed], vec![("blocksize", Attr::Int(b)), ("mode", Attr::Str("DCR".into()))])
}

/// Differentiates `model` (batch 1, input of `input_shape`) with respect to its first input, with
/// standard ONNX operators.
pub fn differentiate(model: &Model, input_shape: &[i64]) -> Result<Differentiated, AutodiffError> {
    differentiate_with(model, input_shape, Kernels::Onnx)
}

/// [`differentiate`] with the backward written by `kernels`.
pub fn differentiate_with(
    model: &Model,
    input_shape: &[i64],
    kernels: Kernels,
) -> Result<Differentiated, AutodiffError> {
    let input = model.inputs.first().ok_or_else(|| AutodiffError::Graph("no input".into()))?.name.clone();
    let consts: HashMap<&str, &Initializer> = model.initializers.iter().map(|i| (i.name.as_str(), i)).collect();
    let mut shape: HashMap<String, Vec<i64>> = HashMap::from([(input.clone(), input_shape.to_vec())]);
    // Values that depend on the input (only those need a gradient).
    let mut live: HashSet<String> = HashSet::from([input.clone()]);
    for n in &model.nodes {
        let s = infer(n, &shape, &consts)?;
        let depends = n.inputs.iter().any(|i| live.contains(i));
        let each: Vec<Vec<i64>> = if n.op_type == "Split" {
            let (axis, sizes) = split_sizes(n, &consts, &s)?;
            sizes.iter().map(|&k| s.iter().enumerate().map(|(i, &d)| if i == axis { k } else { d }).collect()).collect()
        } else {
            vec![s; n.outputs.len()]
        };
        for (o, s) in n.outputs.iter().zip(each) {
            shape.insert(o.clone(), s);
            if depends {
                live.insert(o.clone());
            }
        }
    }
    let mut tape = Tape { nodes: Vec::new(), inits: Vec::new(), count: 0 };
    let mut saved: Vec<String> = Vec::new();
    let save = |v: &str, saved: &mut Vec<String>| {
        if !saved.iter().any(|s| s == v) {
            saved.push(v.to_string());
        }
    };
    // Gradient of each value so far, summed over its consumers.
    let mut grad: HashMap<String, String> = HashMap::new();
    let add_grad = |grad: &mut HashMap<String, String>, tape: &mut Tape, v: &str, g: String| {
        let sum = match grad.remove(v) {
            Some(prev) => tape.node("Add", vec![prev, g], vec![]),
            None => g,
        };
        grad.insert(v.to_string(), sum);
    };
    let mut outputs = Vec::new();
    for o in &model.outputs {
        let s =
            shape.get(&o.name).cloned().ok_or_else(|| AutodiffError::Graph(format!("unknown output {}", o.name)))?;
        outputs.push((o.name.clone(), s));
        add_grad(&mut grad, &mut tape, &o.name, grad_name(&o.name));
    }
    for n in model.nodes.iter().rev() {
        if n.op_type == "Split" {
            let gs: Vec<Option<String>> = n.outputs.iter().map(|o| grad.remove(o)).collect();
            if gs.iter().all(|g| g.is_none()) {
                continue;
            }
            let (axis, _) = split_sizes(n, &consts, &shape[&n.inputs[0]])?;
            let mut parts = Vec::new();
            for (o, g) in n.outputs.iter().zip(gs) {
                parts.push(match g {
                    Some(g) => g,
                    None => {
                        let (zero, dims) = (tape.scalar(0.0), tape.i64s(shape[o].clone()));
                        tape.node("Expand", vec![zero, dims], vec![])
                    }
                });
            }
            let gx = tape.node("Concat", parts, vec![("axis", Attr::Int(axis as i64))]);
            add_grad(&mut grad, &mut tape, &n.inputs[0], gx);
            continue;
        }
        let Some(g) = n.outputs.first().and_then(|o| grad.remove(o)) else { continue };
        let x = n.inputs[0].clone();
        let bad = |msg: &str| AutodiffError::Settings { node: n.name.clone(), op: n.op_type.clone(), msg: msg.into() };
        match n.op_type.as_str() {
            "Identity" => add_grad(&mut grad, &mut tape, &x, g),
            "Relu" | "LeakyRelu" => {
                let alpha = if n.op_type == "Relu" { 0.0 } else { float(n, "alpha").unwrap_or(0.01) };
                // For alpha ≥ 0 the output has the input's sign, and saving the output leaves the
                // convolution before it free to fuse with the activation.
                let sign = if alpha >= 0.0 { n.outputs[0].clone() } else { x.clone() };
                save(&sign, &mut saved);
                if kernels == Kernels::Fused {
                    let gx = tape.fused("LeakyReluGrad", vec![sign, g], vec![("alpha", Attr::Float(alpha))]);
                    add_grad(&mut grad, &mut tape, &x, gx);
                    continue;
                }
                let zero = tape.scalar(0.0);
                let pos = tape.node("Greater", vec![sign, zero.clone()], vec![]);
                let neg = if n.op_type == "Relu" {
                    zero
                } else {
                    let a = tape.scalar(alpha);
                    tape.node("Mul", vec![g.clone(), a], vec![])
                };
                let gx = tape.node("Where", vec![pos, g, neg], vec![]);
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "Sigmoid" => {
                let y = n.outputs[0].clone();
                save(&y, &mut saved);
                let one = tape.scalar(1.0);
                let om = tape.node("Sub", vec![one, y.clone()], vec![]);
                let d = tape.node("Mul", vec![y, om], vec![]);
                let gx = tape.node("Mul", vec![g, d], vec![]);
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "Add" => {
                for v in &n.inputs {
                    if live.contains(v) {
                        add_grad(&mut grad, &mut tape, v, g.clone());
                    }
                }
            }
            "Mul" => {
                for (i, v) in n.inputs.iter().enumerate() {
                    if live.contains(v) {
                        let other = n.inputs[1 - i].clone();
                        if live.contains(&other) {
                            save(&other, &mut saved);
                        } else if let Some(c) = consts.get(other.as_str()) {
                            // The backward graph has its own constants.
                            if !tape.inits.iter().any(|i| i.name == other) {
                                tape.inits.push((*c).clone());
                            }
                        } else {
                            return Err(bad("a factor computed from constants alone; fold it into an initializer"));
                        }
                        let gx = tape.node("Mul", vec![g.clone(), other], vec![]);
                        add_grad(&mut grad, &mut tape, v, gx);
                    }
                }
            }
            "Concat" => {
                let xs = &shape[&x];
                let axis = int(n, "axis").unwrap_or(1);
                let axis = if axis < 0 { axis + xs.len() as i64 } else { axis };
                let mut off = 0;
                for v in &n.inputs {
                    let len = shape[v][axis as usize];
                    if live.contains(v) {
                        let gx = tape.slice(&g, vec![off], vec![off + len], vec![axis], vec![1]);
                        add_grad(&mut grad, &mut tape, v, gx);
                    }
                    off += len;
                }
            }
            "Slice" => {
                // Axis by axis: spread each read position to its step's slot, then pad to the
                // input's extent (or cut where the last step runs past it).
                let xs = shape[&x].clone();
                let mut cur = shape[&n.outputs[0]].clone();
                let mut gx = g;
                for (a, start, step, count) in slice_ranges(n, &consts, &xs)? {
                    let rank = cur.len();
                    if step > 1 {
                        let mut six = cur.clone();
                        six.insert(a + 1, 1);
                        let six_c = tape.i64s(six.clone());
                        let r = tape.node("Reshape", vec![gx, six_c], vec![]);
                        let mut pads = vec![0; 2 * (rank + 1)];
                        pads[rank + 1 + a + 1] = step - 1;
                        let p = tape.pad(&r, pads, 0.0);
                        cur[a] = count * step;
                        let back = tape.i64s(cur.clone());
                        gx = tape.node("Reshape", vec![p, back], vec![]);
                    }
                    let room = xs[a] - start;
                    if cur[a] > room {
                        let (b, mut e) = (vec![0; rank], cur.clone());
                        e[a] = room;
                        let axes: Vec<i64> = (0..rank as i64).collect();
                        gx = tape.slice(&gx, b, e, axes, vec![1; rank]);
                        cur[a] = room;
                    }
                    let mut pads = vec![0; 2 * rank];
                    pads[a] = start;
                    pads[rank + a] = xs[a] - start - cur[a];
                    if pads.iter().any(|&q| q != 0) {
                        gx = tape.pad(&gx, pads, 0.0);
                    }
                    cur[a] = xs[a];
                }
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "Reshape" => {
                let back = tape.i64s(shape[&x].clone());
                let gx = tape.node("Reshape", vec![g, back], vec![]);
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "Transpose" => {
                let perm = transpose_perm(n, shape[&x].len());
                let mut inv = vec![0i64; perm.len()];
                for (i, &p) in perm.iter().enumerate() {
                    inv[p as usize] = i as i64;
                }
                let gx = tape.node("Transpose", vec![g], vec![("perm", Attr::Ints(inv))]);
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "Resize" => {
                let f = resize_factor(n, &consts, &shape[&x])?;
                let pooled = tape.node(
                    "AveragePool",
                    vec![g],
                    vec![("kernel_shape", Attr::Ints(vec![f, f])), ("strides", Attr::Ints(vec![f, f]))],
                );
                let area = tape.scalar((f * f) as f32);
                let gx = tape.node("Mul", vec![pooled, area], vec![]);
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "Conv" => {
                let w = consts.get(n.inputs[1].as_str()).ok_or_else(|| bad("the weight must be a constant"))?;
                let InitData::F32(wv) = &w.data else { return Err(bad("the weight must be float")) };
                let (k, s, p) = window(n, Some([w.dims[2], w.dims[3]]))?;
                let group = int(n, "group").unwrap_or(1);
                let (xs, ys) = (&shape[&x], &shape[&n.outputs[0]]);
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
                    let wf = tape.f32s(vec![c as i64, m as i64, k[0], k[1]], flipped);
                    let pads = vec![k[0] - 1 - p[0], k[1] - 1 - p[1], k[0] - 1 - p[2], k[1] - 1 - p[3]];
                    if pads.iter().any(|&q| q < 0) {
                        return Err(bad("pads larger than kernel − 1"));
                    }
                    tape.node(
                        "Conv",
                        vec![g, wf],
                        vec![("kernel_shape", Attr::Ints(k.to_vec())), ("pads", Attr::Ints(pads))],
                    )
                } else {
                    let wc = tape.f32s(w.dims.clone(), wv.clone());
                    // Rows and columns the forward never read stay out of the transposed output.
                    let op = |i: usize| xs[2 + i] - (s[i] * (ys[2 + i] - 1) + k[i] - p[i] - p[i + 2]);
                    let (oh, ow) = (op(0), op(1));
                    if oh < 0 || ow < 0 || oh >= s[0] || ow >= s[1] {
                        return Err(bad("output shape the transposed convolution cannot reproduce"));
                    }
                    tape.node(
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
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "MaxPool" if kernels == Kernels::Fused => {
                let y = n.outputs[0].clone();
                save(&x, &mut saved);
                save(&y, &mut saved);
                let (k, s, p) = window(n, None)?;
                let attrs = vec![
                    ("kernel_shape", Attr::Ints(k.to_vec())),
                    ("strides", Attr::Ints(s.to_vec())),
                    ("pads", Attr::Ints(p.to_vec())),
                ];
                let gx = tape.fused("MaxPoolGrad", vec![x.clone(), y, g], attrs);
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            "MaxPool" => {
                let y = n.outputs[0].clone();
                save(&x, &mut saved);
                save(&y, &mut saved);
                let (k, s, p) = window(n, None)?;
                let (xs, ys) = (shape[&x].clone(), shape[&y].clone());
                // Windows that tile the input exactly never read the end padding (darknet pads
                // every pool by k − 1 at the end, which stride-2 pools on even sizes never reach).
                let tiles = k == s && k[0] == k[1] && p[0] == 0 && p[1] == 0;
                if tiles && ys[2] * s[0] == xs[2] && ys[3] * s[1] == xs[3] {
                    let gx = tiled_pool_grad(&mut tape, &x, &y, &g, k[0], &ys);
                    add_grad(&mut grad, &mut tape, &x, gx);
                    continue;
                }
                let (hp, wp) = (xs[2] + p[0] + p[2], xs[3] + p[1] + p[3]);
                // Padding never wins: it is the lowest float.
                let xp = if p.iter().any(|&q| q != 0) {
                    tape.pad(&x, vec![0, 0, p[0], p[1], 0, 0, p[2], p[3]], f32::MIN)
                } else {
                    x.clone()
                };
                let zero = tape.scalar(0.0);
                let mut taken: Option<String> = None;
                let mut parts = Vec::new();
                for dy in 0..k[0] {
                    for dx in 0..k[1] {
                        let win = tape.slice(
                            &xp,
                            vec![dy, dx],
                            vec![dy + s[0] * (ys[2] - 1) + 1, dx + s[1] * (ys[3] - 1) + 1],
                            vec![2, 3],
                            vec![s[0], s[1]],
                        );
                        let eq = tape.node("Equal", vec![win, y.clone()], vec![]);
                        let first = match &taken {
                            None => eq.clone(),
                            Some(t) => {
                                let not = tape.node("Not", vec![t.clone()], vec![]);
                                tape.node("And", vec![eq.clone(), not], vec![])
                            }
                        };
                        taken = Some(match taken {
                            None => eq,
                            Some(t) => tape.node("Or", vec![t, first.clone()], vec![]),
                        });
                        let part = tape.node("Where", vec![first, g.clone(), zero.clone()], vec![]);
                        // Back to the padded input's grid: spread by the stride, then shift by the offset.
                        let spread = if s == [1, 1] {
                            part
                        } else {
                            let six = tape.i64s(vec![ys[0], ys[1], ys[2], 1, ys[3], 1]);
                            let r6 = tape.node("Reshape", vec![part, six], vec![]);
                            let padded = tape.pad(&r6, vec![0, 0, 0, 0, 0, 0, 0, 0, 0, s[0] - 1, 0, s[1] - 1], 0.0);
                            let four = tape.i64s(vec![ys[0], ys[1], ys[2] * s[0], ys[3] * s[1]]);
                            tape.node("Reshape", vec![padded, four], vec![])
                        };
                        let (eh, ew) = (hp - dy - ys[2] * s[0], wp - dx - ys[3] * s[1]);
                        let placed = if eh >= 0 && ew >= 0 {
                            tape.pad(&spread, vec![0, 0, dy, dx, 0, 0, eh, ew], 0.0)
                        } else {
                            let cut = tape.slice(
                                &spread,
                                vec![0, 0],
                                vec![ys[2] * s[0] + eh.min(0), ys[3] * s[1] + ew.min(0)],
                                vec![2, 3],
                                vec![1, 1],
                            );
                            tape.pad(&cut, vec![0, 0, dy, dx, 0, 0, eh.max(0), ew.max(0)], 0.0)
                        };
                        parts.push(placed);
                    }
                }
                let summed = if parts.len() == 1 { parts.remove(0) } else { tape.node("Sum", parts, vec![]) };
                let gx = if p.iter().any(|&q| q != 0) {
                    tape.slice(&summed, vec![p[0], p[1]], vec![p[0] + xs[2], p[1] + xs[3]], vec![2, 3], vec![1, 1])
                } else {
                    summed
                };
                add_grad(&mut grad, &mut tape, &x, gx);
            }
            _ => return Err(AutodiffError::Unsupported { node: n.name.clone(), op: n.op_type.clone() }),
        }
    }
    let gx = grad.remove(&input).ok_or_else(|| AutodiffError::Graph("no output depends on the input".into()))?;
    let fixed = |name: &str, s: &[i64]| ValueInfo {
        name: name.into(),
        elem_type: FLOAT,
        dims: s.iter().map(|&d| Dim::Fixed(d)).collect(),
    };
    let saves_input = saved.contains(&input);
    saved.retain(|s| *s != input);
    // A saved value that is also an original output is output once.
    let extra: Vec<&String> = saved.iter().filter(|s| !outputs.iter().any(|o| &o.0 == *s)).collect();
    let mut forward = model.clone();
    forward.inputs = vec![fixed(&input, input_shape)];
    forward.outputs =
        outputs.iter().map(|(n, s)| fixed(n, s)).chain(extra.iter().map(|n| fixed(n, &shape[*n]))).collect();
    let mut b_inputs: Vec<ValueInfo> = saved.iter().map(|n| fixed(n, &shape[n])).collect();
    if saves_input {
        b_inputs.push(fixed(&input, input_shape));
    }
    b_inputs.extend(outputs.iter().map(|(n, s)| fixed(&grad_name(n), s)));
    let out_name = grad_name(&input);
    tape.nodes.push(Node {
        op_type: "Identity".into(),
        name: "bw_out".into(),
        inputs: vec![gx],
        outputs: vec![out_name.clone()],
        attrs: vec![],
        domain: String::new(),
    });
    let backward = Model {
        graph_name: format!("{}_input_gradient", model.graph_name),
        producer: "pav autodiff".into(),
        opset: model.opset.max(13),
        domains: if kernels == Kernels::Fused { vec![(PAV_DOMAIN.into(), 1)] } else { vec![] },
        nodes: tape.nodes,
        initializers: tape.inits,
        inputs: b_inputs,
        outputs: vec![fixed(&out_name, input_shape)],
    };
    Ok(Differentiated { forward, backward, input, input_shape: input_shape.to_vec(), outputs, saved, saves_input })
}
