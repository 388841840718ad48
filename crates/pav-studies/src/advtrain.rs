//! Adversarial training of a YOLOX detector's head (a defence, `pav adv-train`): on frozen
//! features, each grid level's objectness convolution and the target class's row of its class
//! convolution are fitted again to composites of the training views carrying adversarial
//! textures (and the original paint and random blocks, so the clean car stays found). The tuned
//! model is written as ONNX with its sha256, and scored before and after on the held-out views.
//!
//! Only these 1×1 convolutions change: their gradient is a logistic regression's on the features
//! they read, so no weight gradient of the network is needed, and the detector is otherwise the
//! one it was.

use super::{create_dir, write_file, write_markdown, ExperimentError};
use pav_attack::config::OptimizeConfig;
use pav_attack::setup::{random_block_side, random_blocks, Setup};
use pav_attack::view::TrainView;
use pav_core::image::Frame;
use pav_core::progress::Progress;
use pav_detect::config::{DetectorConfig, OutputLayout};
use pav_detect::decode::RawOutput;
use pav_detect::onnx::OnnxDetector;
use pav_detect::preprocess::prepare;
use pav_detect::Detector;
use pav_eval::digital::{paired_bootstrap, Interval};
use pav_onnx::proto::{InitData, Model, ValueInfo};
use serde::Deserialize;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// A `pav adv-train` recipe (TOML; relative paths are relative to the file).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdvTrainConfig {
    /// The detector config to tune (layout `yolox`).
    pub detector: PathBuf,
    /// The optimize config whose views are used: its training views to tune on, its held-out
    /// views to score.
    pub views: PathBuf,
    /// Adversarial textures composited on the training views.
    #[serde(default)]
    pub train_textures: Vec<PathBuf>,
    /// Textures scored on the held-out views (a texture tuned on may be scored too: its views
    /// are new).
    #[serde(default)]
    pub test_textures: Vec<PathBuf>,
    /// Seeds of the random-block textures tuned on.
    #[serde(default)]
    pub random_seeds: Vec<u64>,
    /// Seeds of the random-block textures scored.
    #[serde(default)]
    pub test_random_seeds: Vec<u64>,
    /// Full-batch Adam steps.
    pub steps: usize,
    /// Adam's learning rate.
    pub lr: f64,
    /// Weight of the squared distance to the detector's own weights (keeps the tuned head near
    /// the clean one).
    pub l2: f64,
    /// The sha256 of the model this recipe rebuilds (checked when no texture is added).
    #[serde(default)]
    pub sha256: Option<String>,
}

impl AdvTrainConfig {
    /// Reads a recipe and resolves its paths (`data:` names included).
    pub fn load(path: &Path) -> Result<Self, ExperimentError> {
        let bad = |msg: String| ExperimentError::Invalid(format!("{}: {msg}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|source| ExperimentError::Io { path: path.into(), source })?;
        let mut c: AdvTrainConfig = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let fix = |p: &mut PathBuf| -> Result<(), ExperimentError> {
            *p = pav_run::data::resolve(dir, p).map_err(|e| bad(e.to_string()))?;
            Ok(())
        };
        fix(&mut c.detector)?;
        fix(&mut c.views)?;
        c.train_textures.iter_mut().chain(c.test_textures.iter_mut()).try_for_each(fix)?;
        if c.steps == 0 || !(c.lr > 0.0 && c.lr.is_finite()) || !(c.l2 >= 0.0 && c.l2.is_finite()) {
            return Err(bad(format!("steps {} must be ≥ 1, lr {} > 0 and l2 {} ≥ 0", c.steps, c.lr, c.l2)));
        }
        Ok(c)
    }

    /// Every file the recipe reads.
    pub fn inputs(&self) -> Vec<PathBuf> {
        let mut v = vec![self.detector.clone(), self.views.clone()];
        v.extend(self.train_textures.iter().chain(&self.test_textures).cloned());
        v
    }
}

/// One 1×1 convolution of the head and the feature map it reads.
#[derive(Clone, Debug)]
struct HeadConv {
    weight: String,
    bias: String,
    input: String,
}

/// One grid level's convolutions that are tuned.
#[derive(Clone, Debug)]
struct Level {
    cls: HeadConv,
    obj: HeadConv,
}

/// The head's class and objectness convolutions: 1×1 convolutions with `classes` or one output
/// channel whose output goes through a Sigmoid that is no SiLU's (a SiLU multiplies the Sigmoid
/// with its own input). Paired in graph order: a level's class convolution comes before its
/// objectness one in YOLOX's export.
fn find_levels(model: &Model, classes: usize) -> Result<Vec<Level>, String> {
    let init = |name: &str| model.initializers.iter().find(|i| i.name == name);
    let mut cls = Vec::new();
    let mut obj = Vec::new();
    for n in model.nodes.iter().filter(|n| n.op_type == "Conv" && n.inputs.len() == 3) {
        let Some(w) = init(&n.inputs[1]) else { continue };
        if w.dims.len() != 4 || w.dims[2] != 1 || w.dims[3] != 1 || init(&n.inputs[2]).is_none() {
            continue;
        }
        let out = &n.outputs[0];
        let sigmoid = model.nodes.iter().find(|s| s.op_type == "Sigmoid" && s.inputs[0] == *out);
        let silu = model.nodes.iter().any(|m| m.op_type == "Mul" && m.inputs.contains(out));
        if sigmoid.is_none() || silu {
            continue;
        }
        let conv = HeadConv { weight: n.inputs[1].clone(), bias: n.inputs[2].clone(), input: n.inputs[0].clone() };
        match w.dims[0] as usize {
            c if c == classes => cls.push(conv),
            1 => obj.push(conv),
            _ => {}
        }
    }
    if cls.is_empty() || cls.len() != obj.len() {
        return Err(format!(
            "found {} class and {} objectness convolutions (1×1, through a Sigmoid) in the head: adversarial \
             training tunes a YOLOX head, with one of each per grid level",
            cls.len(),
            obj.len()
        ));
    }
    Ok(cls.into_iter().zip(obj).map(|(cls, obj)| Level { cls, obj }).collect())
}

fn floats<'m>(model: &'m Model, name: &str) -> &'m [f32] {
    match model.initializers.iter().find(|i| i.name == name).map(|i| &i.data) {
        Some(InitData::F32(v)) => v,
        _ => &[],
    }
}

fn floats_mut<'m>(model: &'m mut Model, name: &str) -> &'m mut Vec<f32> {
    match model.initializers.iter_mut().find(|i| i.name == name).map(|i| &mut i.data) {
        Some(InitData::F32(v)) => v,
        _ => unreachable!("find_levels checked the float initializer `{name}`"),
    }
}

/// One logistic unit of the head: weights over the feature channels and a bias.
#[derive(Clone, Debug, PartialEq)]
struct Unit {
    w: Vec<f64>,
    b: f64,
}

/// The tuned parameters: per level, the target class's unit and the objectness unit.
#[derive(Clone, Debug, PartialEq)]
struct Head {
    levels: Vec<(Unit, Unit)>,
}

impl Head {
    fn read(model: &Model, levels: &[Level], class: usize) -> Head {
        let unit = |c: &HeadConv, row: usize| {
            let (w, b) = (floats(model, &c.weight), floats(model, &c.bias));
            let k = w.len() / b.len();
            Unit { w: w[row * k..(row + 1) * k].iter().map(|&v| v as f64).collect(), b: b[row] as f64 }
        };
        Head { levels: levels.iter().map(|l| (unit(&l.cls, class), unit(&l.obj, 0))).collect() }
    }

    fn write(&self, model: &mut Model, levels: &[Level], class: usize) {
        let mut put = |c: &HeadConv, row: usize, u: &Unit| {
            let k = u.w.len();
            let w = floats_mut(model, &c.weight);
            for (dst, src) in w[row * k..(row + 1) * k].iter_mut().zip(&u.w) {
                *dst = *src as f32;
            }
            floats_mut(model, &c.bias)[row] = u.b as f32;
        };
        for (l, (cls, obj)) in levels.iter().zip(&self.levels) {
            put(&l.cls, class, cls);
            put(&l.obj, 0, obj);
        }
    }
}

/// A grid cell of a training composite: its level, the features its two units read, and what
/// it should say.
struct Cell {
    level: usize,
    cls_x: Vec<f32>,
    obj_x: Vec<f32>,
    /// Inside the car's box and near its centre: the car is here.
    positive: bool,
    /// On a photo with its car painted out: no car anywhere.
    free: bool,
}

/// The features of every level of one composite, `[channels, h, w]` each, from the exposed
/// outputs.
fn level_features<'o>(outs: &'o [RawOutput], levels: &[Level]) -> Result<Vec<(&'o RawOutput, &'o RawOutput)>, String> {
    let get = |name: &str| {
        outs.iter()
            .find(|o| o.name == name)
            .ok_or_else(|| format!("the exposed feature map `{name}` did not come back"))
    };
    levels.iter().map(|l| Ok((get(&l.cls.input)?, get(&l.obj.input)?))).collect()
}

/// The cells of one composite: positives are the cells whose centre lies in the car's box and
/// within 2.5 strides of its centre on both axes (YOLOX's centre prior); negatives every cell
/// whose centre lies outside the box. `input_box` is the car's box in model-input pixels; `None`
/// for a photo without its car, whose every cell is a negative.
fn cells(feats: &[(&RawOutput, &RawOutput)], input_w: usize, input_box: Option<[f32; 4]>) -> Vec<Cell> {
    let free = input_box.is_none();
    let input_box = input_box.unwrap_or([f32::NAN; 4]);
    let mut out = Vec::new();
    let (cx, cy) = ((input_box[0] + input_box[2]) / 2.0, (input_box[1] + input_box[3]) / 2.0);
    for (level, (cf, of)) in feats.iter().enumerate() {
        let (c, h, w) = (cf.shape[1], cf.shape[2], cf.shape[3]);
        let s = input_w as f32 / w as f32;
        for i in 0..h {
            for j in 0..w {
                let (x, y) = ((j as f32 + 0.5) * s, (i as f32 + 0.5) * s);
                let inside = x > input_box[0] && x < input_box[2] && y > input_box[1] && y < input_box[3];
                let central = (x - cx).abs() <= 2.5 * s && (y - cy).abs() <= 2.5 * s;
                if inside && !central {
                    continue;
                }
                let at = |f: &RawOutput| (0..c).map(|k| f.data[k * h * w + i * w + j]).collect();
                out.push(Cell { level, cls_x: at(cf), obj_x: at(of), positive: inside, free });
            }
        }
    }
    out
}

fn sigmoid(z: f64) -> f64 {
    1.0 / (1.0 + (-z).exp())
}

/// Binary cross-entropy of logit `z` against `t` and its derivative in `z`.
fn bce(z: f64, t: f64) -> (f64, f64) {
    // log(1 + e^-|z|) + max(z, 0) − t·z, stable for any z.
    (z.max(0.0) - t * z + (-z.abs()).exp().ln_1p(), sigmoid(z) - t)
}

fn dot(u: &Unit, x: &[f32]) -> f64 {
    u.b + u.w.iter().zip(x).map(|(w, x)| w * *x as f64).sum::<f64>()
}

/// The loss of `head` on `cells` and its gradient: the mean over positives of the class and
/// objectness cross-entropies towards 1, plus the mean over negatives of the class one towards 0
/// and, where the clean head saw no object (`quiet`), the objectness one towards 0, the cells of
/// car-free photos averaged apart; plus `l2` times the squared distance to `start`.
fn loss_and_grad(head: &Head, start: &Head, cells: &[Cell], quiet: &[bool], l2: f64) -> (f64, Head) {
    let zero = |u: &Unit| Unit { w: vec![0.0; u.w.len()], b: 0.0 };
    let mut g = Head { levels: head.levels.iter().map(|(c, o)| (zero(c), zero(o))).collect() };
    let count = |f: &dyn Fn(&Cell) -> bool| cells.iter().filter(|c| f(c)).count().max(1) as f64;
    let (pos, neg, free) = (count(&|c| c.positive), count(&|c| !c.positive && !c.free), count(&|c| c.free));
    let mut loss = 0.0;
    let add = |g: &mut Unit, x: &[f32], d: f64| {
        g.b += d;
        g.w.iter_mut().zip(x).for_each(|(gw, x)| *gw += d * *x as f64);
    };
    for (cell, &q) in cells.iter().zip(quiet) {
        let (cls, obj) = &head.levels[cell.level];
        let (gc, go) = &mut g.levels[cell.level];
        let n = if cell.positive {
            pos
        } else if cell.free {
            free
        } else {
            neg
        };
        let t = if cell.positive { 1.0 } else { 0.0 };
        let (l, d) = bce(dot(cls, &cell.cls_x), t);
        loss += l / n;
        add(gc, &cell.cls_x, d / n);
        if cell.positive || q {
            let (l, d) = bce(dot(obj, &cell.obj_x), t);
            loss += l / n;
            add(go, &cell.obj_x, d / n);
        }
    }
    for ((u, s), gu) in head
        .levels
        .iter()
        .flat_map(|(c, o)| [c, o])
        .zip(start.levels.iter().flat_map(|(c, o)| [c, o]))
        .zip(g.levels.iter_mut().flat_map(|(c, o)| [c, o]))
    {
        for ((w, w0), gw) in u.w.iter().zip(&s.w).zip(gu.w.iter_mut()) {
            loss += l2 * (w - w0) * (w - w0);
            *gw += 2.0 * l2 * (w - w0);
        }
        loss += l2 * (u.b - s.b) * (u.b - s.b);
        gu.b += 2.0 * l2 * (u.b - s.b);
    }
    (loss, g)
}

/// Full-batch Adam from `start`; returns the tuned head and the loss before each step.
fn fit(
    start: &Head,
    cells: &[Cell],
    quiet: &[bool],
    cfg: &AdvTrainConfig,
    progress: &dyn Progress,
) -> (Head, Vec<f64>) {
    let (b1, b2, eps) = (0.9, 0.999, 1e-8);
    let flat = |h: &Head| -> Vec<f64> {
        h.levels.iter().flat_map(|(c, o)| [c, o]).flat_map(|u| u.w.iter().copied().chain([u.b])).collect()
    };
    let unflat = |v: &[f64]| -> Head {
        let mut it = v.iter().copied();
        let mut take = |u: &Unit| Unit {
            w: (0..u.w.len()).map(|_| it.next().unwrap_or(0.0)).collect(),
            b: it.next().unwrap_or(0.0),
        };
        Head { levels: start.levels.iter().map(|(c, o)| (take(c), take(o))).collect() }
    };
    let mut p = flat(start);
    let (mut m, mut v) = (vec![0.0; p.len()], vec![0.0; p.len()]);
    let mut losses = Vec::with_capacity(cfg.steps);
    progress.begin("adam steps", cfg.steps as u64);
    for t in 1..=cfg.steps {
        let (loss, g) = loss_and_grad(&unflat(&p), start, cells, quiet, cfg.l2);
        losses.push(loss);
        for (((p, m), v), g) in p.iter_mut().zip(&mut m).zip(&mut v).zip(flat(&g)) {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            let (mh, vh) = (*m / (1.0 - b1.powi(t as i32)), *v / (1.0 - b2.powi(t as i32)));
            *p -= cfg.lr * mh / (vh.sqrt() + eps);
        }
        progress.advance(1);
    }
    progress.end(None);
    (unflat(&p), losses)
}

/// The composite of `view` with `tex` (or the photo itself), as scores see it.
fn composite(view: &TrainView, tex: Option<&[f32]>, setup: &Setup) -> Frame {
    super::table2::frame(view, tex.map(|t| setup.scored(t)).as_deref(), setup)
}

/// The held-out photos with their car painted out.
const NO_CAR: &str = "no car (painted out)";

/// One texture condition: its name (conditions of one name pool into one row), the file it came
/// from, and its texture (`None`: the photo as it is).
struct Condition {
    name: String,
    file: String,
    texture: Option<Vec<f32>>,
}

fn conditions(setup: &Setup, files: &[(String, PathBuf)], seeds: &[u64]) -> Result<Vec<Condition>, ExperimentError> {
    let n = setup.tex_size;
    let mut v = vec![Condition { name: "original".into(), file: String::new(), texture: None }];
    for s in seeds {
        let texture = Some(random_blocks(n, random_block_side(n), *s));
        v.push(Condition { name: "random".into(), file: format!("seed {s}"), texture });
    }
    for (name, f) in files {
        let file = pav_core::path::tidy(f).display().to_string();
        v.push(Condition { name: name.clone(), file, texture: Some(setup.load_texture(f)?) });
    }
    Ok(v)
}

/// The recipe's textures named by their folders ([`super::table2::texture_name`]).
fn named(files: &[PathBuf]) -> Vec<(String, PathBuf)> {
    files.iter().map(|f| (super::table2::texture_name(f), f.clone())).collect()
}

/// What `pav adv-train` made.
pub struct AdvTrainOutcome {
    /// The tuned model.
    pub model: PathBuf,
    /// Its detector config.
    pub config: PathBuf,
    /// The model's sha256.
    pub sha256: String,
    /// The report (Markdown).
    pub markdown: String,
    /// Loss before the first and after the last step.
    pub loss: (f64, f64),
}

/// `pav adv-train`: tunes the head of `cfg`'s detector, scores the held-out views with the
/// recipe's test textures and `extra_tests` (name, file; one name's files pool), writes
/// `<name>_advtrain.onnx`, its detector config `<name>_advtrain.toml`, `loss.csv`,
/// `advtrain.csv` (every held-out view's best car score before and after) and `advtrain.md`
/// into `out`.
pub fn adv_train(
    cfg: &AdvTrainConfig,
    extra_tests: &[(String, PathBuf)],
    out: &Path,
    progress: &dyn Progress,
) -> Result<AdvTrainOutcome, ExperimentError> {
    let det_cfg = DetectorConfig::load(&cfg.detector)?;
    let refuse = |msg: String| ExperimentError::Invalid(format!("{}: {msg}", cfg.detector.display()));
    if !matches!(det_cfg.output, OutputLayout::Yolox { .. }) {
        return Err(refuse(format!(
            "`{}` is not a YOLOX detector (layout yolox): adversarial training tunes a YOLOX head",
            det_cfg.name
        )));
    }
    let [class] = det_cfg.target_classes[..] else {
        return Err(refuse(format!(
            "adversarial training tunes one target class; `{}` has {}",
            det_cfg.name,
            det_cfg.target_classes.len()
        )));
    };
    let bytes =
        std::fs::read(&det_cfg.model).map_err(|source| ExperimentError::Io { path: det_cfg.model.clone(), source })?;
    let mut model = Model::from_bytes(&bytes).map_err(|e| refuse(format!("{}: {e}", det_cfg.model.display())))?;
    let levels = find_levels(&model, det_cfg.class_names.len()).map_err(refuse)?;
    create_dir(out)?;

    // The same model with the head's feature maps as outputs too, to read them per composite.
    let mut exposed = model.clone();
    for l in &levels {
        for c in [&l.cls, &l.obj] {
            if !exposed.outputs.iter().any(|o| o.name == c.input) {
                exposed.outputs.push(ValueInfo { name: c.input.clone(), elem_type: 0, dims: vec![] });
            }
        }
    }
    let exposed_path = out.join("features.onnx");
    write_file(&exposed_path, exposed.to_bytes())?;
    let mut feat_cfg = det_cfg.clone();
    feat_cfg.model = exposed_path.clone();
    let mut features = OnnxDetector::new(feat_cfg, 0)?;

    let opt = OptimizeConfig::load(&cfg.views)?;
    let setup = Setup::load(&opt, None).map_err(|e| ExperimentError::Setup(Box::new(e)))?;
    let train_views = setup.training_views();
    let train = conditions(&setup, &named(&cfg.train_textures), &cfg.random_seeds)?;
    let input = &det_cfg.input;
    let mut all = Vec::new();
    let mut quiet = Vec::new();
    let start = Head::read(&model, &levels, class);
    progress.begin("training composites", (train.len() * train_views.len() + setup.train.len()) as u64);
    for c in &train {
        for v in &train_views {
            progress.advance(1);
            let v = setup.view(*v)?;
            let Some(b) = v.car_box else { continue };
            let (x, map) =
                prepare(&composite(&v, c.texture.as_deref(), &setup), input).map_err(|e| refuse(e.to_string()))?;
            let outs = features.infer(x, &map)?;
            let feats = level_features(&outs, &levels).map_err(refuse)?;
            let ib = [
                b[0] * map.scale_x + map.pad_x,
                b[1] * map.scale_y + map.pad_y,
                b[2] * map.scale_x + map.pad_x,
                b[3] * map.scale_y + map.pad_y,
            ];
            for cell in cells(&feats, input.width, Some(ib)) {
                // Where the clean head sees an object (another car, a person), its objectness is left alone.
                quiet.push(sigmoid(dot(&start.levels[cell.level].1, &cell.obj_x)) < 0.1);
                all.push(cell);
            }
        }
    }
    // The training photos without their car: the head must not learn that a car stands where
    // these streets' cars stood.
    for v in &setup.train {
        progress.advance(1);
        let Some(f) = setup.car_free(&v.name) else { continue };
        let f = f.map_err(|e| refuse(format!("painting the car out of {}: {e}", v.name)))?;
        let (x, map) = prepare(&f, input).map_err(|e| refuse(e.to_string()))?;
        let outs = features.infer(x, &map)?;
        let feats = level_features(&outs, &levels).map_err(refuse)?;
        for cell in cells(&feats, input.width, None) {
            quiet.push(sigmoid(dot(&start.levels[cell.level].1, &cell.obj_x)) < 0.1);
            all.push(cell);
        }
    }
    progress.end(None);
    drop(features);
    let _ = std::fs::remove_file(&exposed_path);
    if !all.iter().any(|c| c.positive) {
        return Err(refuse("no training view has the car in view: nothing to tune on".into()));
    }
    let (tuned, losses) = fit(&start, &all, &quiet, cfg, progress);
    drop(all);
    tuned.write(&mut model, &levels, class);
    let name = format!("{}_advtrain", det_cfg.name);
    let model_path = out.join(format!("{name}.onnx"));
    let tuned_bytes = model.to_bytes();
    write_file(&model_path, &tuned_bytes)?;
    let sha256 = format!("{:x}", Sha256::digest(&tuned_bytes));
    let config_path = out.join(format!("{name}.toml"));
    let toml = format!(
        "# Written by pav adv-train: {} with its head tuned on adversarial composites (sha256 {sha256}).\nextends = {:?}\nname = {:?}\nmodel = {:?}\ndescription = {:?}\n",
        det_cfg.name,
        std::path::absolute(&cfg.detector).unwrap_or(cfg.detector.clone()).display().to_string(),
        format!("{}+advtrain", det_cfg.name),
        format!("{name}.onnx"),
        format!("{} with its head adversarially trained (pav adv-train)", det_cfg.description),
    );
    write_file(&config_path, toml)?;
    let loss_csv: String = std::iter::once("step,loss\n".to_string())
        .chain(losses.iter().enumerate().map(|(i, l)| format!("{i},{l:.6}\n")))
        .collect();
    write_file(&out.join("loss.csv"), loss_csv)?;

    // Held-out views, through the whole detection path of both models.
    let mut tests = named(&cfg.test_textures);
    tests.extend(extra_tests.iter().cloned());
    let test = conditions(&setup, &tests, &cfg.test_random_seeds)?;
    let mut before = OnnxDetector::new(det_cfg.clone(), 0)?;
    let mut after = OnnxDetector::new(DetectorConfig::load(&config_path)?, 0)?;
    let mut rows = vec!["view,texture,file,before,after".to_string()];
    let mut per: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    progress.begin("held-out composites", ((test.len() + 1) * setup.test.len()) as u64);
    let mut score = |c: (&str, &str), v: &TrainView, f: &Frame| -> Result<(f64, f64), ExperimentError> {
        let best = |d: &mut OnnxDetector| -> Result<f64, ExperimentError> {
            Ok(d.propose(f)?.best(d.target_classes()).map_or(0.0, |t| t.score as f64))
        };
        let (b, a) = (best(&mut before)?, best(&mut after)?);
        rows.push(format!("{},{:?},{:?},{b:.4},{a:.4}", v.name, c.0, c.1));
        progress.advance(1);
        Ok((b, a))
    };
    let mut pool = |name: &str, pairs: Vec<(f64, f64)>| match per.iter_mut().find(|(n, _)| n == name) {
        Some((_, p)) => p.extend(pairs),
        None => per.push((name.to_string(), pairs)),
    };
    for c in &test {
        let mut pairs = Vec::new();
        for v in &setup.test {
            pairs.push(score((&c.name, &c.file), v, &composite(v, c.texture.as_deref(), &setup))?);
        }
        pool(&c.name, pairs);
    }
    // The same streets without the car: a tuned head that finds "cars" anywhere shows here.
    let mut pairs = Vec::new();
    for v in &setup.test {
        if let Some(f) = setup.car_free(&v.name) {
            let f = f.map_err(|e| refuse(format!("painting the car out of {}: {e}", v.name)))?;
            pairs.push(score((NO_CAR, ""), v, &f)?);
        }
    }
    pool(NO_CAR, pairs);
    progress.end(None);
    write_file(&out.join("advtrain.csv"), rows.join("\n") + "\n")?;
    let markdown = report(
        &det_cfg.name,
        &per,
        losses.first().copied().unwrap_or(f64::NAN),
        losses.last().copied().unwrap_or(f64::NAN),
        setup.test.len(),
        train_views.len(),
        train.len(),
    );
    write_markdown(out, "advtrain.md", &markdown)?;
    Ok(AdvTrainOutcome {
        model: model_path,
        config: config_path,
        sha256,
        markdown,
        loss: (losses.first().copied().unwrap_or(f64::NAN), losses.last().copied().unwrap_or(f64::NAN)),
    })
}

/// The before/after table: per texture, the mean best car score, the share found at 0.5, and
/// the paired difference with its 95 % bootstrap interval.
fn report(
    name: &str,
    per: &[(String, Vec<(f64, f64)>)],
    l0: f64,
    l1: f64,
    views: usize,
    train_views: usize,
    train_conditions: usize,
) -> String {
    let mut md = format!(
        "# Adversarial training of {name}'s head\n\nTuned on {train_views} training views × {train_conditions} paints and the training photos without their car (loss {l0:.4} → {l1:.4}); scored on {views} held-out views.\n\n\
         | texture | pairs | before: mean best car score / found | after | after − before |\n|---|---:|---:|---:|---:|\n"
    );
    for (tex, pairs) in per {
        let n = pairs.len().max(1) as f64;
        let mean = |f: &dyn Fn(&(f64, f64)) -> f64| pairs.iter().map(f).sum::<f64>() / n;
        let found = |f: &dyn Fn(&(f64, f64)) -> f64| 100.0 * pairs.iter().filter(|p| f(p) >= 0.5).count() as f64 / n;
        let d: Vec<f64> = pairs.iter().map(|(b, a)| a - b).collect();
        let ci = paired_bootstrap(&d, 10_000, 0)
            .map_or("–".into(), |Interval { lo, hi, .. }| format!("[{lo:+.3}, {hi:+.3}]"));
        md += &format!(
            "| {tex} | {} | {:.3} / {:.0} % | {:.3} / {:.0} % | {:+.3} {ci} |\n",
            pairs.len(),
            mean(&|p| p.0),
            found(&|p| p.0),
            mean(&|p| p.1),
            found(&|p| p.1),
            mean(&|p| p.1 - p.0)
        );
    }
    md += &format!("\nFound: best car score ≥ 0.5. On \"{NO_CAR}\" (the held-out photos without their car) a find is a false alarm.\n");
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_loss_gradient_matches_central_differences() {
        let x = |k: usize| (0..3).map(|i| ((i * 7 + k * 3) % 5) as f32 / 5.0 - 0.4).collect::<Vec<f32>>();
        let cells: Vec<Cell> = (0..6)
            .map(|k| Cell { level: k % 2, cls_x: x(k), obj_x: x(k + 1), positive: k % 3 == 0, free: k == 4 })
            .collect();
        let quiet = vec![true, false, true, true, false, true];
        let u = |s: f64| Unit { w: vec![0.3 * s, -0.2, 0.1], b: 0.05 * s };
        let start = Head { levels: vec![(u(1.0), u(-1.0)), (u(0.5), u(2.0))] };
        let head = Head { levels: vec![(u(1.3), u(-0.7)), (u(0.1), u(2.2))] };
        let (_, g) = loss_and_grad(&head, &start, &cells, &quiet, 0.7);
        let h = 1e-6;
        for lvl in 0..2 {
            for which in 0..2 {
                for i in 0..4 {
                    let bump = |s: f64| {
                        let mut hh = head.clone();
                        let unit = if which == 0 { &mut hh.levels[lvl].0 } else { &mut hh.levels[lvl].1 };
                        if i < 3 {
                            unit.w[i] += s
                        } else {
                            unit.b += s
                        }
                        loss_and_grad(&hh, &start, &cells, &quiet, 0.7).0
                    };
                    let num = (bump(h) - bump(-h)) / (2.0 * h);
                    let unit = if which == 0 { &g.levels[lvl].0 } else { &g.levels[lvl].1 };
                    let ana = if i < 3 { unit.w[i] } else { unit.b };
                    assert!((num - ana).abs() < 1e-6, "level {lvl} unit {which} param {i}: {num} vs {ana}");
                }
            }
        }
    }

    #[test]
    fn cross_entropy_is_stable_at_large_logits() {
        for z in [-800.0, -30.0, 0.0, 30.0, 800.0] {
            let (l, d) = bce(z, 1.0);
            assert!(l.is_finite() && d.is_finite(), "{z}");
        }
        assert!((bce(0.0, 1.0).0 - std::f64::consts::LN_2).abs() < 1e-12);
        assert!(bce(800.0, 1.0).0.abs() < 1e-12 && (bce(800.0, 0.0).0 - 800.0).abs() < 1e-9);
    }
}
