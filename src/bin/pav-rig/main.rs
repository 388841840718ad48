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
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "pav-rig",
    version,
    about = "Physical rig for adversarial vehicle camouflage: turntable, capture and frame-by-frame evaluation"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Score every frame of one or more videos with one or more detectors (A_physical).
    Evaluate(evaluate::Args),
    /// Model utilities.
    #[command(subcommand)]
    Model(model::Cmd),
    /// Benchmark: decode / inference / evaluate throughput and the accuracy-vs-time trade-off (CSV + PNG).
    Bench(bench::Args),
    /// Benchmark the rig: command round-trip latency and capture angle-sync error (CSV).
    BenchRig(bench_rig::Args),
    /// Drive the turntable directly.
    Turntable(turntable::Args),
    /// Serve a simulated turntable on a pseudo-terminal (prints its path) until Ctrl-C.
    Simulate(simulate::Args),
    /// Record one or more turntable revolutions: video plus a per-frame angle sidecar.
    Capture(capture::Args),
    /// Camera controls: what a capture can lock.
    #[command(subcommand)]
    Camera(camera::Cmd),
    /// A real capture beside its simulation: A_physical of both and per-angle car scores, the
    /// angle offset between the two tables found from the scores.
    Compare(compare::Args),
    /// Paints filmed on the same shots, frame by frame: per detector, the mean difference of the
    /// best car score against a reference label, with its paired interval.
    Paired(paired::Args),
}

fn main() -> Result<()> {
    match &Cli::parse().cmd {
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
    }
}
