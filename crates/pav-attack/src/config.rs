//! `pav optimize` configs (TOML). Relative paths are resolved against the config's folder.

use super::loss::{ProposalSet, Reduce};
use super::smooth::SmoothNorm;
use pav_core::geometry::camera::CameraConvention;
use pav_core::geometry::parts::Axis;
use pav_print::channel::PrintConfig;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The car and its optimizable region.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshConfig {
    /// OBJ with UVs.
    pub obj: PathBuf,
    /// UV-space image whose pure-white texels are optimized.
    pub region: PathBuf,
    /// Camera convention of the views (and the matching mesh normalization).
    pub camera: CameraConvention,
    /// Texture side in texels (the region image is resampled to it).
    pub texture_size: usize,
    /// Initial texture: a grey value (the authors use 0.5), "random" (colour blocks, 1/64 of the
    /// atlas side) or a texture image's path.
    #[serde(default)]
    pub init: Init,
    /// Real-world car length in metres, for the printable sheet (mesh units are not trusted).
    pub car_length_m: f64,
    /// Limits the region to these parts (`top`, `side`, `end`, each optionally `:a-b` along the
    /// length), like PAV-Camou's half.png; empty keeps the whole region.
    #[serde(default)]
    pub parts: Vec<String>,
    /// A face belongs to a part when |cos| between its normal and the part's axis reaches this.
    #[serde(default = "parts_min_cos")]
    pub parts_min_cos: f32,
    /// Which way the car's front points in the mesh (`+x`, `-z`, …): names the panel each
    /// printed piece goes on (left side, front end, …) and points its arrows.
    #[serde(default)]
    pub front: Option<Axis>,
    /// Which way is up in the mesh; by default the camera convention's (`+z` for fca, `+y` for
    /// pav-camou).
    #[serde(default)]
    pub up: Option<Axis>,
}

impl MeshConfig {
    /// The mesh's up axis: as set, else the camera convention's.
    pub fn up_axis(&self) -> Axis {
        self.up.unwrap_or(match self.camera {
            CameraConvention::Fca => Axis { index: 2, positive: true },
            CameraConvention::PavCamou => Axis { index: 1, positive: true },
        })
    }
}

fn parts_min_cos() -> f32 {
    0.7
}

/// The texture an optimization starts from.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Init {
    /// Every value this grey.
    Grey(f32),
    /// Named start: only "random" (uniform colour blocks 1/64 of the atlas side, seeded by optimizer.seed).
    Named(InitName),
    /// A texture image (any size; resampled to the atlas): fine-tune a texture, a peer's included.
    File(PathBuf),
}

/// Named initial textures.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum InitName {
    /// Uniform random colours in blocks 1/64 of the atlas side: the "random" baseline as a starting point.
    Random,
}

impl Default for Init {
    fn default() -> Self {
        Init::Grey(0.5)
    }
}

/// The PBR views.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TrainingViews {
    /// Training npz files (FCA format); may be empty when `pbr` lists rendered views.
    #[serde(default)]
    pub train: Vec<PathBuf>,
    /// Held-out npz files.
    #[serde(default)]
    pub test: Vec<PathBuf>,
    /// Render (and composite) size in pixels.
    pub size: usize,
    /// Ground-truth boxes (FCA's derived_test_labels.tsv) for P@0.5.
    pub labels: Option<PathBuf>,
    /// Synthetic training views: every training photo again with the car turned in place by
    /// each of these yaw angles (degrees), drawn from an appearance baked from the training
    /// photos (`render::bake`). Used for training only; reports score the photos.
    #[serde(default)]
    pub turns: Vec<f64>,
    /// Folders rendered by `pav views render` from this config's mesh: every view in them is
    /// trained on (after the photos and their turns) and never scored, so held-out scores stay
    /// on real photos.
    #[serde(default)]
    pub pbr: Vec<PathBuf>,
    /// The `pav views render` configs that make the `pbr` folders, in the same order: when a
    /// folder has not been rendered yet, `pav optimize` names the command that renders it.
    #[serde(default)]
    pub render: Vec<PathBuf>,
    /// Keep a rendered view only when some white-box detector finds a car in it as rendered
    /// (before any texture) at this score or above (`detect::detected`): a view whose unattacked
    /// car goes unseen gives L1 and L2 nothing to push on. Default: keep every view.
    #[serde(default)]
    pub pbr_min_score: Option<f32>,
    /// Folders rendered by `pav views render` whose views are held out: scored like `test`
    /// photos (their box is the silhouette's), never trained on. For a car without photos.
    #[serde(default)]
    pub pbr_test: Vec<PathBuf>,
    /// Hold only the files of the `pbr` views and rebuild each view when it is stepped on (a
    /// few milliseconds), instead of holding every built view in memory (a few MB each at 416²):
    /// for view sets larger than memory. The texture is the same either way.
    #[serde(default)]
    pub stream: bool,
}

/// One white-box detector of the ensemble.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WhiteBoxEntry {
    /// Its detector config (configs/detectors/*.toml, as `evaluate` reads them); the target
    /// classes are the config's.
    pub detector: PathBuf,
    /// Weight of its L1 + β·L2 in the sum.
    #[serde(default = "one")]
    pub weight: f32,
    /// Differentiate the float surrogate of a dynamically quantized model (`detect::surrogate`)
    /// instead of refusing it; scoring still runs the quantized model the config names.
    #[serde(default)]
    pub surrogate: bool,
    /// Defences to train through (as a detector config's `[[defence]]` list): the white box is
    /// the defended detector, named `NAME+LABELS` as `--defence` names it in the tables.
    #[serde(default)]
    pub defence: Vec<pav_detect::defence::Defence>,
}

impl WhiteBoxEntry {
    /// The detector config it names, behind its defences.
    pub fn detector_config(&self) -> Result<pav_detect::DetectorConfig, pav_detect::DetectError> {
        let d = pav_detect::DetectorConfig::load(&self.detector)?;
        if self.defence.is_empty() {
            Ok(d)
        } else {
            d.defended(&self.defence)
        }
    }
}

fn one() -> f32 {
    1.0
}

/// Loss weights and shape: L = Σ_d w_d (L1 + β·L2) + γ·Ls.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LossConfig {
    /// β.
    pub beta: f32,
    /// γ.
    pub gamma: f32,
    /// Objectness from which a prediction counts as a box in L1/L2.
    pub box_threshold: f32,
    /// `"mean"` (the paper), `{ top_k = k }`, `{ softmax = τ }` or `"log_max"` (RAUCA-E2E's
    /// `−log(1 − s*)`).
    #[serde(default = "mean")]
    pub reduce: Reduce,
    /// Weight each detection score by its box's IoU with the car's box (RAUCA-E2E's weight), so
    /// a background car does not count; for the score reductions only.
    #[serde(default)]
    pub iou: bool,
    /// Differentiate that weight: each step also moves the boxes off the car (their IoU with it
    /// down), through the detector's box outputs; by default the weight is held constant.
    #[serde(default)]
    pub box_gradient: bool,
    /// L2's set under `"mean"`: `"arg_max"` (the paper, the default) or `"scored"` (every
    /// prediction whose car score reaches `box_threshold`, as the metrics count).
    #[serde(default)]
    pub proposals: ProposalSet,
    /// L_s normalization: `"mean"` over texels (the authors' code, the default) or `"sum"` (Eq. 12).
    #[serde(default)]
    pub smoothness: SmoothNorm,
}

fn mean() -> Reduce {
    Reduce::Mean
}

/// Adam and the schedule.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OptimizerConfig {
    /// Learning rate.
    pub lr: f32,
    /// Passes over the training views.
    pub epochs: usize,
    /// Steps in all, whatever the number of training views (each pass a fresh shuffle, the last
    /// one cut short), instead of `epochs` × views: a fixed budget, so that view sets of different
    /// sizes are compared at the same cost. Absent: `epochs` passes.
    #[serde(default)]
    pub steps: Option<u64>,
    /// Seed for the view order and EoT draws.
    #[serde(default)]
    pub seed: u64,
    /// Texture values are kept in this range.
    #[serde(default = "clamp_default")]
    pub clamp: [f32; 2],
    /// The texture as a sum of this many resolutions (side n, n/2, …; `attack::pyramid`): more
    /// than 1 biases the optimization towards large structures. 1 (the default) optimizes texels.
    #[serde(default = "one_level")]
    pub levels: usize,
    /// White boxes drawn at random for each step (the rest sit it out, the drawn ones' weights
    /// scaled up to the ensemble's total), a regularizer against fitting any one network; absent:
    /// every white box at every step.
    #[serde(default)]
    pub white_boxes_per_step: Option<usize>,
    /// Output the pixel mean of the textures after step `from`, every `every` steps after it and
    /// the last, instead of the last alone (docs/reports/transfer.md, "Averaged snapshots": over four seeds no
    /// gain on the held-out detector). Absent: the last texture.
    #[serde(default)]
    pub average: Option<AverageConfig>,
    /// ONNX Runtime threads per white-box pass (0, the default: the runtime's, one per physical
    /// core), to leave cores to other jobs. The texture does not depend on it: the quick
    /// recipe trained the same bytes at 1 and 2 threads (docs/reports/lofo.md).
    #[serde(default)]
    pub threads: usize,
}

/// `optimizer.average`: which iterates the output texture averages.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AverageConfig {
    /// The first step counted (steps done, as snapshot names count them).
    pub from: u64,
    /// Steps between the textures counted (1: every step).
    #[serde(default = "one_step")]
    pub every: u64,
}

impl AverageConfig {
    /// Whether the texture after `done` steps lies on the average's grid (`from`, `from + every`,
    /// …). The last texture of a run is averaged too, on the grid or not, but only into the
    /// output: a run stopped and resumed with more epochs counts what a straight run counts.
    pub fn on_grid(&self, done: u64) -> bool {
        done >= self.from && (done - self.from) % self.every.max(1) == 0
    }
}

fn one_step() -> u64 {
    1
}

fn one_level() -> usize {
    1
}

fn clamp_default() -> [f32; 2] {
    [1e-4, 1.0 - 1e-4]
}

/// A whole optimization config. `extends = "base.toml"` (relative to the file) starts from
/// another config: tables merge key by key, and every value the file sets (arrays included)
/// replaces the base's.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OptimizeConfig {
    /// Scene TOML (lighting and EoT effects).
    pub scene: PathBuf,
    /// Mesh and region.
    pub mesh: MeshConfig,
    /// Views.
    pub views: TrainingViews,
    /// White-box detectors.
    pub white_box: Vec<WhiteBoxEntry>,
    /// Loss weights.
    pub loss: LossConfig,
    /// Optimizer.
    pub optimizer: OptimizerConfig,
    /// The print channel: when present, the detectors see the texture as this printer prints it
    /// (`print::channel`), and the gamut term pulls texels towards colours it can print.
    #[serde(default)]
    pub print: Option<PrintConfig>,
    /// The config files read: the file loaded, then each one it `extends` (filled by [`Self::load`]).
    #[serde(skip)]
    pub files: Vec<PathBuf>,
}

/// Errors reading a config.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("optimize config {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not a valid config (syntax, an unknown key, a wrong type).
    #[error("optimize config {path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The TOML parser's error.
        source: toml::de::Error,
    },
    /// A `data:` file is unknown or not fetched.
    #[error("optimize config {path}: {source}")]
    Data {
        /// The file.
        path: PathBuf,
        /// Which entry, and the `pav data` command that fixes it.
        source: Box<pav_run::data::DataError>,
    },
    /// A value is out of range.
    #[error("optimize config {path}: {source}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What to change.
        source: InvalidConfig,
    },
}

/// A config value out of range, with what to change.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InvalidConfig(pub String);

impl OptimizeConfig {
    /// Reads the file and the chain of configs it `extends`, resolves relative paths against the
    /// folder of the file that names them, and checks the values.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let (mut c, files): (OptimizeConfig, _) = pav_core::extends::load(path, PATH_KEYS, &["random"])?;
        c.files = files;
        let dir = path.parent().unwrap_or(Path::new("."));
        let mut first_err = None;
        let mut fix = |p: &mut PathBuf| match pav_run::data::resolve(dir, p) {
            Ok(r) => *p = r,
            Err(e) => {
                first_err.get_or_insert(e);
            }
        };
        fix(&mut c.scene);
        fix(&mut c.mesh.obj);
        fix(&mut c.mesh.region);
        c.views.train.iter_mut().for_each(&mut fix);
        c.views.test.iter_mut().for_each(&mut fix);
        c.views.pbr.iter_mut().for_each(&mut fix);
        c.views.render.iter_mut().for_each(&mut fix);
        c.views.pbr_test.iter_mut().for_each(&mut fix);
        if let Some(l) = c.views.labels.as_mut() {
            fix(l);
        }
        c.white_box.iter_mut().for_each(|w| fix(&mut w.detector));
        if let Init::File(p) = &mut c.mesh.init {
            fix(p);
        }
        if let Some(p) = c.print.as_mut() {
            fix(&mut p.profile);
            if let Some(k) = p.calibration.as_mut() {
                fix(k);
            }
        }
        if let Some(source) = first_err {
            return Err(ConfigError::Data { path: path.into(), source: Box::new(source) });
        }
        c.check().map_err(|source| ConfigError::Invalid { path: path.into(), source })?;
        Ok(c)
    }

    /// Every file the optimization reads: scene, mesh, region, initial texture, photos, labels,
    /// rendered views, and each white box's config and model (for `run.toml`).
    #[cfg(feature = "eval")]
    pub fn inputs(&self) -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = self.files.iter().skip(1).cloned().collect();
        v.extend([self.scene.clone(), self.mesh.obj.clone(), self.mesh.region.clone()]);
        if let Init::File(p) = &self.mesh.init {
            v.push(p.clone());
        }
        v.extend(
            self.views.train.iter().chain(&self.views.test).chain(&self.views.pbr).chain(&self.views.pbr_test).cloned(),
        );
        v.extend(self.views.labels.clone());
        if let Some(p) = &self.print {
            v.extend(p.calibration.clone().or(Some(p.profile.clone())));
        }
        let boxes: Vec<PathBuf> = self.white_box.iter().map(|w| w.detector.clone()).collect();
        v.extend(pav_detect::load::detector_inputs(&boxes));
        v
    }

    /// Value checks with messages that say what to change.
    pub fn check(&self) -> Result<(), InvalidConfig> {
        self.check_values().map_err(InvalidConfig)
    }

    fn check_values(&self) -> Result<(), String> {
        let o = &self.optimizer;
        if !(o.lr.is_finite() && o.lr > 0.0) {
            return Err(format!("optimizer.lr must be > 0, got {}", o.lr));
        }
        if o.epochs == 0 {
            return Err("optimizer.epochs must be at least 1".into());
        }
        if o.steps == Some(0) {
            return Err("optimizer.steps must be at least 1 (or left out for `epochs` passes over the views)".into());
        }
        if !(0.0 <= o.clamp[0] && o.clamp[0] < o.clamp[1] && o.clamp[1] <= 1.0) {
            return Err(format!("optimizer.clamp must satisfy 0 ≤ lo < hi ≤ 1, got {:?}", o.clamp));
        }
        if self.views.train.is_empty() && self.views.pbr.is_empty() {
            return Err("views.train lists no npz file and views.pbr no rendered views: nothing to train on".into());
        }
        if !(32..=4096).contains(&self.views.size) {
            return Err(format!("views.size must be in 32..=4096, got {}", self.views.size));
        }
        if let Some(t) = self.views.turns.iter().find(|t| !(t.is_finite() && **t != 0.0 && t.abs() < 180.0)) {
            return Err(format!("views.turns must be non-zero angles within ±180°, got {t}"));
        }
        if let Some(t) = self.views.pbr_min_score.filter(|t| !(*t > 0.0 && *t < 1.0)) {
            return Err(format!("views.pbr_min_score must be in (0, 1), got {t}"));
        }
        if !(16..=8192).contains(&self.mesh.texture_size) {
            return Err(format!("mesh.texture_size must be in 16..=8192, got {}", self.mesh.texture_size));
        }
        if let Err(e) = super::pyramid::Pyramid::new(self.mesh.texture_size, self.optimizer.levels) {
            return Err(format!("optimizer.levels: {e}"));
        }
        if let Some(k) = o.white_boxes_per_step.filter(|k| !(1..=self.white_box.len()).contains(k)) {
            return Err(format!(
                "optimizer.white_boxes_per_step must be in 1..={} (the [[white_box]] entries), got {k}",
                self.white_box.len()
            ));
        }
        if o.average.is_some_and(|a| a.every == 0) {
            return Err("optimizer.average.every must be at least 1".into());
        }
        if let Init::Grey(g) = self.mesh.init {
            if !(0.0..=1.0).contains(&g) {
                return Err(format!("mesh.init must be in [0, 1] or \"random\", got {g}"));
            }
        }
        if !self.mesh.car_length_m.is_finite() || self.mesh.car_length_m <= 0.0 {
            return Err(format!("mesh.car_length_m must be > 0, got {}", self.mesh.car_length_m));
        }
        let l = &self.loss;
        if !(l.beta.is_finite() && l.beta >= 0.0 && l.gamma.is_finite() && l.gamma >= 0.0) {
            return Err(format!("loss.beta and loss.gamma must be ≥ 0, got {} and {}", l.beta, l.gamma));
        }
        if self.white_box.is_empty() {
            return Err("no [[white_box]] detector".into());
        }
        if let Some(w) = self.white_box.iter().find(|w| !(w.weight.is_finite() && w.weight > 0.0)) {
            return Err(format!("white_box weights must be > 0, got {} for {}", w.weight, w.detector.display()));
        }
        match l.reduce {
            Reduce::TopK(0) => return Err("loss.reduce top_k must be at least 1".into()),
            Reduce::Softmax(t) if !(t.is_finite() && t > 0.0) => {
                return Err(format!("loss.reduce softmax temperature must be > 0, got {t}"))
            }
            _ => {}
        }
        if l.proposals != ProposalSet::ArgMax && l.reduce != Reduce::Mean {
            return Err(
                "loss.proposals chooses the set of reduce = \"mean\"; the other reductions weight every prediction"
                    .into(),
            );
        }
        if l.iou && l.reduce == Reduce::Mean {
            return Err(
                "loss.iou weights detection scores, which reduce = \"mean\" does not read; use it with log_max, top_k or softmax"
                    .into(),
            );
        }
        if l.box_gradient && !l.iou {
            return Err("loss.box_gradient differentiates the IoU weight of loss.iou; set iou = true with it".into());
        }
        if !(0.0..=1.0).contains(&l.box_threshold) {
            return Err(format!("loss.box_threshold must be in [0, 1], got {}", l.box_threshold));
        }
        self.parts().map_err(|e| format!("mesh.parts: {e}"))?;
        if !(self.mesh.parts_min_cos > 0.0 && self.mesh.parts_min_cos <= 1.0) {
            return Err(format!("mesh.parts_min_cos must be in (0, 1], got {}", self.mesh.parts_min_cos));
        }
        if let Some(p) = &self.print {
            p.check()?;
        }
        Ok(())
    }

    /// Names of the `[[white_box]]` detectors (read from their configs).
    pub fn white_box_names(&self) -> Result<Vec<String>, pav_detect::DetectError> {
        self.white_box.iter().map(|w| w.detector_config().map(|d| d.name)).collect()
    }

    /// The parsed `mesh.parts`.
    pub fn parts(&self) -> Result<Vec<pav_core::geometry::parts::Part>, pav_core::geometry::parts::PartError> {
        self.mesh.parts.iter().map(|s| s.parse()).collect()
    }
}

/// Keys whose values are paths relative to the file that sets them (`[[white_box]]` entries
/// included).
const PATH_KEYS: &[&[&str]] = &[
    &["scene"],
    &["mesh", "obj"],
    &["mesh", "region"],
    &["mesh", "init"],
    &["views", "train"],
    &["views", "test"],
    &["views", "pbr"],
    &["views", "render"],
    &["views", "pbr_test"],
    &["views", "labels"],
    &["white_box", "detector"],
    &["print", "profile"],
    &["print", "calibration"],
];

impl From<pav_core::extends::ExtendsError> for ConfigError {
    fn from(e: pav_core::extends::ExtendsError) -> Self {
        use pav_core::extends::ExtendsError as E;
        match e {
            E::Read { path, source } => ConfigError::Read { path, source },
            E::Parse { path, source } => ConfigError::Parse { path, source },
            E::Invalid { path, msg } => ConfigError::Invalid { path, source: InvalidConfig(msg) },
        }
    }
}

/// A `views.pbr` or `views.pbr_test` folder not rendered yet, and the `pav views render` command
/// that renders it when the config names its views config (`views.render`).
#[derive(Clone, Debug, PartialEq)]
pub struct MissingViews {
    /// The config key that lists it.
    pub key: &'static str,
    /// The folder.
    pub dir: PathBuf,
    /// Its views config, when `views.render` names it.
    pub config: Option<PathBuf>,
    /// Whether that config is a rig config (rendered by `pav views turntable --rig`).
    pub rig: bool,
}

impl std::fmt::Display for MissingViews {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (key, dir) = (self.key, pav_core::path::tidy(&self.dir));
        let dir = dir.display();
        match &self.config {
            Some(c) => write!(
                f,
                "{key} {dir} has not been rendered yet, or not to the end: run `pav views {} {} -o {dir}` first",
                if self.rig { "turntable --rig" } else { "render" },
                pav_core::path::tidy(c).display()
            ),
            None => write!(
                f,
                "{key} {dir} has not been rendered yet, or not to the end: render it with `pav views render VIEWS.toml -o {dir}` (views.render can name the config)"
            ),
        }
    }
}

impl OptimizeConfig {
    /// The bytes of every config file read, the loaded one first: a checkpoint's fingerprint,
    /// so that a change to a base config is a change of config.
    pub fn file_bytes(&self) -> Result<Vec<u8>, (PathBuf, std::io::Error)> {
        let mut out = Vec::new();
        for f in &self.files {
            out.extend(std::fs::read(f).map_err(|e| (f.clone(), e))?);
        }
        Ok(out)
    }

    /// The `views.pbr` and `views.pbr_test` folders that hold no rendered view set yet.
    pub fn missing_views(&self) -> Vec<MissingViews> {
        let pbr = self.views.pbr.iter().enumerate().map(|(i, d)| ("views.pbr", d, self.views.render.get(i)));
        let test = self.views.pbr_test.iter().map(|d| ("views.pbr_test", d, None));
        pbr.chain(test)
            .filter(|(_, d, _)| !pav_scene::views::is_rendered(d))
            .map(|(key, d, c)| MissingViews {
                key,
                dir: d.clone(),
                config: c.cloned(),
                rig: c.is_some_and(|c| pav_scene::rig::is_rig_config(c)),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The workspace root, where `configs/` lives.
    fn repo() -> &'static Path {
        Path::new(env!("CARGO_MANIFEST_DIR")).parent().and_then(Path::parent).unwrap()
    }

    fn shipped(name: &str) -> PathBuf {
        repo().join("configs/optimize").join(name)
    }

    fn study(name: &str) -> PathBuf {
        repo().join("configs/studies").join(name)
    }

    #[test]
    fn shipped_configs_load_and_resolve_paths() {
        for p in [shipped("paper.toml"), shipped("authors.toml"), study("half.toml"), study("half-random.toml")] {
            let c = OptimizeConfig::load(&p).unwrap_or_else(|e| panic!("{e}"));
            // `data:` entries resolve into the data store, relative paths against the config.
            assert!(c.mesh.obj.starts_with(pav_run::data::store::Store::from_env().root), "{p:?}: {:?}", c.mesh.obj);
            let scenes = repo().join("configs/scenes");
            assert!(pav_core::path::tidy(&c.scene).starts_with(&scenes), "{p:?}: {:?}", c.scene);
        }
        let half = OptimizeConfig::load(&study("half.toml")).unwrap();
        assert_eq!(half.parts().unwrap().len(), 2);
        let turns = OptimizeConfig::load(&study("half-turns.toml")).unwrap();
        assert_eq!((half.views.turns.len(), turns.views.turns.len()), (0, 4));
        // Rendered views resolve like every other path (the folder is made by `pav views render`).
        let pbr = OptimizeConfig::load(&study("half-turns-pbr.toml")).unwrap();
        assert_eq!(pbr.views.pbr, [study("../../out/views_etron")]);
        assert_eq!((pbr.views.train, pbr.mesh, pbr.loss), (turns.views.train, turns.mesh, turns.loss.clone()));
        let pair = OptimizeConfig::load(&study("half-turns-ensemble-pbr.toml")).unwrap();
        assert_eq!((pair.views.pbr.len(), pair.white_box.len(), pair.loss), (1, 2, turns.loss));
    }

    /// A config that `extends` another is the base with the file's keys on top: tables merge key
    /// by key, arrays (of tables too) replace, and a base's relative paths keep their meaning.
    #[test]
    fn extends_merges_over_the_base_and_keeps_its_paths() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("variants");
        std::fs::create_dir(&sub).unwrap();
        let paper = std::fs::read_to_string(shipped("paper.toml")).unwrap();
        // The base sits in another folder than the shipped one, so its `../scenes` path must be
        // rewritten for the variant's folder to mean the same file.
        let base_dir = dir.path().join("configs/optimize");
        std::fs::create_dir_all(&base_dir).unwrap();
        std::fs::create_dir_all(dir.path().join("configs/scenes")).unwrap();
        std::fs::copy(shipped("../scenes/pav-eot.toml"), dir.path().join("configs/scenes/pav-eot.toml")).unwrap();
        std::fs::write(base_dir.join("base.toml"), &paper).unwrap();
        let variant = sub.join("v.toml");
        std::fs::write(
            &variant,
            "extends = \"../configs/optimize/base.toml\"\n[mesh]\ntexture_size = 256\n[optimizer]\nepochs = 2\n",
        )
        .unwrap();
        let base = OptimizeConfig::load(&base_dir.join("base.toml")).unwrap();
        let v = OptimizeConfig::load(&variant).unwrap();
        assert_eq!((v.mesh.texture_size, v.optimizer.epochs), (256, 2));
        assert_eq!(
            (v.optimizer.lr, v.views.clone(), v.loss.clone()),
            (base.optimizer.lr, base.views.clone(), base.loss)
        );
        assert_eq!(pav_core::path::tidy(&v.scene), pav_core::path::tidy(&base.scene));
        assert!(v.scene.is_file() || pav_core::path::tidy(&v.scene).is_file(), "{:?}", v.scene);
        assert_eq!(v.files, [variant.clone(), pav_core::path::tidy(&sub.join("../configs/optimize/base.toml"))]);
        // A two-level chain, and an array that replaces the base's.
        let v2 = sub.join("v2.toml");
        std::fs::write(&v2, "extends = \"v.toml\"\nwhite_box = [{ detector = \"../../detectors/yolox_nano.toml\" }]\n")
            .unwrap();
        let c = OptimizeConfig::load(&v2).unwrap();
        assert_eq!((c.mesh.texture_size, c.white_box.len()), (256, 1));
        assert!(c.white_box[0].detector.ends_with("detectors/yolox_nano.toml"));
        // The checkpoint fingerprint covers the base: a change there is a change of config.
        let before = c.file_bytes().unwrap();
        std::fs::write(base_dir.join("base.toml"), paper.replace("lr = 0.015", "lr = 0.02")).unwrap();
        assert_ne!(OptimizeConfig::load(&v2).map(|c| c.file_bytes().unwrap()).unwrap_or_default(), before);
    }

    #[test]
    fn extends_refuses_a_cycle_a_missing_base_and_a_non_path() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.toml"), dir.path().join("b.toml"));
        std::fs::write(&a, "extends = \"b.toml\"\n").unwrap();
        std::fs::write(&b, "extends = \"./a.toml\"\n").unwrap();
        let e = OptimizeConfig::load(&a).unwrap_err().to_string();
        assert!(e.contains("comes back to"), "{e}");
        std::fs::write(&b, "extends = \"nope.toml\"\n").unwrap();
        let e = OptimizeConfig::load(&a).unwrap_err().to_string();
        assert!(e.contains("nope.toml"), "{e}");
        std::fs::write(&b, "extends = 3\n").unwrap();
        let e = OptimizeConfig::load(&a).unwrap_err().to_string();
        assert!(e.contains("extends must be a config's path"), "{e}");
    }

    #[test]
    fn missing_views_name_the_command_that_renders_them() {
        let c = OptimizeConfig::load(&shipped("quick.toml")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut c2 = c.clone();
        c2.views.pbr = vec![dir.path().join("not-rendered")];
        let m = c2.missing_views();
        assert_eq!(m.len(), 1);
        let text = m[0].to_string();
        assert!(text.contains("pav views render") && text.contains("etron-plates-wide.toml"), "{text}");
        assert!(text.contains("not-rendered"), "{text}");
        // Rig views are rendered by the turntable command.
        c2.views.render = vec![repo().join("configs/rig/train-etron-near.toml")];
        let text = c2.missing_views()[0].to_string();
        assert!(text.contains("pav views turntable --rig") && text.contains("train-etron-near.toml"), "{text}");
        // A folder with a view set is not missing.
        std::fs::create_dir(dir.path().join("not-rendered")).unwrap();
        std::fs::write(dir.path().join("not-rendered/views.toml"), "").unwrap();
        assert!(c2.missing_views().is_empty());
        // One whose render was stopped still is, and so says the message.
        let unfinished = dir.path().join("not-rendered").join(pav_scene::views::UNFINISHED);
        std::fs::write(&unfinished, "").unwrap();
        let text = c2.missing_views()[0].to_string();
        assert!(text.contains("not to the end") && text.contains("not-rendered"), "{text}");
        std::fs::remove_file(&unfinished).unwrap();
        assert!(c2.missing_views().is_empty());
    }

    #[test]
    fn every_shipped_config_and_its_scene_load() {
        // Every .toml under `dir`, in its subfolders too (a study's arms), but for a study's
        // detector descriptions.
        fn tomls(dir: &Path, out: &mut Vec<PathBuf>) {
            for e in std::fs::read_dir(dir).unwrap() {
                let p = e.unwrap().path();
                if p.ends_with("picodet-channels") {
                    continue;
                }
                if p.is_dir() {
                    tomls(&p, out);
                } else if p.extension().is_some_and(|x| x == "toml") {
                    out.push(p);
                }
            }
        }
        let mut all = Vec::new();
        for folder in ["", "../studies"] {
            tomls(&shipped(folder), &mut all);
        }
        for p in &all {
            let c = OptimizeConfig::load(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            pav_scene::Scene::load(&c.scene).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            // The views config that renders each rendered-view folder is there to be run.
            assert!(c.views.render.iter().all(|r| r.is_file()), "{}: {:?}", p.display(), c.views.render);
        }
        assert!(all.len() >= 40, "{} configs", all.len());
    }

    #[test]
    fn a_zero_or_full_turn_is_refused() {
        let mut c = OptimizeConfig::load(&study("half-turns.toml")).unwrap();
        for bad in [0.0, 180.0, f64::NAN] {
            c.views.turns = vec![15.0, bad];
            let e = c.check().unwrap_err().to_string();
            assert!(e.contains("views.turns"), "{e}");
        }
        c.views.turns = vec![-179.0, 15.0];
        c.check().unwrap();
    }

    #[test]
    fn white_boxes_loss_shapes_and_an_initial_texture_file_load() {
        let c = OptimizeConfig::load(&study("half-turns-ensemble.toml")).unwrap();
        let names: Vec<&str> = c.white_box.iter().filter_map(|w| w.detector.file_stem()?.to_str()).collect();
        assert_eq!(names, ["yolov3-tiny", "yolox_nano"]);
        assert!(c.white_box.iter().all(|w| w.detector.is_file()), "{:?}", c.white_box);
        let text = std::fs::read_to_string(shipped("paper.toml")).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let variant = |from: &str, to: &str| {
            let p = dir.path().join("v.toml");
            // Loading checks values, not whether the files exist.
            let t = text.replace(from, to);
            std::fs::write(&p, t).unwrap();
            OptimizeConfig::load(&p)
        };
        let c = variant("reduce = \"mean\"", "reduce = { top_k = 3 }").unwrap();
        assert_eq!(c.loss.reduce, Reduce::TopK(3));
        let c = variant("reduce = \"mean\"", "reduce = { softmax = 0.1 }").unwrap();
        assert_eq!(c.loss.reduce, Reduce::Softmax(0.1));
        let c = variant("reduce = \"mean\"", "reduce = \"log_max\"").unwrap();
        assert_eq!(c.loss.reduce, Reduce::LogMax);
        for (bad, key) in
            [("{ top_k = 0 }", "top_k"), ("{ softmax = -1.0 }", "softmax"), ("\"max\"", "unknown variant")]
        {
            let e = variant("reduce = \"mean\"", &format!("reduce = {bad}")).unwrap_err().to_string();
            assert!(e.contains(key), "{bad}: {e}");
        }
        let scored = "reduce = \"mean\"\nproposals = \"scored\"";
        assert_eq!(variant("reduce = \"mean\"", scored).unwrap().loss.proposals, ProposalSet::Scored);
        let e = variant("reduce = \"mean\"", "reduce = { top_k = 1 }\nproposals = \"scored\"").unwrap_err().to_string();
        assert!(e.contains("loss.proposals"), "{e}");
        assert!(variant("reduce = \"mean\"", "reduce = \"log_max\"\niou = true").unwrap().loss.iou);
        let e = variant("reduce = \"mean\"", "reduce = \"mean\"\niou = true").unwrap_err().to_string();
        assert!(e.contains("loss.iou"), "{e}");
        assert!(
            variant("reduce = \"mean\"", "reduce = \"log_max\"\niou = true\nbox_gradient = true")
                .unwrap()
                .loss
                .box_gradient
        );
        let e = variant("reduce = \"mean\"", "reduce = \"log_max\"\nbox_gradient = true").unwrap_err().to_string();
        assert!(e.contains("loss.box_gradient") && e.contains("iou = true"), "{e}");
        let c = variant("init = 0.5", "init = \"peer.png\"").unwrap();
        assert_eq!(c.mesh.init, Init::File(dir.path().join("peer.png")));
        assert_eq!(variant("init = 0.5", "init = \"random\"").unwrap().mesh.init, Init::Named(InitName::Random));
        let e = variant("weight = 1.0", "weight = 0.0").unwrap_err().to_string();
        assert!(e.contains("white_box weights"), "{e}");
        // Levels default to one (texels); more must halve the atlas evenly (1024 → 32 at 6 levels).
        assert_eq!(variant("seed = 0", "seed = 0").unwrap().optimizer.levels, 1);
        assert_eq!(variant("seed = 0", "seed = 0\nlevels = 6").unwrap().optimizer.levels, 6);
        let e = variant("seed = 0", "seed = 0\nlevels = 12").unwrap_err().to_string();
        assert!(e.contains("optimizer.levels") && e.contains("halve"), "{e}");
        // A subset of white boxes per step: at least one, at most the one listed.
        assert_eq!(variant("seed = 0", "seed = 0").unwrap().optimizer.white_boxes_per_step, None);
        // The average: every step by default; every 0 and unknown keys are refused.
        assert_eq!(variant("seed = 0", "seed = 0").unwrap().optimizer.average, None);
        let a = variant("seed = 0", "seed = 0\naverage = { from = 100 }").unwrap().optimizer.average.unwrap();
        assert_eq!(a, AverageConfig { from: 100, every: 1 });
        let a = variant("seed = 0", "seed = 0\naverage = { from = 100, every = 50 }").unwrap().optimizer.average;
        let a = a.unwrap();
        let counted: Vec<u64> = (1..=490).filter(|&d| a.on_grid(d)).collect();
        assert_eq!(counted, [100, 150, 200, 250, 300, 350, 400, 450]);
        let e = variant("seed = 0", "seed = 0\naverage = { from = 1, every = 0 }").unwrap_err().to_string();
        assert!(e.contains("optimizer.average.every"), "{e}");
        assert!(variant("seed = 0", "seed = 0\naverage = { start = 1 }").is_err());
        let one = variant("seed = 0", "seed = 0\nwhite_boxes_per_step = 1").unwrap();
        assert_eq!(one.optimizer.white_boxes_per_step, Some(1));
        for bad in [0, 2] {
            let e = variant("seed = 0", &format!("seed = 0\nwhite_boxes_per_step = {bad}")).unwrap_err().to_string();
            assert!(e.contains("white_boxes_per_step") && e.contains("1..=1"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_bad_part_is_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.toml");
        let base = shipped("paper.toml").display().to_string();
        std::fs::write(&p, format!("extends = {base:?}\n[mesh]\nparts = [\"side:0.2-0.8\", \"roof\"]\n")).unwrap();
        let e = OptimizeConfig::load(&p).unwrap_err().to_string();
        assert!(e.contains("mesh.parts") && e.contains("roof"), "{e}");
    }
}
