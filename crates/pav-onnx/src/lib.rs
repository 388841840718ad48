#![doc = include_str!("../README.md")]
#![warn(missing_docs)]

pub mod autodiff;
pub mod darknet;
#[cfg(feature = "runtime")]
pub mod fold;
#[cfg(feature = "runtime")]
pub mod gradops;
pub mod proto;
pub mod rewrite;
#[cfg(feature = "runtime")]
pub mod runtime;
#[cfg(feature = "runtime")]
pub mod session;
pub mod surrogate;

pub use autodiff::{differentiate, differentiate_first, differentiate_with, AutodiffError, Differentiated, Kernels};
pub use proto::{Model, ProtoError};
#[cfg(feature = "runtime")]
pub use session::{GradSession, Pass};

/// What can go wrong running graphs: the runtime, a session, a graph or a request that does not fit.
#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    /// ONNX Runtime's library is missing or does not start.
    #[error("{0}")]
    Runtime(String),
    /// ONNX Runtime refused to load a graph or run it.
    #[cfg(feature = "runtime")]
    #[error("model `{model}`: {what}: {source}")]
    Session {
        /// The model's name.
        model: String,
        /// What was being done.
        what: &'static str,
        /// ONNX Runtime's error.
        source: ort::Error,
    },
    /// A request that does not fit the graph (an input without a size, a gradient count).
    #[error("model `{model}`: {msg}")]
    Request {
        /// The model's name.
        model: String,
        /// What does not fit.
        msg: String,
    },
    /// The graph cannot be differentiated.
    #[error(transparent)]
    Autodiff(#[from] AutodiffError),
    /// The graph cannot be read.
    #[error(transparent)]
    Proto(#[from] ProtoError),
}
