//! Scoring detectors: recorded videos (decode, detect, A_physical, reports, charts), the metrics
//! of digital composites (ASR, P@0.5), and what evaluation costs in time.
#![warn(missing_docs)]

#[cfg(feature = "eval")]
pub mod bench;
#[cfg(feature = "eval")]
mod charts;
pub mod compare;
pub mod digital;
pub mod drift;
#[cfg(feature = "eval")]
pub mod merge;
pub mod paired;
pub mod physical;
#[cfg(feature = "eval")]
pub mod report;
#[cfg(feature = "eval")]
pub mod run;
pub mod squeeze;
