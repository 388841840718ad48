//! The print channel: what a printer does to a texture (an ICC soft proof sampled into a
//! differentiable 3D LUT).
#![warn(missing_docs)]

#[cfg(feature = "video")]
pub mod calibrate;
pub mod channel;
pub mod chart;
#[cfg(feature = "video")]
pub mod colorchecker;
pub mod fit;
pub mod lut;
pub mod panels;
pub mod paper;
pub mod pdf;
#[cfg(feature = "video")]
pub mod photo;
pub mod pieces;
pub mod proof;
