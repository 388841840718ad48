//! `pav-rig`: the physical test rig — score recorded turntable videos with real detectors.

use anyhow::{bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use pav::detect::darknet::{to_onnx, Network, Weights};

use pav::eval::run::{default_label, evaluate, EvalOptions, VideoJob};
use pav::rig::camera::{FileSource, FrameSource, LiveCapture, SimCamera};
use pav::rig::capture::{capture, CaptureOptions};
use pav::rig::sim::{Faults, SimOptions, SimTurntable};
use pav::rig::turntable::{self, Turntable, TurntableError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;
use turntable_proto::text::Milli;
use turntable_proto::Command;

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
    /// Benchmark the rig: command round-trip latency and capture angle-sync error (CSV).
    BenchRig(BenchRigArgs),
    /// Drive the turntable directly.
    Turntable(TurntableArgs),
    /// Serve a simulated turntable on a pseudo-terminal (prints its path) until Ctrl-C.
    Simulate(SimulateArgs),
    /// Record one or more turntable revolutions: video plus a per-frame angle sidecar.
    Capture(CaptureArgs),
}

#[derive(Args)]
struct BenchRigArgs {
    /// Serial ports to time besides the simulator (e.g. a QEMU pty or /dev/ttyACM0).
    #[arg(long = "port")]
    ports: Vec<String>,
    /// Round trips per link.
    #[arg(long, default_value_t = 500)]
    n: usize,
    /// Simulated time scales for the angle-sync capture (28 s turn / scale of wall time each).
    #[arg(long, value_delimiter = ',', default_value = "1,4,10")]
    time_scales: Vec<f64>,
    /// Output directory.
    #[arg(long, short = 'o', default_value = "bench")]
    out: PathBuf,
}

#[derive(Args)]
struct PortArgs {
    /// Serial port of the turntable (e.g. /dev/ttyACM0), or `sim` for an in-process simulator.
    #[arg(long, default_value = "/dev/ttyACM0")]
    port: String,
    /// Baud rate (ignored by USB-CDC).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// Per-command timeout in milliseconds.
    #[arg(long, default_value_t = 1000)]
    timeout_ms: u64,
    /// Simulated time speed-up when --port sim.
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
}

#[derive(Args)]
struct TurntableArgs {
    #[command(flatten)]
    port: PortArgs,
    #[command(subcommand)]
    action: TableAction,
}

#[derive(Subcommand)]
enum TableAction {
    /// Print state, position and angle.
    Status,
    /// Return to angle 0 and restart the turn count.
    Home,
    /// Turn to an angle (degrees), or by an angle with --relative.
    Rotate {
        /// Degrees.
        #[arg(allow_hyphen_values = true)]
        degrees: f64,
        /// Turn by DEGREES instead of to it.
        #[arg(long)]
        relative: bool,
    },
    /// Spin continuously; Ctrl-C stops the table.
    Spin {
        /// Seconds per revolution (negative: backwards).
        #[arg(long, default_value = "28s", value_parser = parse_signed_seconds, allow_hyphen_values = true)]
        period: f64,
        /// Revolutions (0 = until Ctrl-C).
        #[arg(long, default_value_t = 1)]
        turns: u32,
    },
    /// Ramp down to a halt.
    Stop,
    /// Emergency stop (locks until unlock).
    Estop,
    /// Clear an alarm.
    Unlock,
}

#[derive(Args)]
struct SimulateArgs {
    /// Simulated time runs this many times faster than wall time.
    #[arg(long, default_value_t = 1.0)]
    time_scale: f64,
    /// Probability of dropping each byte the device sends.
    #[arg(long, default_value_t = 0.0)]
    drop_rate: f64,
    /// Probability of a garbage line before each reply.
    #[arg(long, default_value_t = 0.0)]
    garbage_rate: f64,
    /// Extra reply latency in milliseconds.
    #[arg(long, default_value_t = 0)]
    delay_ms: u64,
    /// Raise a stall alarm this many (simulated) seconds into the first motion.
    #[arg(long)]
    stall_after: Option<f64>,
    /// Hang up the line after this many seconds.
    #[arg(long)]
    disconnect_after: Option<f64>,
}

#[derive(Args)]
struct CaptureArgs {
    #[command(flatten)]
    port: PortArgs,
    /// Frame source: `v4l2:/dev/video0`, `file:VIDEO`, `gst-test` or `sim` (needs --port sim).
    #[arg(long, default_value = "v4l2:/dev/video0")]
    camera: String,
    /// Output video; the sidecar goes beside it as NAME.angles.csv.
    #[arg(long, short = 'o')]
    out: PathBuf,
    /// Seconds per revolution.
    #[arg(long, default_value = "28s", value_parser = parse_signed_seconds, allow_hyphen_values = true)]
    period: f64,
    /// Revolutions to record.
    #[arg(long, default_value_t = 1)]
    turns: u32,
    /// Do not home before recording.
    #[arg(long)]
    no_home: bool,
    /// Requested camera width.
    #[arg(long, default_value_t = 1280)]
    width: usize,
    /// Requested camera height.
    #[arg(long, default_value_t = 720)]
    height: usize,
    /// Requested camera frame rate.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Video codec FourCC (avc1 = H.264, mp4v = MPEG-4 part 2).
    #[arg(long, default_value = "avc1")]
    codec: String,
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

fn parse_signed_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().trim_end_matches('s').parse().map_err(|_| format!("`{s}` is not a duration like 28s"))?;
    if v.is_finite() && v != 0.0 {
        Ok(v)
    } else {
        Err(format!("period must be non-zero, got {s}"))
    }
}

fn parse_seconds(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().trim_end_matches('s').parse().map_err(|_| format!("`{s}` is not a duration like 28s"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("rotation period must be positive, got {s}"))
    }
}

fn jobs(a: &EvaluateArgs) -> Result<Vec<VideoJob>> {
    if !a.labels.is_empty() && a.labels.len() != a.videos.len() {
        bail!("{} labels given for {} videos: give one --label per video or none", a.labels.len(), a.videos.len());
    }
    if a.sidecar.is_some() && a.videos.len() != 1 {
        bail!("--sidecar applies to a single video; with several, put <name>.angles.csv beside each");
    }
    let mut out: Vec<VideoJob> = Vec::new();
    for (i, v) in a.videos.iter().enumerate() {
        let label = a.labels.get(i).cloned().unwrap_or_else(|| default_label(v));
        if out.iter().any(|j| j.label == label) {
            bail!("two videos share the label `{label}`: use --label to tell them apart");
        }
        out.push(VideoJob { path: v.clone(), label, sidecar: a.sidecar.clone() });
    }
    Ok(out)
}

fn cmd_evaluate(a: &EvaluateArgs) -> Result<()> {
    if !(0.0..=1.0).contains(&a.threshold) {
        bail!("--threshold {} must be within [0, 1]", a.threshold);
    }
    let jobs = jobs(a)?;
    let mut detectors = pav::eval::detectors::load_detectors(&a.detectors, &a.classes, a.threads)?;
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
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
        detectors.iter().map(|d| format!("{}={}", d.name(), d.target_label())).collect::<Vec<_>>().join(", "),
        a.stride
    );
    let out = evaluate(&jobs, &mut detectors, &opts, &stop)?;
    println!("{}", pav::eval::report::summary_table(&out.rows, a.threshold));
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
    let given = if b.detectors.is_empty() { vec![PathBuf::from("configs/detectors")] } else { b.detectors.clone() };
    let detectors = pav::eval::detectors::expand_configs(&given)?;
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

/// Opens the turntable, spawning a simulator first for `--port sim` (kept alive by the caller).
fn connect(p: &PortArgs) -> Result<(Option<SimTurntable>, Turntable)> {
    let sim = if p.port == "sim" {
        Some(
            SimTurntable::spawn(SimOptions { time_scale: p.time_scale, ..SimOptions::default() })
                .context("starting the simulated turntable")?,
        )
    } else {
        None
    };
    let path = sim.as_ref().map_or(p.port.clone(), |s| s.path().display().to_string());
    let table = Turntable::open(&path, p.baud, Duration::from_millis(p.timeout_ms))?;
    eprintln!("turntable on {path}: firmware {}, {} microsteps/rev", table.firmware(), table.usteps_per_rev());
    Ok((sim, table))
}

fn ctrl_c_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed)).context("installing the Ctrl-C handler")?;
    Ok(stop)
}

fn milli(deg: f64) -> Result<Milli> {
    Milli::parse(&format!("{deg:.3}")).with_context(|| format!("{deg} is out of range"))
}

fn cmd_turntable(a: &TurntableArgs) -> Result<()> {
    let (_sim, mut t) = connect(&a.port)?;
    let no_progress = Duration::from_secs(5);
    let print_status = |t: &mut Turntable| -> Result<()> {
        let st = t.status()?;
        let deg = t.degrees(st.pos);
        println!(
            "state {:?}{}  position {} microsteps = {:.3}° ({:.3}° in the current turn)",
            st.state,
            st.alarm.map(|x| format!(" (alarm: {})", x.text())).unwrap_or_default(),
            st.pos,
            deg,
            deg.rem_euclid(360.0)
        );
        Ok(())
    };
    let motion = match a.action {
        TableAction::Status => return print_status(&mut t),
        TableAction::Stop => return Ok(t.command(Command::Stop).map(|_| ())?),
        TableAction::Unlock => return Ok(t.command(Command::Unlock).map(|_| ())?),
        TableAction::Estop => return Ok(t.estop()?),
        TableAction::Home => Command::Home,
        TableAction::Rotate { degrees, relative: false } => Command::MoveTo(milli(degrees)?),
        TableAction::Rotate { degrees, relative: true } => Command::MoveBy(milli(degrees)?),
        TableAction::Spin { period, turns } => Command::Spin { period_s: milli(period)?, turns },
    };
    let stop = ctrl_c_flag()?;
    let seq = t.command(motion)?;
    let mut heard = std::time::Instant::now();
    loop {
        if stop.swap(false, Ordering::Relaxed) {
            eprintln!("stopping the table");
            t.command(Command::Stop)?;
        }
        match t.next_event(Duration::from_millis(100))? {
            Some(turntable::Event::Done { seq: Some(s), pos }) if s == seq => {
                println!("done at {pos} microsteps = {:.3}°", t.degrees(pos));
                return Ok(());
            }
            Some(turntable::Event::Alarm(x)) => return Err(TurntableError::Alarm(x).into()),
            Some(_) => heard = std::time::Instant::now(),
            // Angle reports arrive every 50 ms while moving; silence means a dead link.
            None if heard.elapsed() > no_progress => {
                bail!("turntable sent nothing for {no_progress:?} during the motion")
            }
            None => {}
        }
    }
}

fn cmd_bench_rig(b: &BenchRigArgs) -> Result<()> {
    use pav::rig::bench;
    std::fs::create_dir_all(&b.out).with_context(|| format!("creating {}", b.out.display()))?;
    let mut lat = Vec::new();
    let sim = SimTurntable::spawn(SimOptions::default())?;
    let mut t = Turntable::open(&sim.path().to_string_lossy(), 115_200, Duration::from_secs(1))?;
    lat.push(bench::latency(&mut t, "sim (pty)", b.n)?);
    for p in &b.ports {
        let mut t = Turntable::open(p, 115_200, Duration::from_secs(1))?;
        lat.push(bench::latency(&mut t, p, b.n)?);
    }
    for l in &lat {
        eprintln!(
            "{}: median {:.0} µs, p99 {:.0} µs, max {:.0} µs over {}",
            l.link, l.median_us, l.p99_us, l.max_us, l.n
        );
    }
    let tmp = tempfile_dir()?;
    let mut sync = Vec::new();
    for &s in &b.time_scales {
        eprintln!("capturing a simulated 28 s turn at x{s} ({:.1} s)", 28.0 / s);
        let r = bench::angle_sync(s, 30.0, &tmp)?;
        eprintln!("  {} frames: median {:.3}°, p95 {:.3}°, max {:.3}°", r.frames, r.median_deg, r.p95_deg, r.max_deg);
        sync.push(r);
    }
    let _ = std::fs::remove_dir_all(&tmp);
    pav::eval::report::write_csv(&b.out.join("rig_latency.csv"), &lat)?;
    pav::eval::report::write_csv(&b.out.join("rig_angle_sync.csv"), &sync)?;
    eprintln!("wrote {} and {}", b.out.join("rig_latency.csv").display(), b.out.join("rig_angle_sync.csv").display());
    Ok(())
}

fn tempfile_dir() -> Result<PathBuf> {
    let d = std::env::temp_dir().join(format!("pav-bench-rig-{}", std::process::id()));
    std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    Ok(d)
}

fn cmd_simulate(a: &SimulateArgs) -> Result<()> {
    let secs = |s: Option<f64>| s.filter(|v| *v >= 0.0).map(Duration::from_secs_f64);
    let faults = Faults {
        drop_byte: a.drop_rate,
        garbage_line: a.garbage_rate,
        delay: Duration::from_millis(a.delay_ms),
        stall_after: secs(a.stall_after),
        disconnect_after: secs(a.disconnect_after),
        hang_after: None,
    };
    let sim = SimTurntable::spawn(SimOptions { time_scale: a.time_scale, faults, ..SimOptions::default() })?;
    println!("{}", sim.path().display());
    eprintln!("simulated turntable on {} (time x{}); Ctrl-C to stop", sim.path().display(), a.time_scale);
    let stop = ctrl_c_flag()?;
    while !stop.load(Ordering::Relaxed) && sim.is_running() {
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

fn cmd_capture(a: &CaptureArgs) -> Result<()> {
    let codec: Vec<char> = a.codec.chars().collect();
    let [c0, c1, c2, c3] = codec[..] else {
        bail!("--codec must be a 4-character FourCC like avc1, got `{}`", a.codec)
    };
    if a.camera == "sim" && a.port.port != "sim" {
        bail!("--camera sim films the simulated turntable: use it with --port sim");
    }
    let (sim, mut table) = connect(&a.port)?;
    let mut cam: Box<dyn FrameSource> = match a.camera.as_str() {
        "sim" => Box::new(SimCamera::new(sim.as_ref().expect("checked above").truth(), a.width, a.height, a.fps)),
        "gst-test" => Box::new(LiveCapture::gst_test(a.width, a.height, a.fps.round() as u32)?),
        c if c.starts_with("v4l2:") => {
            Box::new(LiveCapture::v4l2(std::path::Path::new(&c[5..]), a.width, a.height, a.fps)?)
        }
        c if c.starts_with("file:") => Box::new(FileSource::open(std::path::Path::new(&c[5..]))?),
        c => bail!("unknown --camera `{c}`: use v4l2:/dev/videoN, file:VIDEO, gst-test or sim"),
    };
    let (w, h) = cam.size();
    eprintln!("camera: {} {w}x{h} at {:.1} fps", cam.describe(), cam.fps());
    let opts = CaptureOptions {
        period_s: a.period,
        turns: a.turns,
        home: !a.no_home,
        fourcc: [c0, c1, c2, c3],
        progress: true,
        ..CaptureOptions::new(&a.out)
    };
    let stop = ctrl_c_flag()?;
    let sum = capture(&mut table, cam.as_mut(), &opts, &stop)?;
    println!(
        "recorded {} frames ({} with angles between reports), table ended at {:.3}°",
        sum.frames,
        sum.interpolated,
        sum.final_deg.unwrap_or(f64::NAN)
    );
    println!("video   {}\nsidecar {}", sum.video.display(), sum.sidecar.display());
    Ok(())
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match &cli.cmd {
        Cmd::Evaluate(a) => cmd_evaluate(a),
        Cmd::Model(ModelCmd::Darknet2onnx { cfg, weights, out }) => cmd_darknet2onnx(cfg, weights, out),
        Cmd::Bench(b) => cmd_bench(b),
        Cmd::BenchRig(b) => cmd_bench_rig(b),
        Cmd::Turntable(t) => cmd_turntable(t),
        Cmd::Simulate(a) => cmd_simulate(a),
        Cmd::Capture(c) => cmd_capture(c),
    }
}
