//! Loading ONNX detectors from config files and folders of them.

use super::defence::Defence;
use super::onnx::OnnxDetector;
use super::{DetectError, Detector, DetectorConfig};
use std::path::PathBuf;

fn config_error(path: &std::path::Path, msg: String) -> DetectError {
    DetectError::Config { path: path.display().to_string(), msg }
}

/// Expands directories into the TOML files they hold (sorted); files pass through.
pub fn expand_configs(paths: &[PathBuf]) -> Result<Vec<PathBuf>, DetectError> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|source| DetectError::ConfigRead {
                    path: p.display().to_string(),
                    what: "the folder".into(),
                    source,
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "toml"))
                .collect();
            if found.is_empty() {
                return Err(config_error(p, "the folder holds no detector configs (*.toml)".into()));
            }
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// The detector configs `paths` name (folders expanded), the configs they extend and their model
/// files, for `run.toml`;
/// what cannot be read is left out (loading the detectors reports it).
pub fn detector_inputs(paths: &[PathBuf]) -> Vec<PathBuf> {
    let configs = expand_configs(paths).unwrap_or_default();
    let models: Vec<PathBuf> = configs
        .iter()
        .filter_map(|c| DetectorConfig::load(c).ok())
        .flat_map(|d| d.bases.into_iter().chain([d.model]))
        .collect();
    configs.into_iter().chain(models).collect()
}

/// Loads every detector of `paths` (files or folders), with `classes` as targets when given,
/// and after each one, the same detector behind each chain of `defences` (`--defence`).
/// Every config is checked before any model loads, so all config mistakes show at once.
pub fn load_detectors(
    paths: &[PathBuf],
    classes: &[String],
    defences: &[Vec<Defence>],
    threads: usize,
) -> Result<Vec<Box<dyn Detector>>, DetectError> {
    let paths = &expand_configs(paths)?;
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
                let derived: Vec<DetectorConfig> = defences
                    .iter()
                    .filter_map(|chain| c.defended(chain).map_err(|e| errors.push(e.to_string())).ok())
                    .collect();
                cfgs.push(c);
                cfgs.extend(derived);
            }
            Err(e) => errors.push(e.to_string()),
        }
    }
    if !errors.is_empty() {
        return Err(DetectError::Configs(errors));
    }
    let mut names: Vec<&str> = cfgs.iter().map(|c| c.name.as_str()).collect();
    names.sort();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(DetectError::Configs(vec![format!("two detector configs are both named `{}`", w[0])]));
    }
    cfgs.into_iter().map(|c| OnnxDetector::new(c, threads).map(|d| Box::new(d) as Box<dyn Detector>)).collect()
}
