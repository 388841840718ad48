//! The `evaluate` pipeline: videos → frames → detections → per-frame records → reports.
//!
//! Every frame record is flushed as soon as it exists and the summary is written from whatever
//! was scored, so a corrupt video, a failing detector or Ctrl-C never loses finished work.

use super::charts::{accuracy_bars, polar_video};
use super::drift::{frame_lights, Drift, DriftLimits, Light};
use super::physical::{Accuracy, FrameRecord};
use super::report::{
    summary_markdown, write_angles_csv, write_summary_csv, write_text, FrameCsv, ReportError, ReportSettings,
    SummaryRow,
};
use pav_core::image::Frame;
use pav_core::progress::Progress;
use pav_core::sidecar::{self, AngleSample};
use pav_core::table::unique;
use pav_core::video::{Decoded, Prefetch, VideoReader};
use pav_detect::check::{box_doubt, scores_out_of_range};
use pav_detect::config::InputConfig;
use pav_detect::defence::DefenceError;
use pav_detect::preprocess::{prepare, InputMap};
use pav_detect::{DetectError, Detector, Proposals};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// One video to score.
#[derive(Clone, Debug)]
pub struct VideoJob {
    /// Video file.
    pub path: PathBuf,
    /// Label in reports (row of the Table-V matrix).
    pub label: String,
    /// Angle sidecar; when `None`, `<video>.angles.csv` is used if it exists.
    pub sidecar: Option<PathBuf>,
}

/// Which frames of each video are scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frames {
    /// Every N-th frame, from the first.
    Stride(usize),
    /// N frames evenly spaced over each video's declared length: the middle frame of each of N
    /// equal stretches, so a turntable video at constant speed is sampled evenly in angle.
    Even(usize),
}

impl Frames {
    /// The frames to score in a video declaring `declared` frames: `None` for a stride (decided
    /// per frame), the sorted indices for even sampling.
    fn indices(self, declared: usize) -> Option<Vec<usize>> {
        match self {
            Frames::Stride(_) => None,
            Frames::Even(n) if n >= declared => Some((0..declared).collect()),
            Frames::Even(n) => Some((0..n).map(|k| ((2 * k + 1) * declared) / (2 * n)).collect()),
        }
    }

    /// Short form for the reports' `sampling` column: `stride 4`, `even 44`.
    pub fn tag(self) -> String {
        match self {
            Frames::Stride(n) => format!("stride {n}"),
            Frames::Even(n) => format!("even {n}"),
        }
    }
}

impl std::fmt::Display for Frames {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Frames::Stride(1) => write!(f, "every frame"),
            Frames::Stride(n) => write!(f, "one frame in {n}"),
            Frames::Even(n) => write!(f, "{n} evenly spaced frames per video"),
        }
    }
}

/// Evaluation settings.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// A frame counts as "car detected" when a target-class score is ≥ this.
    pub threshold: f32,
    /// Which frames are scored.
    pub frames: Frames,
    /// Seconds per turntable revolution, used when a video has no sidecar.
    pub period_s: f64,
    /// Angle at frame 0 when no sidecar.
    pub start_angle_deg: f64,
    /// Angle sectors in the per-angle breakdown.
    pub sectors: usize,
    /// Output directory (created).
    pub out_dir: PathBuf,
    /// Draw PNG plots.
    pub plots: bool,
    /// Threads that run the detectors side by side on each frame (1: one after another).
    /// Records and reports come out in the same order either way.
    pub parallel: usize,
    /// Frames scored at once, each by its own copy of every detector (1: one frame at a time).
    /// Records and reports come out in the same order either way.
    pub lanes: usize,
    /// How far a video's light may drift over the turn before it is flagged.
    pub drift: DriftLimits,
}

/// Wall-clock split of a run, for benchmarks.
#[derive(Clone, Debug, Default)]
pub struct Timing {
    /// Frames decoded (including skipped ones).
    pub frames_decoded: usize,
    /// Frames scored.
    pub frames_scored: usize,
    /// Seconds spent decoding.
    pub decode_s: f64,
    /// Seconds per detector (preprocess + inference + decode of outputs), same order as given.
    pub detector_s: Vec<f64>,
    /// Seconds for the whole run including reports.
    pub total_s: f64,
}

/// Everything a run produced.
#[derive(Debug, Default)]
pub struct EvalOutcome {
    /// One row per (video, detector) that scored at least one frame or failed.
    pub rows: Vec<SummaryRow>,
    /// Every frame record.
    pub records: Vec<FrameRecord>,
    /// Human-readable failures (video or detector errors); the run went on past each.
    pub failures: Vec<String>,
    /// Whether Ctrl-C stopped the run early.
    pub interrupted: bool,
    /// Time split.
    pub timing: Timing,
    /// Files written.
    pub files: Vec<PathBuf>,
    /// What each video added, in the order of the jobs given.
    pub videos: Vec<VideoPart>,
}

/// What one video added to a run, so the shards of a run can be joined in the order one process
/// would have scored them.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VideoPart {
    /// The video's place among the run's videos (0-based).
    pub index: usize,
    /// Its summary rows, before videos that share a label are pooled.
    pub rows: Vec<SummaryRow>,
    /// How many frame records it added (its lines of `frames.csv`, in order).
    pub records: usize,
    /// The failures it added.
    pub failures: Vec<String>,
    /// Where its angles came from: (label, source).
    pub angle_source: Option<(String, String)>,
}

enum Angles {
    Sidecar(HashMap<usize, AngleSample>),
    Period { period_s: f64, start_deg: f64 },
}

impl Angles {
    fn at(&self, frame: usize, fps: f64) -> (f64, Option<f64>) {
        let t = frame as f64 / fps;
        match self {
            Angles::Sidecar(m) => m.get(&frame).map(|s| (s.timestamp_s, Some(s.angle_deg))).unwrap_or((t, None)),
            Angles::Period { period_s, start_deg } => (t, Some((start_deg + 360.0 * t / period_s).rem_euclid(360.0))),
        }
    }
}

impl EvalOptions {
    /// Refuses settings that would score nothing or place angles nowhere.
    pub fn check(&self) -> Result<(), ReportError> {
        let bad = |m: String| Err(ReportError::Options(m));
        if !(0.0..=1.0).contains(&self.threshold) {
            return bad(format!("threshold {} must be within [0, 1]", self.threshold));
        }
        if !(self.period_s.is_finite() && self.period_s != 0.0) {
            return bad(format!("rotation period {} s must be a non-zero number", self.period_s));
        }
        if !self.start_angle_deg.is_finite() {
            return bad(format!("start angle {}° must be a number", self.start_angle_deg));
        }
        if self.sectors == 0 {
            return bad("the per-angle breakdown needs at least one sector".into());
        }
        let d = &self.drift;
        if !(d.luminance.is_finite() && d.luminance > 0.0 && d.colour.is_finite() && d.colour > 0.0) {
            return bad(format!("drift limits {} (luminance) and {} (colour) must be positive", d.luminance, d.colour));
        }
        if matches!(self.frames, Frames::Stride(0) | Frames::Even(0)) {
            return bad(format!("{}: at least one frame must be scored", self.frames.tag()));
        }
        Ok(())
    }
}

/// Error rows, one per detector, for a video that could not be scored at all.
fn failed_rows(label: &str, detectors: &[Box<dyn Detector>], why: &str) -> Vec<SummaryRow> {
    detectors
        .iter()
        .map(|d| SummaryRow {
            video: label.to_string(),
            detector: d.name().to_string(),
            classes: d.target_label(),
            accuracy: Accuracy::default(),
            decoded_frames: 0,
            declared_frames: 0,
            videos: 1,
            status: format!("failed: {why}"),
            drift: None,
        })
        .collect()
}

/// How detectors share the cores: `parallel` detector groups side by side on each frame, `lanes`
/// frames at once, `threads` ONNX Runtime intra-op threads per detector copy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sharing {
    /// Detector groups run side by side on a frame.
    pub parallel: usize,
    /// Frames scored at once.
    pub lanes: usize,
    /// Intra-op threads per detector copy (0: ONNX Runtime's default).
    pub threads: usize,
}

impl Sharing {
    /// How the detectors share the cores, in words for a run's first line (empty when they
    /// run one after another on ONNX Runtime's default threads).
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if self.parallel > 1 {
            parts.push(format!("{} side by side", self.parallel));
        }
        if self.lanes > 1 {
            parts.push(format!("{} frames at once", self.lanes));
        }
        if self.threads > 0 {
            parts.push(format!("{} thread(s) each", self.threads));
        }
        if parts.is_empty() {
            String::new()
        } else {
            format!(" ({})", parts.join(", "))
        }
    }
}

/// Most frames in flight chosen without being asked: each costs a copy of every model, and
/// one decoder thread prepares them all.
const AUTO_LANES: usize = 4;

/// How `detectors` detectors share `cores` cores; `parallel`, `lanes` and `threads` as asked,
/// 0 = choose. With nothing asked, several detectors run side by side, one group per core, and
/// cores left over score further frames at once; every copy then gets one thread each, since
/// two single-threaded runs on two frames outpace one run on two threads on these small models.
pub fn side_by_side(detectors: usize, cores: usize, parallel: usize, lanes: usize, threads: usize) -> Sharing {
    let chosen = threads == 0 && parallel == 0 && lanes == 0;
    let parallel = match parallel {
        0 if threads == 0 && detectors > 1 && cores > 1 => detectors.min(cores),
        0 => 1,
        p => p.min(detectors.max(1)),
    };
    let lanes = match lanes {
        0 if chosen && cores > parallel => (cores / parallel).clamp(1, AUTO_LANES),
        0 => 1,
        l => l,
    };
    let threads = match threads {
        0 if parallel * lanes > 1 => (cores / (parallel * lanes)).max(1),
        t => t,
    };
    Sharing { parallel, lanes, threads }
}

/// One detector's proposals for a frame and the seconds they took; `None` for a detector that
/// failed on an earlier frame.
type Scored = Option<(Result<Proposals, DetectError>, f64)>;

/// A frame's prepared input for one detector (or why its defence failed on it); `None` for a
/// detector that failed earlier.
type Prepared = Option<Result<(Vec<f32>, InputMap), DefenceError>>;

/// Every detector not yet failed on each frame of a batch (frame k by `lanes[k]`, that lane's
/// copies of the detectors), on `workers` threads; results per frame, in the detectors' order.
/// Each thread takes the next (frame, detector) not yet taken, in the order of `cost` (seconds so
/// far, largest first), so that the slowest model starts first and the others fill the
/// remaining threads around it.
fn run_batch(
    lanes: &mut [&mut [Box<dyn Detector>]],
    batch: Vec<Vec<Prepared>>,
    failed: &[Option<String>],
    cost: &[f64],
    workers: usize,
) -> Vec<Vec<Scored>> {
    let one = |det: &mut Box<dyn Detector>, input: Prepared| -> Scored {
        let (input, map) = match input? {
            Ok(x) => x,
            Err(source) => return Some((Err(DetectError::Defence { detector: det.name().to_string(), source }), 0.0)),
        };
        let t = Instant::now();
        let r = det.propose_prepared(input, map);
        Some((r, t.elapsed().as_secs_f64()))
    };
    let n = failed.len();
    let mut results: Vec<Vec<Scored>> = (0..lanes.len()).map(|_| (0..n).map(|_| None).collect()).collect();
    let mut work = Vec::new();
    for (k, (lane, mut prepared)) in lanes.iter_mut().zip(batch).enumerate() {
        for (d, ((det, p), f)) in lane.iter_mut().zip(prepared.iter_mut()).zip(failed).enumerate() {
            let input = if f.is_some() { None } else { Some(p.take().expect("one input per detector")) };
            work.push((k, d, det, input));
        }
    }
    let threads = workers.clamp(1, work.len().max(1));
    if threads == 1 {
        for (k, d, det, x) in work {
            results[k][d] = one(det, x);
        }
        return results;
    }
    // Popped from the end: the costliest first, ties in the frames' then the detectors' order.
    work.sort_by(|a, b| cost[a.1].total_cmp(&cost[b.1]).then((b.0, b.1).cmp(&(a.0, a.1))));
    let queue = std::sync::Mutex::new(work);
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let next = queue.lock().unwrap_or_else(|e| e.into_inner()).pop();
                        let Some((k, d, det, x)) = next else { break };
                        done.push((k, d, one(det, x)));
                    }
                    done
                })
            })
            .collect();
        for h in handles {
            // A detector that panicked is a bug, not a frame to skip: let it surface.
            for (k, d, r) in h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)) {
                results[k][d] = r;
            }
        }
    });
    results
}

/// Runs every detector over the chosen frames of every video and writes the reports into
/// `opts.out_dir`; each video is one stage of `progress`, in frames. Videos that share a label
/// are pooled into one cell (the paper pools its two polar angles): one summary row per label and
/// detector, while `frames.csv` keeps each frame's file.
pub fn evaluate(
    jobs: &[VideoJob],
    detectors: &mut [Box<dyn Detector>],
    opts: &EvalOptions,
    progress: &dyn Progress,
    stop: &AtomicBool,
) -> Result<EvalOutcome, ReportError> {
    opts.check()?;
    let t_run = Instant::now();
    // Lane 0 is the caller's detectors; each further lane scores its frames with copies.
    let mut copies = (1..opts.lanes.max(1))
        .map(|_| detectors.iter().map(|d| d.replica()).collect::<Result<Vec<_>, _>>())
        .collect::<Result<Vec<_>, _>>()?;
    std::fs::create_dir_all(&opts.out_dir).map_err(|e| super::report::io_err(&opts.out_dir, e))?;
    let frames_path = opts.out_dir.join("frames.csv");
    let mut csv = FrameCsv::create(&frames_path)?;
    let mut out = EvalOutcome {
        timing: Timing { detector_s: vec![0.0; detectors.len()], ..Timing::default() },
        ..EvalOutcome::default()
    };
    out.files.push(frames_path);
    let mut angle_sources = Vec::new();
    // Where each video's rows, records, failures and angle source begin.
    let mut starts: Vec<[usize; 4]> = Vec::new();
    for (job, file) in jobs.iter().zip(file_names(jobs)) {
        starts.push([out.rows.len(), out.records.len(), out.failures.len(), angle_sources.len()]);
        let opened = video_angles(job, opts).and_then(|(angles, source)| {
            angle_sources.push((job.label.clone(), source));
            open_video(job, angles, detectors, opts)
        });
        let mut video = match opened {
            Ok(v) => v,
            Err((failure, why)) => {
                out.failures.push(failure);
                out.rows.extend(failed_rows(&job.label, detectors, &why));
                continue;
            }
        };
        if let Some(f) = video.shortfall.take() {
            out.failures.push(f);
        }
        let mut lanes: Vec<&mut [Box<dyn Detector>]> =
            std::iter::once(&mut *detectors).chain(copies.iter_mut().map(|c| c.as_mut_slice())).collect();
        let scored = score_video(&mut video, job, &file, &mut lanes, opts, progress, stop, &mut csv, &mut out)?;
        close_video(&video, scored, job, detectors, &opts.drift, &mut out);
        if out.interrupted {
            break;
        }
    }
    out.videos = video_parts(&out, &starts, &angle_sources);
    out.rows = pool(std::mem::take(&mut out.rows));
    let names: Vec<String> = detectors.iter().map(|d| d.name().to_string()).collect();
    write_reports(&mut out, &settings(opts, angle_sources), opts, &names)?;
    out.timing.total_s = t_run.elapsed().as_secs_f64();
    Ok(out)
}

/// A video opened for scoring: where its angles come from, its decoder (which also prepares
/// every detector's input) and what is known before the first frame.
struct OpenVideo {
    angles: Angles,
    info: pav_core::video::VideoInfo,
    frames: Prefetch<(Vec<Prepared>, Light)>,
    /// The video's status so far: `complete` until something says otherwise.
    status: String,
    /// A failure known at opening (fewer frames than asked), to report once scoring starts.
    shortfall: Option<String>,
}

/// The angles of `job`'s frames: its sidecar, else the turntable's period; with the source in
/// words for the report; a sidecar that cannot be read fails as [`open_video`] does.
fn video_angles(job: &VideoJob, opts: &EvalOptions) -> Result<(Angles, String), (String, String)> {
    match job.sidecar.clone().or_else(|| Some(sidecar::sidecar_path(&job.path)).filter(|p| p.exists())) {
        Some(p) => {
            // A video whose angles are wrong is not scored: per-angle results would be.
            let rows = sidecar::read(&p).map_err(|e| (e.to_string(), e.to_string()))?;
            Ok((Angles::Sidecar(rows.into_iter().map(|r| (r.frame, r)).collect()), format!("sidecar {}", p.display())))
        }
        None => Ok((
            Angles::Period { period_s: opts.period_s, start_deg: opts.start_angle_deg },
            format!("no sidecar; {}° + 360° × t / {} s", opts.start_angle_deg, opts.period_s),
        )),
    }
}

/// Opens `job` for scoring, or says why it cannot be scored at all: (the run's failure line, the
/// reason in its summary rows).
fn open_video(
    job: &VideoJob,
    angles: Angles,
    detectors: &[Box<dyn Detector>],
    opts: &EvalOptions,
) -> Result<OpenVideo, (String, String)> {
    let reader = VideoReader::open(&job.path).map_err(|e| (e.to_string(), e.to_string()))?;
    let info = reader.info().clone();
    let picks = opts.frames.indices(info.declared_frames);
    let mut status = "complete".to_string();
    let mut shortfall = None;
    if let Some(p) = &picks {
        if p.is_empty() {
            let why = format!("{} declares no frame count, so frames cannot be spread over it", job.path.display());
            return Err((format!("{}: {why}", job.label), why));
        }
        if let Frames::Even(n) = opts.frames {
            if p.len() < n {
                status = format!("{n} frames asked, the video declares {}", info.declared_frames);
                shortfall = Some(format!("{}: {status}", job.label));
            }
        }
    }
    // The decoder thread also prepares every detector's input, so this thread only runs models.
    let inputs: Vec<InputConfig> = detectors.iter().map(|d| d.input().clone()).collect();
    let make = move |f: Frame| (inputs.iter().map(|c| Some(prepare(&f, c))).collect::<Vec<_>>(), Light::of(&f));
    let depth = (2 * opts.lanes.max(1)).max(4);
    let frames = match (opts.frames, picks) {
        (Frames::Stride(n), _) => Prefetch::with(reader, move |i| i % n == 0, depth, make),
        (Frames::Even(_), p) => {
            let p = p.unwrap_or_default();
            Prefetch::with(reader, move |i| p.binary_search(&i).is_ok(), depth, make)
        }
    };
    Ok(OpenVideo { angles, info, frames, status, shortfall })
}

/// What scoring one video found, for its summary rows.
struct Scoring {
    /// Frames decoded (skipped ones included).
    decoded: usize,
    /// Scored frames without an angle.
    no_angle: usize,
    /// Frames scored.
    scored: usize,
    /// Each detector's failure, which stopped it on this video.
    failed: Vec<Option<String>>,
    /// Its first record in the run's records.
    first_record: usize,
    /// Each scored frame's light, by frame index.
    lights: Vec<(usize, Light)>,
    /// Per detector, its detections whose box a right description is unlikely to give, and the
    /// first one's frame and reason (`check::box_doubt`).
    doubtful: Vec<(usize, Option<(usize, String)>)>,
}

/// Scores the frames of one opened video in batches of one frame per lane, flushing each record
/// to `csv`; stops at the video's end, a decoder error, Ctrl-C, or when every detector failed.
#[allow(clippy::too_many_arguments)]
fn score_video(
    video: &mut OpenVideo,
    job: &VideoJob,
    file: &str,
    lanes: &mut [&mut [Box<dyn Detector>]],
    opts: &EvalOptions,
    progress: &dyn Progress,
    stop: &AtomicBool,
    csv: &mut FrameCsv,
    out: &mut EvalOutcome,
) -> Result<Scoring, ReportError> {
    let n_det = lanes[0].len();
    progress.begin(&job.label, video.info.declared_frames as u64);
    let mut s = Scoring {
        decoded: 0,
        no_angle: 0,
        scored: 0,
        failed: vec![None; n_det],
        first_record: out.records.len(),
        lights: Vec::new(),
        doubtful: vec![(0, None); n_det],
    };
    loop {
        if stop.load(Ordering::Relaxed) {
            video.status = format!("interrupted after {} frames", s.decoded);
            out.interrupted = true;
            break;
        }
        // Up to one frame per lane, and the time spent waiting for the decoder thread for them
        // (decoding itself overlaps inference).
        let t0 = Instant::now();
        let mut batch = Vec::with_capacity(lanes.len());
        let mut last = None;
        while batch.len() < lanes.len() {
            match video.frames.next_step() {
                Decoded::Skipped => {
                    s.decoded += 1;
                    progress.advance(1);
                }
                Decoded::Frame(i, f) => {
                    s.decoded += 1;
                    progress.advance(1);
                    batch.push((i, s.decoded, f));
                }
                end => {
                    last = Some(end);
                    break;
                }
            }
        }
        out.timing.decode_s += t0.elapsed().as_secs_f64();
        // Per frame: its index, the frames decoded through it, its light; and the models' inputs.
        let (idxs, prepared): (Vec<_>, Vec<Vec<Prepared>>) =
            batch.into_iter().map(|(i, d, (f, light))| ((i, d, light), f)).unzip();
        let in_use = idxs.len();
        let workers = opts.parallel.max(1) * in_use;
        let results = run_batch(&mut lanes[..in_use], prepared, &s.failed, &out.timing.detector_s, workers);
        let mut through = s.decoded;
        for ((idx, decoded_here, light), results) in idxs.into_iter().zip(results) {
            if s.failed.iter().all(Option::is_some) {
                break;
            }
            through = decoded_here;
            out.timing.frames_scored += 1;
            s.scored += 1;
            s.lights.push((idx, light));
            let (time_s, angle_deg) = video.angles.at(idx, video.info.fps);
            s.no_angle += usize::from(angle_deg.is_none());
            for (k, (det, result)) in lanes[0].iter().zip(results).enumerate() {
                // A detector that failed on an earlier frame of this batch scored the later
                // ones too; as one frame at a time, they are not kept.
                let Some((result, seconds)) = result.filter(|_| s.failed[k].is_none()) else { continue };
                out.timing.detector_s[k] += seconds;
                // Scores outside [0, 1] mean a wrong description: none of its scores is kept.
                let checked =
                    result.map_err(|e| e.to_string()).and_then(|p| scores_out_of_range(&p).map_or(Ok(p), Err));
                let props = match checked {
                    Ok(p) => p,
                    Err(e) => {
                        out.failures.push(format!("{}: {}: frame {idx}: {e}", job.label, det.name()));
                        s.failed[k] = Some(format!("stopped at frame {idx}: {e}"));
                        continue;
                    }
                };
                let rec = frame_record(job, file, idx, time_s, angle_deg, det.as_ref(), &props, opts.threshold);
                if let (true, Some(x1), Some(y1), Some(x2), Some(y2)) = (rec.detected, rec.x1, rec.y1, rec.x2, rec.y2) {
                    let doubt = box_doubt([x1, y1, x2, y2], rec.max_score, video.info.width, video.info.height);
                    if let Some(why) = doubt {
                        let d = &mut s.doubtful[k];
                        d.0 += 1;
                        d.1.get_or_insert((idx, why));
                    }
                }
                csv.push(&rec)?;
                out.records.push(rec);
            }
        }
        match last {
            Some(Decoded::Error(e)) => {
                video.status = format!("stopped: {e}");
                out.failures.push(e.to_string());
                break;
            }
            Some(_) => break,
            None if s.failed.iter().all(Option::is_some) => {
                // One frame at a time stops decoding at the frame where the last one failed.
                s.decoded = through;
                break;
            }
            None => {}
        }
    }
    progress.end(None);
    out.timing.frames_decoded += s.decoded;
    Ok(s)
}

/// One detector's record of one frame: its best target-class proposal.
#[allow(clippy::too_many_arguments)]
fn frame_record(
    job: &VideoJob,
    file: &str,
    frame: usize,
    time_s: f64,
    angle_deg: Option<f64>,
    det: &dyn Detector,
    props: &Proposals,
    threshold: f32,
) -> FrameRecord {
    let best = props.best(det.target_classes());
    FrameRecord {
        video: job.label.clone(),
        file: file.to_string(),
        frame,
        time_s,
        angle_deg,
        detector: det.name().to_string(),
        detected: best.is_some_and(|b| pav_detect::detected(b.score, threshold)),
        max_score: best.map(|b| b.score).unwrap_or(0.0),
        x1: best.map(|b| b.bbox[0]),
        y1: best.map(|b| b.bbox[1]),
        x2: best.map(|b| b.bbox[2]),
        y2: best.map(|b| b.bbox[3]),
    }
}

/// The video's final status (cut short, no frames, angles that do not match its frames) and its
/// summary rows, one per detector.
fn close_video(
    video: &OpenVideo,
    s: Scoring,
    job: &VideoJob,
    detectors: &[Box<dyn Detector>],
    limits: &DriftLimits,
    out: &mut EvalOutcome,
) {
    let (declared, decoded) = (video.info.declared_frames, s.decoded);
    let mut status = video.status.clone();
    if decoded == 0 && status == "complete" {
        status = "no frames decoded".into();
        out.failures.push(format!("{}: no frames could be decoded from {}", job.label, job.path.display()));
    } else if status == "complete" && declared > decoded + 1 {
        // Containers estimate counts from duration; more than one frame short means a cut file.
        status = format!("truncated: decoded {decoded} of {declared} declared frames");
        out.failures.push(format!("{}: {status}", job.label));
    }
    if let Angles::Sidecar(rows) = &video.angles {
        // Frames without a row, and rows for frames the video does not have, mean the
        // sidecar and the video are not one recording (or one was cut short).
        let beyond = if out.interrupted { 0 } else { rows.keys().filter(|&&f| f >= decoded).count() };
        let mut problems = Vec::new();
        if s.no_angle > 0 {
            problems.push(format!("{} of {} scored frames have no sidecar row", s.no_angle, s.scored));
        }
        if beyond > 0 {
            problems.push(format!("the sidecar has {beyond} rows for frames beyond the {decoded} decoded"));
        }
        if !problems.is_empty() {
            let msg = format!("angles incomplete: {}", problems.join("; "));
            out.failures.push(format!("{}: {msg}", job.label));
            status = if status == "complete" { msg } else { format!("{status}; {msg}") };
        }
    }
    let recs = &out.records[s.first_record..];
    if let Some(msg) = part_of_a_turn(&video.angles, recs, video.info.fps).filter(|_| !out.interrupted) {
        status = if status == "complete" { msg } else { format!("{status}; {msg}") };
    }
    let drift = Drift::of(&frame_lights(&s.lights), limits);
    let rows: Vec<SummaryRow> = detectors
        .iter()
        .zip(&s.failed)
        .zip(&s.doubtful)
        .map(|((det, failed), doubt)| SummaryRow {
            video: job.label.clone(),
            detector: det.name().to_string(),
            classes: det.target_label(),
            accuracy: Accuracy::of(recs.iter().filter(|r| r.detector == det.name())),
            decoded_frames: decoded,
            declared_frames: declared,
            videos: 1,
            status: failed.clone().unwrap_or_else(|| with_doubt(&status, doubt)),
            drift,
        })
        .collect();
    out.rows.extend(rows);
}

/// A detector's status on a video: the video's, and how many of its detections had a box a right
/// description is unlikely to give, with the first.
fn with_doubt(status: &str, doubt: &(usize, Option<(usize, String)>)) -> String {
    match doubt {
        (n, Some((frame, why))) => {
            let msg = format!("{n} detection(s) with a doubtful box, first at frame {frame}: {why}");
            if status == "complete" {
                msg
            } else {
                format!("{status}; {msg}")
            }
        }
        _ => status.to_string(),
    }
}

/// For a video whose angles come from the period (no sidecar) and whose scored frames span less
/// than one turn at it: how much they span, for its status, since its per-angle table then holds
/// only some sectors (a clip of a few seconds, or a period given wrong).
fn part_of_a_turn(angles: &Angles, recs: &[FrameRecord], fps: f64) -> Option<String> {
    let Angles::Period { period_s, start_deg } = *angles else { return None };
    let last = recs.iter().map(|r| r.frame).max()?;
    // A turn of n frames ends one frame before the first again: frames 0..n span n/fps seconds.
    let span_s = (last + 1) as f64 / fps;
    (span_s + 0.5 / fps < period_s).then(|| {
        let end = start_deg + 360.0 * span_s / period_s;
        format!(
            "less than one turn: {span_s:.1} s of a {period_s} s period, {start_deg:.0}–{end:.0}° (no sidecar; is --period right?)"
        )
    })
}

/// What each video added to `out`, from where each one's rows, records, failures and angle
/// source begin.
fn video_parts(out: &EvalOutcome, starts: &[[usize; 4]], angle_sources: &[(String, String)]) -> Vec<VideoPart> {
    let ends = [out.rows.len(), out.records.len(), out.failures.len(), angle_sources.len()];
    starts
        .iter()
        .enumerate()
        .map(|(index, s)| {
            let e = starts.get(index + 1).unwrap_or(&ends);
            VideoPart {
                index,
                rows: out.rows[s[0]..e[0]].to_vec(),
                records: e[1] - s[1],
                failures: out.failures[s[2]..e[2]].to_vec(),
                angle_source: angle_sources[s[3]..e[3]].first().cloned(),
            }
        })
        .collect()
}

/// The report settings of a run with `opts`.
pub(crate) fn settings(opts: &EvalOptions, angle_sources: Vec<(String, String)>) -> ReportSettings {
    ReportSettings {
        threshold: opts.threshold,
        sampling: opts.frames.tag(),
        sampling_text: opts.frames.to_string(),
        sectors: opts.sectors,
        angle_sources,
        drift: opts.drift,
    }
}

/// Writes `summary.csv`, `angles.csv`, `summary.md` and (unless turned off) the plots.
pub(crate) fn write_reports(
    out: &mut EvalOutcome,
    s: &ReportSettings,
    opts: &EvalOptions,
    detectors: &[String],
) -> Result<(), ReportError> {
    let dir = &opts.out_dir;
    let p = dir.join("summary.csv");
    write_summary_csv(&p, &out.rows, s)?;
    out.files.push(p);
    let p = dir.join("angles.csv");
    write_angles_csv(&p, &out.records, &out.rows, s.sectors)?;
    out.files.push(p);
    let p = dir.join("summary.md");
    write_text(&p, &summary_markdown(&out.rows, &out.records, s))?;
    out.files.push(p);
    if !opts.plots {
        return Ok(());
    }
    let names: Vec<&str> = detectors.iter().map(String::as_str).collect();
    for v in unique(out.records.iter().map(|r| r.video.clone())) {
        let p = dir.join(format!("polar_{}.png", file_safe(&v)));
        polar_video(&p, &v, &names, &out.records, opts.threshold)?;
        out.files.push(p);
    }
    if !out.rows.is_empty() {
        let p = dir.join("accuracy.png");
        accuracy_bars(&p, &out.rows, opts.threshold)?;
        out.files.push(p);
    }
    Ok(())
}

/// One row per (label, detector), in first-seen order: the counts of videos sharing a label add
/// up, and a cell is `complete` only when each of its videos is (otherwise each video's status).
pub(crate) fn pool(rows: Vec<SummaryRow>) -> Vec<SummaryRow> {
    let mut cells: Vec<(SummaryRow, Vec<String>)> = Vec::new();
    for r in rows {
        match cells.iter_mut().find(|(c, _)| c.video == r.video && c.detector == r.detector) {
            Some((c, statuses)) => {
                c.accuracy.detected += r.accuracy.detected;
                c.accuracy.total += r.accuracy.total;
                c.decoded_frames += r.decoded_frames;
                c.declared_frames += r.declared_frames;
                c.videos += r.videos;
                c.drift = Drift::pooled(c.drift, r.drift);
                statuses.push(r.status);
            }
            None => {
                let s = vec![r.status.clone()];
                cells.push((r, s));
            }
        }
    }
    cells
        .into_iter()
        .map(|(mut c, statuses)| {
            if statuses.len() > 1 && statuses.iter().any(|s| s != "complete") {
                let each: Vec<String> =
                    statuses.iter().enumerate().map(|(i, s)| format!("video {}: {s}", i + 1)).collect();
                c.status = each.join("; ");
            }
            c
        })
        .collect()
}

/// The file name of a video, for `frames.csv`.
fn file_name(p: &Path) -> String {
    p.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string())
}

/// The name each job's frames carry in `frames.csv`: the video's file name, or the path as given
/// where another video of the same label has that file name, so that the frames of two videos
/// (two seeds' films of one shot) stay apart when they are paired or grouped by video.
fn file_names(jobs: &[VideoJob]) -> Vec<String> {
    jobs.iter()
        .map(|j| {
            let name = file_name(&j.path);
            let clash = jobs.iter().any(|o| o.label == j.label && o.path != j.path && file_name(&o.path) == name);
            if clash {
                j.path.display().to_string()
            } else {
                name
            }
        })
        .collect()
}

/// Makes a label usable as part of a file name.
fn file_safe(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

/// The jobs for `videos`, labelled by `labels` (one per video, or none: each video's file stem)
/// and with `sidecar` for a single video; refuses mismatched counts and two unlabelled videos
/// that share a stem (pooling is asked for with labels, never by accident).
pub fn video_jobs(videos: &[PathBuf], labels: &[String], sidecar: Option<&Path>) -> Result<Vec<VideoJob>, ReportError> {
    let bad = |m: String| Err(ReportError::Options(m));
    if !labels.is_empty() && labels.len() != videos.len() {
        return bad(format!(
            "{} labels given for {} videos: give one --label per video or none",
            labels.len(),
            videos.len()
        ));
    }
    if sidecar.is_some() && videos.len() != 1 {
        return bad("--sidecar applies to a single video; with several, put <name>.angles.csv beside each".into());
    }
    let mut out: Vec<VideoJob> = Vec::new();
    for (i, v) in videos.iter().enumerate() {
        let label = labels.get(i).cloned().unwrap_or_else(|| default_label(v));
        if labels.is_empty() && out.iter().any(|j| j.label == label) {
            return bad(format!(
                "two videos share the label `{label}`: use --label to tell them apart (or the same --label to pool them)"
            ));
        }
        out.push(VideoJob { path: v.clone(), label, sidecar: sidecar.map(Path::to_path_buf) });
    }
    Ok(out)
}

/// The default label of a video: its file stem.
pub fn default_label(p: &Path) -> String {
    p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_videos_of_one_label_with_one_file_name_keep_their_paths() {
        let job = |path: &str, label: &str| VideoJob { path: path.into(), label: label.into(), sidecar: None };
        let jobs = [
            job("film/s0/videos/e0.mp4", "pav"),
            job("film/s1/videos/e0.mp4", "pav"),
            job("film/s0/videos/e20.mp4", "pav"),
            job("film/rauca/videos/e0.mp4", "rauca"),
        ];
        assert_eq!(file_names(&jobs), ["film/s0/videos/e0.mp4", "film/s1/videos/e0.mp4", "e20.mp4", "e0.mp4"]);
    }

    #[test]
    fn detectors_share_cores_side_by_side_unless_told_otherwise() {
        // (detectors, cores, --parallel, --lanes, --threads) → (parallel, lanes, threads).
        let cases = [
            ((4, 2, 0, 0, 0), (2, 1, 1)),
            ((4, 1, 0, 0, 0), (1, 1, 0)),
            ((3, 8, 0, 0, 0), (3, 2, 1)),
            // Cores the detectors leave free score further frames, one thread per copy.
            ((1, 2, 0, 0, 0), (1, 2, 1)),
            ((1, 16, 0, 0, 0), (1, 4, 4)),
            ((2, 2, 0, 0, 0), (2, 1, 1)),
            // An explicit thread count keeps detectors one after another and frames one at a
            // time unless --parallel or --lanes says so.
            ((4, 2, 0, 0, 2), (1, 1, 2)),
            ((1, 2, 0, 0, 2), (1, 1, 2)),
            ((4, 2, 3, 0, 0), (3, 1, 1)),
            ((2, 2, 5, 0, 1), (2, 1, 1)),
            ((4, 2, 1, 0, 0), (1, 1, 0)),
            ((1, 2, 0, 3, 0), (1, 3, 1)),
            ((1, 2, 0, 1, 0), (1, 1, 0)),
        ];
        for ((d, c, p, l, t), (parallel, lanes, threads)) in cases {
            assert_eq!(side_by_side(d, c, p, l, t), Sharing { parallel, lanes, threads }, "{:?}", (d, c, p, l, t));
        }
    }
}
