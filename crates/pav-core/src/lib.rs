//! The base layer of pav: what every method block and job stands on. Nothing here knows of
//! detectors or textures, runs nothing outside the process but the video encoder, and reads no
//! repository; the one rig format, the per-frame angle sidecar, is here because the simulated
//! turntable (pav-scene), the rig and the scoring all read or write it.
#![warn(missing_docs)]

pub mod colour;
pub mod durable;
pub mod extends;
pub mod geometry;
pub mod image;
pub mod path;
#[cfg(feature = "plot")]
pub mod plot;
pub mod progress;
pub mod rng;
pub mod sidecar;
pub mod step;
pub mod table;
#[cfg(feature = "video")]
pub mod video;
