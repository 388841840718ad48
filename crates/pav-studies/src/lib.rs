//! Experiments that combine the optimizer with scoring: a `pav optimize` run and what it leaves
//! behind, the paper's Table II on composites, and cross-validation of the whole attack.

pub mod advtrain;
pub mod boxes;
pub mod crossval;
pub mod curve;
pub mod lofo;
pub mod outputs;
pub mod per_view;
pub mod table1;
pub mod table2;

use pav_attack::setup::Setup;
use pav_print::channel::{PrintChannel, PrintConfig};
use std::path::{Path, PathBuf};

/// Why an experiment failed.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// The optimization config.
    #[error(transparent)]
    Config(#[from] pav_attack::config::ConfigError),
    /// Preparing the views.
    #[error(transparent)]
    Setup(Box<pav_attack::setup::SetupError>),
    /// The white-box detector.
    #[error(transparent)]
    WhiteBox(#[from] pav_attack::whitebox::WhiteBoxError),
    /// The optimization.
    #[error(transparent)]
    Optimize(Box<pav_attack::optimize::OptimizeError>),
    /// Filtering the rendered views (`views.pbr_min_score`).
    #[error(transparent)]
    Keep(#[from] pav_attack::setup::KeepError),
    /// The printable sheet.
    #[error(transparent)]
    Sheet(#[from] pav_attack::export::SheetError),
    /// A scoring detector.
    #[error(transparent)]
    Detect(#[from] pav_detect::DetectError),
    /// An image file.
    #[error(transparent)]
    Image(#[from] pav_core::image::ImageError),
    /// A chart.
    #[error(transparent)]
    Plot(#[from] pav_core::plot::PlotError),
    /// A CSV table.
    #[error(transparent)]
    Table(#[from] pav_core::table::TableError),
    /// The print channel's profile.
    #[error("print profile: {0}")]
    Print(#[from] pav_print::proof::ProofError),
    /// Shards of a job array.
    #[error(transparent)]
    Shard(#[from] pav_run::shard::ShardError),
    /// A file or folder.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// An input that cannot be used as given.
    #[error("{0}")]
    Invalid(String),
    /// Ctrl-C stopped the experiment; its finished work is kept.
    #[error("stopped; run again to resume from {0}")]
    Stopped(PathBuf),
}

// Boxed: these two are large, and every experiment returns this error.
impl From<pav_attack::setup::SetupError> for ExperimentError {
    fn from(e: pav_attack::setup::SetupError) -> Self {
        ExperimentError::Setup(Box::new(e))
    }
}

impl From<pav_attack::optimize::OptimizeError> for ExperimentError {
    fn from(e: pav_attack::optimize::OptimizeError) -> Self {
        ExperimentError::Optimize(Box::new(e))
    }
}

/// How composites are scored: which detectors, at which threshold. The config's `[[white_box]]`
/// detectors are starred in tables; the others are black boxes.
#[derive(Clone, Debug)]
pub struct Scoring {
    /// Detector configs or folders of them.
    pub detectors: Vec<PathBuf>,
    /// A car counts as detected when its score reaches this (`detect::detected`).
    pub threshold: f32,
    /// Score textures as this printer prints them; `None`: as the config's `[print]` table
    /// says (unprinted without one).
    pub print: Option<PrintConfig>,
    /// Each detector is also scored behind each of these defence chains (`--defence`).
    pub defences: Vec<Vec<pav_detect::defence::Defence>>,
}

impl Scoring {
    /// Sets the channel `setup`'s scores see textures through.
    pub fn apply_print(&self, setup: &mut Setup) -> Result<(), ExperimentError> {
        if let Some(p) = &self.print {
            setup.print_scored = Some(PrintChannel::open(p)?);
        }
        Ok(())
    }
}

/// Creates `dir` and its parents.
fn create_dir(dir: &Path) -> Result<(), ExperimentError> {
    std::fs::create_dir_all(dir).map_err(|source| ExperimentError::Io { path: dir.into(), source })
}

/// Writes a Markdown report to `out/name`.
fn write_markdown(out: &Path, name: &str, md: &str) -> Result<(), ExperimentError> {
    write_file(&out.join(name), md)
}

/// Writes `bytes` to `path` whole or not at all, naming the file in the error.
fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<(), ExperimentError> {
    pav_core::durable::write(path, bytes).map_err(|source| ExperimentError::Io { path: path.into(), source })
}
