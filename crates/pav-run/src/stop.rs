//! How a long job is stopped. The first Ctrl-C, SIGTERM or SIGHUP asks it to stop after the unit
//! of work in progress (a view, a frame, a step), keeping everything finished and saying how to
//! go on; a second one ends the process at once, for a user who cannot wait for the unit (a
//! Blender batch, a slow model) and accepts losing it.

use std::sync::atomic::{AtomicBool, Ordering};

/// What a signal does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnSignal {
    /// The first: the job finishes the unit in progress, then stops.
    Finish,
    /// A second: the process ends now.
    Quit,
}

/// The exit status of a process ended at once by a second signal: 128 + SIGINT, as a shell
/// reports a process Ctrl-C ended.
pub const QUIT_STATUS: i32 = 130;

/// Raises the job's stop `flag`, and says what this signal does: the first finishes the unit in
/// progress, any later one quits.
pub fn on_signal(flag: &AtomicBool) -> OnSignal {
    if flag.swap(true, Ordering::SeqCst) {
        OnSignal::Quit
    } else {
        OnSignal::Finish
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_signal_finishes_the_unit_and_a_second_quits() {
        let flag = AtomicBool::new(false);
        assert_eq!(on_signal(&flag), OnSignal::Finish);
        assert!(flag.load(Ordering::SeqCst), "the job sees the stop");
        assert_eq!(on_signal(&flag), OnSignal::Quit);
        assert_eq!(on_signal(&flag), OnSignal::Quit);
    }
}
