//! Fixing a graph's input sizes, and folding what they decide into constants: every value the
//! data nodes read that is computed from shapes and constants alone (not from any input's values)
//! is read off one run of ONNX Runtime and becomes an initializer. What is left computes on data
//! only, with constant shapes, reshape targets and slice bounds, as [`crate::autodiff`]
//! needs. Exported detectors compute their reshape targets at run time (`Shape → Gather →
//! Concat → Reshape`) so that one file serves every batch size.

use crate::proto::{Dim, InitData, Initializer, Model, ValueInfo, FLOAT, INT64};
use crate::runtime::{session_builder, session_err};
use crate::OnnxError;
use ort::value::{DynValue, Tensor};
use std::collections::HashSet;

/// What [`fold_shapes`] did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FoldReport {
    /// Values made initializers.
    pub folded: usize,
    /// Nodes removed (the folded values' producers and everything only they read).
    pub nodes_removed: usize,
}

fn read(name: &str, v: &DynValue) -> Result<Initializer, OnnxError> {
    let err = |what| session_err(name, what);
    let (shape, data) = if let Ok((s, d)) = v.try_extract_tensor::<f32>() {
        (s.to_vec(), InitData::F32(d.to_vec()))
    } else if let Ok((s, d)) = v.try_extract_tensor::<i64>() {
        (s.to_vec(), InitData::I64(d.to_vec()))
    } else {
        return Err(err("folding a constant")(ort::Error::new(format!(
            "`{name}` is neither f32 nor i64: pav cannot fold it"
        ))));
    };
    Ok(Initializer { name: name.into(), dims: shape, data })
}

/// `model` with its inputs fixed to `sizes` (every input some node reads, by name; the others are
/// dropped) and every value computed without any input's values folded into an initializer;
/// `what` names the model in errors.
pub fn fold_shapes(model: &Model, sizes: &[(&str, Vec<i64>)], what: &str) -> Result<(Model, FoldReport), OnnxError> {
    let mut fixed = model.clone();
    // Inputs nothing reads any more (a post-processor's, once the graph is cut before it) go.
    let consumed: HashSet<&str> = model.nodes.iter().flat_map(|n| n.inputs.iter().map(|i| i.as_str())).collect();
    fixed.inputs.retain(|i| consumed.contains(i.name.as_str()));
    for input in &mut fixed.inputs {
        let (_, dims) = sizes.iter().find(|(n, _)| *n == input.name).ok_or_else(|| OnnxError::Request {
            model: what.into(),
            msg: format!("no size given for the input `{}`", input.name),
        })?;
        input.dims = dims.iter().map(|&d| Dim::Fixed(d)).collect();
    }
    // Values that depend on an input's values; a Shape's output depends only on sizes, now fixed.
    let mut data: HashSet<String> = fixed.inputs.iter().map(|i| i.name.clone()).collect();
    for n in &fixed.nodes {
        if !matches!(n.op_type.as_str(), "Shape" | "Size") && n.inputs.iter().any(|i| data.contains(i)) {
            data.extend(n.outputs.iter().cloned());
        }
    }
    let inits: HashSet<&str> = fixed.initializers.iter().map(|i| i.name.as_str()).collect();
    let mut needed: Vec<String> = Vec::new();
    for n in fixed.nodes.iter().filter(|n| n.outputs.iter().any(|o| data.contains(o))) {
        for i in &n.inputs {
            if !i.is_empty() && !data.contains(i) && !inits.contains(i.as_str()) && !needed.contains(i) {
                needed.push(i.clone());
            }
        }
    }
    let mut folded = Vec::with_capacity(needed.len());
    if !needed.is_empty() {
        let probe = Model {
            outputs: needed.iter().map(|n| ValueInfo { name: n.clone(), elem_type: 0, dims: vec![] }).collect(),
            ..fixed.clone()
        };
        let err = |w| session_err(what, w);
        let mut session = session_builder(what, 1)?
            .commit_from_memory(&probe.to_bytes())
            .map_err(err("loading the graph to fold"))?;
        let mut feed: Vec<(String, DynValue)> = Vec::new();
        for i in &fixed.inputs {
            let shape: Vec<usize> =
                i.dims.iter().map(|d| if let Dim::Fixed(v) = d { *v as usize } else { 1 }).collect();
            let n: usize = shape.iter().product();
            // The folded values do not depend on the inputs' values, so zeros serve.
            let v = match i.elem_type {
                FLOAT => Tensor::from_array((shape, vec![0f32; n])).map_err(err("preparing an input"))?.into_dyn(),
                INT64 => Tensor::from_array((shape, vec![0i64; n])).map_err(err("preparing an input"))?.into_dyn(),
                t => {
                    return Err(OnnxError::Request {
                        model: what.into(),
                        msg: format!("input `{}` has element type {t}", i.name),
                    })
                }
            };
            feed.push((i.name.clone(), v));
        }
        let outs = session.run(feed).map_err(err("running the graph to fold"))?;
        for n in &needed {
            let v = outs
                .get(n.as_str())
                .ok_or_else(|| OnnxError::Request { model: what.into(), msg: format!("no value `{n}`") })?;
            folded.push(read(n, v)?);
        }
    }
    let before = fixed.nodes.len();
    fixed.nodes.retain(|n| n.outputs.iter().any(|o| data.contains(o)));
    fixed.initializers.extend(folded);
    fixed.prune();
    let report = FoldReport { folded: needed.len(), nodes_removed: before - fixed.nodes.len() };
    Ok((fixed, report))
}
