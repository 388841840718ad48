//! Detector configs (TOML): everything needed to run an ONNX detector without code changes.

use super::coco::COCO80;
use super::defence::{chain_label, Defence};
pub use super::layout::BoxFrame;
use super::layout::{Activation, Arrange, CellOrder, Centre, Description, Encoding, Level, OutputPart};
use super::DetectError;
use pav_core::extends::{load, ExtendsError};
use pav_core::image::resize::Interpolation;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Channel order the model expects.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ChannelOrder {
    /// Red, green, blue.
    Rgb,
    /// Blue, green, red (OpenCV order).
    Bgr,
}

/// How a frame is fitted to the model input.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Resize {
    /// Keep aspect ratio, pad the rest with `pad_value`.
    Letterbox,
    /// Scale each axis independently to fill the input.
    Stretch,
}

/// Where a letterboxed image sits in the input.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Default, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Align {
    /// Image at the top-left corner, padding right and bottom (YOLOX).
    TopLeft,
    /// Image centred, padding split on both sides (Ultralytics).
    #[default]
    Center,
}

/// Model input description.
#[derive(Clone, Debug, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct InputConfig {
    /// Input tensor name; the model's first input when absent.
    pub name: Option<String>,
    /// Input width in pixels.
    pub width: usize,
    /// Input height in pixels.
    pub height: usize,
    /// Channel order.
    pub channels: ChannelOrder,
    /// Each 0–255 pixel value is multiplied by this (1/255 for [0,1] input).
    #[serde(default = "one")]
    pub scale: f32,
    /// Subtracted after scaling, per channel in model channel order.
    #[serde(default)]
    pub mean: [f32; 3],
    /// Divides after subtracting the mean, per channel.
    #[serde(default = "ones")]
    pub std: [f32; 3],
    /// Letterbox or stretch.
    pub resize: Resize,
    /// Resampling filter.
    #[serde(default)]
    pub interpolation: Interpolation,
    /// Padding value (0–255 scale, before normalization) for letterbox.
    #[serde(default = "pad114")]
    pub pad_value: u8,
    /// Letterbox placement.
    #[serde(default)]
    pub align: Align,
    /// Further inputs the model reads, each fed a value pav computes per frame.
    #[serde(default)]
    pub extra: Vec<ExtraInput>,
    /// Input transforms applied to the 8-bit input image before normalization, in order (the
    /// config's `[[defence]]` list, then any `--defence` chain).
    #[serde(skip)]
    pub defence: Vec<Defence>,
}

/// A model input beside the image (PicoDet's `scale_factor`), fed per frame.
#[derive(Clone, Debug, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ExtraInput {
    /// The input's name in the model.
    pub name: String,
    /// What it receives.
    pub value: ExtraValue,
}

/// The value of an [`ExtraInput`].
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ExtraValue {
    /// float32 `[1, 2]`: input height / frame height, input width / frame width (PaddleDetection's
    /// `scale_factor`, with which a graph maps its boxes back to frame pixels).
    ScaleYx,
    /// int64 `[1, 2]`: the input's width and height.
    SizeWh,
}

/// One column of a [`OutputLayout::Rows`] output.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Column {
    /// The class index (a negative one marks an empty row).
    Class,
    /// The detection's score.
    Score,
    /// Left edge.
    X1,
    /// Top edge.
    Y1,
    /// Right edge.
    X2,
    /// Bottom edge.
    Y2,
    /// A column pav does not read.
    Skip,
}

impl Column {
    /// Class, score, x1, y1, x2, y2: the default row.
    pub fn xyxy_rows() -> Vec<Column> {
        vec![Column::Class, Column::Score, Column::X1, Column::Y1, Column::X2, Column::Y2]
    }
}

fn one() -> f32 {
    1.0
}
fn ones() -> [f32; 3] {
    [1.0; 3]
}
fn pad114() -> u8 {
    114
}
fn default_strides() -> Vec<usize> {
    vec![8, 16, 32]
}

/// One darknet YOLO head.
#[derive(Clone, Debug, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HeadConfig {
    /// Output tensor name.
    pub output: String,
    /// Anchors (w, h) in input pixels, in the order of the head's channels.
    pub anchors: Vec<[f32; 2]>,
}

/// Output layout: how to turn the model's raw outputs into proposals.
#[derive(Clone, Debug, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(tag = "layout", rename_all = "kebab-case", deny_unknown_fields)]
pub enum OutputLayout {
    /// Darknet YOLOv3 heads `[N, A·(5+C), H, W]` raw logits; sigmoid and anchors applied here.
    Darknet {
        /// Heads in any order.
        heads: Vec<HeadConfig>,
    },
    /// YOLOX `[N, R, 5+C]`: (dx, dy, log w, log h, obj, classes), obj/cls already sigmoid.
    Yolox {
        /// Output tensor name; the first output when absent.
        output: Option<String>,
        /// Strides of the grid levels, in row order.
        #[serde(default = "default_strides")]
        strides: Vec<usize>,
    },
    /// Ultralytics YOLOv5u/v8 `[N, 4+C, R]`: (cx, cy, w, h) in input pixels, class scores, no objectness.
    Ultralytics {
        /// Output tensor name; the first output when absent.
        output: Option<String>,
    },
    /// Generalized-focal-loss heads (NanoDet): per grid level of each stride a class map
    /// `[N, R, C]` (already sigmoid) and a box map `[N, R, 4·bins]` of distances to the left, top,
    /// right and bottom sides as distributions over `bins` (softmax, expectation, times the
    /// stride) from the cell centre `(x·s + (s − 1)/2, y·s + (s − 1)/2)`. Outputs are matched by
    /// shape (R from the stride, the width from the classes or bins), since exporters number them.
    Gfl {
        /// Strides of the grid levels.
        #[serde(default = "default_strides")]
        strides: Vec<usize>,
        /// Bins per side distance (NanoDet's `reg_max + 1`).
        #[serde(default = "eight")]
        bins: usize,
    },
    /// Final detections, one per row (post-processing and NMS inside the graph, as PicoDet's
    /// export and YOLO exports with NMS appended): the columns say what each holds.
    Rows {
        /// Output tensor name; else the first float output of rank 2 or 3 whose rows are as long
        /// as `columns`.
        output: Option<String>,
        /// What each column holds; must name class, score, x1, y1, x2 and y2 once each.
        #[serde(default = "Column::xyxy_rows")]
        columns: Vec<Column>,
        /// Which pixels the boxes are in.
        #[serde(default)]
        frame: BoxFrame,
        /// The class scores `[1, C, N]` the graph's NMS reads (class-major probabilities): what
        /// a white box differentiates, the graph cut before its NMS. Optional; only
        /// `pav optimize` reads it.
        #[serde(default)]
        scores: Option<String>,
        /// The boxes `[1, N, 4]` (x1, y1, x2, y2) the graph's NMS reads, in input pixels once
        /// the extra inputs are neutral (a `scale_yx` of 1): what a white box weights its scores
        /// by under `loss.iou`. Optional; only `pav optimize` reads it.
        #[serde(default)]
        boxes: Option<String>,
    },
    /// Any other layout, written out as a [`Description`]: which outputs hold the boxes, the
    /// scores, an objectness or labels, the box encoding, the activations and the grid.
    Custom(Box<Description>),
    /// DETR family (RT-DETR, D-FINE, DEIM): per-query labels, xyxy boxes and scores.
    Detr {
        /// Labels output (int64).
        labels: String,
        /// Boxes output, xyxy in the pixel space given by `size_input`.
        boxes: String,
        /// Scores output.
        scores: String,
        /// Int64 input `[N, 2]` that receives the target size (w, h); we pass the input size.
        size_input: Option<String>,
        /// The raw class logits `[1, Q, C]` the post-processor turns into scores: what a white box
        /// differentiates (the post-processor's top-k selection has no gradient). Optional; only
        /// `pav optimize` reads it.
        #[serde(default)]
        logits: Option<String>,
        /// The same decoder layer's boxes `[1, Q, 4]` (cx, cy, w, h as shares of the input side):
        /// what a white box weights its scores by under `loss.iou`. Optional; only `pav optimize`
        /// reads it.
        #[serde(default)]
        pred_boxes: Option<String>,
    },
}

/// Class names and which classes count as "the car".
#[derive(Clone, Debug, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClassConfig {
    /// `coco80` for the built-in list, or a path to a names file (one per line).
    #[serde(default = "coco80")]
    pub names: String,
    /// Class names that count as a detection of the vehicle.
    #[serde(default = "car")]
    pub target: Vec<String>,
}

fn eight() -> usize {
    8
}

fn coco80() -> String {
    "coco80".into()
}
fn car() -> Vec<String> {
    vec!["car".into()]
}

impl Default for ClassConfig {
    fn default() -> Self {
        ClassConfig { names: coco80(), target: car() }
    }
}

/// A detector config as written: the keys of `configs/detectors/*.toml`.
#[derive(Clone, Debug, Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(rename = "DetectorConfig")]
struct RawConfig {
    /// Short name used in reports.
    name: String,
    /// The ONNX model: a path relative to the config, or `data:NAME/FILE` in pav's data store.
    model: PathBuf,
    /// Free text: where the model comes from, its licence, what was checked.
    #[serde(default)]
    description: String,
    /// How a frame becomes the model's input.
    input: InputConfig,
    /// How the model's outputs become boxes and scores.
    output: OutputLayout,
    /// Class names and the target classes.
    #[serde(default)]
    classes: ClassConfig,
    /// IoU above which non-maximum suppression keeps only the higher-scored of two boxes of one class.
    #[serde(default = "nms_default")]
    nms_iou: f32,
    /// Defences in front of the model (docs/defences.md), applied in the order listed.
    #[serde(default)]
    defence: Vec<Defence>,
}

/// The IoU above which two boxes of one class are one detection, unless a config says otherwise.
fn nms_default() -> f32 {
    0.5
}

/// Target classes that cannot be set.
#[derive(Debug, thiserror::Error)]
pub enum TargetError {
    /// No class was named.
    #[error("at least one target class is needed")]
    None,
    /// A name the model does not have.
    #[error("target class `{name}` is not among the model's {classes} classes")]
    Unknown {
        /// The name given.
        name: String,
        /// How many classes the model has.
        classes: usize,
    },
}

/// A validated detector config with resolved paths and class indices.
#[derive(Clone, Debug)]
pub struct DetectorConfig {
    /// Short name used in reports.
    pub name: String,
    /// Free text.
    pub description: String,
    /// Model file (resolved against the config's directory).
    pub model: PathBuf,
    /// Input description.
    pub input: InputConfig,
    /// Output layout.
    pub output: OutputLayout,
    /// Class names.
    pub class_names: Vec<String>,
    /// Indices of the target classes.
    pub target_classes: Vec<usize>,
    /// IoU above which non-maximum suppression keeps only the higher-scored of two boxes of one
    /// class; every path that turns proposals into detections reads it (`Detector::nms_iou`).
    pub nms_iou: f32,
    /// Defences rewritten into the model when it loads (feature norm clipping); the input
    /// transforms are in [`InputConfig::defence`].
    pub model_defence: Vec<Defence>,
    /// Where the config was read from.
    pub source: PathBuf,
    /// The configs it `extends`, nearest first.
    pub bases: Vec<PathBuf>,
}

impl DetectorConfig {
    /// The keys a detector config file takes, with their types, defaults and meanings.
    pub fn schema() -> schemars::Schema {
        schemars::schema_for!(RawConfig)
    }

    /// Reads and validates a TOML config; relative paths in it are relative to its directory.
    pub fn load(path: &Path) -> Result<Self, DetectError> {
        let cfg_err = |msg: String| DetectError::Config { path: path.display().to_string(), msg };
        let shown = path.display().to_string();
        let (raw, files): (RawConfig, _) =
            load(path, &[&["model"], &["classes", "names"]], &["coco80"]).map_err(|e| match e {
                ExtendsError::Read { path, source } => {
                    DetectError::ConfigRead { path: path.display().to_string(), what: "the file".into(), source }
                }
                ExtendsError::Parse { path, source } => {
                    DetectError::ConfigParse { path: path.display().to_string(), source }
                }
                ExtendsError::Invalid { path, msg } => DetectError::Config { path: path.display().to_string(), msg },
            })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let resolve = |p: &Path| {
            pav_run::data::resolve(dir, p)
                .map_err(|source| DetectError::ConfigData { path: shown.clone(), source: Box::new(source) })
        };
        let class_names: Vec<String> = if raw.classes.names == "coco80" {
            COCO80.iter().map(|s| s.to_string()).collect()
        } else {
            let p = resolve(Path::new(&raw.classes.names))?;
            std::fs::read_to_string(&p)
                .map_err(|source| DetectError::ConfigRead {
                    path: shown.clone(),
                    what: format!("the class names file {}", p.display()),
                    source,
                })?
                .lines()
                .map(|l| l.trim().to_string())
                .filter(|l| !l.is_empty())
                .collect()
        };
        let mut cfg = DetectorConfig {
            name: raw.name,
            description: raw.description,
            model: resolve(&raw.model)?,
            input: raw.input,
            output: raw.output,
            class_names,
            target_classes: Vec::new(),
            nms_iou: raw.nms_iou,
            model_defence: Vec::new(),
            source: path.to_path_buf(),
            bases: files[1..].to_vec(),
        };
        cfg.add_defences(raw.defence);
        cfg.set_targets(&raw.classes.target).map_err(|e| cfg_err(e.to_string()))?;
        cfg.validate().map_err(cfg_err)?;
        Ok(cfg)
    }

    /// Replaces the target classes by name (e.g. from `--classes car,truck`).
    pub fn set_targets(&mut self, names: &[String]) -> Result<(), TargetError> {
        if names.is_empty() {
            return Err(TargetError::None);
        }
        self.target_classes = names
            .iter()
            .map(|n| {
                self.class_names
                    .iter()
                    .position(|c| c == n)
                    .ok_or_else(|| TargetError::Unknown { name: n.clone(), classes: self.class_names.len() })
            })
            .collect::<Result<_, _>>()?;
        Ok(())
    }

    /// The same detector behind `chain` as well (after the config's own defences), named
    /// `NAME+LABELS` (`yolox_nano+median3`); the chain is checked against the input size.
    pub fn defended(&self, chain: &[Defence]) -> Result<DetectorConfig, DetectError> {
        let mut d = self.clone();
        d.name = format!("{}+{}", self.name, chain_label(chain));
        d.add_defences(chain.iter().cloned());
        d.validate().map_err(|msg| DetectError::Config { path: self.source.display().to_string(), msg })?;
        Ok(d)
    }

    /// Appends `defences`: input transforms to the input's chain, the others to the model's.
    fn add_defences(&mut self, defences: impl IntoIterator<Item = Defence>) {
        for d in defences {
            if d.on_input() {
                self.input.defence.push(d);
            } else {
                self.model_defence.push(d);
            }
        }
    }

    /// Names of the target classes, joined for reports.
    pub fn target_names(&self) -> String {
        self.target_classes.iter().map(|&i| self.class_names[i].as_str()).collect::<Vec<_>>().join("+")
    }

    fn validate(&self) -> Result<(), String> {
        let i = &self.input;
        if i.width == 0 || i.height == 0 {
            return Err(format!("input size {}x{} must be positive", i.width, i.height));
        }
        if !i.scale.is_finite() || i.scale == 0.0 {
            return Err(format!("input.scale = {} must be finite and non-zero", i.scale));
        }
        if i.std.iter().any(|s| !s.is_finite() || *s == 0.0) || i.mean.iter().any(|m| !m.is_finite()) {
            return Err(format!("input.mean {:?} / input.std {:?} must be finite, std non-zero", i.mean, i.std));
        }
        for (n, d) in i.defence.iter().chain(&self.model_defence).enumerate() {
            d.check(i.width, i.height).map_err(|e| format!("defence {} ({}): {e}", n + 1, d.label()))?;
        }
        if !(0.0..=1.0).contains(&self.nms_iou) {
            return Err(format!("nms_iou = {} must be in [0, 1]", self.nms_iou));
        }
        match &self.output {
            OutputLayout::Darknet { heads } if heads.is_empty() || heads.iter().any(|h| h.anchors.is_empty()) => {
                Err("darknet layout needs at least one head, each with anchors".into())
            }
            OutputLayout::Yolox { strides, .. } if strides.is_empty() || strides.contains(&0) => {
                Err(format!("yolox strides {strides:?} must be non-empty and positive"))
            }
            OutputLayout::Gfl { strides, bins } if strides.is_empty() || strides.contains(&0) || *bins < 2 => {
                Err(format!("gfl strides {strides:?} must be non-empty and positive, bins ({bins}) at least 2"))
            }
            OutputLayout::Rows { columns, .. }
                if [Column::Class, Column::Score, Column::X1, Column::Y1, Column::X2, Column::Y2]
                    .iter()
                    .any(|c| columns.iter().filter(|k| *k == c).count() != 1) =>
            {
                Err(format!("rows columns {columns:?} must name class, score, x1, y1, x2 and y2 once each"))
            }
            // Boxes the graph maps back by scale alone miss a centred letterbox's padding.
            OutputLayout::Rows { frame: BoxFrame::Image, .. }
                if i.resize == Resize::Letterbox && i.align == Align::Center =>
            {
                Err("rows in image pixels need input.resize = \"stretch\" or a top-left letterbox".into())
            }
            OutputLayout::Custom(d)
                if d.boxes.frame == BoxFrame::Image && i.resize == Resize::Letterbox && i.align == Align::Center =>
            {
                Err("boxes in image pixels need input.resize = \"stretch\" or a top-left letterbox".into())
            }
            OutputLayout::Custom(d) => d.validate(self.class_names.len()),
            _ => Ok(()),
        }
    }
}

fn named(output: &Option<String>) -> Vec<String> {
    output.iter().cloned().collect()
}

/// Why final rows give a white box no gradient, and the keys that give one.
const ROWS_GRADIENT: &str = "the rows are final detections, which have no gradient: set `scores` (the class-major [1, C, N] scores the graph's NMS reads) and, for `loss.iou`, `boxes` in [output] (`pav-rig model inspect --values` lists the graph's values), or describe the graph as `custom` with [output.raw]";

/// Why a DETR's queries give a white box no gradient, and the keys that give one.
const DETR_GRADIENT: &str = "the queries' labels and scores come after a top-k, which has no gradient: set `logits` and, for `loss.iou`, `pred_boxes` in [output] (`pav-rig model inspect --values` lists the graph's values)";

impl OutputLayout {
    /// The description a white box differentiates, or why there is none, with the keys of
    /// this layout that give one.
    pub fn gradient(&self, classes: usize) -> Result<Description, String> {
        let d = self.describe(classes);
        match d.gradient() {
            Ok(g) => Ok(g.clone()),
            Err(why) => Err(match self {
                OutputLayout::Rows { .. } => ROWS_GRADIENT.to_string(),
                OutputLayout::Detr { .. } => DETR_GRADIENT.to_string(),
                _ => why,
            }),
        }
    }

    /// The layout as a [`Description`]; the named layouts are presets of one.
    pub fn describe(&self, classes: usize) -> Description {
        let grid =
            |strides: &[usize]| strides.iter().map(|&s| Level { stride: Some(s), anchors: Vec::new() }).collect();
        match self {
            OutputLayout::Custom(d) => (**d).clone(),
            OutputLayout::Darknet { heads } => {
                let src = OutputPart {
                    output: heads.iter().map(|h| h.output.clone()).collect(),
                    arrange: Arrange::Planes,
                    per_level: true,
                    ..OutputPart::default()
                };
                Description {
                    levels: heads.iter().map(|h| Level { stride: None, anchors: h.anchors.clone() }).collect(),
                    order: CellOrder::AnchorCell,
                    centre: Centre::Cell,
                    boxes: OutputPart { encoding: Some(Encoding::Darknet), ..src.clone() },
                    objectness: Some(OutputPart { column: 4, activation: Activation::Sigmoid, ..src.clone() }),
                    scores: OutputPart { column: 5, activation: Activation::Sigmoid, ..src },
                    labels: None,
                    raw: None,
                }
            }
            OutputLayout::Yolox { output, strides } => {
                let src = OutputPart { output: named(output), ..OutputPart::default() };
                Description {
                    levels: grid(strides),
                    order: CellOrder::AnchorCell,
                    centre: Centre::Cell,
                    boxes: OutputPart { encoding: Some(Encoding::Grid), ..src.clone() },
                    objectness: Some(OutputPart { column: 4, ..src.clone() }),
                    scores: OutputPart { column: 5, ..src },
                    labels: None,
                    raw: None,
                }
            }
            OutputLayout::Ultralytics { output } => {
                let src = OutputPart { output: named(output), arrange: Arrange::Columns, ..OutputPart::default() };
                Description {
                    levels: Vec::new(),
                    order: CellOrder::AnchorCell,
                    centre: Centre::Cell,
                    boxes: OutputPart { encoding: Some(Encoding::Cxcywh), ..src.clone() },
                    scores: OutputPart { column: 4, ..src },
                    objectness: None,
                    labels: None,
                    raw: None,
                }
            }
            OutputLayout::Gfl { strides, bins } => Description {
                levels: grid(strides),
                order: CellOrder::AnchorCell,
                centre: Centre::Pixel,
                boxes: OutputPart {
                    per_level: true,
                    width: Some(4 * bins),
                    encoding: Some(Encoding::LtrbBins),
                    bins: Some(*bins),
                    clip: true,
                    ..OutputPart::default()
                },
                scores: OutputPart { per_level: true, width: Some(classes), ..OutputPart::default() },
                objectness: None,
                labels: None,
                raw: None,
            },
            OutputLayout::Rows { output, columns, frame, scores: before, boxes: before_boxes } => {
                let at = |c: Column| columns.iter().position(|k| *k == c).unwrap_or(0);
                let src = OutputPart { output: named(output), width: Some(columns.len()), ..OutputPart::default() };
                Description {
                    levels: Vec::new(),
                    order: CellOrder::AnchorCell,
                    centre: Centre::Cell,
                    boxes: OutputPart {
                        encoding: Some(Encoding::Xyxy),
                        coords: Some([Column::X1, Column::Y1, Column::X2, Column::Y2].map(at)),
                        frame: *frame,
                        ..src.clone()
                    },
                    scores: OutputPart { column: at(Column::Score), ..src.clone() },
                    labels: Some(OutputPart { column: at(Column::Class), ..src }),
                    objectness: None,
                    // The class-major scores and the boxes the graph's NMS reads.
                    raw: before.as_ref().map(|s| {
                        Box::new(Description {
                            boxes: OutputPart {
                                output: named(before_boxes),
                                width: Some(4),
                                encoding: Some(Encoding::Xyxy),
                                ..OutputPart::default()
                            },
                            scores: OutputPart {
                                output: vec![s.clone()],
                                arrange: Arrange::Columns,
                                width: Some(classes),
                                ..OutputPart::default()
                            },
                            ..Description::empty()
                        })
                    }),
                }
            }
            OutputLayout::Detr { labels, boxes, scores, logits, pred_boxes, .. } => Description {
                levels: Vec::new(),
                order: CellOrder::AnchorCell,
                centre: Centre::Cell,
                boxes: OutputPart {
                    output: vec![boxes.clone()],
                    encoding: Some(Encoding::Xyxy),
                    ..OutputPart::default()
                },
                scores: OutputPart { output: vec![scores.clone()], ..OutputPart::default() },
                labels: Some(OutputPart { output: vec![labels.clone()], ..OutputPart::default() }),
                objectness: None,
                // The last decoder layer's class logits and boxes, before the top-k.
                raw: logits.as_ref().map(|l| {
                    Box::new(Description {
                        boxes: OutputPart {
                            output: named(pred_boxes),
                            width: Some(4),
                            encoding: Some(Encoding::Cxcywh),
                            normalized: true,
                            ..OutputPart::default()
                        },
                        scores: OutputPart {
                            output: vec![l.clone()],
                            width: Some(classes),
                            activation: Activation::Sigmoid,
                            ..OutputPart::default()
                        },
                        ..Description::empty()
                    })
                }),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, body: &str) -> PathBuf {
        let p = dir.join("d.toml");
        std::fs::write(&p, body).unwrap();
        p
    }

    const BASE: &str = "name='x'\nmodel='m.onnx'\n[input]\nwidth=32\nheight=32\nchannels='rgb'\nresize='stretch'\n";

    #[test]
    fn resolves_model_path_and_default_car_target() {
        let d = tempfile::tempdir().unwrap();
        let c = DetectorConfig::load(&write(d.path(), &format!("{BASE}[output]\nlayout='ultralytics'\n"))).unwrap();
        assert_eq!(c.model, d.path().join("m.onnx"));
        assert_eq!(c.target_classes, vec![2]);
        assert_eq!(c.target_names(), "car");
    }

    #[test]
    fn unknown_layout_and_unknown_class_are_clear_errors() {
        let d = tempfile::tempdir().unwrap();
        let e =
            DetectorConfig::load(&write(d.path(), &format!("{BASE}[output]\nlayout='ssd'\n"))).unwrap_err().to_string();
        assert!(e.contains("unknown variant `ssd`") && e.contains("ultralytics"), "{e}");
        let e = DetectorConfig::load(&write(
            d.path(),
            &format!("{BASE}[output]\nlayout='ultralytics'\n[classes]\ntarget=['tank']\n"),
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("`tank`"), "{e}");
        let e = DetectorConfig::load(&write(d.path(), &format!("{BASE}std=[1,0,1]\n[output]\nlayout='ultralytics'\n")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("std"), "{e}");
    }

    #[test]
    fn rows_need_every_column_once_and_image_boxes_no_centred_padding() {
        let d = tempfile::tempdir().unwrap();
        let c = DetectorConfig::load(&write(d.path(), &format!("{BASE}[output]\nlayout='rows'\n"))).unwrap();
        assert!(
            matches!(c.output, OutputLayout::Rows { ref columns, frame: BoxFrame::Input, .. } if columns.len() == 6)
        );
        let e = DetectorConfig::load(&write(
            d.path(),
            &format!("{BASE}[output]\nlayout='rows'\ncolumns=['class','score','x1','y1','x2','x2']\n"),
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("once each"), "{e}");
        let centred = BASE.replace("'stretch'", "'letterbox'\nalign='center'");
        let e = DetectorConfig::load(&write(d.path(), &format!("{centred}[output]\nlayout='rows'\nframe='image'\n")))
            .unwrap_err()
            .to_string();
        assert!(e.contains("stretch"), "{e}");
        let e = DetectorConfig::load(&write(
            d.path(),
            &format!("{BASE}[[input.extra]]\nname='s'\nvalue='scale'\n[output]\nlayout='rows'\n"),
        ))
        .unwrap_err()
        .to_string();
        assert!(e.contains("scale_yx"), "{e}");
    }

    #[test]
    fn widths_are_shared_by_parts_of_one_tensor_and_own_where_given() {
        let d = OutputLayout::Yolox { output: None, strides: vec![8] }.describe(80);
        assert_eq!(
            [crate::layout::Role::Boxes, crate::layout::Role::Scores, crate::layout::Role::Objectness]
                .map(|r| d.width(r, 80)),
            [85; 3]
        );
        let g = OutputLayout::Gfl { strides: vec![8], bins: 8 }.describe(80);
        assert_eq!((g.width(crate::layout::Role::Boxes, 80), g.width(crate::layout::Role::Scores, 80)), (32, 80));
        let r = OutputLayout::Rows {
            output: None,
            columns: vec![Column::Skip, Column::Y1, Column::X1, Column::Y2, Column::X2, Column::Score, Column::Class],
            frame: BoxFrame::Input,
            scores: None,
            boxes: None,
        }
        .describe(80);
        assert_eq!(r.boxes.coords, Some([2, 1, 4, 3]));
        assert_eq!(
            (r.scores.column, r.labels.as_ref().unwrap().column, r.width(crate::layout::Role::Boxes, 80)),
            (5, 6, 7)
        );
        for l in [OutputLayout::Ultralytics { output: None }, OutputLayout::Gfl { strides: vec![8, 16], bins: 4 }] {
            l.describe(80).validate(80).unwrap();
        }
    }

    #[test]
    fn a_custom_layout_is_read_and_checked_when_the_config_loads() {
        let d = tempfile::tempdir().unwrap();
        let ssd = "[output]\nlayout='custom'\n[[output.levels]]\nstride=8\nanchors=[[10,10]]\n[output.boxes]\nencoding='prior'\nvariances=[0.1,0.2]\nwidth=4\n[output.scores]\nactivation='softmax'\nbackground=0\nwidth=81\n";
        let c = DetectorConfig::load(&write(d.path(), &format!("{BASE}{ssd}"))).unwrap();
        let OutputLayout::Custom(l) = &c.output else { panic!("{:?}", c.output) };
        assert_eq!((l.levels.len(), l.scores.background), (1, Some(0)));
        let e = DetectorConfig::load(&write(d.path(), &format!("{BASE}{}", ssd.replace("width=81", "width=80"))))
            .unwrap_err()
            .to_string();
        assert!(e.contains("d.toml") && e.contains("columns up to 81 of rows 80 wide"), "{e}");
        let e = DetectorConfig::load(&write(d.path(), &format!("{BASE}{}", ssd.replace("stride=8", "strid=8"))))
            .unwrap_err()
            .to_string();
        assert!(e.contains("strid"), "{e}");
    }

    #[test]
    fn a_config_extends_another_and_adds_defences() {
        let d = tempfile::tempdir().unwrap();
        let sub = d.path().join("variants");
        std::fs::create_dir(&sub).unwrap();
        let names = d.path().join("names.txt");
        std::fs::write(&names, "car\ntruck\n").unwrap();
        let base = write(d.path(), &format!("{BASE}[output]\nlayout='ultralytics'\n[classes]\nnames='names.txt'\n"));
        std::fs::write(
            sub.join("v.toml"),
            "extends = '../d.toml'\nname = 'x+median3'\n[[defence]]\nkind = 'median'\nk = 3\n[[defence]]\nkind = 'clip'\nlayers = ['f']\n",
        )
        .unwrap();
        let c = DetectorConfig::load(&sub.join("v.toml")).unwrap();
        assert_eq!(c.name, "x+median3");
        // The base's relative paths keep meaning the base's folder.
        assert_eq!(pav_core::path::tidy(&c.model), pav_core::path::tidy(&d.path().join("m.onnx")));
        assert_eq!(c.class_names, ["car", "truck"]);
        assert_eq!(c.input.defence, [Defence::Median(crate::defence::Median { k: 3 })]);
        assert_eq!(c.model_defence, [Defence::Clip(crate::defence::Clip { layers: vec!["f".into()], level: 1.0 })]);
        assert_eq!(c.bases, [pav_core::path::tidy(&base)]);
        std::fs::write(sub.join("w.toml"), "extends = 'v.toml'\n[[defence]]\nkind = 'median'\nk = 2\n").unwrap();
        let e = DetectorConfig::load(&sub.join("w.toml")).unwrap_err().to_string();
        assert!(e.contains("w.toml") && e.contains("k = 2 must be odd"), "{e}");
    }
}
