//! `pav lofo`: leave one family out. Transfer is the claim that a texture hides the car from
//! detectors it never trained against; held out by family, each detector family in turn is left
//! out of the white boxes, the recipe is trained against all the others over several seeds, and
//! the family left out scores the texture on a held-out set beside a peer's published texture and
//! random colour blocks, paired view by view.

use super::outputs::{optimize_and_report, OptimizeRun, Prepared};
use super::per_view::ScoredView;
use super::table2::eval_digital;
use super::{create_dir, write_markdown, ExperimentError, Scoring};
use pav_attack::config::OptimizeConfig;
use pav_attack::export::PrintSpec;
use pav_attack::optimize::Finish;
use pav_core::progress::Progress;
use pav_core::table::write_csv;
use pav_run::provenance::{Run, FILE};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// One arm: a recipe config whose white boxes are every family but one.
#[derive(Clone, Debug)]
pub struct Arm {
    /// The config trained.
    pub config: PathBuf,
    /// The family it leaves out, by its detector's name.
    pub held_out: String,
    /// That detector's config, as another arm trains against it (scored as it ships: an int8
    /// model by itself, not by its float surrogate).
    pub detector: PathBuf,
    /// Every file the config reads (`OptimizeConfig::inputs`), for a run's record.
    pub inputs: Vec<PathBuf>,
}

impl Arm {
    /// Its folder in the output: `without-NAME`, holding `seed<S>/` per seed.
    pub fn dir(&self) -> String {
        format!("without-{}", self.held_out)
    }
}

/// The arms of `configs`: each must leave out exactly one of the families the configs train
/// against together.
pub fn arms(configs: &[PathBuf]) -> Result<Vec<Arm>, ExperimentError> {
    // Each config with its white boxes' names.
    let loaded: Vec<(OptimizeConfig, Vec<String>)> = configs
        .iter()
        .map(|c| {
            let cfg = OptimizeConfig::load(c)?;
            let names = cfg.white_box_names()?;
            Ok((cfg, names))
        })
        .collect::<Result<_, ExperimentError>>()?;
    let mut all: BTreeMap<String, PathBuf> = BTreeMap::new();
    for (cfg, names) in &loaded {
        for (name, w) in names.iter().zip(&cfg.white_box) {
            all.entry(name.clone()).or_insert_with(|| w.detector.clone());
        }
    }
    let mut out = Vec::new();
    for (config, (cfg, names)) in configs.iter().zip(loaded) {
        let missing: Vec<&String> = all.keys().filter(|n| !names.contains(n)).collect();
        let [held_out] = missing.as_slice() else {
            return Err(ExperimentError::Invalid(format!(
                "{}: an arm leaves out exactly one of the families the configs train against together ({}); it leaves out {}",
                config.display(),
                all.keys().cloned().collect::<Vec<_>>().join(", "),
                if missing.is_empty() { "none".to_string() } else { missing.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ") }
            )));
        };
        if out.iter().any(|a: &Arm| &a.held_out == *held_out) {
            return Err(ExperimentError::Invalid(format!("two configs leave out {held_out}")));
        }
        out.push(Arm {
            config: config.clone(),
            held_out: (*held_out).clone(),
            detector: all[*held_out].clone(),
            inputs: cfg.inputs(),
        });
    }
    Ok(out)
}

/// The training units: every arm at every seed, in a fixed order (a shard's share is cut from
/// it). Seed by seed, so that a run stopped part way has every arm at its first seeds.
pub fn units(arms: &[Arm], seeds: &[u64]) -> Vec<(usize, u64)> {
    seeds.iter().flat_map(|&s| (0..arms.len()).map(move |a| (a, s))).collect()
}

/// A unit's folder, relative to the output folder.
pub fn unit_dir(arm: &Arm, seed: u64) -> PathBuf {
    Path::new(&arm.dir()).join(format!("seed{seed}"))
}

/// The result key a unit's run.toml gets once its texture is written.
const FINISHED: &str = "finished";

/// Whether the unit in `dir` finished (a killed one resumes from its checkpoint).
pub fn finished(dir: &Path) -> bool {
    Run::read(&dir.join(FILE)).is_ok_and(|r| r.result.get(FINISHED).is_some_and(|v| v == "yes"))
}

/// Writes `run` as the `run.toml` of `dir`.
fn write_run(dir: &Path, run: &Run) -> Result<(), ExperimentError> {
    run.write(&dir.join(FILE)).map_err(|source| ExperimentError::Io { path: dir.join(FILE), source })
}

/// Trains `arm` at `seed` into `dir`, unless it finished there before; a run stopped part way
/// resumes from its checkpoint. Returns whether it trained now.
pub fn train(
    arm: &Arm,
    seed: u64,
    dir: &Path,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<bool, ExperimentError> {
    if finished(dir) {
        return Ok(false);
    }
    let mut p = Prepared::load(&arm.config, None, stop)?;
    p.cfg.optimizer.seed = seed;
    create_dir(dir)?;
    let record = Run::start()
        .config(&arm.config)
        .inputs(p.cfg.inputs().iter().map(|p| p.as_path()))
        .setting("seed", seed)
        .setting("held_out", &arm.held_out)
        .setting("training_views", p.setup.training_views().len())
        .setting("pbr_kept", p.pbr_kept.as_ref().map_or("all".to_string(), |k| k.to_string()));
    write_run(dir, &record)?;
    let run = OptimizeRun {
        out: dir.to_path_buf(),
        resume: dir.join("checkpoint.bin").is_file(),
        epochs: None,
        snapshot_every: 0,
        print: PrintSpec { scale: 20.0, dpi: 300.0 },
    };
    if matches!(optimize_and_report(&p, &run, progress, stop)?.finish, Finish::Stopped) {
        return Err(ExperimentError::Stopped(dir.to_path_buf()));
    }
    let mut record = record;
    record.result(FINISHED, "yes");
    write_run(dir, &record)?;
    Ok(true)
}

/// The trained texture of an arm against one other texture, for the family it left out, on the
/// held-out views: mean best car scores and their difference over (seed, view) pairs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct LofoRow {
    /// The family left out, scoring.
    pub held_out: String,
    /// The other texture.
    pub against: String,
    /// Mean best car score of the arm's textures (over seeds and views).
    pub score: f64,
    /// The other texture's (a random kind: each view's mean over its seeds).
    pub other: f64,
    /// Share of (seed, view) pairs the arm's texture leaves detected at the threshold.
    pub detected: f64,
    /// The other texture's share.
    pub other_detected: f64,
    /// score − other.
    pub diff: f64,
    /// 95 % interval of the difference, low end, resampling seeds and views.
    pub lo: f64,
    /// High end.
    pub hi: f64,
    /// Half the interval's width.
    pub half_width: f64,
    /// The lowest of the per-seed mean differences.
    pub seed_min: f64,
    /// The highest.
    pub seed_max: f64,
    /// Seeds.
    pub seeds: usize,
    /// Held-out views.
    pub views: usize,
}

/// The mean of `d[seed][view]` with a 95 % percentile interval from `resamples` two-level
/// bootstrap resamples: seeds drawn with replacement, and views drawn with replacement, so that
/// the interval carries both the spread between seeds and the spread between views.
pub fn two_level_bootstrap(d: &[Vec<f64>], resamples: usize, seed: u64) -> Option<(f64, f64, f64)> {
    let (s, v) = (d.len(), d.first()?.len());
    if v == 0 || d.iter().any(|r| r.len() != v) {
        return None;
    }
    let mut rng = pav_core::rng::Rng::new(seed);
    let mut means: Vec<f64> = (0..resamples.max(1))
        .map(|_| {
            let seeds: Vec<usize> = (0..s).map(|_| (rng.next_u64() % s as u64) as usize).collect();
            let mut sum = 0.0;
            for _ in 0..v {
                let at = (rng.next_u64() % v as u64) as usize;
                sum += seeds.iter().map(|&k| d[k][at]).sum::<f64>();
            }
            sum / (s * v) as f64
        })
        .collect();
    means.sort_by(f64::total_cmp);
    let at = |q: f64| means[((q * (means.len() - 1) as f64).round() as usize).min(means.len() - 1)];
    let mean = d.iter().flatten().sum::<f64>() / (s * v) as f64;
    Some((mean, at(0.025), at(0.975)))
}

/// A texture's scores of one detector: view → (seed, best car score) over its seeds.
type SeedScores<'a> = BTreeMap<&'a str, Vec<(u64, f64)>>;

/// The rows of one arm from its held-out `records` (as `pav eval-digital` writes them):
/// `mine` (one record per seed and view) against each other texture but the original paint.
pub fn compare(records: &[ScoredView], held_out: &str, mine: &str, threshold: f32) -> Vec<LofoRow> {
    let held: Vec<&ScoredView> = records.iter().filter(|r| r.role == "held-out" && r.detector == held_out).collect();
    let mut views: Vec<&str> = held.iter().map(|r| r.view.as_str()).collect();
    views.sort_unstable();
    views.dedup();
    let mut by: BTreeMap<&str, SeedScores> = BTreeMap::new();
    for r in &held {
        by.entry(r.texture.as_str()).or_default().entry(r.view.as_str()).or_default().push((r.seed, r.score as f64));
    }
    let Some(own) = by.get(mine) else { return Vec::new() };
    let mut seeds: Vec<u64> = own.values().flatten().map(|(s, _)| *s).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let grid: Vec<Vec<f64>> = seeds
        .iter()
        .map(|s| views.iter().map(|v| own[v].iter().find(|(k, _)| k == s).map_or(f64::NAN, |(_, x)| *x)).collect())
        .collect();
    let hit = |x: f64| if x >= threshold as f64 { 1.0 } else { 0.0 };
    let mean = |xs: &[f64]| xs.iter().sum::<f64>() / xs.len().max(1) as f64;
    let mut out = Vec::new();
    for (other, theirs) in &by {
        if *other == mine || *other == "original" || views.iter().any(|v| !theirs.contains_key(v)) {
            continue;
        }
        let per_view: Vec<f64> =
            views.iter().map(|v| mean(&theirs[v].iter().map(|p| p.1).collect::<Vec<_>>())).collect();
        let seen: Vec<f64> =
            views.iter().map(|v| mean(&theirs[v].iter().map(|p| hit(p.1)).collect::<Vec<_>>())).collect();
        let d: Vec<Vec<f64>> = grid.iter().map(|row| row.iter().zip(&per_view).map(|(a, b)| a - b).collect()).collect();
        if d.iter().flatten().any(|x| x.is_nan()) {
            continue;
        }
        let Some((diff, lo, hi)) = two_level_bootstrap(&d, 10_000, 7) else { continue };
        let per_seed: Vec<f64> = d.iter().map(|r| mean(r)).collect();
        let flat: Vec<f64> = grid.iter().flatten().copied().collect();
        out.push(LofoRow {
            held_out: held_out.into(),
            against: (*other).into(),
            score: mean(&flat),
            other: mean(&per_view),
            detected: mean(&flat.iter().map(|&x| hit(x)).collect::<Vec<_>>()),
            other_detected: mean(&seen),
            diff,
            lo,
            hi,
            half_width: (hi - lo) / 2.0,
            seed_min: per_seed.iter().copied().fold(f64::INFINITY, f64::min),
            seed_max: per_seed.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            seeds: seeds.len(),
            views: views.len(),
        });
    }
    out
}

/// The textures of `arm` at `seeds`, trained into `out`, linked into `pool/NAME/seed<S>/` so
/// that they are scored as one texture under the arm's name (a run training later seeds in the
/// same folder meanwhile is not read). Every unit must have finished.
fn pool(arm: &Arm, seeds: &[u64], out: &Path, pool: &Path) -> Result<PathBuf, ExperimentError> {
    let dir = pool.join(arm.dir());
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|source| ExperimentError::Io { path: dir.clone(), source })?;
    }
    for &seed in seeds {
        let unit = out.join(unit_dir(arm, seed));
        if !finished(&unit) {
            return Err(ExperimentError::Invalid(format!(
                "{}: seed {seed} without {} has not finished training; run `pav lofo` with the same arms and seeds to train it",
                unit.display(),
                arm.held_out
            )));
        }
        let to = dir.join(format!("seed{seed}"));
        create_dir(&to)?;
        for f in ["texture.png", FILE] {
            let (a, b) = (unit.join(f), to.join(f));
            std::fs::hard_link(&a, &b)
                .or_else(|_| std::fs::copy(&a, &b).map(|_| ()))
                .map_err(|source| ExperimentError::Io { path: b.clone(), source })?;
        }
    }
    Ok(dir)
}

/// Scores every arm's `seeds` (trained into `out`) on the held-out views of `heldout` by the
/// family it left out, beside `references` and `random_seeds` random textures of each kind, and
/// writes each arm's `pav eval-digital` outputs into `out/without-NAME/heldout/`, then
/// `lofo.csv` and `lofo.md` into `out`.
#[allow(clippy::too_many_arguments)]
pub fn score(
    arms: &[Arm],
    seeds: &[u64],
    heldout: &Path,
    references: &[PathBuf],
    random_seeds: u64,
    threshold: f32,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Vec<LofoRow>, ExperimentError> {
    let mut rows = Vec::new();
    // What every arm's scores rest on; a rerun that finds them unchanged keeps an arm's scores.
    let held_inputs = OptimizeConfig::load(heldout)?.inputs();
    let base = Run::start()
        .config(heldout)
        .inputs(held_inputs.iter().map(|p| p.as_path()))
        .inputs(references.iter().map(|p| p.as_path()))
        .setting("random_seeds", random_seeds)
        .setting("threshold", threshold);
    for arm in arms {
        let dir = out.join(arm.dir()).join("heldout");
        let trained = pool(arm, seeds, out, &dir.join("pool"))?;
        let scoring = Scoring { detectors: vec![arm.detector.clone()], threshold, print: None, defences: Vec::new() };
        let textures: Vec<PathBuf> = std::iter::once(trained.clone()).chain(references.iter().cloned()).collect();
        let detector = pav_detect::load::detector_inputs(std::slice::from_ref(&arm.detector));
        let mine: Vec<PathBuf> = seeds.iter().map(|s| trained.join(format!("seed{s}/texture.png"))).collect();
        let seed_list: Vec<String> = seeds.iter().map(|s| s.to_string()).collect();
        let mut record = base
            .clone()
            .inputs(detector.iter().chain(&mine).map(|p| p.as_path()))
            .setting("held_out", &arm.held_out)
            .setting("seeds", seed_list.join(","));
        let records = match scored_before(&dir, &record) {
            Some(records) => {
                progress.note(&format!("{}: held-out scores kept from an earlier run", arm.dir()));
                records
            }
            None => {
                let (_, records) = eval_digital(heldout, &textures, random_seeds, &scoring, None, &dir, progress)?;
                record.result(SCORED, "yes");
                write_run(&dir, &record)?;
                records
            }
        };
        let arm_rows = compare(&records, &arm.held_out, &arm.dir(), threshold);
        if arm_rows.first().is_some_and(|r| r.seeds != seeds.len()) {
            return Err(ExperimentError::Invalid(format!(
                "{}: seeds scored differ from seeds trained",
                trained.display()
            )));
        }
        rows.extend(arm_rows);
    }
    write_csv(&out.join("lofo.csv"), &rows)?;
    write_markdown(out, "lofo.md", &markdown(&rows))?;
    Ok(rows)
}

/// The result key an arm's held-out `run.toml` gets once its scores are written.
const SCORED: &str = "scored";

/// The records an earlier run wrote into `dir` when it scored the same inputs with the same
/// settings as `now` would (its `run.toml`, written after the scores, says so); None otherwise,
/// and for a run stopped before it finished.
fn scored_before(dir: &Path, now: &Run) -> Option<Vec<ScoredView>> {
    let before = Run::read(&dir.join(FILE)).ok()?;
    if before.result.get(SCORED).is_none_or(|v| v != "yes") || scored_on(&before) != scored_on(now) {
        return None;
    }
    let mut r = csv::Reader::from_path(dir.join("digital_views.csv")).ok()?;
    r.deserialize().collect::<Result<Vec<ScoredView>, _>>().ok()
}

/// A file a run read, as its path and sha256.
type FileSha<'a> = (&'a str, &'a str);

/// What a held-out record's scores rest on: its config, its inputs' sha256 and its settings.
fn scored_on(r: &Run) -> (Option<FileSha<'_>>, Vec<FileSha<'_>>, &BTreeMap<String, String>) {
    fn file(i: &pav_run::provenance::Input) -> FileSha<'_> {
        (i.path.as_str(), i.sha256.as_str())
    }
    (r.config.as_ref().map(file), r.inputs.iter().map(file).collect(), &r.settings)
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[LofoRow]) -> String {
    let mut md = String::from(
        "# Leave one family out\n\nEach row: the recipe trained without the family left out, scored by it on the held-out views, against another texture. Mean best car score (detected at the threshold, %); difference over (seed, view) pairs with a 95 % interval resampling seeds and views (below zero: the trained texture hides the car better).\n\n| held out | against | trained | other | difference [95 %] | ± | per seed | seeds | views |\n|---|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        md.push_str(&format!(
            "| {} | {} | {:.3} ({:.0} %) | {:.3} ({:.0} %) | {:+.3} [{:+.3}, {:+.3}] | {:.3} | {:+.3} … {:+.3} | {} | {} |\n",
            r.held_out,
            r.against,
            r.score,
            100.0 * r.detected,
            r.other,
            100.0 * r.other_detected,
            r.diff,
            r.lo,
            r.hi,
            r.half_width,
            r.seed_min,
            r.seed_max,
            r.seeds,
            r.views
        ));
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_level_interval_carries_the_spread_between_seeds() {
        // Two seeds whose views agree with each other but whose levels differ: a view-only
        // bootstrap would give a narrow interval; resampling seeds widens it to their spread.
        let views = 210;
        let d: Vec<Vec<f64>> = [-0.10, 0.10]
            .iter()
            .map(|level| (0..views).map(|v| level + 0.01 * ((v % 7) as f64 - 3.0)).collect())
            .collect();
        let (mean, lo, hi) = two_level_bootstrap(&d, 4000, 1).unwrap();
        assert!(mean.abs() < 1e-9);
        assert!(lo < -0.09 && hi > 0.09, "{lo} {hi}");
        let flat: Vec<f64> = d.iter().flatten().copied().collect();
        let one = pav_eval::digital::paired_bootstrap(&flat, 4000, 1).unwrap();
        assert!(one.hi - one.lo < 0.05, "the view bootstrap alone: {} {}", one.lo, one.hi);
        // One seed: the views' spread alone, as the paired bootstrap gives it.
        let (_, lo1, hi1) = two_level_bootstrap(&d[..1], 4000, 1).unwrap();
        assert!(hi1 - lo1 < 0.01 && lo1 < -0.1 && hi1 > -0.1, "{lo1} {hi1}");
        assert!(two_level_bootstrap(&[], 10, 1).is_none());
        assert!(two_level_bootstrap(&[vec![1.0], vec![]], 10, 1).is_none());
    }

    fn record(texture: &str, seed: u64, view: &str, score: f32) -> ScoredView {
        ScoredView {
            fold: 0,
            role: "held-out",
            view: view.into(),
            texture: texture.into(),
            seed,
            detector: "yolox_nano".into(),
            score,
        }
    }

    #[test]
    fn an_arm_is_compared_with_each_other_texture_view_by_view() {
        let mut r = Vec::new();
        for (v, base) in [("a", 0.8f32), ("b", 0.6), ("c", 0.2)] {
            r.push(record("original", 0, v, base));
            r.push(record("rauca-e2e", 0, v, base - 0.1));
            for s in 1..=2 {
                r.push(record("random", s, v, base + 0.01 * s as f32));
            }
            for s in 0..3 {
                r.push(record("without-yolox_nano", s, v, base - 0.2 + 0.05 * s as f32));
            }
        }
        r.push(record("other-family", 0, "a", 0.9));
        let rows = compare(&r, "yolox_nano", "without-yolox_nano", 0.5);
        let against: Vec<&str> = rows.iter().map(|r| r.against.as_str()).collect();
        // The original is no reference, and a texture missing views is skipped.
        assert_eq!(against, ["random", "rauca-e2e"]);
        let rauca = &rows[1];
        // Each view: −0.2 + 0.05·s against −0.1, seeds 0..3: mean −0.05.
        assert!((rauca.diff + 0.05).abs() < 1e-6, "{rauca:?}");
        assert!((rauca.seed_min + 0.1).abs() < 1e-6 && rauca.seed_max.abs() < 1e-6, "{rauca:?}");
        assert_eq!((rauca.seeds, rauca.views), (3, 3));
        // Detected at 0.5: of the trained, views a (0.6, 0.65, 0.7) and b's seed 2 (0.5).
        assert!((rauca.detected - 4.0 / 9.0).abs() < 1e-9, "{}", rauca.detected);
        let random = &rows[0];
        assert!((random.other - (0.8 + 0.6 + 0.2 + 3.0 * 0.015) / 3.0).abs() < 1e-6, "{random:?}");
    }
}
