//! The attack (paper Algorithm 1): views → composite → detector → loss → texture.

pub mod adam;
pub mod checkpoint;
pub mod config;
#[cfg(feature = "optimize")]
pub mod crossval;
#[cfg(feature = "optimize")]
pub mod digital;
pub mod export;
#[cfg(feature = "optimize")]
pub mod loss;
#[cfg(feature = "optimize")]
pub mod optimize;
#[cfg(feature = "optimize")]
pub mod outputs;
pub mod setup;
pub mod smooth;
pub mod view;
#[cfg(feature = "optimize")]
pub mod whitebox;
