//! ONNX Runtime backend: any ONNX detector described by a [`DetectorConfig`].

use super::config::{DetectorConfig, OutputLayout};
use super::config::{ExtraInput, ExtraValue, InputConfig};
use super::decode::{decode_described, LayoutError, Proposals, RawOutput};
use super::defence::clip_graph;
use super::layout::Description;
use super::preprocess::InputMap;
use super::{DetectError, Detector};
use ort::session::Session;
use ort::value::{Tensor, TensorElementType, ValueType};
use pav_onnx::proto::Model;
use pav_onnx::runtime::session_builder;
use pav_onnx::surrogate::dequantize;

/// Wraps an ONNX Runtime error of detector `name` while doing `what`.
pub(crate) fn session_err<'a, E: Into<ort::Error>>(
    name: &'a str,
    what: &'static str,
) -> impl Fn(E) -> DetectError + 'a {
    move |e| DetectError::Session { detector: name.to_string(), what, source: e.into() }
}

/// A detector running an ONNX model through ONNX Runtime.
pub struct OnnxDetector {
    cfg: DetectorConfig,
    session: Session,
    input_name: String,
    /// The inputs beside the image: the config's, and a DETR's target size.
    extra: Vec<ExtraInput>,
    /// The config's output layout as a description, built once rather than per frame.
    layout: Description,
    /// Intra-op threads asked for at load, so a replica gets the same.
    threads: usize,
}

impl OnnxDetector {
    /// Loads the model named by `cfg` with `threads` intra-op threads (0 = runtime default).
    pub fn new(cfg: DetectorConfig, threads: usize) -> Result<Self, DetectError> {
        let model_err =
            |msg: String| DetectError::Model { detector: cfg.name.clone(), path: cfg.model.display().to_string(), msg };
        if !cfg.model.is_file() {
            return Err(model_err(format!(
                "does not exist (from {}{})",
                cfg.source.display(),
                if cfg.model.to_string_lossy().contains(".deps") { "; run scripts/setup.sh" } else { "" }
            )));
        }
        let mut builder = session_builder(&cfg.name, threads)?
            // evaluate decodes and prepares the next frame on another thread meanwhile: a pool
            // spinning between runs would take its core.
            .with_intra_op_spinning(false)
            .map_err(session_err(&cfg.name, "turning spinning off"))?;
        let session = match defended_graph(&cfg)? {
            Some(bytes) => builder.commit_from_memory(&bytes),
            None => builder.commit_from_file(&cfg.model),
        }
        .map_err(session_err(&cfg.name, "loading the ONNX model"))?;
        let names: Vec<String> = session.inputs().iter().map(|i| i.name().to_string()).collect();
        let mut extra = cfg.input.extra.clone();
        if let OutputLayout::Detr { size_input: Some(s), .. } = &cfg.output {
            extra.push(ExtraInput { name: s.clone(), value: ExtraValue::SizeWh });
        }
        let fed_apart = |n: &String| extra.iter().any(|e| &e.name == n);
        let input_name = match &cfg.input.name {
            Some(n) if names.contains(n) => n.clone(),
            Some(n) => return Err(model_err(format!("has no input `{n}` (inputs: {})", names.join(", ")))),
            None => names.iter().find(|n| !fed_apart(n)).cloned().ok_or_else(|| model_err("has no inputs".into()))?,
        };
        if let Some(e) = extra.iter().find(|e| !names.contains(&e.name)) {
            let what = match e.value {
                ExtraValue::ScaleYx => "the scale factor",
                ExtraValue::SizeWh => "the target size",
            };
            return Err(model_err(format!("has no input `{}` for {what} (inputs: {})", e.name, names.join(", "))));
        }
        let unfed: Vec<&String> = names.iter().filter(|n| **n != input_name && !fed_apart(n)).collect();
        if !unfed.is_empty() {
            return Err(model_err(format!("has inputs the config does not feed: {unfed:?}")));
        }
        let layout = cfg.output.describe(cfg.class_names.len());
        let mut det = OnnxDetector { cfg, session, input_name, extra, layout, threads };
        det.check_layout()?;
        Ok(det)
    }

    /// Decodes one run on a blank input, so that an output layout that does not fit the model
    /// is refused when it loads rather than at its first frame.
    fn check_layout(&mut self) -> Result<(), DetectError> {
        let (w, h) = (self.cfg.input.width, self.cfg.input.height);
        let map = InputMap::identity(w, h);
        let raw = self.infer(vec![0.0; 3 * w * h], &map)?;
        self.decode(&raw, &map).map(|_| ())
    }

    /// The proposals in one run's outputs, boxes mapped by `map`.
    fn decode(&self, raw: &[RawOutput], map: &InputMap) -> Result<Proposals, DetectError> {
        let c = &self.cfg;
        decode_described(&self.layout, raw, c.input.width, c.input.height, c.class_names.len(), map)
            .map_err(|source| DetectError::Output { detector: c.name.clone(), source })
    }

    /// Whether the model accepts any input height and width (symbolic spatial dimensions).
    pub fn accepts_any_size(&self) -> bool {
        self.session.inputs().iter().find(|i| i.name() == self.input_name).is_some_and(|i| match i.dtype() {
            ValueType::Tensor { shape, .. } => shape.len() == 4 && shape[2] < 0 && shape[3] < 0,
            _ => false,
        })
    }

    /// The config this detector was built from.
    pub fn config(&self) -> &DetectorConfig {
        &self.cfg
    }

    /// Runs the model on an already prepared NCHW input (of a frame `map` maps back to) and
    /// returns its raw outputs.
    pub fn infer(&mut self, input: Vec<f32>, map: &InputMap) -> Result<Vec<RawOutput>, DetectError> {
        let (w, h) = (self.cfg.input.width, self.cfg.input.height);
        let name = self.cfg.name.clone();
        let inf_err = |source| DetectError::Session { detector: name.clone(), what: "inference", source };
        let image = Tensor::from_array(([1usize, 3, h, w], input)).map_err(inf_err)?;
        let mut feed: Vec<(String, ort::session::SessionInputValue<'_>)> =
            vec![(self.input_name.clone(), image.into())];
        for e in &self.extra {
            let value: ort::session::SessionInputValue<'_> = match e.value {
                ExtraValue::ScaleYx => {
                    Tensor::from_array(([1usize, 2], vec![map.scale_y, map.scale_x])).map_err(inf_err)?.into()
                }
                ExtraValue::SizeWh => {
                    Tensor::from_array(([1usize, 2], vec![w as i64, h as i64])).map_err(inf_err)?.into()
                }
            };
            feed.push((e.name.clone(), value));
        }
        let outputs = self.session.run(feed).map_err(inf_err)?;
        let mut raw = Vec::with_capacity(outputs.len());
        for (oname, value) in outputs.iter() {
            let shape_of = |s: &[i64]| s.iter().map(|&d| d.max(0) as usize).collect::<Vec<_>>();
            let out = match value.dtype() {
                ValueType::Tensor { ty: TensorElementType::Float32, .. } => {
                    let (s, d) = value.try_extract_tensor::<f32>().map_err(inf_err)?;
                    RawOutput { name: oname.to_string(), shape: shape_of(s), data: d.to_vec() }
                }
                ValueType::Tensor { ty: TensorElementType::Int32, .. } => {
                    let (s, d) = value.try_extract_tensor::<i32>().map_err(inf_err)?;
                    RawOutput {
                        name: oname.to_string(),
                        shape: shape_of(s),
                        data: d.iter().map(|&v| v as f32).collect(),
                    }
                }
                ValueType::Tensor { ty: TensorElementType::Int64, .. } => {
                    let (s, d) = value.try_extract_tensor::<i64>().map_err(inf_err)?;
                    RawOutput {
                        name: oname.to_string(),
                        shape: shape_of(s),
                        data: d.iter().map(|&v| v as f32).collect(),
                    }
                }
                other => {
                    return Err(DetectError::Output {
                        detector: name,
                        source: LayoutError(format!(
                            "output `{oname}` has type {other:?}; only float32, int32 and int64 tensors are read"
                        )),
                    })
                }
            };
            raw.push(out);
        }
        Ok(raw)
    }
}

/// The model of `cfg` with its model-side defences rewritten in (an int8 model first replaced by
/// its float surrogate), as ONNX bytes; `None` when it has none.
fn defended_graph(cfg: &DetectorConfig) -> Result<Option<Vec<u8>>, DetectError> {
    if cfg.model_defence.is_empty() {
        return Ok(None);
    }
    let refuse = |msg: String| DetectError::Config { path: cfg.source.display().to_string(), msg };
    let bytes = std::fs::read(&cfg.model).map_err(|source| DetectError::ConfigRead {
        path: cfg.source.display().to_string(),
        what: format!("the model {}", cfg.model.display()),
        source,
    })?;
    let mut model = Model::from_bytes(&bytes).map_err(|e| refuse(format!("feature norm clipping: {e}")))?;
    if is_quantized(&model) {
        model = dequantize(&model).map_err(|e| refuse(format!("the float surrogate to clip: {e}")))?.0;
    }
    clip_graph(&mut model, &cfg.model_defence).map_err(|e| refuse(format!("feature norm clipping: {e}")))?;
    Ok(Some(model.to_bytes()))
}

/// Whether a graph is dynamically quantized (int8 convolutions without a gradient).
pub fn is_quantized(model: &Model) -> bool {
    model.nodes.iter().any(|n| n.op_type == "ConvInteger" || n.op_type == "DynamicQuantizeLinear")
}

impl Detector for OnnxDetector {
    fn name(&self) -> &str {
        &self.cfg.name
    }

    fn target_classes(&self) -> &[usize] {
        &self.cfg.target_classes
    }

    fn nms_iou(&self) -> f32 {
        self.cfg.nms_iou
    }

    fn target_label(&self) -> String {
        self.cfg.target_names()
    }

    fn input(&self) -> &InputConfig {
        &self.cfg.input
    }

    fn propose_prepared(&mut self, input: Vec<f32>, map: InputMap) -> Result<Proposals, DetectError> {
        let raw = self.infer(input, &map)?;
        self.decode(&raw, &map)
    }

    fn replica(&self) -> Result<Box<dyn Detector>, DetectError> {
        Ok(Box::new(OnnxDetector::new(self.cfg.clone(), self.threads)?))
    }
}
