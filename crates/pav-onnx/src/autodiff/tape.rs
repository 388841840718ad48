//! The backward graph as it is written: nodes with unique names, and its own constants.

use super::PAV_DOMAIN;
use crate::proto::{Attr, InitData, Initializer, Node};

/// Builds the backward graph node by node, with unique names and its own constants.
pub(crate) struct Tape {
    pub(super) nodes: Vec<Node>,
    pub(super) inits: Vec<Initializer>,
    pub(super) count: usize,
    /// The opset the backward's operators need (ScatterElements' `reduction`: 16).
    pub(super) opset: i64,
}

impl Tape {
    pub(super) fn fresh(&mut self, what: &str) -> String {
        self.count += 1;
        format!("bw{}_{what}", self.count)
    }
    pub(super) fn node(&mut self, op: &str, inputs: Vec<String>, attrs: Vec<(&str, Attr)>) -> String {
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
    pub(super) fn fused(&mut self, op: &str, inputs: Vec<String>, attrs: Vec<(&str, Attr)>) -> String {
        let out = self.node(op, inputs, attrs);
        if let Some(n) = self.nodes.last_mut() {
            n.domain = PAV_DOMAIN.into();
        }
        out
    }
    pub(super) fn f32s(&mut self, dims: Vec<i64>, v: Vec<f32>) -> String {
        let name = self.fresh("const");
        self.inits.push(Initializer { name: name.clone(), dims, data: InitData::F32(v) });
        name
    }
    pub(super) fn i64s(&mut self, v: Vec<i64>) -> String {
        let name = self.fresh("const");
        self.inits.push(Initializer { name: name.clone(), dims: vec![v.len() as i64], data: InitData::I64(v) });
        name
    }
    pub(super) fn scalar(&mut self, v: f32) -> String {
        self.f32s(vec![], vec![v])
    }
    pub(super) fn slice(
        &mut self,
        x: &str,
        starts: Vec<i64>,
        ends: Vec<i64>,
        axes: Vec<i64>,
        steps: Vec<i64>,
    ) -> String {
        let (s, e, a, st) = (self.i64s(starts), self.i64s(ends), self.i64s(axes), self.i64s(steps));
        self.node("Slice", vec![x.into(), s, e, a, st], vec![])
    }
    pub(super) fn pad(&mut self, x: &str, pads: Vec<i64>, value: f32) -> String {
        let (p, v) = (self.i64s(pads), self.scalar(value));
        self.node("Pad", vec![x.into(), p, v], vec![])
    }
    /// `g` of shape `from` summed down to `to`: the adjoint of numpy broadcasting.
    pub(super) fn unbroadcast(&mut self, g: String, from: &[i64], to: &[i64]) -> String {
        if from == to {
            return g;
        }
        let lead = from.len() - to.len();
        let axes: Vec<i64> =
            (0..from.len()).filter(|&i| i < lead || (to[i - lead] == 1 && from[i] != 1)).map(|i| i as i64).collect();
        let summed = if axes.is_empty() {
            g
        } else {
            let a = self.i64s(axes);
            self.node("ReduceSum", vec![g, a], vec![("keepdims", Attr::Int(1))])
        };
        let t = self.i64s(to.to_vec());
        self.node("Reshape", vec![summed, t], vec![])
    }
    /// `g` reshaped to `to` (the adjoint of every pure reshape: Reshape, Flatten, (Un)squeeze).
    pub(super) fn reshape(&mut self, g: String, to: &[i64]) -> String {
        let t = self.i64s(to.to_vec());
        self.node("Reshape", vec![g, t], vec![])
    }
    /// Zeros of `dims`.
    pub(super) fn zeros(&mut self, dims: &[i64]) -> String {
        let (z, d) = (self.scalar(0.0), self.i64s(dims.to_vec()));
        self.node("Expand", vec![z, d], vec![])
    }
    /// `updates` added into zeros of `dims` at `indices` along `axis` (repeated indices sum).
    pub(super) fn scatter_add(&mut self, dims: &[i64], indices: String, updates: String, axis: i64) -> String {
        self.opset = self.opset.max(16);
        let z = self.zeros(dims);
        self.node(
            "ScatterElements",
            vec![z, indices, updates],
            vec![("axis", Attr::Int(axis)), ("reduction", Attr::Str("add".into()))],
        )
    }
    /// A constant int64 tensor.
    pub(super) fn i64_tensor(&mut self, dims: Vec<i64>, v: Vec<i64>) -> String {
        let name = self.fresh("const");
        self.inits.push(Initializer { name: name.clone(), dims, data: InitData::I64(v) });
        name
    }
    /// `a · bᵀ` over the last two axes.
    pub(super) fn matmul_t(&mut self, a: String, b: String, b_rank: usize, transpose_a: bool, a_rank: usize) -> String {
        let t = |tape: &mut Tape, v: String, r: usize| {
            let mut perm: Vec<i64> = (0..r as i64).collect();
            perm.swap(r - 1, r - 2);
            tape.node("Transpose", vec![v], vec![("perm", Attr::Ints(perm))])
        };
        if transpose_a {
            let at = t(self, a, a_rank);
            self.node("MatMul", vec![at, b], vec![])
        } else {
            let bt = t(self, b, b_rank);
            self.node("MatMul", vec![a, bt], vec![])
        }
    }
}
