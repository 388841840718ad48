//! Object detectors: configs, preprocessing, output decoding, NMS and backends.
#![warn(missing_docs)]

#[cfg(feature = "eval")]
pub mod check;
pub mod coco;
pub mod config;
pub mod decode;
pub mod defence;
pub mod inspect;
pub mod layout;
#[cfg(feature = "eval")]
pub mod load;
pub mod nms;
#[cfg(feature = "eval")]
pub mod onnx;
pub mod preprocess;

pub use config::DetectorConfig;
pub use decode::Proposals;

use pav_core::image::Frame;

/// The one detection rule of every metric (A_physical, ASR, the white-box reports): a car counts
/// as detected when its score reaches the threshold. The paper uses 0.5; the authors' code counts
/// `score > 0.6`, which differs from `score ≥ 0.6` only for a score of exactly 0.6.
pub fn detected(score: f32, threshold: f32) -> bool {
    score >= threshold
}

/// An axis-aligned box `[x1, y1, x2, y2]` in frame pixels.
pub type BBox = [f32; 4];

/// One detection after thresholding and NMS.
#[derive(Clone, Debug, PartialEq)]
pub struct Detection {
    /// Class index in the detector's class list.
    pub class_id: usize,
    /// Final score (objectness × class probability where the model has both).
    pub score: f32,
    /// Box in frame pixels.
    pub bbox: BBox,
}

/// The best box of the target classes in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TargetScore {
    /// Highest target-class score over all proposals.
    pub score: f32,
    /// The proposal's box in frame pixels.
    pub bbox: BBox,
    /// Its class (one of the target classes).
    pub class_id: usize,
}

/// A detector that maps a frame to scored proposals; `Send`, so that several can run side by side
/// on one frame.
pub trait Detector: Send {
    /// Short name used in reports.
    fn name(&self) -> &str;
    /// Runs the model and returns every proposal in frame coordinates.
    fn propose(&mut self, frame: &Frame) -> Result<Proposals, DetectError> {
        let (input, map) = preprocess::prepare(frame, self.input())
            .map_err(|source| DetectError::Defence { detector: self.name().to_string(), source })?;
        self.propose_prepared(input, map)
    }
    /// How a frame becomes the model's input; [`preprocess::prepare`] with it can run on any
    /// thread (evaluate prepares the next frames while the model runs).
    fn input(&self) -> &config::InputConfig;
    /// [`Detector::propose`] on a frame already prepared for [`Detector::input`].
    fn propose_prepared(&mut self, input: Vec<f32>, map: preprocess::InputMap) -> Result<Proposals, DetectError>;
    /// Class indices that count as the vehicle.
    fn target_classes(&self) -> &[usize];
    /// The IoU of its config's non-maximum suppression (`nms_iou`).
    fn nms_iou(&self) -> f32;
    /// Those classes' names joined by `+`, for reports.
    fn target_label(&self) -> String;
    /// A second, independent copy of this detector (its own runtime session), so that two
    /// frames can be scored at once; evaluate makes one per extra frame in flight.
    fn replica(&self) -> Result<Box<dyn Detector>, DetectError>;
}

/// Errors from building or running a detector.
#[derive(Debug, thiserror::Error)]
pub enum DetectError {
    /// The detector config is invalid.
    #[error("detector config {path}: {msg}")]
    Config {
        /// Config file.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// The model or class-names file named by `data:` is unknown or not fetched.
    #[error("detector config {path}: {source}")]
    ConfigData {
        /// Config file.
        path: String,
        /// Which entry, and the `pav data` command that fixes it.
        source: Box<pav_run::data::DataError>,
    },
    /// A config file, its class-names file or a folder of configs could not be read.
    #[error("detector config {path}: cannot read {what}: {source}")]
    ConfigRead {
        /// Config file or folder.
        path: String,
        /// What was being read.
        what: String,
        /// Why.
        source: std::io::Error,
    },
    /// A config file is not valid TOML for a detector.
    #[error("detector config {path}: {source}")]
    ConfigParse {
        /// Config file.
        path: String,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// Several configs are invalid; each line names one.
    #[error("invalid detector config:\n  {}", .0.join("\n  "))]
    Configs(Vec<String>),
    /// The model file is missing or does not fit its config.
    #[error("detector `{detector}`: model file {path} {msg}")]
    Model {
        /// Detector name.
        detector: String,
        /// Model path.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// The ONNX toolchain refused: the runtime is missing, or a graph cannot be read, folded or
    /// differentiated.
    #[error(transparent)]
    Onnx(#[from] pav_onnx::OnnxError),
    /// The runtime refused to load a model or run it.
    #[cfg(feature = "eval")]
    #[error("detector `{detector}`: {what}: {source}")]
    Session {
        /// Detector name.
        detector: String,
        /// What was being done.
        what: &'static str,
        /// ONNX Runtime's error.
        source: ort::Error,
    },
    /// An input defence failed on a frame.
    #[error("detector `{detector}`: {source}")]
    Defence {
        /// Detector name.
        detector: String,
        /// What failed.
        source: defence::DefenceError,
    },
    /// The model's outputs do not fit the configured layout.
    #[error("detector `{detector}`: {source}")]
    Output {
        /// Detector name.
        detector: String,
        /// What does not fit.
        source: decode::LayoutError,
    },
}
