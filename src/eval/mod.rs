//! Scoring recorded videos: decode, detect, A_physical, reports and plots.

#[cfg(feature = "eval")]
pub mod bench;
pub mod physical;
#[cfg(feature = "eval")]
pub mod plot;
pub mod report;
#[cfg(feature = "eval")]
pub mod run;
#[cfg(feature = "eval")]
pub mod video;
