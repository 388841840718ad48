//! pav: physical adversarial camouflage for vehicles (PAV-Camou) and the rig that scores it.
//!
//! The workspace's crates are the library's layers; a crate only depends on crates of the layers
//! below it, and no job depends on another (`tests/it/layers.rs` checks the manifests):
//!
//! | layer | crates (modules of this crate) |
//! |---|---|
//! | 0 base | `pav-core`: [`colour`], [`durable`], [`extends`], [`path`], [`image`], [`video`], [`geometry`], [`rng`], [`sidecar`], [`step`], [`table`], [`plot`], [`progress`]; `pav-run`: [`data`], [`provenance`], [`shard`], [`stop`] (what a run reads and records, and how it stops); `pav-onnx` (ONNX graphs and their gradients, no pav dependency) |
//! | 1 method blocks | `pav-print` ([`print`]), `pav-render` ([`render`]), `pav-scene` ([`scene`]), `pav-dataset` ([`dataset`]), `pav-detect` ([`detect`]), `pav-uv` ([`uv`]) |
//! | 2 jobs | `pav-attack` ([`attack`], the optimizer), `pav-eval` ([`eval`], scoring), `pav-rig` ([`rig`], turntable and capture) |
//! | 3 studies and tooling | `pav-studies` ([`studies`]): the paper's tables and the studies, which combine the optimizer and scoring; `pav-results` ([`results`]): results tables as data; `pav-cluster` ([`cluster`]): job scripts for a cluster; `pav-reference` ([`reference`]): the reference pages |
//! | 4 binaries | this crate: `pav` and `pav-rig`, clap and printing, one file per command |
//!
//! This crate re-exports each lower crate under its module name, so `pav::detect` is
//! `pav_detect` and `pav::image` is `pav_core::image`.
//!
//! Data flows one way: mesh + poses → G-buffers → textured render → EoT → composite → detector
//! → loss → texture; and video → frames → detections → metrics → reports.
#![warn(missing_docs)]

#[cfg(feature = "plot")]
pub use pav_core::plot;
#[cfg(feature = "video")]
pub use pav_core::video;
pub use pav_core::{colour, durable, extends, geometry, image, path, progress, rng, sidecar, step, table};
pub use pav_run::{data, provenance, shard, stop};

pub use pav_attack as attack;
pub use pav_cluster as cluster;
pub use pav_dataset as dataset;
pub use pav_detect as detect;
#[cfg(feature = "doctor")]
pub use pav_doctor as doctor;
pub use pav_eval as eval;
pub use pav_print as print;
pub use pav_reference as reference;
pub use pav_render as render;
pub use pav_results as results;
#[cfg(feature = "rig")]
pub use pav_rig as rig;
pub use pav_scene as scene;
pub use pav_uv as uv;

#[cfg(feature = "optimize")]
pub use pav_studies as studies;
