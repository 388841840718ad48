//! The base layer of pav: what every method block and job stands on. Nothing here knows of
//! detectors, textures or rigs.
#![warn(missing_docs)]

pub mod cluster;
pub mod colour;
pub mod data;
pub mod extends;
pub mod geometry;
pub mod image;
#[cfg(feature = "plot")]
pub mod plot;
pub mod progress;
pub mod provenance;
pub mod results;
pub mod rng;
pub mod shard;
pub mod sidecar;
pub mod step;
pub mod table;
#[cfg(feature = "video")]
pub mod video;
