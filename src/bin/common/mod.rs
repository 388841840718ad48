//! What both binaries share: a terminal progress bar behind the library's `Progress`, and the
//! Ctrl-C flag that long jobs poll.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use pav::progress::Progress;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// A progress bar on stderr: one bar per stage, notes printed above it.
#[derive(Default)]
pub struct Bar {
    bar: Mutex<Option<ProgressBar>>,
}

impl Bar {
    fn with(&self, f: impl FnOnce(&ProgressBar)) {
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            f(b);
        }
    }
}

impl Progress for Bar {
    fn begin(&self, label: &str, total: u64) {
        let b = ProgressBar::new(total);
        b.set_style(
            ProgressStyle::with_template("{prefix:>12} [{bar:30}] {pos}/{len} {elapsed_precise} (eta {eta}) {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        b.set_prefix(label.to_string());
        *self.bar.lock().unwrap_or_else(|e| e.into_inner()) = Some(b);
    }
    fn advance(&self, n: u64) {
        self.with(|b| b.inc(n));
    }
    fn set_position(&self, done: u64) {
        self.with(|b| b.set_position(done));
    }
    fn status(&self, msg: &str) {
        self.with(|b| b.set_message(msg.to_string()));
    }
    fn note(&self, line: &str) {
        match self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            Some(b) if !b.is_finished() => b.println(line),
            _ => eprintln!("{line}"),
        }
    }
    fn end(&self, kept: Option<&str>) {
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            match kept {
                Some(msg) => b.abandon_with_message(msg.to_string()),
                None => b.finish_and_clear(),
            }
        }
    }
}

/// A flag that Ctrl-C, SIGTERM or SIGHUP raises, so long runs save their state and stop between
/// steps (a service manager's stop or a closed terminal loses nothing either).
pub fn ctrl_c_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .context("installing the Ctrl-C and SIGTERM handler")?;
    Ok(stop)
}
