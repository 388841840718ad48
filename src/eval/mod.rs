//! Scoring detectors: recorded videos (decode, detect, A_physical, reports, charts), the metrics
//! of digital composites (ASR, P@0.5), and what evaluation costs in time.

/// The one detection rule of every metric (A_physical, ASR, the white-box reports): a car counts
/// as detected when its score reaches the threshold. The paper uses 0.5; the authors' code counts
/// `score > 0.6`, which differs from `score ≥ 0.6` only for a score of exactly 0.6.
pub fn detected(score: f32, threshold: f32) -> bool {
    score >= threshold
}

#[cfg(feature = "eval")]
pub mod bench;
#[cfg(feature = "eval")]
mod charts;
pub mod digital;
pub mod physical;
#[cfg(feature = "eval")]
pub mod report;
#[cfg(feature = "eval")]
pub mod run;
