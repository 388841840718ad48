//! The print channel: what a printer does to a texture (an ICC soft proof sampled into a
//! differentiable 3D LUT).

pub mod channel;
pub mod lut;
pub mod proof;
