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
#[cfg(feature = "optimize")]
mod eval_digital;
#[cfg(feature = "optimize")]
mod lofo;
#[cfg(feature = "optimize")]
mod optimize;
mod paint;
mod print;
mod render;
mod results;
#[cfg(feature = "optimize")]
mod table1;
mod uv;
mod views;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "pav", version, about = "PAV-Camou texture tools: optimize, score, render and print the texture")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Optimize an adversarial texture (PAV-Camou, paper Algorithm 1) against the config's
    /// white-box detectors; writes the texture, a printable sheet, loss curves, previews and scores.
    #[cfg(feature = "optimize")]
    Optimize(optimize::Args),
    /// Digital evaluation in the shape of the paper's Table II: ASR and P@0.5 of every detector on
    /// the views composited with the original paint, a random texture and each given texture.
    #[cfg(feature = "optimize")]
    EvalDigital(eval_digital::Args),
    /// k-fold cross-validation of the attack: every view is held out once, the texture is
    /// optimized on the rest, and the held-out views are scored by every detector against the
    /// photo and several random textures (a Table II in which no texture has seen its test views).
    #[cfg(feature = "optimize")]
    Crossval(crossval::Args),
    /// Leave one family out: each arm trains the recipe against every detector family but one
    /// over several seeds; the family left out scores it on the held-out set, paired view by
    /// view against a peer's texture and random blocks with intervals over seeds and views.
    #[cfg(feature = "optimize")]
    Lofo(lofo::Args),
    /// The paper's Table I from crossval runs: held-out car score and P@0.5 per texture and
    /// detector, and each run against every baseline with paired 95 % intervals.
    #[cfg(feature = "optimize")]
    Table1(table1::Args),
    /// Adversarial training (a defence): tune a YOLOX detector's head on composites carrying
    /// adversarial textures; writes the tuned ONNX model, its detector config and its sha256.
    #[cfg(feature = "optimize")]
    AdvTrain(adv_train::Args),
    /// UV map tools.
    #[command(subcommand)]
    Uv(uv::Cmd),
    /// Time the render stages on a mesh (G-buffer per view, texture gather and its adjoint,
    /// shading) at several image sizes; writes CSV.
    BenchRender(bench_render::Args),
    /// Time the white-box step (detector forward, and forward + input gradient) at several
    /// composite sizes; writes CSV.
    #[cfg(feature = "optimize")]
    BenchStep(bench_step::Args),
    /// Render the mesh with its UV texture (flat, unlit) and the textured-region mask as PNGs.
    Render(render::Args),
    /// The car's paint with a texture's sheet stuck on (the texture over the config's region, the
    /// car's own paint elsewhere), for `pav views` and the simulated turntable.
    Paint(paint::Args),
    /// Physically based views of the car by Blender Cycles (headless): photos, masks, manifest.
    #[command(subcommand)]
    Views(views::Cmd),
    /// The print channel: a texture as a printer prints it (ICC soft proof).
    #[command(subcommand)]
    Print(print::Cmd),
    /// The external data (models, meshes, CARLA samples, textures) by manifest: list, fetch
    /// with checksums, find.
    #[command(subcommand)]
    Data(data::Cmd),
    /// Results as data: record a run's headline table under results/, and generate the
    /// documents' tables from those files.
    #[command(subcommand)]
    Results(results::Cmd),
    /// Scripts that run a long job on a cluster: a Slurm job array (or a Kubernetes Indexed
    /// Job) of its shards and the merge that joins them.
    #[command(subcommand)]
    Cluster(cluster::Cmd),
}

/// How `eval-digital` and `crossval` score composites.
#[cfg(feature = "optimize")]
#[derive(clap::Args, Debug)]
struct Scoring {
    /// Detector configs or folders of them.
    #[arg(long = "detectors", short = 'd', default_value = "configs/detectors")]
    detectors: Vec<std::path::PathBuf>,
    /// A car counts as detected when its score reaches this (paper 0.5; the authors' code 0.6).
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    /// Score every texture as printed: through the config's [print] table, else Ghostscript's
    /// CMYK profile (a config with [print] is always scored as printed).
    #[arg(long)]
    print: bool,
    /// Score as printed through this ICC output profile (implies --print).
    #[arg(long = "profile", alias = "print-profile", value_parser = pav::data::arg_path)]
    print_profile: Option<std::path::PathBuf>,
    /// Also score with each detector behind this input defence, named `DETECTOR+LABEL`
    /// (`median:k=3`, `bits:b=5`, `jpeg:q=75`, `cutout:n=2,s=40`, `noise:sigma=8`; `+` chains
    /// them); repeat for several.
    #[arg(long = "defence", value_name = "SPEC", value_parser = common::parse_defence)]
    defences: Vec<common::DefenceArg>,
}

#[cfg(feature = "optimize")]
impl Scoring {
    /// `run` with the scoring's inputs (detector configs, models, a print profile) and settings.
    fn record(&self, run: pav::provenance::Run) -> pav::provenance::Run {
        run.inputs(pav::detect::load::detector_inputs(&self.detectors).iter().map(|p| p.as_path()))
            .setting("threshold", self.threshold)
            .setting("print", self.print || self.print_profile.is_some())
            .inputs(self.print_profile.iter().map(|p| p.as_path()))
            .setting("defences", common::defence_chains(&self.defences).1)
    }

    /// The library's scoring options; `config` is the optimize config whose [print] table --print reads.
    fn to_lib(&self, config: &std::path::Path) -> anyhow::Result<pav::studies::Scoring> {
        let print = if self.print || self.print_profile.is_some() {
            let mut p = pav::attack::config::OptimizeConfig::load(config)?.print.unwrap_or_default();
            if let Some(f) = &self.print_profile {
                p.profile = f.clone();
            }
            Some(p)
        } else {
            None
        };
        let defences = common::defence_chains(&self.defences).0;
        Ok(pav::studies::Scoring { detectors: self.detectors.clone(), threshold: self.threshold, print, defences })
    }
}

fn main() -> Result<()> {
    match Cli::parse().cmd {
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
        Cmd::Results(c) => results::run(&c),
        Cmd::Cluster(c) => cluster::run(&c),
    }
}
