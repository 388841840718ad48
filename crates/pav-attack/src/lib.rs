//! The optimizer (paper Algorithm 1): views → composite → detector → loss → texture, with its
//! checkpoints, the printable sheet, and the UV-map tools that make the texture printable.
#![warn(missing_docs)]

pub mod adam;
#[cfg(feature = "optimize")]
pub mod bench;
pub mod checkpoint;
pub mod config;
pub mod defended;
pub mod export;
pub mod loss;
#[cfg(feature = "optimize")]
pub mod optimize;
#[cfg(feature = "optimize")]
pub mod outputs;
pub mod pieces;
pub mod placement;
pub mod pyramid;
pub mod setup;
pub mod smooth;
pub mod uv;
pub mod view;
pub mod view_scores;
#[cfg(feature = "optimize")]
pub mod whitebox;
