//! Darknet network + weights → ONNX graph (opset 13) whose outputs are the raw YOLO head maps.
//!
//! Outputs are named `head0`, `head1`, … in `[yolo]` order, each `[N, A·(5+C), H, W]` logits, so
//! decoding (sigmoid, anchors) stays with the caller and the graph is comparable layer for
//! layer with OpenCV DNN's darknet reader.

use super::cfg::{DarknetActivation, Layer, Network};
use super::weights::Weights;
use super::DarknetError;
use crate::proto::{Attr, Dim, InitData, Initializer, Model, Node, ValueInfo, FLOAT};

/// Name of the graph input.
pub const INPUT_NAME: &str = "images";

/// What [`convert`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Converted {
    /// Layers in the cfg.
    pub layers: usize,
    /// YOLO heads (graph outputs).
    pub heads: usize,
    /// Size of the ONNX file.
    pub bytes: usize,
}

/// Converts the darknet `cfg` + `weights` files to an ONNX file at `out`, written under a
/// temporary name and renamed, so an interrupted conversion never leaves half a model behind.
pub fn convert(
    cfg: &std::path::Path,
    weights: &std::path::Path,
    out: &std::path::Path,
) -> Result<Converted, DarknetError> {
    let net = Network::from_file(cfg)?;
    let w = Weights::from_file(weights, &net)?;
    let model = export(&net, &w)?;
    let bytes = model.to_bytes();
    let io = |path: &std::path::Path| {
        let path = path.to_path_buf();
        move |source| DarknetError::Write { path, source }
    };
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io(dir))?;
    }
    let tmp = out.with_extension("onnx.part");
    std::fs::write(&tmp, &bytes).map_err(io(&tmp))?;
    std::fs::rename(&tmp, out).map_err(io(out))?;
    Ok(Converted { layers: net.layers.len(), heads: model.outputs.len(), bytes: bytes.len() })
}

/// Builds the ONNX model for `net` with `weights`.
pub fn export(net: &Network, weights: &Weights) -> Result<Model, DarknetError> {
    let mut nodes = Vec::new();
    let mut inits = Vec::new();
    let mut names: Vec<String> = Vec::with_capacity(net.layers.len());
    let mut convs = weights.convs.iter();
    let mut outputs = Vec::new();
    // Spatial size per layer, to declare output shapes.
    let (mut h, mut w) = (net.height, net.width);
    let mut sizes: Vec<(usize, usize)> = Vec::new();
    let chans = net.channels_per_layer();
    let node = |op: &str, name: String, inputs: Vec<String>, out: String, attrs: Vec<(String, Attr)>| Node {
        op_type: op.into(),
        name,
        inputs,
        outputs: vec![out],
        attrs,
        domain: String::new(),
    };
    for (i, layer) in net.layers.iter().enumerate() {
        let prev = names.last().cloned().unwrap_or_else(|| INPUT_NAME.to_string());
        let out = format!("l{i}");
        let name = match layer {
            Layer::Conv { size, stride, pad, activation, .. } => {
                let cw = convs.next().filter(|c| c.layer == i).ok_or_else(|| DarknetError::Weights {
                    path: String::new(),
                    msg: format!("no weights for convolution layer {i}"),
                })?;
                let (wn, bn) = (format!("w{i}"), format!("b{i}"));
                inits.push(Initializer {
                    name: wn.clone(),
                    dims: cw.shape.iter().map(|&d| d as i64).collect(),
                    data: InitData::F32(cw.weight.clone()),
                });
                inits.push(Initializer {
                    name: bn.clone(),
                    dims: vec![cw.shape[0] as i64],
                    data: InitData::F32(cw.bias.clone()),
                });
                let (k, s, p) = (*size as i64, *stride as i64, *pad as i64);
                let conv_out =
                    if *activation == DarknetActivation::Linear { out.clone() } else { format!("{out}_conv") };
                nodes.push(node(
                    "Conv",
                    format!("conv{i}"),
                    vec![prev, wn, bn],
                    conv_out.clone(),
                    vec![
                        ("kernel_shape".into(), Attr::Ints(vec![k, k])),
                        ("strides".into(), Attr::Ints(vec![s, s])),
                        ("pads".into(), Attr::Ints(vec![p, p, p, p])),
                    ],
                ));
                if *activation == DarknetActivation::Leaky {
                    nodes.push(node(
                        "LeakyRelu",
                        format!("leaky{i}"),
                        vec![conv_out],
                        out.clone(),
                        vec![("alpha".into(), Attr::Float(0.1))],
                    ));
                }
                h = (h + 2 * pad - size) / stride + 1;
                w = (w + 2 * pad - size) / stride + 1;
                out
            }
            Layer::MaxPool { size, stride } => {
                // Darknet pads size-1 in total, bottom/right first, with values that never win the max.
                let (k, s) = (*size as i64, *stride as i64);
                let total = k - 1;
                let (lo, hi) = (total / 2, total - total / 2);
                nodes.push(node(
                    "MaxPool",
                    format!("pool{i}"),
                    vec![prev],
                    out.clone(),
                    vec![
                        ("kernel_shape".into(), Attr::Ints(vec![k, k])),
                        ("strides".into(), Attr::Ints(vec![s, s])),
                        ("pads".into(), Attr::Ints(vec![lo, lo, hi, hi])),
                    ],
                ));
                h = (h + total as usize - size) / stride + 1;
                w = (w + total as usize - size) / stride + 1;
                out
            }
            Layer::Upsample { stride } => {
                let sc = format!("scales{i}");
                inits.push(Initializer {
                    name: sc.clone(),
                    dims: vec![4],
                    data: InitData::F32(vec![1.0, 1.0, *stride as f32, *stride as f32]),
                });
                nodes.push(node(
                    "Resize",
                    format!("upsample{i}"),
                    vec![prev, String::new(), sc],
                    out.clone(),
                    vec![
                        ("mode".into(), Attr::Str("nearest".into())),
                        ("coordinate_transformation_mode".into(), Attr::Str("asymmetric".into())),
                        ("nearest_mode".into(), Attr::Str("floor".into())),
                    ],
                ));
                h *= stride;
                w *= stride;
                out
            }
            Layer::Route { layers } => {
                (h, w) = sizes[layers[0]];
                if let Some(&bad) = layers.iter().find(|&&l| sizes[l] != (h, w)) {
                    return Err(DarknetError::Unsupported {
                        index: i,
                        kind: "route".into(),
                        msg: format!("layer {bad} is {:?}, layer {} is {:?}", sizes[bad], layers[0], (h, w)),
                    });
                }
                if layers.len() == 1 {
                    names[layers[0]].clone()
                } else {
                    nodes.push(node(
                        "Concat",
                        format!("route{i}"),
                        layers.iter().map(|&l| names[l].clone()).collect(),
                        out.clone(),
                        vec![("axis".into(), Attr::Int(1))],
                    ));
                    out
                }
            }
            Layer::Yolo(head) => {
                let expect = head.anchors.len() * (5 + head.classes);
                let got = chans[i.saturating_sub(1)];
                if i == 0 || got != expect {
                    return Err(DarknetError::Unsupported {
                        index: i,
                        kind: "yolo".into(),
                        msg: format!(
                            "input has {got} channels, {} anchors × (5+{}) = {expect} expected",
                            head.anchors.len(),
                            head.classes
                        ),
                    });
                }
                let out_name = format!("head{}", outputs.len());
                nodes.push(node("Identity", format!("yolo{i}"), vec![prev.clone()], out_name.clone(), vec![]));
                outputs.push(ValueInfo {
                    name: out_name,
                    elem_type: FLOAT,
                    dims: vec![
                        Dim::Symbolic("N".into()),
                        Dim::Fixed(expect as i64),
                        Dim::Symbolic(format!("H/{}", net.height / h)),
                        Dim::Symbolic(format!("W/{}", net.width / w)),
                    ],
                });
                prev
            }
        };
        names.push(name);
        sizes.push((h, w));
    }
    if outputs.is_empty() {
        return Err(DarknetError::Unsupported {
            index: net.layers.len(),
            kind: "net".into(),
            msg: "no [yolo] layer".into(),
        });
    }
    Ok(Model {
        graph_name: "darknet".into(),
        producer: format!("pav {}", env!("CARGO_PKG_VERSION")),
        opset: 13,
        domains: vec![],
        nodes,
        initializers: inits,
        inputs: vec![ValueInfo {
            name: INPUT_NAME.into(),
            elem_type: FLOAT,
            // Spatial size is symbolic: the network is fully convolutional with anchors in pixels,
            // so any multiple of its total stride works (320, 416, 608, ...).
            dims: vec![
                Dim::Symbolic("N".into()),
                Dim::Fixed(net.channels as i64),
                Dim::Symbolic("H".into()),
                Dim::Symbolic("W".into()),
            ],
        }],
        outputs,
    })
}
