//! Minimal ONNX protobuf writer: just the messages needed to emit an inference graph.
//!
//! Writing the wire format by hand keeps `protoc` and a generated-code dependency out of the
//! build; field numbers follow onnx/onnx.proto3.

/// ONNX tensor element type codes (TensorProto.DataType).
pub const FLOAT: i32 = 1;
/// ONNX int64 element type code.
pub const INT64: i32 = 7;

#[derive(Default)]
struct Buf(Vec<u8>);

impl Buf {
    fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.0.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.0.push(v as u8);
    }
    fn key(&mut self, field: u32, wire: u8) {
        self.varint(((field as u64) << 3) | wire as u64);
    }
    fn int(&mut self, field: u32, v: i64) {
        self.key(field, 0);
        self.varint(v as u64);
    }
    fn float(&mut self, field: u32, v: f32) {
        self.key(field, 5);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn bytes(&mut self, field: u32, b: &[u8]) {
        self.key(field, 2);
        self.varint(b.len() as u64);
        self.0.extend_from_slice(b);
    }
    fn str(&mut self, field: u32, s: &str) {
        self.bytes(field, s.as_bytes());
    }
    fn msg(&mut self, field: u32, m: Buf) {
        self.bytes(field, &m.0);
    }
}

/// A node attribute value.
#[derive(Clone, Debug)]
pub enum Attr {
    /// A single integer.
    Int(i64),
    /// A single float.
    Float(f32),
    /// A string.
    Str(String),
    /// A list of integers.
    Ints(Vec<i64>),
}

/// A graph node: `op_type(inputs) -> outputs` with attributes.
#[derive(Clone, Debug)]
pub struct Node {
    /// Operator name, e.g. `Conv`.
    pub op_type: String,
    /// Node name (unique in the graph).
    pub name: String,
    /// Input value names; an empty string is an omitted optional input.
    pub inputs: Vec<String>,
    /// Output value names.
    pub outputs: Vec<String>,
    /// Attributes in declaration order.
    pub attrs: Vec<(String, Attr)>,
    /// Operator set domain; empty for the default ONNX operators.
    pub domain: String,
}

/// A constant tensor stored in the graph.
#[derive(Clone, Debug)]
pub struct Initializer {
    /// Value name.
    pub name: String,
    /// Dimensions.
    pub dims: Vec<i64>,
    /// Data, already in the element type named by `data_type`.
    pub data: InitData,
}

/// Initializer payload.
#[derive(Clone, Debug)]
pub enum InitData {
    /// float32 values.
    F32(Vec<f32>),
    /// int64 values.
    I64(Vec<i64>),
}

/// A graph input or output: name, element type and shape (`None` = symbolic dimension).
#[derive(Clone, Debug)]
pub struct ValueInfo {
    /// Value name.
    pub name: String,
    /// Element type code (`FLOAT`, `INT64`).
    pub elem_type: i32,
    /// Dimensions.
    pub dims: Vec<Dim>,
}

/// One dimension of a value's shape.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Dim {
    /// A fixed size.
    Fixed(i64),
    /// A named size that the runtime fixes (batch, height, width).
    Symbolic(String),
}

/// A whole model: one graph with opset imports.
#[derive(Clone, Debug)]
pub struct Model {
    /// Graph name.
    pub graph_name: String,
    /// Who wrote it.
    pub producer: String,
    /// Default-domain opset version.
    pub opset: i64,
    /// Further operator sets the nodes use: (domain, version).
    pub domains: Vec<(String, i64)>,
    /// Nodes in topological order.
    pub nodes: Vec<Node>,
    /// Constant tensors.
    pub initializers: Vec<Initializer>,
    /// Graph inputs.
    pub inputs: Vec<ValueInfo>,
    /// Graph outputs.
    pub outputs: Vec<ValueInfo>,
}

fn encode_attr(name: &str, a: &Attr) -> Buf {
    // AttributeProto: name=1, f=2, i=3, s=4, ints=8, type=20 (FLOAT=1, INT=2, STRING=3, INTS=7)
    let mut b = Buf::default();
    b.str(1, name);
    match a {
        Attr::Float(f) => {
            b.float(2, *f);
            b.int(20, 1);
        }
        Attr::Int(i) => {
            b.int(3, *i);
            b.int(20, 2);
        }
        Attr::Str(s) => {
            b.str(4, s);
            b.int(20, 3);
        }
        Attr::Ints(v) => {
            for i in v {
                b.int(8, *i);
            }
            b.int(20, 7);
        }
    }
    b
}

fn encode_node(n: &Node) -> Buf {
    // NodeProto: input=1, output=2, name=3, op_type=4, attribute=5
    let mut b = Buf::default();
    for i in &n.inputs {
        b.str(1, i);
    }
    for o in &n.outputs {
        b.str(2, o);
    }
    b.str(3, &n.name);
    b.str(4, &n.op_type);
    for (k, a) in &n.attrs {
        b.msg(5, encode_attr(k, a));
    }
    if !n.domain.is_empty() {
        b.str(7, &n.domain);
    }
    b
}

fn encode_init(t: &Initializer) -> Buf {
    // TensorProto: dims=1, data_type=2, name=8, raw_data=9 (little-endian)
    let mut b = Buf::default();
    for d in &t.dims {
        b.int(1, *d);
    }
    let (code, raw): (i32, Vec<u8>) = match &t.data {
        InitData::F32(v) => (FLOAT, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
        InitData::I64(v) => (INT64, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
    };
    b.int(2, code as i64);
    b.str(8, &t.name);
    b.bytes(9, &raw);
    b
}

fn encode_value_info(v: &ValueInfo) -> Buf {
    // ValueInfoProto{name=1, type=2}; TypeProto{tensor_type=1}; Tensor{elem_type=1, shape=2};
    // TensorShapeProto{dim=1}; Dimension{dim_value=1, dim_param=2}
    let mut shape = Buf::default();
    for d in &v.dims {
        let mut dim = Buf::default();
        match d {
            Dim::Fixed(n) => dim.int(1, *n),
            Dim::Symbolic(s) => dim.str(2, s),
        }
        shape.msg(1, dim);
    }
    let mut tensor = Buf::default();
    tensor.int(1, v.elem_type as i64);
    tensor.msg(2, shape);
    let mut ty = Buf::default();
    ty.msg(1, tensor);
    let mut b = Buf::default();
    b.str(1, &v.name);
    b.msg(2, ty);
    b
}

impl Model {
    /// Serializes the model to ONNX protobuf bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        // GraphProto: node=1, name=2, initializer=5, input=11, output=12
        let mut g = Buf::default();
        for n in &self.nodes {
            g.msg(1, encode_node(n));
        }
        g.str(2, &self.graph_name);
        for t in &self.initializers {
            g.msg(5, encode_init(t));
        }
        for v in &self.inputs {
            g.msg(11, encode_value_info(v));
        }
        for v in &self.outputs {
            g.msg(12, encode_value_info(v));
        }
        // ModelProto: ir_version=1, producer_name=2, graph=7, opset_import=8{domain=1, version=2}
        let mut m = Buf::default();
        m.int(1, 8);
        m.str(2, &self.producer);
        m.msg(7, g);
        let mut op = Buf::default();
        op.str(1, "");
        op.int(2, self.opset);
        m.msg(8, op);
        for (domain, version) in &self.domains {
            let mut op = Buf::default();
            op.str(1, domain);
            op.int(2, *version);
            m.msg(8, op);
        }
        m.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varint_matches_protobuf_spec_examples() {
        // From the protobuf encoding guide: 150 -> 96 01, 300 -> ac 02.
        let mut b = Buf::default();
        b.varint(150);
        b.varint(300);
        b.varint(1);
        assert_eq!(b.0, vec![0x96, 0x01, 0xac, 0x02, 0x01]);
    }

    #[test]
    fn negative_int_is_ten_byte_twos_complement() {
        let mut b = Buf::default();
        b.int(1, -1);
        assert_eq!(b.0.len(), 11);
        assert_eq!(b.0[0], 0x08);
        assert_eq!(b.0[10], 0x01);
    }
}
