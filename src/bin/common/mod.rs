//! What both binaries share: a terminal progress bar behind the library's `Progress`, and the
//! Ctrl-C flag that long jobs poll.

use anyhow::{Context, Result};
use indicatif::{HumanDuration, ProgressBar, ProgressStyle};
use pav::progress::Progress;
use std::io::IsTerminal;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

mod args;
pub use args::*;

/// A progress bar on stderr, one per stage, notes printed above it. When stderr is not a
/// terminal (a log file, `nohup`, CI) indicatif draws nothing and drops `println`, so the bar
/// writes plain lines instead: each stage's start and end, its count at most every
/// [`LOG_EVERY`], and every note.
pub struct Bar {
    bar: Mutex<Option<ProgressBar>>,
    plain: bool,
    last_line: Mutex<Instant>,
}

/// How often a stage's count is written as a line when stderr is not a terminal.
const LOG_EVERY: Duration = Duration::from_secs(30);

impl Default for Bar {
    fn default() -> Self {
        Bar { bar: Mutex::new(None), plain: !std::io::stderr().is_terminal(), last_line: Mutex::new(Instant::now()) }
    }
}

impl Bar {
    fn with(&self, f: impl FnOnce(&ProgressBar)) {
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            f(b);
        }
    }

    /// In plain mode, the stage's count as a line when `force`d or [`LOG_EVERY`] after the last;
    /// [`Progress::end`] writes the final count.
    fn log_count(&self, force: bool) {
        if !self.plain {
            return;
        }
        let mut last = self.last_line.lock().unwrap_or_else(|e| e.into_inner());
        let b = self.bar.lock().unwrap_or_else(|e| e.into_inner());
        let Some(b) = b.as_ref() else { return };
        if force || last.elapsed() >= LOG_EVERY {
            eprintln!("{}", count_line(b));
            *last = Instant::now();
        }
    }
}

/// `label: pos/len, elapsed (eta) message` for a log file.
fn count_line(b: &ProgressBar) -> String {
    let len = b.length().filter(|&n| n > 0).map_or(String::new(), |n| format!("/{n}"));
    let eta = if b.position() > 0 && b.length().is_some_and(|n| b.position() < n) {
        format!(" (eta {})", HumanDuration(b.eta()))
    } else {
        String::new()
    };
    let msg = b.message();
    let msg = if msg.is_empty() { msg } else { format!(" {msg}") };
    format!("{}: {}{len}, {}{eta}{msg}", b.prefix(), b.position(), HumanDuration(b.elapsed()))
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
        self.log_count(true);
    }
    fn advance(&self, n: u64) {
        self.with(|b| b.inc(n));
        self.log_count(false);
    }
    fn set_position(&self, done: u64) {
        self.with(|b| b.set_position(done));
        self.log_count(true);
    }
    fn status(&self, msg: &str) {
        self.with(|b| b.set_message(msg.to_string()));
    }
    fn note(&self, line: &str) {
        match self.bar.lock().unwrap_or_else(|e| e.into_inner()).as_ref() {
            Some(b) if !self.plain && !b.is_finished() => b.println(line),
            _ => eprintln!("{line}"),
        }
    }
    fn end(&self, kept: Option<&str>) {
        if let Some(b) = self.bar.lock().unwrap_or_else(|e| e.into_inner()).take() {
            if self.plain {
                eprintln!("{}, {}", count_line(&b), kept.unwrap_or("done"));
            }
            match kept {
                Some(msg) => b.abandon_with_message(msg.to_string()),
                None => b.finish_and_clear(),
            }
        }
    }
}

/// A flag that Ctrl-C, SIGTERM or SIGHUP raises, so long runs save their state and stop after
/// the unit in progress (a service manager's stop or a closed terminal loses nothing either); a
/// second signal ends the process at once (`pav::stop`).
pub fn ctrl_c_flag() -> Result<Arc<AtomicBool>> {
    use pav::stop::{on_signal, OnSignal, QUIT_STATUS};
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || match on_signal(&flag) {
        OnSignal::Finish => eprintln!("\nstopping after the unit in progress (Ctrl-C again to stop at once)"),
        OnSignal::Quit => {
            eprintln!("\nstopped at once: the unit in progress is lost, what finished before it is kept");
            std::process::exit(QUIT_STATUS);
        }
    })
    .context("installing the Ctrl-C and SIGTERM handler")?;
    Ok(stop)
}

/// One `--defence` value: a chain of input defences applied left to right.
#[derive(Clone, Debug)]
pub struct DefenceArg(pub Vec<pav::detect::defence::Defence>);

/// Parses `--defence median:k=3`, `jpeg:q=75+bits:b=5`, ...
pub fn parse_defence(s: &str) -> Result<DefenceArg, String> {
    pav::detect::defence::parse_chain(s).map(DefenceArg).map_err(|e| e.to_string())
}

/// The chains of `--defence` values, and their labels for `run.toml` (`median3;jpeg75`).
pub fn defence_chains(args: &[DefenceArg]) -> (Vec<Vec<pav::detect::defence::Defence>>, String) {
    let chains: Vec<_> = args.iter().map(|a| a.0.clone()).collect();
    let labels = pav::detect::defence::chains_label(&chains);
    (chains, labels)
}

/// `--shard K/N` and `--merge`, the same on every job that a cluster's job array can split.
#[derive(clap::Args, Clone, Debug)]
pub struct ShardArgs {
    /// Run only shard K of N (1-based, e.g. `$SLURM_ARRAY_TASK_ID` of an array 1-N) into
    /// <out>/shard-K-of-N with its own run.toml; `--merge` joins the shards afterwards.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<pav::shard::Shard>,
    /// Join the shard folders in <out> into the job's result; give the same arguments the shards
    /// had. Refuses shards of another config, commit or data, and names missing ones.
    #[arg(long, conflicts_with = "shard")]
    pub merge: bool,
}

impl ShardArgs {
    /// Where this run writes its `run.toml`: the shard's folder, or the output folder itself.
    pub fn record_dir(&self, out: &std::path::Path) -> std::path::PathBuf {
        self.shard.map_or_else(|| out.to_path_buf(), |s| s.dir(out))
    }

    /// Records the cut in `run` and writes it: a shard's into its folder; a merge's only after
    /// every shard in `out` is found and matches it, returning them.
    pub fn write_record(
        &self,
        run: pav::provenance::Run,
        out: &std::path::Path,
    ) -> Result<Option<Vec<(pav::shard::Shard, std::path::PathBuf)>>> {
        let (run, shards) = if self.merge {
            let shards = pav::shard::find_checked(out, &run)?;
            (run.setting("shards", shards.len()), Some(shards))
        } else {
            (run.setting("shard", self.shard.map_or("whole".into(), |s| s.to_string())), None)
        };
        let path = self.record_dir(out).join(pav::provenance::FILE);
        run.write(&path).with_context(|| format!("writing {}", path.display()))?;
        Ok(shards)
    }
}

/// `println!` for a command's output on stdout, quiet when the reader has gone (`pav … | head`):
/// the process ends with 141, as one killed by SIGPIPE does, instead of panicking. SIGPIPE itself
/// stays ignored, so a write to a dead encoder is an error the job handles, not a silent death.
macro_rules! outln {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout(), $($t)*) {
            $crate::common::stdout_failed(e)
        }
    }};
}

/// `print!` with [`outln!`]'s handling of a closed stdout.
#[allow(unused_macros)] // pav-rig's commands only
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = write!(std::io::stdout(), $($t)*) {
            $crate::common::stdout_failed(e)
        }
    }};
}

/// Ends the process after a failed write to stdout: quietly with 141 when the reader has gone,
/// else with the error.
pub fn stdout_failed(e: std::io::Error) -> ! {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(141);
    }
    eprintln!("Error: writing to standard output: {e}");
    std::process::exit(1);
}
