//! `pav-rig`: the physical test rig: drive the turntable, record turntable videos with per-frame
//! angles, and score every frame with real detectors (A_physical).

#[macro_use]
#[path = "../common/mod.rs"]
mod common;

mod bench;
mod bench_rig;
mod camera;
mod capture;
mod compare;
mod evaluate;
mod model;
mod paired;
mod port;
mod simulate;
mod turntable;

use anyhow::Result;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "pav-rig",
    version,
    about = "Physical rig for adversarial vehicle camouflage: turntable, capture and frame-by-frame evaluation",
    subcommand_help_heading = "Jobs"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drive the turntable: status, home, rotate, spin, stop.
    #[command(after_help = "Examples:
  pav-rig turntable --port /dev/ttyACM0 status
  pav-rig turntable --port /dev/ttyACM0 spin --period 28s")]
    Turntable(turntable::Args),
    /// A camera's controls: what a capture can lock.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav-rig camera list /dev/video0")]
    Camera(camera::Cmd),
    /// Record turntable revolutions: a video plus each frame's table angle in a sidecar.
    #[command(after_help = "Examples:
  pav-rig capture --port /dev/ttyACM0 --camera v4l2:/dev/video0 --period 28s --exposure 166 -o runs/camo.mp4
  pav-rig capture --port sim --camera sim --rig configs/rig/phone-etron.toml --time-scale 4 -o out/sim/original.mp4")]
    Capture(capture::Args),
    /// Score every frame of videos with every detector: A_physical per detector and angle.
    #[command(after_help = "Examples:
  pav-rig evaluate runs/camo.mp4 -o out/real
  pav-rig evaluate out/sim/original.mp4 out/sim/camo.mp4 --label original --label camouflaged -d configs/detectors -o out/sim/eval")]
    Evaluate(evaluate::Args),
    /// A real capture beside its simulation: A_physical of both and the angle offset between them.
    ///
    /// Per-angle car scores of both; the offset between the two tables' zeros is found from the
    /// scores.
    #[command(after_help = "Examples:
  pav-rig compare out/eval --real real --sim sim -o out/compare")]
    Compare(compare::Args),
    /// Paints filmed on the same shots, compared frame by frame with a paired interval.
    ///
    /// Per detector, the mean difference of the best car score against a reference label.
    #[command(after_help = "Examples:
  pav-rig paired out/eval --against original -o out/paired")]
    Paired(paired::Args),
    /// Bring your own detector: inspect an ONNX model, check a detector config, convert, dequantize.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav-rig model inspect data:models-yolox/yolox_nano.onnx -o my_detector.toml
  pav-rig model check --config my_detector.toml fixtures/turntable.mp4#0")]
    Model(model::Cmd),
    /// Serve a simulated turntable on a pseudo-terminal (prints its path) until Ctrl-C.
    #[command(after_help = "Examples:
  pav-rig simulate --time-scale 4
  pav-rig simulate --drop-rate 0.01 --delay-ms 20")]
    Simulate(simulate::Args),
    /// Time decoding, inference and evaluate, and what accuracy costs in time; CSV and PNG.
    #[command(after_help = "Examples:
  pav-rig bench --video fixtures/turntable.mp4 --strides 1,2,4 -o out/bench")]
    Bench(bench::Args),
    /// Time the rig: command round trips and the angle sync of a capture; CSV.
    #[command(after_help = "Examples:
  pav-rig bench-rig --time-scales 1,4 -o out/bench")]
    BenchRig(bench_rig::Args),
    /// Write the reference page of every command from this binary's own definition.
    #[command(hide = true)]
    Reference {
        /// The folder of the pages.
        #[arg(long, short = 'o', default_value = "docs/reference")]
        out: std::path::PathBuf,
    },
}

/// The commands that are not a user's jobs: the project's own tooling.
const GROUPS: &[(&str, &[&str])] = &[("Project tooling", &["bench", "bench-rig"])];

fn main() -> Result<()> {
    let matches = common::grouped(Cli::command(), GROUPS).get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    match &cli.cmd {
        Cmd::Evaluate(a) => evaluate::run(a),
        Cmd::Model(c) => model::run(c),
        Cmd::Bench(a) => bench::run(a),
        Cmd::BenchRig(a) => bench_rig::run(a),
        Cmd::Turntable(a) => turntable::run(a),
        Cmd::Simulate(a) => simulate::run(a),
        Cmd::Capture(a) => capture::run(a),
        Cmd::Camera(c) => camera::run(c),
        Cmd::Compare(a) => compare::run(a),
        Cmd::Paired(a) => paired::run(a),
        Cmd::Reference { out } => {
            let pages = pav::reference::commands::write(&mut common::grouped(Cli::command(), GROUPS), out)?;
            outln!("wrote {} pages into {}", pages.len(), out.display());
            Ok(())
        }
    }
}
