//! How long jobs report how far they are. The library calls a [`Progress`]; binaries draw it
//! (a progress bar on a terminal) and tests pass [`Silent`].

/// Receives progress from a long job. Every method has a no-op default.
pub trait Progress {
    /// A new stage of `total` units (frames, steps, views; 0 when unknown), named `label`.
    fn begin(&self, _label: &str, _total: u64) {}
    /// `n` more units of the current stage are done.
    fn advance(&self, _n: u64) {}
    /// Jumps to `done` units (a resumed job starts part way).
    fn set_position(&self, _done: u64) {}
    /// A short status for the current stage (the latest loss, an angle).
    fn status(&self, _msg: &str) {}
    /// A line worth keeping above the bar (a skipped step, a warning).
    fn note(&self, _line: &str) {}
    /// The current stage is over; `kept` says whether its last state stays shown.
    fn end(&self, _kept: Option<&str>) {}
}

/// Reports nothing.
pub struct Silent;

impl Progress for Silent {}
