//! One backward rule per operator, and the table that finds it.
//!
//! A rule reads its node through [`Ctx`] (shapes, constants, which values depend on the input)
//! and writes the gradients of the node's inputs through [`Back`] (the tape, the tensors the
//! backward reads from the forward, the gradients summed so far). Adding an operator means adding
//! one function here and one row to [`RULES`], and one finite-difference test to
//! `tests/autodiff_ops.rs`.

mod binary;
mod conv;
mod elementwise;
mod layout;
mod pool;
mod reduce;
mod select;

use super::tape::Tape;
use super::{AutodiffError, Kernels};
use crate::proto::{Initializer, Node};
use std::collections::{HashMap, HashSet};

/// What a rule knows about its node and the forward graph.
pub(super) struct Ctx<'a> {
    /// The node differentiated.
    pub n: &'a Node,
    /// The static shape of every value.
    pub shape: &'a HashMap<String, Vec<i64>>,
    /// The graph's initializers by name.
    pub consts: &'a HashMap<&'a str, &'a Initializer>,
    /// Values that depend on the graph's input.
    pub live: &'a HashSet<String>,
    /// How element-wise-heavy backwards are written.
    pub kernels: Kernels,
    /// The forward graph's opset.
    pub opset: i64,
}

impl Ctx<'_> {
    /// The shape of `v`, computed or constant.
    pub fn dims(&self, v: &str) -> Vec<i64> {
        self.shape.get(v).or_else(|| self.consts.get(v).map(|c| &c.dims)).cloned().unwrap_or_default()
    }

    /// A setting of this node that its rule does not cover.
    pub fn bad(&self, msg: &str) -> AutodiffError {
        AutodiffError::Settings { node: self.n.name.clone(), op: self.n.op_type.clone(), msg: msg.into() }
    }
}

/// What the rules write: the backward graph, the forward values it reads, the gradients so far.
pub(super) struct Back {
    /// The backward graph.
    pub tape: Tape,
    /// Forward values the backward reads, in the order they were first asked for.
    pub saved: Vec<String>,
    /// The gradient of each value so far, summed over its consumers.
    pub grad: HashMap<String, String>,
}

impl Back {
    /// Marks the forward value `v` as read by the backward.
    pub fn save(&mut self, v: &str) {
        if !self.saved.iter().any(|s| s == v) {
            self.saved.push(v.to_string());
        }
    }

    /// Adds `g` to the gradient of `v`.
    pub fn add(&mut self, v: &str, g: String) {
        let sum = match self.grad.remove(v) {
            Some(prev) => self.tape.node("Add", vec![prev, g], vec![]),
            None => g,
        };
        self.grad.insert(v.to_string(), sum);
    }

    /// A value the backward reads: saved from the forward when it depends on the input, copied
    /// into the backward's constants when it is one; `None` for a value computed from constants
    /// alone.
    pub fn reuse(&mut self, cx: &Ctx, v: &str) -> Option<String> {
        if cx.live.contains(v) {
            self.save(v);
        } else {
            let c = cx.consts.get(v)?;
            if !self.tape.inits.iter().any(|i| i.name == v) {
                self.tape.inits.push((*c).clone());
            }
        }
        Some(v.to_string())
    }
}

/// A rule from the gradient of its node's first output.
type FromFirst = fn(&Ctx, &mut Back, String) -> Result<(), AutodiffError>;

/// A rule from the gradient of each output of its node (`None` where nothing reads it).
type FromEach = fn(&Ctx, &mut Back, Vec<Option<String>>) -> Result<(), AutodiffError>;

/// A rule's function.
pub(super) enum Backward {
    /// From the gradient of the node's first output.
    First(FromFirst),
    /// From the gradient of each output.
    Each(FromEach),
}

/// One operator's backward rule.
pub(super) struct Rule {
    /// The ONNX operator.
    pub op: &'static str,
    /// What the rule covers, where it is less than the operator (shown in errors).
    pub covers: &'static str,
    /// Whether inputs other than the first can carry a gradient.
    pub several_inputs: bool,
    /// The rule.
    pub backward: Backward,
}

const fn first(op: &'static str, covers: &'static str, f: FromFirst) -> Rule {
    Rule { op, covers, several_inputs: false, backward: Backward::First(f) }
}

const fn several(op: &'static str, covers: &'static str, f: FromFirst) -> Rule {
    Rule { op, covers, several_inputs: true, backward: Backward::First(f) }
}

/// Every operator with a backward rule.
pub(super) const RULES: &[Rule] = &[
    first("Conv", "", conv::conv),
    first("MaxPool", "", pool::max_pool),
    first("LeakyRelu", "", elementwise::leaky_relu),
    first("Relu", "", elementwise::leaky_relu),
    first("Sigmoid", "", elementwise::sigmoid),
    first("HardSigmoid", "", elementwise::hard_sigmoid),
    several("Add", "", binary::add_sub),
    several("Sub", "", binary::add_sub),
    several("Mul", "", binary::mul),
    several("Div", "broadcasting", binary::div),
    several("MatMul", "", binary::matmul),
    first("Pow", "constant exponent", elementwise::pow),
    first("Sqrt", "", elementwise::sqrt),
    first("Exp", "", elementwise::exp),
    first("Tanh", "", elementwise::tanh),
    first("Min", "a constant second operand", elementwise::min_max),
    first("Max", "a constant second operand", elementwise::min_max),
    first("Log", "", elementwise::log),
    first("Neg", "", elementwise::neg),
    first("Clip", "", elementwise::clip),
    first("Softmax", "", reduce::softmax),
    first("ReduceMean", "", reduce::reduce_mean_sum),
    first("ReduceSum", "", reduce::reduce_mean_sum),
    several("Concat", "", layout::concat),
    Rule { op: "Split", covers: "", several_inputs: false, backward: Backward::Each(layout::split) },
    first("Resize", "nearest (integer factors), linear (any constant size)", layout::resize),
    first("Slice", "", layout::slice),
    first("Reshape", "", layout::reshape),
    first("Flatten", "", layout::reshape_like),
    first("Squeeze", "", layout::reshape_like),
    first("Unsqueeze", "", layout::reshape_like),
    first("Transpose", "", layout::transpose),
    first("Cast", "to float", elementwise::cast),
    first("Identity", "", elementwise::identity),
    first("Pad", "constant", layout::pad),
    first("AveragePool", "", reduce::average_pool),
    first("GlobalAveragePool", "", reduce::global_average_pool),
    first("ReduceMax", "", reduce::reduce_max),
    first("TopK", "values", select::top_k),
    first("Gather", "constant indices", select::gather),
    first("GatherElements", "", select::gather_elements),
    first("Expand", "", layout::expand),
    several("GridSample", "bilinear, zeros", select::grid_sample),
];

/// The rule for `op`.
pub(super) fn find(op: &str) -> Option<&'static Rule> {
    RULES.iter().find(|r| r.op == op)
}

/// The operators with a backward rule.
pub fn operators() -> Vec<&'static str> {
    RULES.iter().map(|r| r.op).collect()
}

/// The operators with a backward rule, with what each covers, for error messages.
pub fn supported() -> String {
    RULES
        .iter()
        .map(|r| if r.covers.is_empty() { r.op.to_string() } else { format!("{} ({})", r.op, r.covers) })
        .collect::<Vec<_>>()
        .join(", ")
}
