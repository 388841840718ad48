//! How `eval-digital` and `crossval` score composites: the options both take.

use crate::common;

/// How `eval-digital` and `crossval` score composites.
#[derive(clap::Args, Debug)]
pub struct Scoring {
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

impl Scoring {
    /// `run` with the scoring's inputs (detector configs, models, a print profile) and settings.
    pub fn record(&self, run: pav::provenance::Run) -> pav::provenance::Run {
        run.inputs(pav::detect::load::detector_inputs(&self.detectors).iter().map(|p| p.as_path()))
            .setting("threshold", self.threshold)
            .setting("print", self.print || self.print_profile.is_some())
            .inputs(self.print_profile.iter().map(|p| p.as_path()))
            .setting("defences", common::defence_chains(&self.defences).1)
    }

    /// The library's scoring options; `config` is the optimize config whose [print] table --print reads.
    pub fn to_lib(&self, config: &std::path::Path) -> anyhow::Result<pav::studies::Scoring> {
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
