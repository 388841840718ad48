//! pav: physical adversarial camouflage for vehicles (PAV-Camou) and the rig that scores it.
//!
//! The library is layered; a module only uses modules of its own layer or the layers below it
//! (`tests/layers.rs` checks this):
//!
//! | layer | modules |
//! |---|---|
//! | 0 base | [`cluster`], [`colour`], [`data`], [`extends`], [`provenance`], [`image`], [`video`], [`geometry`], [`rng`], [`shard`], [`sidecar`], [`table`], [`plot`], [`progress`] |
//! | 1 method blocks | [`print`], [`render`], [`scene`], [`dataset`], [`detect`] |
//! | 2 jobs | [`attack`] (the optimizer), [`eval`] (scoring), [`rig`] (turntable and capture); no job uses another |
//! | 3 experiments | [`experiments`]: what combines the optimizer and scoring |
//!
//! Data flows one way: mesh + poses → G-buffers → textured render → EoT → composite → detector
//! → loss → texture; and video → frames → detections → metrics → reports.
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
pub mod rng;
pub mod shard;
pub mod sidecar;
pub mod step;
pub mod table;
#[cfg(feature = "video")]
pub mod video;

pub mod dataset;
pub mod detect;
pub mod print;
pub mod render;
pub mod scene;

pub mod attack;
pub mod eval;
#[cfg(feature = "rig")]
pub mod rig;

#[cfg(feature = "optimize")]
pub mod experiments;
