//! `pav-rig evaluate`.

use crate::common::{ctrl_c_flag, defence_chains, parse_defence, parse_seconds, Bar, DefenceArg, ShardArgs};
use anyhow::{bail, Result};
use pav::detect::load::load_detectors;
use pav::eval::drift::DriftLimits;
use pav::eval::report::summary_table;
use pav::eval::run::{evaluate, video_jobs, EvalOptions, EvalOutcome, Frames, VideoJob};
use pav::eval::squeeze::Thresholds;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Video files (mp4, avi, mkv, ...). Each may have a `<name>.angles.csv` sidecar beside it.
    #[arg(required = true)]
    videos: Vec<PathBuf>,
    /// Detector config TOML, or a directory of them; repeat for several detectors.
    #[arg(long = "detectors", short = 'd', alias = "detector", default_value = "configs/detectors")]
    detectors: Vec<PathBuf>,
    /// Label per video, in order (default: file stem), e.g. `--label original --label camouflaged`.
    /// Videos given the same label are pooled into one row (e.g. the two polar angles of a texture).
    #[arg(long = "label")]
    labels: Vec<String>,
    /// Angle sidecar CSV (frame,timestamp_s,angle_deg), only with a single video.
    #[arg(long)]
    sidecar: Option<PathBuf>,
    /// Score every N-th frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stride: u64,
    /// Score N frames evenly spaced over each video instead (the middle frame of each of N equal
    /// stretches; the paper's Table V cells look like 44 per video, two videos pooled).
    #[arg(long, value_name = "N", conflicts_with = "stride", value_parser = clap::value_parser!(u64).range(1..))]
    sample: Option<u64>,
    /// A frame counts as "car detected" when a target-class score is at least this.
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    /// Target classes overriding the configs, comma-separated (e.g. `car,truck`).
    #[arg(long, value_delimiter = ',')]
    classes: Vec<String>,
    /// Seconds per turn for videos without a sidecar, e.g. `28s` or `28`.
    #[arg(long, alias = "rotation-period", default_value = "28s", value_parser = parse_seconds)]
    period: f64,
    /// Turntable angle at the first frame for videos without a sidecar (degrees).
    #[arg(long, default_value_t = 0.0)]
    start_angle: f64,
    /// Angle sectors in the per-angle breakdown.
    #[arg(long, alias = "angle-bins", default_value_t = 12, value_parser = clap::value_parser!(u64).range(1..=360))]
    sectors: u64,
    /// Output directory for CSV, Markdown and PNG reports.
    #[arg(long, short = 'o', default_value = "out/evaluate")]
    out: PathBuf,
    /// ONNX Runtime intra-op threads per detector (0: one each when detectors or frames run side
    /// by side, else ONNX Runtime's default of one per core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Detectors run side by side on each frame, each on a thread (0: one per core when there
    /// are several detectors and --threads is not given; 1: one after another).
    #[arg(long, default_value_t = 0)]
    parallel: usize,
    /// Frames scored at once, each with its own copy of every model (0: the cores the detectors
    /// leave free, at most 4, when neither --threads nor --parallel is given; 1: one at a time).
    #[arg(long, default_value_t = 0)]
    lanes: usize,
    /// Also score each detector behind this input defence, named `DETECTOR+LABEL`: `median:k=3`,
    /// `bits:b=5`, `jpeg:q=75`, `cutout:n=2,s=40`, `noise:sigma=8`; `+` chains them. Repeat for
    /// several; the undefended detectors stay, so each defence's clean cost shows beside it.
    #[arg(long = "defence", value_name = "SPEC", value_parser = parse_defence)]
    defences: Vec<DefenceArg>,
    /// Feature squeezing as an attack detector (Xu et al.): also score each detector behind bit
    /// depth 4 and a 3×3 median (`DETECTOR+bits4`, `DETECTOR+median3`) and flag the frames whose
    /// best car score either moves by more than a threshold; writes squeeze.csv and squeeze.md.
    #[arg(long)]
    squeeze: bool,
    /// With --squeeze: labels of legitimate videos (the original paint); each detector's threshold
    /// flags --squeeze-false-flags of their frames. Repeatable.
    #[arg(long = "squeeze-clean", value_name = "LABEL", requires = "squeeze")]
    squeeze_clean: Vec<String>,
    /// With --squeeze-clean: the share of legitimate frames flagged.
    #[arg(long, default_value_t = 0.05, requires = "squeeze_clean")]
    squeeze_false_flags: f64,
    /// With --squeeze: one fixed threshold for every detector instead.
    #[arg(long, requires = "squeeze", conflicts_with = "squeeze_clean")]
    squeeze_threshold: Option<f32>,
    /// Flag a video whose light drifts more than this over the turn, measured on the half of the
    /// scene that stands still (read from the video, not the detectors): the spread of its mean
    /// luminance (5th to 95th percentile) as a share of the median. A camera on automatic
    /// exposure that follows the car drifts; its A_physical is marked ⚠.
    #[arg(long, default_value_t = 0.05)]
    drift_luminance: f64,
    /// Flag a video whose grey-world colour (red or blue share) spreads more than this over the
    /// turn (5th to 95th percentile): automatic white balance.
    #[arg(long, default_value_t = 0.01)]
    drift_colour: f64,
    /// Skip the PNG plots.
    #[arg(long)]
    no_plots: bool,
    #[command(flatten)]
    shard: ShardArgs,
}

pub fn run(a: &Args) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    if a.threads > cores {
        eprintln!(
            "warning: --threads {} is more than this machine's {cores} cores; threads beyond them only take \
             turns (a run can take many times longer); 0 lets ONNX Runtime choose",
            a.threads
        );
    }
    if !(0.0..=1.0).contains(&a.threshold) {
        bail!("--threshold {} must be within [0, 1]", a.threshold);
    }
    if !a.start_angle.is_finite() {
        bail!("--start-angle {} must be a number of degrees", a.start_angle);
    }
    let jobs = video_jobs(&a.videos, &a.labels, a.sidecar.as_deref())?;
    let stop = ctrl_c_flag()?;
    let frames = match a.sample {
        Some(n) => Frames::Even(n as usize),
        None => Frames::Stride(a.stride as usize),
    };
    let squeezing = squeeze(a, &jobs)?;
    let (mut chains, _) = defence_chains(&a.defences);
    if a.squeeze {
        pav::eval::squeeze::add_squeezers(&mut chains);
    }
    let defence_labels = pav::detect::defence::chains_label(&chains);
    let count = pav::detect::load::expand_configs(&a.detectors)?.len() * (1 + chains.len());
    let sharing = pav::eval::run::side_by_side(count, cores, a.parallel, a.lanes, a.threads);
    let opts = EvalOptions {
        threshold: a.threshold,
        frames,
        period_s: a.period,
        start_angle_deg: a.start_angle,
        sectors: a.sectors as usize,
        out_dir: a.out.clone(),
        plots: !a.no_plots,
        parallel: sharing.parallel,
        lanes: sharing.lanes,
        drift: DriftLimits { luminance: a.drift_luminance, colour: a.drift_colour },
    };
    opts.check()?;
    // A merge scores nothing; the others load their detectors before anything is written.
    let mut detectors =
        if a.shard.merge { Vec::new() } else { load_detectors(&a.detectors, &a.classes, &chains, sharing.threads)? };
    let sidecars: Vec<PathBuf> =
        jobs.iter().map(|j| j.sidecar.clone().unwrap_or_else(|| pav::sidecar::sidecar_path(&j.path))).collect();
    let record = pav::provenance::Run::start()
        .inputs(jobs.iter().map(|j| j.path.as_path()).chain(sidecars.iter().map(|p| p.as_path())))
        .inputs(pav::detect::load::detector_inputs(&a.detectors).iter().map(|p| p.as_path()))
        .setting("threshold", a.threshold)
        .setting("defences", &defence_labels)
        .setting("sampling", frames.tag())
        .setting("rotation_period_s", a.period)
        .setting("start_angle_deg", a.start_angle)
        .setting("squeeze", squeezing.as_ref().map_or_else(|| "off".into(), Thresholds::setting))
        .tool("onnxruntime", pav_onnx::runtime::runtime_version())
        .tool("opencv", pav::video::opencv_version());
    let shards = a.shard.write_record(record, &a.out)?;
    if let Some(shards) = shards {
        let out = pav::eval::merge::merge(&shards, jobs.len(), &opts)?;
        eprintln!("joined {} shards of {} video(s)", shards.len(), jobs.len());
        squeeze_report(squeezing.as_ref(), &out, &opts.out_dir)?;
        return report(&out, a.threshold);
    }
    // A shard scores its own videos into its folder; the merge puts them back in order.
    let picked: Vec<usize> = a.shard.shard.map_or_else(|| (0..jobs.len()).collect(), |s| s.units(jobs.len()));
    let jobs: Vec<VideoJob> = picked.iter().map(|&i| jobs[i].clone()).collect();
    let opts = EvalOptions { out_dir: a.shard.record_dir(&a.out), ..opts };
    eprintln!(
        "scoring {} video(s) with {} detector(s){}; threshold {}, classes {}, {}",
        jobs.len(),
        detectors.len(),
        sharing.describe(),
        a.threshold,
        detectors.iter().map(|d| format!("{}={}", d.name(), d.target_label())).collect::<Vec<_>>().join(", "),
        frames
    );
    let out = evaluate(&jobs, &mut detectors, &opts, &Bar::default(), &stop)?;
    if a.shard.shard.is_some() && !out.interrupted {
        let names: Vec<String> = detectors.iter().map(|d| d.name().to_string()).collect();
        pav::eval::merge::write_index(&opts.out_dir, &names, &out, &picked)?;
    } else if !out.interrupted {
        squeeze_report(squeezing.as_ref(), &out, &opts.out_dir)?;
    }
    report(&out, a.threshold)
}

/// `--squeeze`'s thresholds, checked against the videos' labels; `None` without `--squeeze`.
fn squeeze(a: &Args, jobs: &[VideoJob]) -> Result<Option<Thresholds>> {
    if !a.squeeze {
        return Ok(None);
    }
    let how = match a.squeeze_threshold {
        Some(t) => Thresholds::Fixed(t),
        None if a.squeeze_clean.is_empty() => bail!(
            "--squeeze needs --squeeze-clean LABEL (legitimate videos that set each threshold) or --squeeze-threshold T"
        ),
        None => Thresholds::Clean { clean: a.squeeze_clean.clone(), false_flags: a.squeeze_false_flags },
    };
    how.check(&jobs.iter().map(|j| j.label.as_str()).collect::<Vec<_>>())?;
    Ok(Some(how))
}

/// With --squeeze: writes and prints the squeeze report.
fn squeeze_report(how: Option<&Thresholds>, out: &EvalOutcome, dir: &std::path::Path) -> Result<()> {
    if let Some(how) = how {
        outln!("{}", pav::eval::squeeze::write_report(&out.records, how, dir)?);
    }
    Ok(())
}

/// Prints the summary and the files written; fails when the run was cut short or had problems.
fn report(out: &EvalOutcome, threshold: f32) -> Result<()> {
    outln!("{}", summary_table(&out.rows, threshold));
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
