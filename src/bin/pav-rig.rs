//! `pav-rig`: the physical test rig — score recorded turntable videos with real detectors.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use pav::detect::darknet::{to_onnx, Network, Weights};
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav::eval::run::{default_label, evaluate, EvalOptions, VideoJob};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "pav-rig",
    version,
    about = "Physical rig for adversarial vehicle camouflage: evaluate recorded turntable videos"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Score every frame of one or more videos with one or more detectors (A_physical).
    Evaluate(EvaluateArgs),
    /// Model utilities.
    #[command(subcommand)]
    Model(ModelCmd),
    /// Benchmark: decode / inference / evaluate throughput and the accuracy-vs-time trade-off (CSV + PNG).
    Bench(BenchArgs),
}

#[derive(Args)]
struct BenchArgs {
    /// Video to score.
    #[arg(long, default_value = "fixtures/carla_orbit.mp4")]
    video: PathBuf,
    /// Detector configs or directories of them (default: configs/detectors).
    #[arg(long = "detector", short = 'd')]
    detectors: Vec<PathBuf>,
    /// Strides for the trade-off.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    strides: Vec<usize>,
    /// Second input size, for models that accept any input size.
    #[arg(long, default_value_t = 320)]
    alt_size: usize,
    /// ONNX Runtime intra-op threads (0 = runtime default).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Timed repetitions; the fastest is kept.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Score threshold.
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    /// Output directory.
    #[arg(long, short = 'o', default_value = "bench")]
    out: PathBuf,
}

#[derive(Subcommand)]
enum ModelCmd {
    /// Convert a darknet cfg + weights (YOLOv3/YOLOv3-tiny) to an ONNX graph with raw head outputs.
    Darknet2onnx {
        /// Darknet .cfg file.
        #[arg(long)]
        cfg: PathBuf,
        /// Darknet .weights file.
        #[arg(long)]
        weights: PathBuf,
        /// Output .onnx path.
        #[arg(long)]
        out: PathBuf,
    },
}

/// Options shared by `evaluate` and the benchmark.
#[derive(Args, Clone)]
struct EvaluateArgs {
    /// Video files (mp4, avi, mkv, ...). Each may have a `<name>.angles.csv` sidecar beside it.
    #[arg(required = true)]
    videos: Vec<PathBuf>,
    /// Detector config TOML, or a directory of them; repeat for several detectors.
    #[arg(long = "detector", short = 'd', required = true)]
    detectors: Vec<PathBuf>,
    /// Label per video, in order (default: file stem), e.g. `--label original --label camouflaged`.
    #[arg(long = "label")]
    labels: Vec<String>,
    /// Angle sidecar CSV (frame,timestamp_s,angle_deg), only with a single video.
    #[arg(long)]
    sidecar: Option<PathBuf>,
    /// Score every N-th frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stride: u64,
    /// A frame counts as "car detected" when a target-class score is at least this.
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    /// Target classes overriding the configs, comma-separated (e.g. `car,truck`).
    #[arg(long, value_delimiter = ',')]
    classes: Vec<String>,
    /// Turntable period for videos without a sidecar, e.g. `28s` or `28`.
    #[arg(long, default_value = "28s", value_parser = parse_seconds)]
    rotation_period: f64,
    /// Turntable angle at the first frame for videos without a sidecar (degrees).
    #[arg(long, default_value_t = 0.0)]
    start_angle: f64,
    /// Angle sectors in the per-angle breakdown.
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u64).range(1..=360))]
    angle_bins: u64,
    /// Output directory for CSV, Markdown and PNG reports.
    #[arg(long, short = 'o', default_value = "out/evaluate")]
    out: PathBuf,
    /// ONNX Runtime intra-op threads per detector (0 = runtime default).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Skip the PNG plots.
    #[arg(long)]
    no_plots: bool,
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .trim_end_matches('s')
        .parse()
        .map_err(|_| format!("`{s}` is not a duration like 28s"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("rotation period must be positive, got {s}"))
    }
}

/// Expands directories into the TOML files they hold (sorted); files pass through.
fn expand_configs(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("listing {}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "toml"))
                .collect();
            if found.is_empty() {
                bail!("{} holds no detector configs (*.toml)", p.display());
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

fn load_detectors(
    paths: &[PathBuf],
    classes: &[String],
    threads: usize,
) -> Result<Vec<Box<dyn Detector>>> {
    let paths = &expand_configs(paths)?;
    // Validate every config before loading any model, so all config mistakes show at once.
    let mut cfgs = Vec::new();
    let mut errors = Vec::new();
    for p in paths {
        match DetectorConfig::load(p) {
            Ok(mut c) => {
                if !classes.is_empty() {
                    if let Err(e) = c.set_targets(classes) {
                        errors.push(format!("{}: {e}", p.display()));
                    }
                }
                cfgs.push(c);
            }
            Err(e) => errors.push(e.to_string()),
        }
    }
    if !errors.is_empty() {
        bail!("invalid detector config:\n  {}", errors.join("\n  "));
    }
    let mut names: Vec<&str> = cfgs.iter().map(|c| c.name.as_str()).collect();
    names.sort();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        bail!("two detector configs are both named `{}`", w[0]);
    }
    cfgs.into_iter()
        .map(|c| {
            OnnxDetector::new(c, threads)
                .map(|d| Box::new(d) as Box<dyn Detector>)
                .map_err(anyhow::Error::from)
        })
        .collect()
}

fn jobs(a: &EvaluateArgs) -> Result<Vec<VideoJob>> {
    if !a.labels.is_empty() && a.labels.len() != a.videos.len() {
        bail!(
            "{} labels given for {} videos: give one --label per video or none",
            a.labels.len(),
            a.videos.len()
        );
    }
    if a.sidecar.is_some() && a.videos.len() != 1 {
        bail!(
            "--sidecar applies to a single video; with several, put <name>.angles.csv beside each"
        );
    }
    let mut out: Vec<VideoJob> = Vec::new();
    for (i, v) in a.videos.iter().enumerate() {
        let label = a.labels.get(i).cloned().unwrap_or_else(|| default_label(v));
        if out.iter().any(|j| j.label == label) {
            bail!("two videos share the label `{label}`: use --label to tell them apart");
        }
        out.push(VideoJob {
            path: v.clone(),
            label,
            sidecar: a.sidecar.clone(),
        });
    }
    Ok(out)
}

fn cmd_evaluate(a: &EvaluateArgs) -> Result<()> {
    if !(0.0..=1.0).contains(&a.threshold) {
        bail!("--threshold {} must be within [0, 1]", a.threshold);
    }
    let jobs = jobs(a)?;
    let mut detectors = load_detectors(&a.detectors, &a.classes, a.threads)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    let opts = EvalOptions {
        threshold: a.threshold,
        stride: a.stride as usize,
        rotation_period_s: a.rotation_period,
        start_angle_deg: a.start_angle,
        angle_bins: a.angle_bins as usize,
        out_dir: a.out.clone(),
        progress: true,
        plots: !a.no_plots,
    };
    eprintln!(
        "scoring {} video(s) with {} detector(s); threshold {}, classes {}, stride {}",
        jobs.len(),
        detectors.len(),
        a.threshold,
        detectors
            .iter()
            .map(|d| format!("{}={}", d.name(), d.target_label()))
            .collect::<Vec<_>>()
            .join(", "),
        a.stride
    );
    let out = evaluate(&jobs, &mut detectors, &opts, &stop)?;
    println!(
        "{}",
        pav::eval::report::summary_table(&out.rows, a.threshold)
    );
    for f in &out.files {
        eprintln!("wrote {}", f.display());
    }
    if out.interrupted {
        bail!("interrupted: reports above cover the frames scored before Ctrl-C");
    }
    if !out.failures.is_empty() {
        bail!(
            "{} problem(s); results above cover what could be scored:\n  {}",
            out.failures.len(),
            out.failures.join("\n  ")
        );
    }
    Ok(())
}

fn cmd_darknet2onnx(cfg: &Path, weights: &Path, out: &Path) -> Result<()> {
    let net = Network::from_file(cfg)?;
    let w = Weights::from_file(weights, &net)?;
    let model = to_onnx::export(&net, &w)?;
    let bytes = model.to_bytes();
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    // Write then rename so an interrupted conversion never leaves a half model behind.
    let tmp = out.with_extension("onnx.part");
    std::fs::write(&tmp, &bytes).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, out).with_context(|| format!("renaming to {}", out.display()))?;
    eprintln!(
        "wrote {} ({} layers, {} heads, {:.1} MB)",
        out.display(),
        net.layers.len(),
        model.outputs.len(),
        bytes.len() as f64 / 1e6
    );
    Ok(())
}

fn cmd_bench(b: &BenchArgs) -> Result<()> {
    let given = if b.detectors.is_empty() {
        vec![PathBuf::from("configs/detectors")]
    } else {
        b.detectors.clone()
    };
    let detectors = expand_configs(&given)?;
    if b.strides.is_empty() || b.strides.contains(&0) {
        bail!("--strides must be positive, got {:?}", b.strides);
    }
    let opts = pav::eval::bench::BenchOptions {
        video: b.video.clone(),
        detectors,
        strides: b.strides.clone(),
        alt_size: Some(b.alt_size),
        threads: b.threads,
        repeats: b.repeats,
        threshold: b.threshold,
        out_dir: b.out.clone(),
    };
    pav::eval::bench::run(&opts)?;
    for f in ["throughput.csv", "tradeoff.csv", "tradeoff.png"] {
        eprintln!("wrote {}", b.out.join(f).display());
    }
    Ok(())
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match &cli.cmd {
        Cmd::Evaluate(a) => cmd_evaluate(a),
        Cmd::Model(ModelCmd::Darknet2onnx { cfg, weights, out }) => {
            cmd_darknet2onnx(cfg, weights, out)
        }
        Cmd::Bench(b) => cmd_bench(b),
    }
}
