//! `pav-rig bench`: what evaluation costs in time, and what cheaper settings cost in accuracy.
//!
//! Writes `throughput.csv` (decode, bare ONNX Runtime inference, full detector and whole
//! `evaluate` frames/s per detector) and `tradeoff.csv` + `tradeoff.png` (A_physical and seconds
//! for each stride and input size).

use super::physical::Accuracy;
use super::report::ReportError;
use super::run::{evaluate, side_by_side, EvalOptions, Sharing, VideoJob};
use pav_core::image::Frame;
use pav_core::plot::{labelled_lines, LabelledLine, PlotError};
use pav_core::progress::{Progress, Silent};
use pav_core::table::unique;
use pav_core::table::{write_csv, TableError};
use pav_core::video::{VideoError, VideoReader};
use pav_detect::onnx::OnnxDetector;
use pav_detect::preprocess::prepare;
use pav_detect::{DetectError, Detector, DetectorConfig};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// Benchmark settings.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Video to score.
    pub video: PathBuf,
    /// Detector configs.
    pub detectors: Vec<PathBuf>,
    /// Strides for the trade-off.
    pub strides: Vec<usize>,
    /// Second input size for models whose spatial input size is free.
    pub alt_size: Option<usize>,
    /// ONNX Runtime intra-op threads (0 = as evaluate chooses).
    pub threads: usize,
    /// Frames scored at once (0 = as evaluate chooses).
    pub lanes: usize,
    /// Timed repetitions; the fastest is kept.
    pub repeats: usize,
    /// Score threshold.
    pub threshold: f32,
    /// Output directory.
    pub out_dir: PathBuf,
}

/// One row of `throughput.csv`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Throughput {
    /// Detector name.
    pub detector: String,
    /// Input size `WxH`.
    pub input: String,
    /// Intra-op threads per model copy (0 = runtime default).
    pub threads: usize,
    /// Frames scored at once, each by its own copy of the model; bare inference and the
    /// detector alone are timed the same way, so the ratio compares like with like.
    pub lanes: usize,
    /// Frames in the video.
    pub frames: usize,
    /// Video decode frames/s.
    pub decode_fps: f64,
    /// Preprocessing (resize, normalize) ms per frame.
    pub preprocess_ms: f64,
    /// Bare `Session::run` ms per frame on prepared inputs (wall time over all lanes).
    pub bare_infer_ms: f64,
    /// Bare inference frames/s.
    pub bare_infer_fps: f64,
    /// Preprocess + inference + output decoding frames/s.
    pub detector_fps: f64,
    /// Whole `evaluate` (decode, detect, records, reports) frames/s.
    pub evaluate_fps: f64,
    /// `evaluate_fps / bare_infer_fps`: the share of raw model speed the pipeline keeps.
    pub evaluate_over_bare: f64,
}

/// One row of `tradeoff.csv`.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Tradeoff {
    /// Detector name.
    pub detector: String,
    /// Input size `WxH`.
    pub input: String,
    /// Every N-th frame scored.
    pub stride: usize,
    /// f_o.
    pub frames_scored: usize,
    /// f_d.
    pub detected: usize,
    /// A_physical.
    pub a_physical: f64,
    /// Wall seconds for the whole `evaluate`.
    pub seconds: f64,
    /// Video frames covered per second.
    pub video_fps: f64,
}

/// Why a benchmark failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The video.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The video decoded to nothing.
    #[error("{0} has no decodable frames")]
    NoFrames(PathBuf),
    /// A detector.
    #[error(transparent)]
    Detect(#[from] DetectError),
    /// `evaluate` itself.
    #[error(transparent)]
    Report(#[from] ReportError),
    /// `evaluate` ran but reported problems.
    #[error("evaluate failed: {0}")]
    Evaluate(String),
    /// Writing the CSVs.
    #[error(transparent)]
    Table(#[from] TableError),
    /// Drawing the plot.
    #[error(transparent)]
    Plot(#[from] pav_core::plot::PlotError),
    /// Creating the output folder.
    #[error("creating {path}: {source}")]
    Io {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

type Result<T> = std::result::Result<T, BenchError>;

fn best_of<T>(repeats: usize, mut f: impl FnMut() -> Result<T>) -> Result<(f64, T)> {
    let mut best: Option<(f64, T)> = None;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let v = f()?;
        let s = t.elapsed().as_secs_f64();
        if best.as_ref().is_none_or(|b| s < b.0) {
            best = Some((s, v));
        }
    }
    Ok(best.expect("at least one repeat"))
}

/// How one detector shares the cores in the benchmark: as `evaluate` would share them.
fn sharing(opts: &BenchOptions) -> Sharing {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    side_by_side(1, cores, 0, opts.lanes, opts.threads)
}

fn decode_all(video: &Path) -> Result<Vec<Frame>> {
    let mut r = VideoReader::open(video)?;
    let mut frames = Vec::new();
    while let Some((_, f)) = r.read()? {
        frames.push(f);
    }
    if frames.is_empty() {
        return Err(BenchError::NoFrames(video.into()));
    }
    Ok(frames)
}

/// Runs `work` on each lane's copy of a model with every `lanes`-th item (lane k takes items
/// k, k + lanes, …), the lanes side by side.
fn across_lanes<T: Send>(
    dets: &mut [OnnxDetector],
    items: Vec<T>,
    work: impl Fn(&mut OnnxDetector, T) -> Result<()> + Sync,
) -> Result<()> {
    let lanes = dets.len().max(1);
    let mut split: Vec<Vec<T>> = (0..lanes).map(|_| Vec::new()).collect();
    for (i, x) in items.into_iter().enumerate() {
        split[i % lanes].push(x);
    }
    if lanes == 1 {
        return split.pop().unwrap_or_default().into_iter().try_for_each(|x| work(&mut dets[0], x));
    }
    std::thread::scope(|s| {
        let handles: Vec<_> = dets
            .iter_mut()
            .zip(split)
            .map(|(d, xs)| {
                let work = &work;
                s.spawn(move || xs.into_iter().try_for_each(|x| work(d, x)))
            })
            .collect();
        handles.into_iter().try_for_each(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
    })
}

fn run_evaluate(
    opts: &BenchOptions,
    sharing: Sharing,
    cfg: &DetectorConfig,
    stride: usize,
) -> Result<(f64, Accuracy, usize)> {
    let tmp = std::env::temp_dir().join(format!("pav-bench-{}", std::process::id()));
    let eval_opts = EvalOptions {
        threshold: opts.threshold,
        frames: super::run::Frames::Stride(stride),
        period_s: 28.0,
        start_angle_deg: 0.0,
        sectors: 12,
        out_dir: tmp.clone(),
        plots: false,
        parallel: 1,
        lanes: sharing.lanes,
        drift: super::drift::DriftLimits::default(),
    };
    let job = VideoJob { path: opts.video.clone(), label: "bench".into(), sidecar: None };
    let mut dets: Vec<Box<dyn Detector>> = vec![Box::new(OnnxDetector::new(cfg.clone(), sharing.threads)?)];
    let (secs, out) = best_of(opts.repeats, || {
        Ok(evaluate(std::slice::from_ref(&job), &mut dets, &eval_opts, &Silent, &AtomicBool::new(false))?)
    })?;
    let _ = std::fs::remove_dir_all(&tmp);
    if !out.failures.is_empty() {
        return Err(BenchError::Evaluate(out.failures.join("; ")));
    }
    Ok((secs, out.rows[0].accuracy, out.timing.frames_decoded))
}

/// Runs the benchmark and writes its CSVs and plot into `opts.out_dir`; each measurement is a
/// note on `progress`.
pub fn bench_evaluate(opts: &BenchOptions, progress: &dyn Progress) -> Result<(Vec<Throughput>, Vec<Tradeoff>)> {
    std::fs::create_dir_all(&opts.out_dir).map_err(|source| BenchError::Io { path: opts.out_dir.clone(), source })?;
    let (decode_s, frames) = best_of(opts.repeats, || decode_all(&opts.video))?;
    let n = frames.len();
    progress.note(&format!("decode: {n} frames in {decode_s:.3} s ({:.0} fps)", n as f64 / decode_s));
    let mut thr = Vec::new();
    let mut trade = Vec::new();
    let sharing = sharing(opts);
    for path in &opts.detectors {
        let cfg = DetectorConfig::load(path)?;
        let mut dets = (0..sharing.lanes)
            .map(|_| OnnxDetector::new(cfg.clone(), sharing.threads))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let input = format!("{}x{}", cfg.input.width, cfg.input.height);
        for det in &mut dets {
            for f in frames.iter().take(2) {
                det.propose(f)?; // warm-up: first runs allocate and pick kernels
            }
        }
        let (pre_s, inputs) = best_of(opts.repeats, || {
            frames
                .iter()
                .map(|f| prepare(f, &cfg.input))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(|source| DetectError::Defence { detector: cfg.name.clone(), source }.into())
        })?;
        let mut bare_s = f64::INFINITY;
        for _ in 0..opts.repeats.max(1) {
            let batch = inputs.clone();
            let t = Instant::now();
            across_lanes(&mut dets, batch, |d, (x, map)| {
                d.infer(x, &map)?;
                Ok(())
            })?;
            bare_s = bare_s.min(t.elapsed().as_secs_f64());
        }
        let (det_s, _) = best_of(opts.repeats, || {
            across_lanes(&mut dets, frames.iter().collect(), |d, f| {
                d.propose(f)?;
                Ok(())
            })
        })?;
        let (eval_s, _, decoded) = run_evaluate(opts, sharing, &cfg, 1)?;
        let row = Throughput {
            detector: cfg.name.clone(),
            input: input.clone(),
            threads: sharing.threads,
            lanes: sharing.lanes,
            frames: n,
            decode_fps: n as f64 / decode_s,
            preprocess_ms: 1e3 * pre_s / n as f64,
            bare_infer_ms: 1e3 * bare_s / n as f64,
            bare_infer_fps: n as f64 / bare_s,
            detector_fps: n as f64 / det_s,
            evaluate_fps: decoded as f64 / eval_s,
            evaluate_over_bare: (decoded as f64 / eval_s) / (n as f64 / bare_s),
        };
        progress.note(&format!(
            "{}: bare {:.1} fps, detector {:.1} fps, evaluate {:.1} fps ({:.0} % of bare)",
            row.detector,
            row.bare_infer_fps,
            row.detector_fps,
            row.evaluate_fps,
            100.0 * row.evaluate_over_bare
        ));
        thr.push(row);
        let mut sizes = vec![cfg.clone()];
        if let Some(s) = opts.alt_size.filter(|&s| s != cfg.input.width || s != cfg.input.height) {
            if dets[0].accepts_any_size() {
                let mut c = cfg.clone();
                (c.input.width, c.input.height) = (s, s);
                sizes.push(c);
            } else {
                progress.note(&format!("{}: fixed input size, skipping {s}x{s}", cfg.name));
            }
        }
        for c in &sizes {
            for &stride in &opts.strides {
                let (secs, acc, decoded) = run_evaluate(opts, sharing, c, stride)?;
                let t = Tradeoff {
                    detector: c.name.clone(),
                    input: format!("{}x{}", c.input.width, c.input.height),
                    stride,
                    frames_scored: acc.total,
                    detected: acc.detected,
                    a_physical: acc.rate().unwrap_or(f64::NAN),
                    seconds: secs,
                    video_fps: decoded as f64 / secs,
                };
                progress.note(&format!("  {} stride {stride}: A = {:.3} in {secs:.2} s", t.input, t.a_physical));
                trade.push(t);
            }
        }
    }
    write_csv(&opts.out_dir.join("throughput.csv"), &thr)?;
    write_csv(&opts.out_dir.join("tradeoff.csv"), &trade)?;
    plot_tradeoff(&opts.out_dir.join("tradeoff.png"), &trade)?;
    Ok((thr, trade))
}

/// Accuracy against time: one line per (detector, input size), one labelled point per stride.
fn plot_tradeoff(path: &Path, rows: &[Tradeoff]) -> std::result::Result<(), PlotError> {
    let lines: Vec<LabelledLine> = unique(rows.iter().map(|r| (r.detector.clone(), r.input.clone())))
        .into_iter()
        .map(|(d, inp)| LabelledLine {
            points: rows
                .iter()
                .filter(|r| r.detector == d && r.input == inp)
                .map(|r| (r.seconds, 100.0 * r.a_physical, format!("{}", r.stride)))
                .collect(),
            label: format!("{d} {inp}"),
        })
        .collect();
    labelled_lines(
        path,
        "What accuracy costs in time (labels: stride)",
        ("seconds per video", "A_physical [%]"),
        &lines,
    )
}
