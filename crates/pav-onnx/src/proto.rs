//! Minimal ONNX protobuf reader and writer: the messages of an inference graph (nodes,
//! attributes, initializers, typed inputs and outputs, opset imports).
//!
//! Reading and writing the wire format by hand keeps `protoc` and a generated-code dependency out
//! of the build; field numbers follow onnx/onnx.proto3.

/// ONNX tensor element type codes (TensorProto.DataType).
pub const FLOAT: i32 = 1;
/// ONNX uint8 element type code.
pub const UINT8: i32 = 2;
/// ONNX int8 element type code.
pub const INT8: i32 = 3;
/// ONNX int64 element type code.
pub const INT64: i32 = 7;
/// ONNX element type code of int32.
pub const INT32: i32 = 6;

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
    /// A list of floats.
    Floats(Vec<f32>),
    /// A tensor (a `Constant` node's value).
    Tensor(Initializer),
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
    /// int32 values (Paddle exports write some constants so).
    I32(Vec<i32>),
    /// uint8 values (quantized weights and zero points).
    U8(Vec<u8>),
    /// int8 values (quantized weights and zero points).
    I8(Vec<i8>),
}

impl InitData {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            InitData::F32(v) => v.len(),
            InitData::I64(v) => v.len(),
            InitData::I32(v) => v.len(),
            InitData::U8(v) => v.len(),
            InitData::I8(v) => v.len(),
        }
    }

    /// Whether it holds no value.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A graph input or output: name, element type and shape (`None` = symbolic dimension).
#[derive(Clone, Debug)]
pub struct ValueInfo {
    /// Value name.
    pub name: String,
    /// Element type code (`FLOAT`, `INT64`; 0: untyped, for an output the runtime types).
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

impl Node {
    /// `op(inputs) -> outputs` in the default domain, named after its first output.
    pub fn new(op: &str, inputs: &[&str], outputs: &[&str]) -> Node {
        Node {
            op_type: op.into(),
            name: outputs.first().copied().unwrap_or(op).into(),
            inputs: inputs.iter().map(|s| s.to_string()).collect(),
            outputs: outputs.iter().map(|s| s.to_string()).collect(),
            attrs: Vec::new(),
            domain: String::new(),
        }
    }

    /// The node with attribute `key` set to `value`.
    pub fn attr(mut self, key: &str, value: Attr) -> Node {
        self.attrs.push((key.into(), value));
        self
    }
}

impl Initializer {
    /// A float32 constant.
    pub fn f32(name: &str, dims: &[i64], values: Vec<f32>) -> Initializer {
        Initializer { name: name.into(), dims: dims.to_vec(), data: InitData::F32(values) }
    }

    /// An int64 constant.
    pub fn i64(name: &str, dims: &[i64], values: Vec<i64>) -> Initializer {
        Initializer { name: name.into(), dims: dims.to_vec(), data: InitData::I64(values) }
    }
}

impl ValueInfo {
    /// A float32 value of fixed shape.
    pub fn f32(name: &str, dims: &[i64]) -> ValueInfo {
        ValueInfo { name: name.into(), elem_type: FLOAT, dims: dims.iter().map(|&d| Dim::Fixed(d)).collect() }
    }
}

impl Model {
    /// A graph of the default domain at `opset`.
    pub fn graph(
        opset: i64,
        nodes: Vec<Node>,
        initializers: Vec<Initializer>,
        inputs: Vec<ValueInfo>,
        outputs: Vec<ValueInfo>,
    ) -> Model {
        Model {
            graph_name: "graph".into(),
            producer: "pav-onnx".into(),
            opset,
            domains: Vec::new(),
            nodes,
            initializers,
            inputs,
            outputs,
        }
    }
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
        Attr::Floats(v) => {
            for f in v {
                b.float(7, *f);
            }
            b.int(20, 6);
        }
        Attr::Tensor(t) => {
            b.msg(5, encode_init(t));
            b.int(20, 4);
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
        InitData::I32(v) => (INT32, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
        InitData::U8(v) => (UINT8, v.clone()),
        InitData::I8(v) => (INT8, v.iter().map(|x| *x as u8).collect()),
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
    let mut b = Buf::default();
    b.str(1, &v.name);
    // Element type 0 (unknown) writes the name alone: ONNX Runtime then types the value itself.
    if v.elem_type != 0 {
        let mut tensor = Buf::default();
        tensor.int(1, v.elem_type as i64);
        tensor.msg(2, shape);
        let mut ty = Buf::default();
        ty.msg(1, tensor);
        b.msg(2, ty);
    }
    b
}

impl Model {
    /// Drops the nodes no graph output depends on, then the initializers no node reads.
    pub fn prune(&mut self) {
        let mut needed: std::collections::HashSet<String> = self.outputs.iter().map(|o| o.name.clone()).collect();
        let mut keep = vec![false; self.nodes.len()];
        for (i, n) in self.nodes.iter().enumerate().rev() {
            if n.outputs.iter().any(|o| needed.contains(o)) {
                keep[i] = true;
                needed.extend(n.inputs.iter().cloned());
            }
        }
        let mut k = keep.into_iter();
        self.nodes.retain(|_| k.next().unwrap_or(true));
        self.initializers.retain(|i| needed.contains(&i.name));
    }

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

/// Why bytes are not an ONNX model pav can read.
#[derive(Debug, thiserror::Error)]
pub enum ProtoError {
    /// The protobuf wire format is broken (truncated, a bad varint or wire type).
    #[error("not a valid ONNX protobuf: {0}")]
    Wire(&'static str),
    /// Valid protobuf with content pav does not read (named).
    #[error("ONNX model: {0}")]
    Unsupported(String),
}

/// One protobuf field: number and value.
enum Field<'a> {
    Varint(u64),
    Fixed32([u8; 4]),
    Fixed64,
    Bytes(&'a [u8]),
}

/// Iterates over the fields of one message.
struct Fields<'a>(&'a [u8]);

impl<'a> Fields<'a> {
    fn varint(&mut self) -> Result<u64, ProtoError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let (&b, rest) = self.0.split_first().ok_or(ProtoError::Wire("truncated varint"))?;
            self.0 = rest;
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(ProtoError::Wire("varint longer than 10 bytes"))
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], ProtoError> {
        if self.0.len() < n {
            return Err(ProtoError::Wire("truncated field"));
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Ok(a)
    }
    fn next_field(&mut self) -> Result<Option<(u32, Field<'a>)>, ProtoError> {
        if self.0.is_empty() {
            return Ok(None);
        }
        let key = self.varint()?;
        let f = match key & 7 {
            0 => Field::Varint(self.varint()?),
            1 => {
                self.take(8)?;
                Field::Fixed64
            }
            2 => {
                let n = self.varint()? as usize;
                Field::Bytes(self.take(n)?)
            }
            5 => Field::Fixed32(self.take(4)?.try_into().map_err(|_| ProtoError::Wire("fixed32"))?),
            _ => return Err(ProtoError::Wire("unsupported wire type (groups)")),
        };
        Ok(Some(((key >> 3) as u32, f)))
    }
}

/// Calls `f` on every field of `bytes`.
fn each<'a>(bytes: &'a [u8], mut f: impl FnMut(u32, Field<'a>) -> Result<(), ProtoError>) -> Result<(), ProtoError> {
    let mut it = Fields(bytes);
    while let Some((n, v)) = it.next_field()? {
        f(n, v)?;
    }
    Ok(())
}

fn utf8(b: &[u8]) -> Result<String, ProtoError> {
    String::from_utf8(b.to_vec()).map_err(|_| ProtoError::Wire("a string that is not UTF-8"))
}

/// A repeated int64 field, packed or not.
fn push_ints(out: &mut Vec<i64>, f: Field) -> Result<(), ProtoError> {
    match f {
        Field::Varint(v) => out.push(v as i64),
        Field::Bytes(b) => {
            let mut p = Fields(b);
            while !p.0.is_empty() {
                out.push(p.varint()? as i64);
            }
        }
        _ => return Err(ProtoError::Wire("an integer list of the wrong wire type")),
    }
    Ok(())
}

/// A repeated float field, packed or not.
fn push_floats(out: &mut Vec<f32>, f: Field) -> Result<(), ProtoError> {
    match f {
        Field::Fixed32(b) => out.push(f32::from_le_bytes(b)),
        Field::Bytes(b) if b.len() % 4 == 0 => {
            out.extend(b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])))
        }
        _ => return Err(ProtoError::Wire("a float list of the wrong wire type")),
    }
    Ok(())
}

fn decode_attr(b: &[u8]) -> Result<(String, Attr), ProtoError> {
    let (mut name, mut ty) = (String::new(), 0u64);
    let (mut f, mut i, mut s) = (None, None, None);
    let (mut ints, mut floats, mut tensor) = (Vec::new(), Vec::new(), None);
    each(b, |n, v| {
        match (n, v) {
            (1, Field::Bytes(x)) => name = utf8(x)?,
            (5, Field::Bytes(x)) => tensor = Some(decode_init(x)?),
            (2, Field::Fixed32(x)) => f = Some(f32::from_le_bytes(x)),
            (3, Field::Varint(x)) => i = Some(x as i64),
            (4, Field::Bytes(x)) => s = Some(utf8(x)?),
            (7, v) => push_floats(&mut floats, v)?,
            (8, v) => push_ints(&mut ints, v)?,
            (20, Field::Varint(x)) => ty = x,
            _ => {}
        }
        Ok(())
    })?;
    // AttributeType: FLOAT=1, INT=2, STRING=3, TENSOR=4, FLOATS=6, INTS=7.
    let a = match ty {
        4 => Attr::Tensor(tensor.ok_or(ProtoError::Wire("a tensor attribute without its tensor"))?),
        1 => Attr::Float(f.unwrap_or(0.0)),
        2 => Attr::Int(i.unwrap_or(0)),
        3 => Attr::Str(s.unwrap_or_default()),
        6 => Attr::Floats(floats),
        7 => Attr::Ints(ints),
        t => return Err(ProtoError::Unsupported(format!("attribute `{name}` of type {t} (graphs, lists of tensors)"))),
    };
    Ok((name, a))
}

fn decode_node(b: &[u8]) -> Result<Node, ProtoError> {
    let mut n = Node {
        op_type: String::new(),
        name: String::new(),
        inputs: vec![],
        outputs: vec![],
        attrs: vec![],
        domain: String::new(),
    };
    each(b, |k, v| {
        if let Field::Bytes(x) = v {
            match k {
                1 => n.inputs.push(utf8(x)?),
                2 => n.outputs.push(utf8(x)?),
                3 => n.name = utf8(x)?,
                4 => n.op_type = utf8(x)?,
                5 => n.attrs.push(decode_attr(x)?),
                7 => n.domain = utf8(x)?,
                _ => {}
            }
        }
        Ok(())
    })?;
    if n.name.is_empty() {
        n.name = n.outputs.first().cloned().unwrap_or_default();
    }
    Ok(n)
}

fn decode_init(b: &[u8]) -> Result<Initializer, ProtoError> {
    let (mut dims, mut ty, mut name) = (Vec::new(), 0u64, String::new());
    let (mut floats, mut ints, mut raw) = (Vec::new(), Vec::new(), None);
    each(b, |k, v| {
        match (k, v) {
            (1, v) => push_ints(&mut dims, v)?,
            (2, Field::Varint(x)) => ty = x,
            (4, v) => push_floats(&mut floats, v)?,
            // int32_data holds 8-bit tensors written without raw_data.
            (5 | 7, v) => push_ints(&mut ints, v)?,
            (8, Field::Bytes(x)) => name = utf8(x)?,
            (9, Field::Bytes(x)) => raw = Some(x),
            // external_data, or data_location = EXTERNAL (a writer may state DEFAULT, 0, explicitly).
            (13, _) | (14, Field::Varint(1)) => {
                return Err(ProtoError::Unsupported("tensors stored outside the file".into()))
            }
            _ => {}
        }
        Ok(())
    })?;
    let data = match (ty as i32, raw) {
        (FLOAT, Some(r)) if r.len() % 4 == 0 => {
            InitData::F32(r.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
        }
        (FLOAT, None) => InitData::F32(floats),
        (INT64, Some(r)) if r.len() % 8 == 0 => {
            InitData::I64(r.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().unwrap_or([0; 8]))).collect())
        }
        (INT64, None) => InitData::I64(ints),
        (INT32, Some(r)) if r.len() % 4 == 0 => {
            InitData::I32(r.chunks_exact(4).map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
        }
        (INT32, None) => InitData::I32(ints.iter().map(|&i| i as i32).collect()),
        (UINT8, Some(r)) => InitData::U8(r.to_vec()),
        (UINT8, None) => InitData::U8(ints.iter().map(|&i| i as u8).collect()),
        (INT8, Some(r)) => InitData::I8(r.iter().map(|&b| b as i8).collect()),
        (INT8, None) => InitData::I8(ints.iter().map(|&i| i as i8).collect()),
        (t, _) => return Err(ProtoError::Unsupported(format!("initializer `{name}` of element type {t}"))),
    };
    let n = data.len();
    if dims.iter().product::<i64>() != n as i64 {
        return Err(ProtoError::Unsupported(format!("initializer `{name}`: {n} values for dims {dims:?}")));
    }
    Ok(Initializer { name, dims, data })
}

fn decode_value_info(b: &[u8]) -> Result<ValueInfo, ProtoError> {
    let mut v = ValueInfo { name: String::new(), elem_type: 0, dims: vec![] };
    each(b, |k, f| {
        match (k, f) {
            (1, Field::Bytes(x)) => v.name = utf8(x)?,
            (2, Field::Bytes(ty)) => each(ty, |k, f| match (k, f) {
                (1, Field::Bytes(tensor)) => each(tensor, |k, f| {
                    match (k, f) {
                        (1, Field::Varint(e)) => v.elem_type = e as i32,
                        (2, Field::Bytes(shape)) => each(shape, |k, f| {
                            if let (1, Field::Bytes(dim)) = (k, f) {
                                let mut d = Dim::Symbolic(String::new());
                                each(dim, |k, f| {
                                    match (k, f) {
                                        (1, Field::Varint(n)) => d = Dim::Fixed(n as i64),
                                        (2, Field::Bytes(s)) => d = Dim::Symbolic(utf8(s)?),
                                        _ => {}
                                    }
                                    Ok(())
                                })?;
                                v.dims.push(d);
                            }
                            Ok(())
                        })?,
                        _ => {}
                    }
                    Ok(())
                }),
                _ => Ok(()),
            })?,
            _ => {}
        }
        Ok(())
    })?;
    Ok(v)
}

impl Model {
    /// Parses ONNX protobuf bytes (one graph, tensors stored in the file).
    pub fn from_bytes(bytes: &[u8]) -> Result<Model, ProtoError> {
        let mut m = Model {
            graph_name: String::new(),
            producer: String::new(),
            opset: 0,
            domains: vec![],
            nodes: vec![],
            initializers: vec![],
            inputs: vec![],
            outputs: vec![],
        };
        let mut graph = None;
        each(bytes, |k, f| {
            match (k, f) {
                (2, Field::Bytes(x)) => m.producer = utf8(x)?,
                (7, Field::Bytes(x)) => graph = Some(x),
                (8, Field::Bytes(x)) => {
                    let (mut domain, mut version) = (String::new(), 0i64);
                    each(x, |k, f| {
                        match (k, f) {
                            (1, Field::Bytes(d)) => domain = utf8(d)?,
                            (2, Field::Varint(v)) => version = v as i64,
                            _ => {}
                        }
                        Ok(())
                    })?;
                    if domain.is_empty() || domain == "ai.onnx" {
                        m.opset = version;
                    } else {
                        m.domains.push((domain, version));
                    }
                }
                _ => {}
            }
            Ok(())
        })?;
        let graph = graph.ok_or(ProtoError::Unsupported("no graph".into()))?;
        each(graph, |k, f| {
            if let Field::Bytes(x) = f {
                match k {
                    1 => m.nodes.push(decode_node(x)?),
                    2 => m.graph_name = utf8(x)?,
                    5 => m.initializers.push(decode_init(x)?),
                    11 => m.inputs.push(decode_value_info(x)?),
                    12 => m.outputs.push(decode_value_info(x)?),
                    _ => {}
                }
            }
            Ok(())
        })?;
        // Before IR version 4 the initializers were also listed as graph inputs.
        let consts: std::collections::HashSet<&str> = m.initializers.iter().map(|i| i.name.as_str()).collect();
        let inputs = std::mem::take(&mut m.inputs);
        m.inputs = inputs.into_iter().filter(|v| !consts.contains(v.name.as_str())).collect();
        if m.opset == 0 {
            return Err(ProtoError::Unsupported("no default-domain opset import".into()));
        }
        Ok(m)
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

    #[test]
    fn a_written_model_reads_back_unchanged() {
        let node = |op: &str, i: &[&str], o: &str, attrs: Vec<(String, Attr)>| Node {
            op_type: op.into(),
            name: format!("n_{o}"),
            inputs: i.iter().map(|s| s.to_string()).collect(),
            outputs: vec![o.into()],
            attrs,
            domain: String::new(),
        };
        let m = Model {
            graph_name: "g".into(),
            producer: "test".into(),
            opset: 13,
            domains: vec![("pav".into(), 1)],
            nodes: vec![
                node("Conv", &["x", "w"], "y", vec![("pads".into(), Attr::Ints(vec![1, 1, -1, 1]))]),
                node("LeakyRelu", &["y"], "z", vec![("alpha".into(), Attr::Float(0.1))]),
                node("Resize", &["z", "", "s"], "r", vec![("mode".into(), Attr::Str("nearest".into()))]),
                node(
                    "Foo",
                    &["r"],
                    "out",
                    vec![("f".into(), Attr::Floats(vec![0.5, -2.0])), ("k".into(), Attr::Int(-3))],
                ),
            ],
            initializers: vec![
                Initializer { name: "w".into(), dims: vec![1, 3, 1, 1], data: InitData::F32(vec![1.0, -2.5, 3.0]) },
                Initializer { name: "s".into(), dims: vec![2], data: InitData::I64(vec![-1, 1 << 40]) },
                Initializer { name: "q".into(), dims: vec![3], data: InitData::U8(vec![0, 128, 255]) },
                Initializer { name: "z".into(), dims: vec![2], data: InitData::I8(vec![-128, 127]) },
                Initializer { name: "i".into(), dims: vec![2], data: InitData::I32(vec![i32::MIN, 7]) },
            ],
            inputs: vec![ValueInfo {
                name: "x".into(),
                elem_type: FLOAT,
                dims: vec![Dim::Fixed(1), Dim::Fixed(3), Dim::Symbolic("h".into()), Dim::Fixed(8)],
            }],
            outputs: vec![ValueInfo { name: "out".into(), elem_type: FLOAT, dims: vec![] }],
        };
        let back = Model::from_bytes(&m.to_bytes()).unwrap();
        assert_eq!(format!("{back:?}"), format!("{m:?}"));
    }

    #[test]
    fn broken_bytes_are_refused() {
        let m = Model {
            graph_name: "g".into(),
            producer: "p".into(),
            opset: 13,
            domains: vec![],
            nodes: vec![],
            initializers: vec![],
            inputs: vec![],
            outputs: vec![],
        };
        let b = m.to_bytes();
        assert!(matches!(Model::from_bytes(&b[..b.len() - 1]), Err(ProtoError::Wire(_))));
        assert!(matches!(Model::from_bytes(&[0x0f]), Err(ProtoError::Wire(_))));
    }
}
