//! pav: physical adversarial camouflage for vehicles (PAV-Camou) and the rig that scores it.
//!
//! Data flows one way: video → frames → detections → metrics → report (see `eval`), and
//! mesh → render → composite → detect → loss for texture optimization.

pub mod attack;
pub mod dataset;
pub mod detect;
pub mod eval;
pub mod geometry;
pub mod render;
#[cfg(feature = "rig")]
pub mod rig;
pub mod rng;
pub mod scene;
pub mod sidecar;
