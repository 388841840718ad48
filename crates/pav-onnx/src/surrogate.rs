//! A float surrogate of a dynamically quantized ONNX model: every
//! `DynamicQuantizeLinear → ConvInteger → Cast → Mul(scale) [→ Add(bias)]` chain becomes one
//! float `Conv` on the unquantized input with the dequantized weights `(w − zero_point)·scale`
//! and the bias; every `DynamicQuantizeLinear [→ Transpose] → MatMulInteger → Cast → Mul(scale)`
//! becomes a float `MatMul` (after the same `Transpose` of the float input) with the dequantized
//! weights. A MatMul's bias stays the `Add` it is.
//!
//! ONNX Runtime's dynamic int8 models (`yolov8n_int8.onnx`) cannot be differentiated: their
//! activations are rounded to 8 bits at every layer. The surrogate is the float network their
//! weights came from, up to the weights' own rounding. It is **not** the evaluated model; how far
//! its scores lie from the int8 model's must be measured and reported wherever it is used.

use crate::proto::{InitData, Initializer, Model, Node};
use std::collections::{HashMap, HashSet};

/// Why a model cannot be turned into a float surrogate.
#[derive(Debug, thiserror::Error)]
pub enum SurrogateError {
    /// A quantized product that is not in the form ONNX Runtime's dynamic quantizer writes.
    #[error("{op} `{node}`: {why}")]
    Pattern {
        /// `ConvInteger` or `MatMulInteger`.
        op: String,
        /// The node.
        node: String,
        /// What was expected.
        why: String,
    },
    /// Integer operators the rewrite does not cover are left in the graph.
    #[error("the surrogate still holds integer operators: {0}")]
    Leftover(String),
}

/// What [`dequantize`] changed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SurrogateReport {
    /// `ConvInteger` chains replaced by float `Conv`s.
    pub convs: usize,
    /// `MatMulInteger` chains replaced by float `MatMul`s.
    pub matmuls: usize,
    /// Nodes removed in all (chains and the quantizers nothing reads any more).
    pub nodes_removed: usize,
}

fn pattern(node: &Node, why: impl Into<String>) -> SurrogateError {
    SurrogateError::Pattern { op: node.op_type.clone(), node: node.name.clone(), why: why.into() }
}

/// Values of a scalar or per-output-channel initializer as f32 (zero points and scales).
fn values(init: &Initializer) -> Vec<f32> {
    match &init.data {
        InitData::F32(v) => v.clone(),
        InitData::I64(v) => v.iter().map(|&x| x as f32).collect(),
        InitData::I32(v) => v.iter().map(|&x| x as f32).collect(),
        InitData::U8(v) => v.iter().map(|&x| x as f32).collect(),
        InitData::I8(v) => v.iter().map(|&x| x as f32).collect(),
    }
}

/// The float surrogate of `model` (see the module doc), with what changed.
pub fn dequantize(model: &Model) -> Result<(Model, SurrogateReport), SurrogateError> {
    let inits: HashMap<&str, &Initializer> = model.initializers.iter().map(|i| (i.name.as_str(), i)).collect();
    let producer: HashMap<&str, &Node> =
        model.nodes.iter().flat_map(|n| n.outputs.iter().map(move |o| (o.as_str(), n))).collect();
    let mut readers: HashMap<&str, Vec<&Node>> = HashMap::new();
    for n in &model.nodes {
        for i in &n.inputs {
            readers.entry(i.as_str()).or_default().push(n);
        }
    }
    let only_reader = |value: &str, op: &str, n: &Node| -> Result<&Node, SurrogateError> {
        match readers.get(value).map(|r| r.as_slice()) {
            Some([r]) if r.op_type == op => Ok(r),
            _ => Err(pattern(n, format!("its output must feed exactly one {op}"))),
        }
    };
    // Node name → replacement (None: drop it).
    let mut replace: HashMap<String, Option<Node>> = HashMap::new();
    let mut new_inits = Vec::new();
    let mut float_inputs = Vec::new();
    for n in model.nodes.iter().filter(|n| matches!(n.op_type.as_str(), "ConvInteger" | "MatMulInteger")) {
        let conv = n.op_type == "ConvInteger";
        let [xq, wq, _xzp, wzp] = n.inputs.as_slice() else {
            return Err(pattern(n, "expected inputs (x, w, x_zero_point, w_zero_point)"));
        };
        // A MatMul's quantized input may be transposed on the way (attention's value products).
        let between = producer.get(xq.as_str()).filter(|p| !conv && p.op_type == "Transpose");
        let quantized = between.map_or(xq, |t| &t.inputs[0]);
        let quantizer = producer
            .get(quantized.as_str())
            .filter(|p| p.op_type == "DynamicQuantizeLinear")
            .ok_or_else(|| pattern(n, "its input must come from DynamicQuantizeLinear"))?;
        let mut x = quantizer.inputs[0].clone();
        if let Some(t) = between {
            let out = format!("{}_float", t.outputs[0]);
            float_inputs.push(Node {
                op_type: "Transpose".into(),
                name: format!("{}_float", t.name),
                inputs: vec![x],
                outputs: vec![out.clone()],
                attrs: t.attrs.clone(),
                domain: String::new(),
            });
            x = out;
        }
        let w = inits.get(wq.as_str()).ok_or_else(|| pattern(n, "its weight must be an initializer"))?;
        let zp = inits.get(wzp.as_str()).map(|z| values(z)).ok_or_else(|| pattern(n, "no weight zero point"))?;
        let cast = only_reader(&n.outputs[0], "Cast", n)?;
        let mul = only_reader(&cast.outputs[0], "Mul", n)?;
        let scale_value = mul.inputs.iter().find(|i| **i != cast.outputs[0]).ok_or_else(|| pattern(n, "no scale"))?;
        // The scale is x_scale·w_scale, computed by a Mul of the quantizer's scale and an initializer.
        let scale_mul = producer
            .get(scale_value.as_str())
            .filter(|p| p.op_type == "Mul")
            .ok_or_else(|| pattern(n, "its scale must be a Mul of the input's and the weight's scales"))?;
        let w_scale = scale_mul
            .inputs
            .iter()
            .find_map(|i| inits.get(i.as_str()))
            .map(|s| values(s))
            .ok_or_else(|| pattern(n, "the weight scale must be an initializer"))?;
        // A Conv weight's output channel is its first axis, a MatMul weight's its last.
        let oc = *(if conv { w.dims.first() } else { w.dims.last() })
            .ok_or_else(|| pattern(n, "weight without dims"))? as usize;
        let per = w.data.len() / oc.max(1);
        let channel = |k: usize| if conv { k / per } else { k % oc };
        let pick = |v: &[f32], c: usize| if v.len() == oc { v[c] } else { v[0] };
        if !(zp.len() == 1 || zp.len() == oc) || !(w_scale.len() == 1 || w_scale.len() == oc) {
            return Err(pattern(n, "zero point and scale must be per tensor or per output channel"));
        }
        let wv = values(w);
        let deq: Vec<f32> =
            wv.iter().enumerate().map(|(k, &q)| (q - pick(&zp, channel(k))) * pick(&w_scale, channel(k))).collect();
        let name = format!("{}_dequantized", w.name);
        new_inits.push(Initializer { name: name.clone(), dims: w.dims.clone(), data: InitData::F32(deq) });
        let mut inputs = vec![x, name];
        let mut outputs = mul.outputs.clone();
        // A bias added after the rescale (`Add(conv, Reshape(bias, [C, 1, 1]))`) goes into the
        // Conv, so no broadcasting Add is left for the gradient graph.
        if let (true, Some([add])) = (conv, readers.get(mul.outputs[0].as_str()).map(|r| r.as_slice())) {
            let other = add.inputs.iter().find(|i| **i != mul.outputs[0]);
            let bias = other
                .and_then(|o| producer.get(o.as_str()))
                .filter(|r| r.op_type == "Reshape")
                .and_then(|r| inits.get(r.inputs[0].as_str()))
                .filter(|b| add.op_type == "Add" && b.data.len() == oc && matches!(b.data, InitData::F32(_)));
            if let Some(b) = bias {
                inputs.push(b.name.clone());
                outputs = add.outputs.clone();
                replace.insert(add.name.clone(), None);
            }
        }
        let float = Node {
            op_type: (if conv { "Conv" } else { "MatMul" }).into(),
            name: format!("{}_float", n.name),
            inputs,
            outputs,
            attrs: n.attrs.clone(),
            domain: String::new(),
        };
        replace.insert(n.name.clone(), Some(float));
        replace.insert(cast.name.clone(), None);
        replace.insert(mul.name.clone(), None);
    }
    // The float transposes go just before their products (which come after the quantizers).
    let mut nodes = Vec::with_capacity(model.nodes.len());
    for n in &model.nodes {
        match replace.get(&n.name) {
            Some(Some(r)) => {
                nodes.extend(float_inputs.iter().filter(|t| r.inputs.first() == t.outputs.first()).cloned());
                nodes.push(r.clone());
            }
            Some(None) => {}
            None => nodes.push(n.clone()),
        }
    }
    let mut out = Model {
        nodes,
        initializers: model.initializers.iter().cloned().chain(new_inits).collect(),
        producer: "pav surrogate".into(),
        ..model.clone()
    };
    // The quantizers and scale products nothing reads any more go, with the integer weights.
    out.prune();
    let leftover: Vec<String> = out
        .nodes
        .iter()
        .filter(|n| matches!(n.op_type.as_str(), "ConvInteger" | "MatMulInteger" | "DynamicQuantizeLinear"))
        .map(|n| n.op_type.clone())
        .collect::<HashSet<_>>()
        .into_iter()
        .collect();
    if !leftover.is_empty() {
        return Err(SurrogateError::Leftover(leftover.join(", ")));
    }
    let made = |op: &str| replace.values().flatten().filter(|r| r.op_type == op).count();
    let report = SurrogateReport {
        convs: made("Conv"),
        matmuls: made("MatMul"),
        nodes_removed: model.nodes.len() - out.nodes.len(),
    };
    Ok((out, report))
}
