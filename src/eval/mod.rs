//! Scoring detectors: recorded videos (decode, detect, A_physical, reports, plots) and digital
//! composites (ASR, P@0.5).

#[cfg(feature = "eval")]
pub mod bench;
#[cfg(feature = "eval")]
pub mod detectors;
pub mod digital;
pub mod physical;
#[cfg(feature = "eval")]
pub mod plot;
pub mod report;
#[cfg(feature = "eval")]
pub mod run;
#[cfg(feature = "eval")]
pub mod video;
