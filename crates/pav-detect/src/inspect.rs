//! `pav-rig model inspect`: what an ONNX detector takes and gives (names, element types, shapes,
//! opset, operators), the output shapes of one run on a blank image, a guess at which of pav's
//! output layouts it follows, and a detector-config skeleton to complete.

use pav_onnx::proto::{Dim, Model, ProtoError, ValueInfo, FLOAT, INT64};
use std::collections::BTreeMap;
use std::path::Path;

/// One graph input or output.
#[derive(Clone, Debug, PartialEq)]
pub struct Port {
    /// Its name.
    pub name: String,
    /// Element type ("float32", "int64", …).
    pub dtype: String,
    /// Dimensions as declared: a number, or the symbol's name.
    pub declared: Vec<String>,
    /// Dimensions of one run on a blank image (outputs, after [`Inspection::probe`]).
    pub ran: Option<Vec<usize>>,
}

/// What a model file says about itself.
#[derive(Clone, Debug)]
pub struct Inspection {
    /// Who exported it.
    pub producer: String,
    /// Default-domain opset.
    pub opset: i64,
    /// Further operator sets.
    pub domains: Vec<(String, i64)>,
    /// Operator counts.
    pub ops: BTreeMap<String, usize>,
    /// Inputs (initializers excluded).
    pub inputs: Vec<Port>,
    /// Outputs.
    pub outputs: Vec<Port>,
}

/// pav's guess at a model's output layout.
#[derive(Clone, Debug, PartialEq)]
pub struct Guess {
    /// A layout pav decodes (`darknet`, `yolox`, `ultralytics`, `detr`, `gfl`, `rows`, or
    /// `custom` for one to describe), or None.
    pub layout: Option<&'static str>,
    /// What in the shapes led to it.
    pub why: String,
}

fn dtype(code: i32) -> String {
    match code {
        FLOAT => "float32".into(),
        INT64 => "int64".into(),
        2 => "uint8".into(),
        3 => "int8".into(),
        6 => "int32".into(),
        10 => "float16".into(),
        0 => "?".into(),
        other => format!("type {other}"),
    }
}

fn port(v: &ValueInfo) -> Port {
    Port {
        name: v.name.clone(),
        dtype: dtype(v.elem_type),
        declared: v
            .dims
            .iter()
            .map(|d| match d {
                Dim::Fixed(n) => n.to_string(),
                Dim::Symbolic(s) if s.is_empty() => "?".into(),
                Dim::Symbolic(s) => s.clone(),
            })
            .collect(),
        ran: None,
    }
}

impl Inspection {
    /// Reads a model's bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Inspection, ProtoError> {
        let m = Model::from_bytes(bytes)?;
        let inits: std::collections::HashSet<&str> = m.initializers.iter().map(|i| i.name.as_str()).collect();
        let mut ops = BTreeMap::new();
        for n in &m.nodes {
            *ops.entry(n.op_type.clone()).or_insert(0) += 1;
        }
        Ok(Inspection {
            producer: m.producer.clone(),
            opset: m.opset,
            domains: m.domains.clone(),
            ops,
            inputs: m.inputs.iter().filter(|i| !inits.contains(i.name.as_str())).map(port).collect(),
            outputs: m.outputs.iter().map(port).collect(),
        })
    }

    /// The image input: the first 4-D float input.
    pub fn image_input(&self) -> Option<&Port> {
        self.inputs.iter().find(|p| p.dtype == "float32" && p.declared.len() == 4)
    }

    /// The image input's side when fixed (its height).
    pub fn fixed_side(&self) -> Option<usize> {
        self.image_input().and_then(|p| p.declared[2].parse().ok())
    }

    /// Output shapes: the run's when probed, else the declared fixed ones.
    fn shape(&self, p: &Port) -> Option<Vec<usize>> {
        p.ran.clone().or_else(|| p.declared.iter().map(|d| d.parse().ok()).collect())
    }

    /// Guesses the layout from the output shapes, for an image side `side`.
    pub fn guess(&self, side: usize) -> Guess {
        let shapes: Vec<(&Port, Option<Vec<usize>>)> = self.outputs.iter().map(|p| (p, self.shape(p))).collect();
        let g = |layout: Option<&'static str>, why: String| Guess { layout, why };
        if shapes.iter().any(|(_, s)| s.is_none()) {
            return g(
                None,
                "some output shapes are symbolic: run `model inspect` with ONNX Runtime (the default) to see them"
                    .into(),
            );
        }
        // Exports without a batch dimension (`[1600, 80]`) read as batch 1.
        let shapes: Vec<(&Port, Vec<usize>)> = shapes
            .into_iter()
            .map(|(p, s)| {
                let s = s.unwrap_or_default();
                (p, if s.len() == 2 && p.dtype == "float32" { [&[1][..], &s].concat() } else { s })
            })
            .collect();
        let rows = |strides: &[usize]| strides.iter().map(|s| (side / s) * (side / s)).sum::<usize>();
        let has_int = shapes.iter().any(|(p, _)| p.dtype == "int64");
        let box4 = shapes.iter().any(|(_, s)| s.last() == Some(&4));
        if has_int && box4 && shapes.len() >= 3 {
            return g(
                Some("detr"),
                "an int64 output (labels) beside a [.., 4] output (boxes) and scores: DETR-style per-query detections"
                    .into(),
            );
        }
        if shapes.len() == 1 {
            let s = &shapes[0].1;
            if s.len() == 3 {
                let (a, b) = (s[1], s[2]);
                if a == rows(&[8, 16, 32]) && b > 5 {
                    return g(Some("yolox"), format!("one [1, {a}, {b}] output: {a} rows = the grid cells of strides 8, 16, 32 at {side}², {b} = 4 box + objectness + {} classes", b - 5));
                }
                if b == rows(&[8, 16, 32]) && a > 4 {
                    return g(Some("ultralytics"), format!("one [1, {a}, {b}] output: {b} columns = the grid cells of strides 8, 16, 32 at {side}², {a} = 4 box + {} classes, no objectness", a - 4));
                }
            }
            if let Some((strides, anchors)) =
                (s.len() == 3 && s[2] > 5).then(|| flattened_anchors(side, s[1])).flatten()
            {
                return g(
                    Some("custom"),
                    format!(
                        "one [1, {}, {}] output: {} rows = {anchors} anchors × the grid cells of strides {strides:?} at {side}², {} = 4 box + objectness + {} classes: anchor-based rows flattened into one matrix (YOLOv5's export)",
                        s[1],
                        s[2],
                        s[1],
                        s[2],
                        s[2] - 5
                    ),
                );
            }
        }
        let grid = |h: usize, w: usize| h == w && h > 0 && side % h == 0 && h * 64 >= side;
        if let [(_, s)] = shapes.as_slice() {
            if s.len() == 4 && grid(s[2], s[3]) && s[1] > 5 && !(s[1] % 3 == 0 && s[1] / 3 > 5) {
                return g(
                    Some("custom"),
                    format!(
                        "one [1, {}, {h}, {h}] map of stride {}: an anchor-free grid of objectness, 4 box values and {} classes per cell (FastestDet's head)",
                        s[1],
                        side / s[2],
                        s[1] - 5,
                        h = s[2]
                    ),
                );
            }
        }
        if shapes.iter().all(|(_, s)| s.len() == 4 && grid(s[1], s[2]) && s[3] > 15 && s[3] == shapes[0].1[3]) {
            let k = shapes[0].1[3];
            return g(
                Some("custom"),
                format!(
                    "{} [1, H, W, {k}] grids with channels last: per cell several anchors' boxes side by side, an objectness per anchor and one class block they share (YOLO-FastestV2's head: {k} = 3 × (4 box + 1 objectness) + {} classes)",
                    shapes.len(),
                    k - 15
                ),
            );
        }
        if shapes.iter().all(|(_, s)| s.len() == 4 && s[2] * 32 >= side && side % s[2] == 0)
            && shapes.iter().all(|(_, s)| s[1] % 3 == 0 && s[1] / 3 > 5)
        {
            let c = shapes[0].1[1] / 3 - 5;
            return g(
                Some("darknet"),
                format!(
                    "{} [1, 3·(5+{c}), H, W] heads: darknet YOLO with 3 anchors per cell, raw logits",
                    shapes.len()
                ),
            );
        }
        if shapes.iter().any(|(_, s)| six_wide(s)) {
            return g(Some("rows"), "an [N, 6] output (class, score, box per row, likely with a count output): detections after an NMS inside the graph".into());
        }
        if let Some((b, sc)) = self.ssd_outputs() {
            return g(
                Some("custom"),
                format!(
                    "separate boxes `{}` [.., N, 4] and scores `{}` [.., N, {}] per proposal: SSD-style offsets from prior boxes",
                    b.name,
                    sc.name,
                    self.shape(sc).and_then(|s| s.last().copied()).unwrap_or(0)
                ),
            );
        }
        let per_cell: Vec<usize> = shapes.iter().filter(|(_, s)| s.len() == 3).map(|(_, s)| s[1]).collect();
        if !per_cell.is_empty() && per_cell.iter().sum::<usize>() % rows(&[8, 16, 32]) == 0 {
            let widths: Vec<usize> = shapes.iter().filter(|(_, s)| s.len() == 3).map(|(_, s)| s[2]).collect();
            if widths.iter().any(|w| w % 4 == 0 && *w > 4 && *w <= 64) {
                return g(Some("gfl"), format!("outputs per grid level of strides 8, 16, 32 with widths {widths:?}: a class map and a box map of 4 binned distances (GFL head, as NanoDet)"));
            }
        }
        g(
            None,
            format!(
                "output shapes {:?} match none of pav's layouts",
                shapes.iter().map(|(_, s)| s.clone()).collect::<Vec<_>>()
            ),
        )
    }

    /// A detector config to complete: the input from the model, the output from the guess.
    pub fn skeleton(&self, name: &str, model: &str, side: usize, guess: &Guess) -> String {
        let mut t = format!(
            "# Completed from `pav-rig model inspect`: check every value marked CHECK against the model's\n# upstream demo code.\nname = \"{name}\"\ndescription = \"{}{}\"\nmodel = \"{model}\"\n\n[input]\n",
            if self.producer.is_empty() { "ONNX model".to_string() } else { format!("exported by {}", self.producer) },
            if self.opset > 0 { format!(", opset {}", self.opset) } else { String::new() }
        );
        if let Some(p) = self.image_input() {
            t.push_str(&format!("name = \"{}\"\n", p.name));
        }
        // A float input beside the image of a rows model: a graph that maps its boxes back itself
        // by scale alone, which a stretched input keeps exact.
        let scale_input = self
            .inputs
            .iter()
            .find(|p| p.dtype == "float32" && Some(p.name.as_str()) != self.image_input().map(|i| i.name.as_str()))
            .filter(|_| guess.layout == Some("rows"));
        let resize = if scale_input.is_some() { "stretch" } else { "letterbox" };
        t.push_str(&format!(
            "width = {side}\nheight = {side}\nchannels = \"rgb\"        # CHECK: rgb or bgr\nscale = 0.00392156862745098   # CHECK: 1/255, or 1.0 with mean and std\nresize = \"{resize}\"      # CHECK: letterbox or stretch\ninterpolation = \"bilinear\"\npad_value = 114\n"
        ));
        if let Some(p) = scale_input {
            t.push_str(&format!("\n[[input.extra]]\nname = \"{}\"\nvalue = \"scale_yx\"     # CHECK: [input/frame height, input/frame width]\n", p.name));
        }
        t.push_str("\n[output]\n");
        match guess.layout {
            Some("detr") => {
                let find = |dt: &str, last: Option<usize>| {
                    self.outputs
                        .iter()
                        .find(|p| {
                            p.dtype == dt
                                && last.is_none_or(|l| self.shape(p).and_then(|s| s.last().copied()) == Some(l))
                        })
                        .map(|p| p.name.clone())
                        .unwrap_or_default()
                };
                let boxes = find("float32", Some(4));
                let scores = self
                    .outputs
                    .iter()
                    .find(|p| p.dtype == "float32" && p.name != boxes)
                    .map(|p| p.name.clone())
                    .unwrap_or_default();
                t.push_str(&format!(
                    "layout = \"detr\"\nlabels = \"{}\"\nboxes = \"{boxes}\"\nscores = \"{scores}\"\n",
                    find("int64", None)
                ));
                if let Some(s) = self.inputs.iter().find(|p| p.dtype == "int64") {
                    t.push_str(&format!("size_input = \"{}\"\n", s.name));
                }
            }
            Some("darknet") => {
                t.push_str("layout = \"darknet\"\n");
                for p in &self.outputs {
                    t.push_str(&format!("[[output.heads]]\noutput = \"{}\"\nanchors = []      # CHECK: the cfg's anchors of this head, [[w, h], ...] in input pixels\n", p.name));
                }
            }
            Some("rows") => {
                let rows = self
                    .outputs
                    .iter()
                    .find(|p| self.shape(p).is_some_and(|s| six_wide(&s)))
                    .map(|p| p.name.clone())
                    .unwrap_or_default();
                let frame = if scale_input.is_some() { "image" } else { "input" };
                t.push_str(&format!("layout = \"rows\"\noutput = \"{rows}\"\ncolumns = [\"class\", \"score\", \"x1\", \"y1\", \"x2\", \"y2\"]   # CHECK: the upstream post-processor's order\nframe = \"{frame}\"      # CHECK: image (boxes in frame pixels) or input\n"));
            }
            Some("custom") if guess.why.contains("FastestDet") => {
                let (name, stride) = (&self.outputs[0].name, self.shape(&self.outputs[0]).map_or(0, |s| side / s[2].max(1)));
                let part = format!("output = [\"{name}\"]\narrange = \"planes\"\nper_level = true\n");
                t.push_str(&format!(
                    "layout = \"custom\"\n# FastestDet's head: per cell objectness, 4 box values, then the class scores (CHECK\n# against the upstream post-processor: centre offsets through tanh, sizes as shares of\n# the input through a sigmoid, scores obj^0.6 · cls^0.4, obj and classes already\n# activated in the graph).\n[[output.levels]]\nstride = {stride}\n\n[output.boxes]\n{part}column = 1\nencoding = \"tanh-share\"\n\n[output.objectness]\n{part}column = 0\npower = 0.6\n\n[output.scores]\n{part}column = 5\npower = 0.4\n"
                ));
            }
            Some("custom") if guess.why.contains("YOLO-FastestV2") => {
                let names = self.outputs.iter().map(|p| format!("\"{}\"", p.name)).collect::<Vec<_>>().join(", ");
                t.push_str("layout = \"custom\"\norder = \"in-row\"     # each cell's row holds its three anchors side by side\n# CHECK: one level per output, with its stride and three anchors [w, h] in input pixels,\n# from the model's config.\n");
                for p in &self.outputs {
                    let stride = self.shape(p).map_or(0, |s| side / s[1].max(1));
                    t.push_str(&format!("[[output.levels]]\nstride = {stride}\nanchors = []\n"));
                }
                let part = format!("output = [{names}]\nper_level = true\n");
                t.push_str(&format!(
                    "\n[output.boxes]\n{part}encoding = \"yolov5\"\nactivated = true     # CHECK: the export applies the sigmoid\nanchor_step = 4\n\n[output.objectness]\n{part}column = 12\nanchor_step = 1\npower = 0.6          # CHECK: the upstream score rule\n\n[output.scores]\n{part}column = 15\npower = 0.4\n"
                ));
            }
            Some("custom") => match self.ssd_outputs() {
                Some((b, sc)) => t.push_str(&format!(
                    "layout = \"custom\"\norder = \"cell-anchor\"     # CHECK: SSD's rows go cell by cell, each cell's priors together\n# CHECK: one level per feature map, with its stride and prior sizes [w, h] in input pixels,\n# from the model's anchor generator.\n[[output.levels]]\nstride = 16\nanchors = []\n\n[output.boxes]\noutput = \"{}\"\nencoding = \"prior\"\nvariances = [0.1, 0.2]     # CHECK: the box coder's scales\n# coords = [1, 0, 3, 2]      # CHECK: TensorFlow's exports give ty, tx, th, tw\n\n[output.scores]\noutput = \"{}\"\nactivation = \"softmax\"     # CHECK: softmax, sigmoid or none\nbackground = 0             # CHECK: the background column, if any\n",
                    b.name, sc.name
                )),
                None => t.push_str(&format!(
                    "layout = \"custom\"\n# Rows (cx, cy, w, h, objectness, classes), already decoded to input pixels as YOLOv5's\n# export writes them. CHECK: raw logits instead (values far outside the input) need\n# encoding = \"yolov5\", [[output.levels]] with strides and anchors, and activation = \"sigmoid\".\n[output.boxes]\noutput = \"{}\"\nencoding = \"cxcywh\"\n\n[output.objectness]\noutput = \"{0}\"\ncolumn = 4\n\n[output.scores]\noutput = \"{0}\"\ncolumn = 5\n",
                    self.outputs[0].name
                )),
            },
            Some("gfl") => {
                let bins = self.outputs.iter().filter_map(|p| self.shape(p)?.last().copied()).min().unwrap_or(32) / 4;
                t.push_str(&format!("layout = \"gfl\"\nstrides = [8, 16, 32]\nbins = {bins}\n"));
            }
            Some(l) => t.push_str(&format!("layout = \"{l}\"\noutput = \"{}\"\n", self.outputs[0].name)),
            None => t.push_str(&format!("# {}\nlayout = \"\"   # CHECK: no layout of pav's fits\n", guess.why)),
        }
        t.push_str("\n[classes]\nnames = \"coco80\"\ntarget = [\"car\"]\n");
        t
    }
}

/// Rows of six values, `[N, 6]` or `[1, N, 6]`: detections after an NMS.
fn six_wide(s: &[usize]) -> bool {
    s.len() >= 2 && s[s.len() - 1] == 6 && s[..s.len() - 2].iter().all(|d| *d == 1)
}

/// The strides (a run of two or more of 8, 16, 32, 64) and anchors per cell (2 to 9) whose grids
/// at `side` hold exactly `rows` rows, if any.
fn flattened_anchors(side: usize, rows: usize) -> Option<(Vec<usize>, usize)> {
    let all = [8, 16, 32, 64];
    for anchors in 2..=9 {
        for from in 0..all.len() {
            for to in from + 2..=all.len() {
                let strides = &all[from..to];
                if anchors * strides.iter().map(|s| (side / s) * (side / s)).sum::<usize>() == rows {
                    return Some((strides.to_vec(), anchors));
                }
            }
        }
    }
    None
}

impl Inspection {
    /// Exactly two float outputs holding a box and a score row per proposal, `[.., N, 4]` and
    /// `[.., N, K ≥ 2]`: SSD's.
    fn ssd_outputs(&self) -> Option<(&Port, &Port)> {
        let float: Vec<(&Port, Vec<usize>)> = self
            .outputs
            .iter()
            .filter(|p| p.dtype == "float32")
            .filter_map(|p| Some((p, self.shape(p)?)))
            .filter(|(_, s)| s.len() >= 2)
            .collect();
        if float.len() != 2 || self.outputs.len() != 2 {
            return None;
        }
        let rows = |s: &[usize]| s[s.len() - 2];
        let (b, sc) = if float[0].1.last() == Some(&4) { (&float[0], &float[1]) } else { (&float[1], &float[0]) };
        (b.1.last() == Some(&4) && rows(&b.1) == rows(&sc.1) && sc.1.last().is_some_and(|k| *k >= 2))
            .then_some((b.0, sc.0))
    }
}

/// A blank image of side `side` for the model's image input, and a plausible constant for each
/// other input (an int64 size input the side, a float input of two values the scale 1).
#[cfg(feature = "eval")]
fn blank_feed(
    insp: &Inspection,
    side: usize,
    err: impl Fn(ort::Error) -> super::DetectError + Copy,
) -> Result<Vec<(String, ort::session::SessionInputValue<'static>)>, super::DetectError> {
    use ort::value::Tensor;
    let image = insp.image_input().map(|p| p.name.clone());
    let mut feed: Vec<(String, ort::session::SessionInputValue<'static>)> = Vec::new();
    for p in &insp.inputs {
        let dims: Vec<usize> = p
            .declared
            .iter()
            .enumerate()
            .map(|(i, d)| d.parse().unwrap_or(if Some(&p.name) == image.as_ref() && i >= 2 { side } else { 1 }))
            .collect();
        let n: usize = dims.iter().product();
        let value: ort::session::SessionInputValue<'static> = if p.dtype == "int64" {
            Tensor::from_array((dims, vec![side as i64; n])).map_err(err)?.into()
        } else if Some(&p.name) == image.as_ref() {
            Tensor::from_array((dims, vec![0.5f32; n])).map_err(err)?.into()
        } else {
            Tensor::from_array((dims, vec![1f32; n])).map_err(err)?.into()
        };
        feed.push((p.name.clone(), value));
    }
    Ok(feed)
}

/// Runs the model once on a blank image of side `side` ([`blank_feed`]) and records each
/// output's shape.
#[cfg(feature = "eval")]
pub fn probe(model: &Path, insp: &mut Inspection, side: usize) -> Result<(), super::DetectError> {
    let name = model.display().to_string();
    let err = super::onnx::session_err(&name, "probing the model");
    let mut session = pav_onnx::runtime::session_builder(&name, 1)?
        .commit_from_file(model)
        .map_err(super::onnx::session_err(&name, "loading the ONNX model"))?;
    let outputs = session.run(blank_feed(insp, side, &err)?).map_err(&err)?;
    for (oname, value) in outputs.iter() {
        if let ort::value::ValueType::Tensor { shape, .. } = value.dtype() {
            if let Some(p) = insp.outputs.iter_mut().find(|p| p.name == oname) {
                p.ran = Some(shape.iter().map(|&d| d.max(0) as usize).collect());
            }
        }
    }
    Ok(())
}

/// One value a graph computes: what a description may name inside the graph (the scores and
/// boxes a post-processor reads, the logits before a top-k).
#[derive(Clone, Debug, PartialEq)]
pub struct Value {
    /// Its name.
    pub name: String,
    /// The operator that computes it.
    pub op: String,
    /// Its shape in one run on a blank image.
    pub shape: Vec<usize>,
}

/// Every tensor value the graph computes, in node order, with its shape in one run on a blank
/// image of side `side`.
#[cfg(feature = "eval")]
pub fn values(model: &Path, insp: &Inspection, side: usize) -> Result<Vec<Value>, super::DetectError> {
    use pav_onnx::proto::{Model, ValueInfo};
    let name = model.display().to_string();
    let unread = |msg: String| super::DetectError::Model { detector: name.clone(), path: name.clone(), msg };
    let bytes = std::fs::read(model).map_err(|e| unread(format!("cannot be read: {e}")))?;
    let mut m = Model::from_bytes(&bytes).map_err(|e| unread(format!("is no ONNX graph pav reads: {e}")))?;
    let made: Vec<(String, String)> = m
        .nodes
        .iter()
        .filter(|n| n.op_type != "Constant")
        .flat_map(|n| n.outputs.iter().filter(|o| !o.is_empty()).map(|o| (o.clone(), n.op_type.clone())))
        .collect();
    m.outputs = made.iter().map(|(o, _)| ValueInfo { name: o.clone(), elem_type: 0, dims: vec![] }).collect();
    let err = super::onnx::session_err(&name, "running the graph for its values");
    let mut session = pav_onnx::runtime::session_builder(&name, 1)?
        .commit_from_memory(&m.to_bytes())
        .map_err(super::onnx::session_err(&name, "loading the ONNX model"))?;
    let outputs = session.run(blank_feed(insp, side, &err)?).map_err(&err)?;
    let mut out = Vec::new();
    for (value, op) in made {
        let Some(v) = outputs.get(value.as_str()) else { continue };
        if let ort::value::ValueType::Tensor { shape, .. } = v.dtype() {
            out.push(Value { name: value, op, shape: shape.iter().map(|&d| d.max(0) as usize).collect() });
        }
    }
    Ok(out)
}

/// What ONNX Runtime reports of a model's inputs and outputs, for a graph pav's own reader does
/// not parse (opset and operators then unknown).
#[cfg(feature = "eval")]
pub fn from_session(model: &Path) -> Result<Inspection, super::DetectError> {
    use ort::value::{TensorElementType as T, ValueType};
    let name = model.display().to_string();
    let session = pav_onnx::runtime::session_builder(&name, 1)?
        .commit_from_file(model)
        .map_err(super::onnx::session_err(&name, "loading the ONNX model"))?;
    let port = |n: &str, t: &ValueType| {
        let (dtype, declared) = match t {
            ValueType::Tensor { ty, shape, dimension_symbols } => (
                match ty {
                    T::Float32 => "float32".to_string(),
                    T::Int64 => "int64".to_string(),
                    T::Int32 => "int32".to_string(),
                    other => format!("{other:?}"),
                },
                shape
                    .iter()
                    .zip(dimension_symbols.iter())
                    .map(|(d, s)| {
                        if *d >= 0 {
                            d.to_string()
                        } else if s.is_empty() {
                            "?".into()
                        } else {
                            s.to_string()
                        }
                    })
                    .collect(),
            ),
            other => (format!("{other:?}"), Vec::new()),
        };
        Port { name: n.to_string(), dtype, declared, ran: None }
    };
    Ok(Inspection {
        producer: String::new(),
        opset: 0,
        domains: Vec::new(),
        ops: BTreeMap::new(),
        inputs: session.inputs().iter().map(|i| port(i.name(), i.dtype())).collect(),
        outputs: session.outputs().iter().map(|o| port(o.name(), o.dtype())).collect(),
    })
}

/// Reads and inspects a model file (without running it).
pub fn inspect_file(model: &Path) -> Result<Inspection, String> {
    let bytes = std::fs::read(model).map_err(|e| format!("{}: {e}", model.display()))?;
    Inspection::from_bytes(&bytes).map_err(|e| format!("{}: {e}", model.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(outputs: &[(&str, &[usize])]) -> Inspection {
        let port = |(n, s): &(&str, &[usize])| Port {
            name: n.to_string(),
            dtype: "float32".into(),
            declared: s.iter().map(|d| d.to_string()).collect(),
            ran: None,
        };
        Inspection {
            producer: String::new(),
            opset: 17,
            domains: Vec::new(),
            ops: BTreeMap::new(),
            inputs: vec![port(&("images", &[1, 3, 640, 640]))],
            outputs: outputs.iter().map(port).collect(),
        }
    }

    #[test]
    fn exports_of_other_layouts_are_named_for_what_they_are() {
        let g = model(&[("output0", &[1, 25200, 85])]).guess(640);
        assert_eq!(g.layout, Some("custom"));
        assert!(g.why.contains("3 anchors × the grid cells of strides [8, 16, 32] at 640²"), "{}", g.why);
        // YOLOX's anchor-free rows stay YOLOX.
        assert_eq!(model(&[("output", &[1, 8400, 85])]).guess(640).layout, Some("yolox"));
        // Ultralytics' export with NMS appended: [1, 300, 6].
        assert_eq!(model(&[("output0", &[1, 300, 6])]).guess(640).layout, Some("rows"));
        let g = model(&[("scores", &[1, 1917, 91]), ("boxes", &[1, 1917, 4])]).guess(300);
        assert!(g.layout == Some("custom") && g.why.contains("`boxes` [.., N, 4]"), "{}", g.why);
        let t = model(&[("scores", &[1, 1917, 91]), ("boxes", &[1, 1917, 4])]).skeleton("m", "m.onnx", 300, &g);
        assert!(t.contains("encoding = \"prior\"") && t.contains("output = \"scores\""), "{t}");
    }
}
