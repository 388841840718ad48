//! The shards of one `pav-rig evaluate` run joined into its reports: each shard scored some of
//! the videos into its own folder and listed what each video added (`videos.json`); the merge
//! puts the videos back in the order the run was given them and writes the reports one process
//! scoring them all would have written.

use super::physical::FrameRecord;
use super::report::{FrameCsv, ReportError};
use super::run::{pool, settings, write_reports, EvalOptions, EvalOutcome, VideoPart};
use pav_run::shard::{Shard, ShardError};
use std::path::{Path, PathBuf};

/// The file in a shard's folder that lists what each of its videos added.
pub const SHARD_INDEX: &str = "videos.json";

/// What a shard scored: its detectors, in order, and per video what it added.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
pub struct ShardIndex {
    /// Detector names, in the run's order.
    pub detectors: Vec<String>,
    /// The shard's videos, indexed among all of the run's.
    pub videos: Vec<VideoPart>,
}

/// Writes a shard's index into its folder; `indices[i]` is the run-wide index of the shard's
/// `i`-th video.
pub fn write_index(dir: &Path, detectors: &[String], out: &EvalOutcome, indices: &[usize]) -> Result<(), ReportError> {
    let videos =
        out.videos.iter().map(|v| VideoPart { index: indices[v.index], ..v.clone() }).collect::<Vec<VideoPart>>();
    let index = ShardIndex { detectors: detectors.to_vec(), videos };
    Ok(pav_run::shard::write_json(&dir.join(SHARD_INDEX), &index)?)
}

fn read_index(dir: &Path) -> Result<Option<ShardIndex>, ReportError> {
    let path = dir.join(SHARD_INDEX);
    Ok(if path.exists() { Some(pav_run::shard::read_json(&path)?) } else { None })
}

fn read_frames(path: &Path) -> Result<Vec<FrameRecord>, ReportError> {
    let bad = |why: String| ReportError::Read { path: path.to_path_buf(), why };
    let mut r = csv::Reader::from_path(path).map_err(|e| bad(e.to_string()))?;
    r.deserialize().collect::<Result<_, _>>().map_err(|e| bad(e.to_string()))
}

/// Joins the shards (found and checked by `shard::find_checked`) of a run over `videos` videos
/// into `opts.out_dir`: `frames.csv` and every report, as one process would have written them.
/// Refused before writing anything: a shard without its index (not finished), a video no shard
/// or two shards scored, shards that scored with other detectors.
pub fn merge(shards: &[(Shard, PathBuf)], videos: usize, opts: &EvalOptions) -> Result<EvalOutcome, ReportError> {
    let mut parts: Vec<Option<(PathBuf, VideoPart, Vec<FrameRecord>)>> = vec![None; videos];
    let mut detectors: Option<(PathBuf, Vec<String>)> = None;
    for (shard, dir) in shards {
        let Some(index) = read_index(dir)? else {
            if shard.units(videos).is_empty() {
                continue;
            }
            return Err(ShardError::Unfinished { shard: dir.clone(), what: "its videos".into() }.into());
        };
        match &detectors {
            Some((first, names)) if *names != index.detectors => {
                return Err(ReportError::Options(format!(
                    "{} scored with detectors {}, {} with {}: shards of different runs",
                    dir.display(),
                    index.detectors.join(", "),
                    first.display(),
                    names.join(", ")
                )))
            }
            Some(_) => {}
            None => detectors = Some((dir.clone(), index.detectors.clone())),
        }
        let mut records = read_frames(&dir.join("frames.csv"))?.into_iter();
        for v in index.videos {
            let what = format!("video {}", v.index + 1);
            let slot = parts
                .get_mut(v.index)
                .ok_or_else(|| ReportError::Options(format!("{}: {what}, but the run has {videos}", dir.display())))?;
            if let Some((other, _, _)) = slot {
                return Err(ShardError::Duplicate { what, a: other.clone(), b: dir.clone() }.into());
            }
            let recs: Vec<FrameRecord> = records.by_ref().take(v.records).collect();
            if recs.len() < v.records {
                return Err(ShardError::Unfinished { shard: dir.clone(), what: format!("{what}'s frames.csv") }.into());
            }
            *slot = Some((dir.clone(), v, recs));
        }
    }
    if let Some(i) = parts.iter().position(Option::is_none) {
        let shard = pav_run::shard::owner_dir(shards, i);
        return Err(ShardError::Unfinished { shard, what: format!("video {}", i + 1) }.into());
    }
    std::fs::create_dir_all(&opts.out_dir).map_err(|e| super::report::io_err(&opts.out_dir, e))?;
    let frames_path = opts.out_dir.join("frames.csv");
    let mut csv = FrameCsv::create(&frames_path)?;
    let mut out = EvalOutcome { files: vec![frames_path], ..EvalOutcome::default() };
    let mut angle_sources = Vec::new();
    for (_, v, recs) in parts.into_iter().flatten() {
        for r in &recs {
            csv.push(r)?;
        }
        out.records.extend(recs);
        out.rows.extend(v.rows.iter().cloned());
        out.failures.extend(v.failures.iter().cloned());
        angle_sources.extend(v.angle_source.clone());
        out.videos.push(v);
    }
    out.rows = pool(std::mem::take(&mut out.rows));
    let names = detectors.map(|d| d.1).unwrap_or_default();
    write_reports(&mut out, &settings(opts, angle_sources), opts, &names)?;
    Ok(out)
}
