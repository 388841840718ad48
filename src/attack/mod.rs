//! The attack (paper Algorithm 1): views → composite → detector → loss → texture.

pub mod adam;
pub mod config;
#[cfg(feature = "optimize")]
pub mod loss;
pub mod setup;
pub mod smooth;
pub mod view;
#[cfg(feature = "optimize")]
pub mod whitebox;
