//! `pav`: the texture side of PAV-Camou: optimize a texture, score it on composites,
//! cross-validate it, render the textured car, and check or adjust its UV map.

// Only the optimizer's commands take Ctrl-C.
#[cfg_attr(not(feature = "optimize"), allow(dead_code))]
#[macro_use]
#[path = "../common/mod.rs"]
mod common;

#[cfg(feature = "optimize")]
mod adv_train;
mod bench_render;
#[cfg(feature = "optimize")]
mod bench_step;
mod cluster;
#[cfg(feature = "optimize")]
mod crossval;
mod data;
#[cfg(feature = "doctor")]
mod doctor;
#[cfg(feature = "optimize")]
mod eval_digital;
#[cfg(feature = "optimize")]
mod lofo;
#[cfg(feature = "optimize")]
mod optimize;
mod paint;
mod print;
#[cfg(feature = "video")]
mod print_calibrate;
#[cfg(feature = "video")]
mod print_chart;
mod print_pieces;
mod render;
mod results;
#[cfg(feature = "optimize")]
mod scoring;
#[cfg(feature = "optimize")]
mod table1;
mod uv;
mod views;

use anyhow::Result;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "pav",
    version,
    about = "PAV-Camou texture tools: optimize, score, render and print the texture",
    subcommand_help_heading = "Jobs"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Optimize an adversarial texture against the config's white-box detectors.
    ///
    /// PAV-Camou, the paper's Algorithm 1. Writes the texture, a printable sheet, loss curves,
    /// previews and scores.
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav optimize --config configs/optimize/recommended.toml -o out/recommended
  pav optimize --config configs/optimize/paper.toml --seeds 0,1,2,3 -o out/paper")]
    Optimize(optimize::Args),
    /// Score textures on the config's photos with every detector (the paper's Table II).
    ///
    /// ASR and P@0.5 of every detector on the views composited with the original paint, random
    /// textures and each given texture, with paired intervals.
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav eval-digital --config configs/optimize/paper.toml -t out/paper/texture.png -o out/digital
  pav eval-digital --config configs/optimize/paper.toml --print -t out/paper/texture.png -o out/digital-printed")]
    EvalDigital(eval_digital::Args),
    /// The car's paint with a texture's sheet stuck on, for views and the simulated turntable.
    ///
    /// The texture over the config's region, the car's own paint elsewhere.
    #[command(after_help = "Examples:
  pav paint --config configs/optimize/paper.toml --texture out/paper/texture.png -o out/paper/painted.png")]
    Paint(paint::Args),
    /// Print a texture: soft proof, colour chart, printer calibration.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav print proof --config configs/optimize/paper.toml --texture out/paper/texture.png -o out/paper/proof.png
  pav print chart --config configs/optimize/paper.toml --texture out/paper/texture.png --paper a4 -o out/chart")]
    Print(print::Cmd),
    /// Physically based views of the car by Blender Cycles: photos, masks, manifest, turntable videos.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav views render --config configs/views/ci.toml -o out/views
  pav views turntable --rig configs/rig/phone-etron.toml --rasterizer -o out/turntable")]
    Views(views::Cmd),
    /// Render the mesh with its UV texture (flat, unlit) and the textured-region mask as PNGs.
    #[command(after_help = "Examples:
  pav render --orbit 2.2,20,45 -o out/orbit.png
  pav render --pose data:fca/carla_dataset/test/data12504.npz -o out/render.png")]
    Render(render::Args),
    /// Check or adjust the mesh's UV map.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav uv check -o out/uv
  pav uv adjust -o out/uv_adjusted")]
    Uv(uv::Cmd),
    /// The external data (models, meshes, CARLA samples, textures): list, fetch with checksums, find.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav data list
  pav data path rauca-e2e/RAUCA_E2E.png")]
    Data(data::Cmd),
    /// Check this machine: every piece pav's jobs need, found or missing with its fix.
    ///
    /// ONNX Runtime, OpenCV, the data store, the shipped detectors, ffmpeg, Blender, the print
    /// profile, serial ports (and whether you may open them) and cameras (and what they lock).
    /// Exits non-zero when the main job cannot run.
    #[cfg(feature = "doctor")]
    #[command(after_help = "Examples:
  pav doctor
  pav doctor -d configs/detectors-wide")]
    Doctor(doctor::Args),
    /// k-fold cross-validation of the attack: every view held out once.
    ///
    /// The texture is optimized on the rest, and the held-out views are scored by every detector
    /// against the photo and several random textures (a Table II in which no texture has seen its
    /// test views).
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav crossval --config configs/optimize/recommended.toml --reference data:rauca-e2e/RAUCA_E2E.png -o out/cv
  pav crossval --config configs/optimize/quick.toml --folds 3 --seeds 0,1 -o out/cv")]
    Crossval(crossval::Args),
    /// Leave one detector family out: does the texture transfer to a family it never saw?
    ///
    /// Each arm trains the recipe against every family but one over several seeds; the family
    /// left out scores it on the held-out set, paired view by view against a peer's texture and
    /// random blocks, with intervals over seeds and views.
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav lofo --config configs/studies/lofo/without-yolox_nano.toml --seeds 0,1 -o out/lofo")]
    Lofo(lofo::Args),
    /// The paper's Table I from crossval runs, with paired 95 % intervals against every baseline.
    ///
    /// Held-out car score and P@0.5 per texture and detector.
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav table1 out/cv/seed0 out/cv/seed1 --label rec --label rec -o out/cv/table1")]
    Table1(table1::Args),
    /// Adversarial training, a defence: tune a YOLOX detector's head on adversarial composites.
    ///
    /// Writes the tuned ONNX model, its detector config and its sha256.
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav adv-train --config configs/advtrain/yolox_nano.toml -o out/advtrain")]
    AdvTrain(adv_train::Args),
    /// Time the render stages at several image sizes; writes CSV.
    ///
    /// G-buffer per view, texture gather and its adjoint, shading.
    #[command(after_help = "Examples:
  pav bench-render --sizes 416,800 -o out/bench/render.csv")]
    BenchRender(bench_render::Args),
    /// Time the white-box step at several composite sizes; writes CSV.
    ///
    /// The detector's forward, and forward + input gradient.
    #[cfg(feature = "optimize")]
    #[command(after_help = "Examples:
  pav bench-step -d configs/detectors/yolox_nano.toml --sizes 416 --threads 2")]
    BenchStep(bench_step::Args),
    /// Results as data: record a run's headline table, generate the documents' tables from it.
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav results write
  pav results check")]
    Results(results::Cmd),
    /// Scripts that run a long job's shards on a cluster and merge them (Slurm, Kubernetes).
    #[command(subcommand)]
    #[command(after_help = "Examples:
  pav cluster slurm --tasks 6 --cpus-per-task 2 --mem 4G -o jobs/cv -- target/release/pav crossval --config configs/optimize/quick.toml -o out/cv")]
    Cluster(cluster::Cmd),
    /// Write the reference page of every command from this binary's own definition, and of
    /// every config file's keys from the config types.
    #[command(hide = true)]
    Reference {
        /// The folder of the pages.
        #[arg(long, short = 'o', default_value = "docs/reference")]
        out: std::path::PathBuf,
    },
}

/// The commands that are not a user's jobs: the project's studies, and its own tooling.
const GROUPS: &[(&str, &[&str])] = &[
    ("Studies", &["crossval", "lofo", "table1", "adv-train"]),
    ("Project tooling", &["bench-render", "bench-step", "results", "cluster"]),
];

fn main() -> Result<()> {
    let matches = common::grouped(Cli::command(), GROUPS).get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    match cli.cmd {
        #[cfg(feature = "optimize")]
        Cmd::Optimize(a) => optimize::run(&a),
        #[cfg(feature = "optimize")]
        Cmd::EvalDigital(a) => eval_digital::run(&a),
        #[cfg(feature = "optimize")]
        Cmd::Crossval(a) => crossval::run(&a),
        #[cfg(feature = "optimize")]
        Cmd::Lofo(a) => lofo::run(&a),
        #[cfg(feature = "optimize")]
        Cmd::Table1(a) => table1::run(&a),
        #[cfg(feature = "optimize")]
        Cmd::AdvTrain(a) => adv_train::run(&a),
        Cmd::Uv(c) => uv::run(&c),
        Cmd::BenchRender(a) => bench_render::run(&a),
        #[cfg(feature = "optimize")]
        Cmd::BenchStep(a) => bench_step::run(&a),
        Cmd::Render(a) => render::run(&a),
        Cmd::Paint(a) => paint::run(&a),
        Cmd::Views(c) => views::run(&c),
        Cmd::Print(c) => print::run(&c),
        Cmd::Data(c) => data::run(&c),
        #[cfg(feature = "doctor")]
        Cmd::Doctor(a) => doctor::run(&a),
        Cmd::Results(c) => results::run(&c),
        Cmd::Cluster(c) => cluster::run(&c),
        Cmd::Reference { out } => {
            let mut pages = pav::reference::commands::write(&mut common::grouped(Cli::command(), GROUPS), &out)?;
            pages.extend(pav::reference::config::write(&out)?);
            outln!("wrote {} pages into {}", pages.len(), out.display());
            Ok(())
        }
    }
}
