//! Darknet models: the cfg network description, the weights file, and export to ONNX.

pub mod cfg;
pub mod to_onnx;
pub mod weights;

pub use cfg::{Layer, Network};
pub use weights::Weights;

/// Errors reading or converting a darknet model.
#[derive(Debug, thiserror::Error)]
pub enum DarknetError {
    /// The cfg or weights file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// File that failed.
        path: std::path::PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The converted model could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// File or folder that failed.
        path: std::path::PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The cfg text is malformed.
    #[error("{path}:{line}: {msg}")]
    Cfg {
        /// cfg file.
        path: String,
        /// 1-based line number (0 when not tied to one line).
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// The weights file does not fit the network.
    #[error("weights {path}: {msg}")]
    Weights {
        /// weights file.
        path: String,
        /// What is wrong.
        msg: String,
    },
    /// The network uses a layer the exporter does not support.
    #[error("layer {index} ([{kind}]) is not supported: {msg}")]
    Unsupported {
        /// Layer index (0-based, as darknet counts).
        index: usize,
        /// Section name.
        kind: String,
        /// Why.
        msg: String,
    },
}
