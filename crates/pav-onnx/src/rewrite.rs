//! Graph rewrites that change what a model computes: feature norm clipping (a defence).

use crate::proto::{Attr, Initializer, Model, Node};
use crate::OnnxError;

/// Feature norm clipping after the tensor `layer` (`[N, C, H, W]`): every feature vector (the
/// channels at one position) whose L2 norm exceeds `level` times the mean norm over the map's
/// positions is scaled down to that bound, the others pass unchanged (Yu et al., ICCV 2021, with
/// `level = 1`). Every consumer of `layer` reads the clipped tensor instead; the graph's outputs
/// keep their names. Built from ReduceSum, Sqrt, GlobalAveragePool, Div and Clip, so the result
/// stays differentiable by [`crate::differentiate`]. An infinite level leaves every output as it was.
pub fn clip_feature_norms(model: &mut Model, layer: &str, level: f32) -> Result<(), OnnxError> {
    let refuse = |msg: String| OnnxError::Request { model: model.graph_name.clone(), msg };
    if level.is_nan() || level <= 0.0 {
        return Err(refuse(format!("clipping level {level} must be positive")));
    }
    if model.opset < 11 {
        return Err(refuse(format!("feature norm clipping needs opset 11 or later (the graph has {})", model.opset)));
    }
    let produced_at = model.nodes.iter().position(|n| n.outputs.iter().any(|o| o == layer));
    let is_input = model.inputs.iter().any(|i| i.name == layer);
    if produced_at.is_none() && !is_input {
        let mut near: Vec<&str> = model
            .nodes
            .iter()
            .flat_map(|n| n.outputs.iter().map(String::as_str))
            .filter(|o| o.contains(layer) || layer.contains(*o))
            .take(5)
            .collect();
        if near.is_empty() {
            near = model.nodes.iter().rev().take(3).flat_map(|n| n.outputs.first().map(String::as_str)).collect();
        }
        return Err(refuse(format!(
            "the graph has no tensor `{layer}` to clip (its tensors are its nodes' outputs, such as {})",
            near.iter().map(|s| format!("`{s}`")).collect::<Vec<_>>().join(", ")
        )));
    }
    // Fresh names that no existing tensor uses.
    let tag = format!("clip_norm_{}", model.nodes.len());
    let name = |s: &str| format!("{layer}/{tag}/{s}");
    let clipped = name("out");
    for n in model.nodes.iter_mut() {
        for i in n.inputs.iter_mut().filter(|i| i.as_str() == layer) {
            i.clone_from(&clipped);
        }
    }
    let mut nodes = Vec::new();
    let square = name("square");
    nodes.push(Node::new("Mul", &[layer, layer], &[&square]));
    let sum = name("sum");
    nodes.push(if model.opset >= 13 {
        model.initializers.push(Initializer::i64(&name("axes"), &[1], vec![1]));
        Node::new("ReduceSum", &[&square, &name("axes")], &[&sum]).attr("keepdims", Attr::Int(1))
    } else {
        Node::new("ReduceSum", &[&square], &[&sum]).attr("axes", Attr::Ints(vec![1])).attr("keepdims", Attr::Int(1))
    });
    let norm = name("norm");
    nodes.push(Node::new("Sqrt", &[&sum], &[&norm]));
    let mean = name("mean");
    nodes.push(Node::new("GlobalAveragePool", &[&norm], &[&mean]));
    for (c, v) in [("level", level), ("eps", 1e-12), ("zero", 0.0), ("one", 1.0)] {
        model.initializers.push(Initializer::f32(&name(c), &[], vec![v]));
    }
    let bound = name("bound");
    nodes.push(Node::new("Mul", &[&mean, &name("level")], &[&bound]));
    let safe = name("safe_norm");
    nodes.push(Node::new("Add", &[&norm, &name("eps")], &[&safe]));
    let ratio = name("ratio");
    nodes.push(Node::new("Div", &[&bound, &safe], &[&ratio]));
    let scale = name("scale");
    nodes.push(Node::new("Clip", &[&ratio, &name("zero"), &name("one")], &[&scale]));
    nodes.push(Node::new("Mul", &[layer, &scale], &[&clipped]));
    let at = produced_at.map_or(0, |p| p + 1);
    model.nodes.splice(at..at, nodes);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::proto::ValueInfo;

    fn relu_graph() -> Model {
        Model::graph(
            13,
            vec![Node::new("Relu", &["x"], &["f"]), Node::new("Identity", &["f"], &["y"])],
            Vec::new(),
            vec![ValueInfo::f32("x", &[1, 2, 2, 2])],
            vec![ValueInfo::f32("y", &[1, 2, 2, 2]), ValueInfo::f32("f", &[1, 2, 2, 2])],
        )
    }

    #[test]
    fn consumers_read_the_clipped_tensor_and_outputs_keep_their_names() {
        let mut m = relu_graph();
        clip_feature_norms(&mut m, "f", 1.0).unwrap();
        let id = m.nodes.iter().find(|n| n.op_type == "Identity").unwrap();
        assert!(id.inputs[0].ends_with("/out") && id.inputs[0] != "f");
        assert_eq!(m.nodes[0].op_type, "Relu");
        // Every new node comes after the producer and before the consumer.
        let last = m.nodes.iter().position(|n| n.outputs[0] == id.inputs[0]).unwrap();
        assert!(last < m.nodes.iter().position(|n| n.op_type == "Identity").unwrap());
        assert_eq!(m.outputs[1].name, "f");
    }

    #[test]
    fn unknown_layers_and_bad_levels_are_refused() {
        let mut m = relu_graph();
        let e = clip_feature_norms(&mut m, "g", 1.0).unwrap_err().to_string();
        assert!(e.contains("no tensor `g`") && e.contains("`y`"), "{e}");
        for level in [0.0, -1.0, f32::NAN] {
            assert!(clip_feature_norms(&mut m, "f", level).unwrap_err().to_string().contains("must be positive"));
        }
    }
}
