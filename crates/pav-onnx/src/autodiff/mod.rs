//! Input gradients of ONNX graphs, as ONNX graphs: from a frozen-weight inference graph, a forward
//! graph that also outputs what the backward needs, and a backward graph from the gradients of the
//! outputs (and those saved tensors) to the gradient of the input. ONNX Runtime then runs both
//! ([`crate::session`]), with the kernels it runs inference with.
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
//! - For transformers (DETR): `Sub`, `Div` and broadcasting in every binary operator (the gradient
//!   summed back over the broadcast axes), `MatMul` (G·Bᵀ and Aᵀ·G), `Pow` by a constant, `Sqrt`,
//!   `Log`, `Neg`, `Clip`, `Exp`, `Tanh`, `Min` and `Max` with a constant, `Softmax`, `ReduceMean`, `ReduceSum`, `ReduceMax` (to the maximum),
//!   `Flatten`, `(Un)Squeeze`, `Cast` to float, constant `Pad`, `AveragePool` (a transposed
//!   uniform convolution), `GlobalAveragePool`, `Expand`.
//! - Selections: `TopK`'s values, `GatherElements` and `Gather` (constant indices) scatter the
//!   gradient back to where they read (`ScatterElements` with `reduction = add`, opset 16); the
//!   indices themselves carry none.
//! - `GridSample` (bilinear, zero padding, align_corners = 0), which has no gradient operator in
//!   ONNX: both gradients written out from the four corners of every sample (`grid_sample_grad`).
//!
//! Shapes are fixed at differentiation time (batch 1, the given input size); a graph that computes
//! its shapes at run time is folded first ([`crate::fold`]).

mod rules;
mod shapes;
mod tape;

use crate::proto::{Dim, InitData, Initializer, Model, Node, ValueInfo, FLOAT, INT64};
use rules::{Back, Backward, Ctx};
use shapes::{infer, int, split_sizes};
use std::collections::{HashMap, HashSet};
use tape::Tape;

/// Why a graph cannot be differentiated.
#[derive(Debug, thiserror::Error)]
pub enum AutodiffError {
    /// An operator without a backward rule.
    #[error("node `{node}`: operator {op} has no backward rule in pav (supported: {})", rules::supported())]
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
    /// several), which the session must register (`crate::gradops`); CPU only.
    Fused,
}

/// The operators with a backward rule, with what each covers where it is less than the operator.
pub fn supported() -> String {
    rules::supported()
}

/// The operators with a backward rule.
pub fn operators() -> Vec<&'static str> {
    rules::operators()
}

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
    /// The original outputs the backward takes gradients for, in order, with their shapes.
    pub outputs: Vec<(String, Vec<i64>)>,
    /// Outputs the forward computes without a gradient (a detector's boxes, read to weight the
    /// loss), in order, with their shapes; the forward outputs them after `outputs`.
    pub forward_only: Vec<(String, Vec<i64>)>,
    /// The tensors the backward reads from the forward, in the order the forward outputs them
    /// after the original outputs (the graph input is never among them).
    pub saved: Vec<String>,
    /// Whether the backward also reads the graph input itself.
    pub saves_input: bool,
}

/// Every value's shape for an input of `input_shape`, the values that depend on the input, and
/// the element types of those that are not float.
struct Values {
    input: String,
    shape: HashMap<String, Vec<i64>>,
    live: HashSet<String>,
    elem: HashMap<String, i32>,
}

fn values(model: &Model, input_shape: &[i64]) -> Result<Values, AutodiffError> {
    let input = model.inputs.first().ok_or_else(|| AutodiffError::Graph("no input".into()))?.name.clone();
    let consts: HashMap<&str, &Initializer> = model.initializers.iter().map(|i| (i.name.as_str(), i)).collect();
    let mut shape: HashMap<String, Vec<i64>> = HashMap::from([(input.clone(), input_shape.to_vec())]);
    // Values that depend on the input (only those need a gradient, and the float ones get one).
    let mut live: HashSet<String> = HashSet::from([input.clone()]);
    // Element types of the values that are not float (index tensors a backward may read).
    let mut elem: HashMap<String, i32> = HashMap::new();
    for n in &model.nodes {
        let s = infer(n, &shape, &consts)?;
        let depends = n.inputs.iter().any(|i| live.contains(i));
        let first = n.inputs.first().and_then(|i| {
            elem.get(i)
                .copied()
                .or_else(|| consts.get(i.as_str()).filter(|c| matches!(c.data, InitData::I64(_))).map(|_| INT64))
        });
        match n.op_type.as_str() {
            "TopK" => {
                elem.insert(n.outputs[1].clone(), INT64);
            }
            "Cast" => {
                let to = int(n, "to").unwrap_or(FLOAT as i64) as i32;
                if to != FLOAT {
                    elem.insert(n.outputs[0].clone(), to);
                }
            }
            "Shape" | "Size" | "ArgMax" | "ArgMin" => {
                elem.insert(n.outputs[0].clone(), INT64);
            }
            _ => {
                if let Some(t) = first {
                    for o in &n.outputs {
                        elem.insert(o.clone(), t);
                    }
                }
            }
        }
        let each: Vec<Vec<i64>> = if n.op_type == "Split" {
            let (axis, sizes) = split_sizes(n, &consts, &s)?;
            sizes.iter().map(|&k| s.iter().enumerate().map(|(i, &d)| if i == axis { k } else { d }).collect()).collect()
        } else if n.op_type == "TopK" {
            vec![s; 2]
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
    Ok(Values { input, shape, live, elem })
}

/// The shape of every value `model`'s nodes compute for an input of `input_shape` (batch 1), the
/// input's included, as differentiation fixes them: what a caller reads to choose the outputs to
/// differentiate.
pub fn value_shapes(model: &Model, input_shape: &[i64]) -> Result<HashMap<String, Vec<i64>>, AutodiffError> {
    Ok(values(model, input_shape)?.shape)
}

/// The shapes of `model`'s outputs, in order, among `shapes` ([`value_shapes`]).
pub fn output_shapes(
    model: &Model,
    shapes: &HashMap<String, Vec<i64>>,
) -> Result<Vec<(String, Vec<i64>)>, AutodiffError> {
    model
        .outputs
        .iter()
        .map(|o| {
            let s = shapes.get(&o.name).cloned();
            s.map(|s| (o.name.clone(), s)).ok_or_else(|| AutodiffError::Graph(format!("unknown output {}", o.name)))
        })
        .collect()
}

/// Name of the gradient input that seeds `output`'s gradient.
pub fn grad_name(value: &str) -> String {
    format!("grad_{value}")
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
    differentiate_first(model, input_shape, kernels, model.outputs.len())
}

/// [`differentiate_with`] for the first `seeded` outputs of `model`; the others are computed by
/// the forward only ([`Differentiated::forward_only`]), so the backward never walks their branch.
pub fn differentiate_first(
    model: &Model,
    input_shape: &[i64],
    kernels: Kernels,
    seeded: usize,
) -> Result<Differentiated, AutodiffError> {
    let consts: HashMap<&str, &Initializer> = model.initializers.iter().map(|i| (i.name.as_str(), i)).collect();
    let Values { input, shape, live, elem } = values(model, input_shape)?;
    let mut bw = Back {
        tape: Tape { nodes: Vec::new(), inits: Vec::new(), count: 0, opset: 13 },
        saved: Vec::new(),
        grad: HashMap::new(),
    };
    let (mut outputs, mut forward_only) = (Vec::new(), Vec::new());
    for (k, o) in model.outputs.iter().enumerate() {
        let s =
            shape.get(&o.name).cloned().ok_or_else(|| AutodiffError::Graph(format!("unknown output {}", o.name)))?;
        if k >= seeded {
            forward_only.push((o.name.clone(), s));
            continue;
        }
        outputs.push((o.name.clone(), s));
        bw.add(&o.name, grad_name(&o.name));
    }
    for n in model.nodes.iter().rev() {
        let rule = rules::find(&n.op_type);
        let each = matches!(rule, Some(r) if matches!(r.backward, Backward::Each(_)));
        // A rule of every output reads them all; the others read their first output's gradient.
        let seeds: Vec<Option<String>> = if each {
            n.outputs.iter().map(|o| bw.grad.remove(o)).collect()
        } else {
            vec![n.outputs.first().and_then(|o| bw.grad.remove(o))]
        };
        if seeds.iter().all(Option::is_none) {
            continue;
        }
        let x = &n.inputs[0];
        // Ops whose gradient goes to their first input only: none when it is a constant (anchors
        // gathered by live indices) or not float (indices cast to float).
        let several = rule.is_some_and(|r| r.several_inputs) || each;
        if !several && (!live.contains(x) || elem.contains_key(x)) {
            continue;
        }
        let Some(rule) = rule else {
            return Err(AutodiffError::Unsupported { node: n.name.clone(), op: n.op_type.clone() });
        };
        let cx = Ctx { n, shape: &shape, consts: &consts, live: &live, kernels, opset: model.opset };
        match rule.backward {
            Backward::First(f) => {
                let Some(g) = seeds.into_iter().next().flatten() else { continue };
                f(&cx, &mut bw, g)?
            }
            Backward::Each(f) => f(&cx, &mut bw, seeds)?,
        }
    }
    let Back { mut tape, mut saved, mut grad } = bw;
    let gx = grad.remove(&input).ok_or_else(|| AutodiffError::Graph("no output depends on the input".into()))?;
    let fixed = |name: &str, s: &[i64]| ValueInfo {
        name: name.into(),
        elem_type: elem.get(name).copied().unwrap_or(FLOAT),
        dims: s.iter().map(|&d| Dim::Fixed(d)).collect(),
    };
    let saves_input = saved.contains(&input);
    saved.retain(|s| *s != input);
    // A saved value that is also an original output is output once.
    let extra: Vec<&String> =
        saved.iter().filter(|s| !outputs.iter().chain(&forward_only).any(|o| &o.0 == *s)).collect();
    let mut forward = model.clone();
    forward.inputs = vec![fixed(&input, input_shape)];
    forward.outputs = outputs
        .iter()
        .chain(&forward_only)
        .map(|(n, s)| fixed(n, s))
        .chain(extra.iter().map(|n| fixed(n, &shape[*n])))
        .collect();
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
        opset: model.opset.max(tape.opset),
        domains: if kernels == Kernels::Fused { vec![(PAV_DOMAIN.into(), 1)] } else { vec![] },
        nodes: tape.nodes,
        initializers: tape.inits,
        inputs: b_inputs,
        outputs: vec![fixed(&out_name, input_shape)],
    };
    Ok(Differentiated {
        forward,
        backward,
        input,
        input_shape: input_shape.to_vec(),
        outputs,
        forward_only,
        saved,
        saves_input,
    })
}
