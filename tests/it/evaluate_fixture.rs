//! `evaluate` on the recorded CARLA fixture reproduces the per-frame truth exactly for two real
//! detectors, with sidecar angles, stride, several videos, and partial results on bad input; the
//! reports are the same whether detectors run one after another or side by side, and whether
//! frames are scored one at a time or several at once, a detector failing mid-video included.

use crate::common;

use pav::detect::config::InputConfig;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::{prepare, InputMap};
use pav::detect::{DetectError, Detector, DetectorConfig, Proposals};
use pav::eval::physical::Accuracy;
use pav::eval::run::{evaluate, EvalOptions, EvalOutcome, Frames, VideoJob};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

struct Truth {
    visible: bool,
    angle: f64,
    refs: HashMap<&'static str, f32>,
}

fn fixture() -> PathBuf {
    common::repo().join("fixtures/carla_orbit.mp4")
}

fn truth() -> Vec<Truth> {
    let mut rd = csv::Reader::from_path(common::repo().join("fixtures/carla_orbit.truth.csv")).unwrap();
    rd.records()
        .map(|r| {
            let r = r.unwrap();
            let refs = HashMap::from([("yolox_nano", r[4].parse().unwrap()), ("yolov8n_int8", r[5].parse().unwrap())]);
            Truth { visible: &r[2] == "true", angle: r[3].parse().unwrap(), refs }
        })
        .collect()
}

/// Ground truth "detected": the car is in the frame and the independent reference score is ≥ 0.5.
fn expected(t: &Truth, det: &str) -> bool {
    t.visible && t.refs[det] >= 0.5
}

fn detectors(names: &[&str]) -> Vec<Box<dyn Detector>> {
    names
        .iter()
        .map(|n| {
            Box::new(OnnxDetector::new(DetectorConfig::load(&common::detector_config(n)).unwrap(), 1).unwrap())
                as Box<dyn Detector>
        })
        .collect()
}

fn opts(out: &Path, frames: Frames) -> EvalOptions {
    EvalOptions {
        threshold: 0.5,
        frames,
        period_s: 28.0,
        start_angle_deg: 0.0,
        sectors: 8,
        out_dir: out.to_path_buf(),
        plots: true,
        parallel: 1,
        lanes: 1,
        drift: pav::eval::drift::DriftLimits::default(),
    }
}

fn run(jobs: &[VideoJob], dets: &[&str], out: &Path, stride: usize) -> EvalOutcome {
    run_frames(jobs, dets, out, Frames::Stride(stride))
}

fn run_frames(jobs: &[VideoJob], dets: &[&str], out: &Path, frames: Frames) -> EvalOutcome {
    let mut d = detectors(dets);
    evaluate(jobs, &mut d, &opts(out, frames), &pav::progress::Silent, &AtomicBool::new(false)).unwrap()
}

fn job(path: PathBuf, label: &str) -> VideoJob {
    VideoJob { path, label: label.into(), sidecar: None }
}

const DETS: [&str; 2] = ["yolox_nano", "yolov8n_int8"];

#[test]
fn a_physical_matches_truth_frame_by_frame() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = run(&[job(fixture(), "orbit")], &DETS, tmp.path(), 1);
    let truth = truth();
    assert!(out.failures.is_empty(), "{:?}", out.failures);
    assert_eq!(out.records.len(), truth.len() * DETS.len());
    for r in &out.records {
        let t = &truth[r.frame];
        assert_eq!(r.detected, expected(t, &r.detector), "{} frame {}: score {}", r.detector, r.frame, r.max_score);
        // Angles come from the sidecar beside the video.
        assert!((r.angle_deg.unwrap() - t.angle).abs() < 0.06, "frame {} angle {:?}", r.frame, r.angle_deg);
    }
    for det in DETS {
        let want = truth.iter().filter(|t| expected(t, det)).count();
        let row = out.rows.iter().find(|r| r.detector == det).unwrap();
        assert_eq!(row.accuracy, Accuracy { detected: want, total: truth.len() }, "{det}");
        assert_eq!((want, row.status.as_str()), (30, "complete"));
    }
    // Reports exist and the per-angle CSV adds up to the totals.
    for f in ["frames.csv", "summary.csv", "summary.md", "angles.csv", "polar_orbit.png", "accuracy.png"] {
        assert!(tmp.path().join(f).metadata().unwrap().len() > 0, "{f} missing or empty");
    }
    let mut rd = csv::Reader::from_path(tmp.path().join("angles.csv")).unwrap();
    let mut per_det: HashMap<String, (usize, usize)> = HashMap::new();
    for r in rd.records() {
        let r = r.unwrap();
        let e = per_det.entry(r[1].to_string()).or_default();
        e.0 += r[4].parse::<usize>().unwrap();
        e.1 += r[5].parse::<usize>().unwrap();
    }
    assert_eq!(per_det["yolox_nano"], (45, 30));
}

#[test]
fn stride_scores_every_nth_frame() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = run(&[job(fixture(), "orbit")], &["yolox_nano"], tmp.path(), 4);
    let truth = truth();
    let frames: Vec<usize> = out.records.iter().map(|r| r.frame).collect();
    assert_eq!(frames, (0..45).step_by(4).collect::<Vec<_>>());
    let want = (0..45).step_by(4).filter(|&f| expected(&truth[f], "yolox_nano")).count();
    assert_eq!(out.rows[0].accuracy, Accuracy { detected: want, total: 12 });
    assert_eq!(out.rows[0].decoded_frames, 45);
}

#[test]
fn several_videos_make_a_table_and_bad_ones_keep_the_rest() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let corrupt = tmp.path().join("corrupt.mp4");
    std::fs::write(&corrupt, b"this is not a video at all, just text that claims to be one").unwrap();
    // Cut without an index (moov at the end): cannot even be opened.
    let cut = tmp.path().join("cut.mp4");
    let bytes = std::fs::read(fixture()).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    // Cut with the index first (faststart): opens, then the stream ends early.
    let faststart = tmp.path().join("faststart.mp4");
    let ok = std::process::Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-i"])
        .arg(fixture())
        .args(["-c", "copy", "-movflags", "+faststart"])
        .arg(&faststart)
        .status()
        .expect("ffmpeg (installed by scripts/setup.sh)");
    assert!(ok.success());
    let fs_bytes = std::fs::read(&faststart).unwrap();
    let truncated = tmp.path().join("truncated.mp4");
    std::fs::write(&truncated, &fs_bytes[..fs_bytes.len() * 6 / 10]).unwrap();
    let jobs = [
        job(fixture(), "original"),
        job(tmp.path().join("missing.mp4"), "missing"),
        job(corrupt, "corrupt"),
        job(cut, "cut"),
        job(truncated, "truncated"),
        job(fixture(), "again"),
    ];
    let out_dir = tmp.path().join("out");
    let out = run(&jobs, &DETS, &out_dir, 1);
    let fail = out.failures.join("\n");
    assert!(fail.contains("missing.mp4 does not exist"), "{fail}");
    assert!(fail.contains("corrupt.mp4 cannot be opened"), "{fail}");
    assert!(fail.contains("cut.mp4 cannot be opened"), "{fail}");
    // The truncated video keeps what it decoded and says how far it got.
    let t = out.rows.iter().find(|r| r.video == "truncated" && r.detector == "yolox_nano").unwrap();
    assert!(t.accuracy.total > 0 && t.accuracy.total < 45, "{t:?}");
    assert!(t.status.starts_with("truncated: decoded") && t.status.contains("of 45"), "{}", t.status);
    // The good videos before and after the bad ones are fully scored.
    for label in ["original", "again"] {
        let r = out.rows.iter().find(|r| r.video == label && r.detector == "yolox_nano").unwrap();
        assert_eq!((r.accuracy.detected, r.accuracy.total), (30, 45), "{label}");
    }
    let md = std::fs::read_to_string(out_dir.join("summary.md")).unwrap();
    assert!(md.contains("| Video | yolox_nano | yolov8n_int8 |"), "{md}");
    // Both detectors' cells for one video; its light is the video's, one row whatever they found.
    assert!(md.contains("| original | 66.7") && md.contains("| again | 66.7"), "{md}");
    let light = |v: &str| {
        let row = md
            .lines()
            .find(|l| l.starts_with(&format!("| {v} | ")) && (l.ends_with("steady |") || l.ends_with("drifted |")));
        row.map(|l| l[v.len() + 4..].to_string())
    };
    assert!(light("original").is_some() && light("original") == light("again"), "{md}");
    assert!(md.contains("Score threshold **0.5**; target classes **car**"), "{md}");
    let summary = std::fs::read_to_string(out_dir.join("summary.csv")).unwrap();
    assert!(summary.lines().any(|l| l.starts_with("missing,yolox_nano") && l.contains("failed")), "{summary}");
}

#[test]
fn even_sampling_picks_the_middle_of_equal_stretches_and_shared_labels_pool() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    // The same recording under a second name, sidecar included: one texture at two polar angles.
    let copy = tmp.path().join("second.mp4");
    std::fs::copy(fixture(), &copy).unwrap();
    std::fs::copy(common::repo().join("fixtures/carla_orbit.angles.csv"), tmp.path().join("second.angles.csv"))
        .unwrap();
    let jobs = [job(fixture(), "texture"), job(copy, "texture"), job(tmp.path().join("gone.mp4"), "lost")];
    let out = run_frames(&jobs, &["yolox_nano"], &tmp.path().join("out"), Frames::Even(11));
    // 45 frames in 11 stretches of 45/11: the middle frame of each.
    let want: Vec<usize> = vec![2, 6, 10, 14, 18, 22, 26, 30, 34, 38, 42];
    for file in ["carla_orbit.mp4", "second.mp4"] {
        let frames: Vec<usize> = out.records.iter().filter(|r| r.file == file).map(|r| r.frame).collect();
        assert_eq!(frames, want, "{file}");
    }
    let truth = truth();
    let hits = want.iter().filter(|&&f| expected(&truth[f], "yolox_nano")).count();
    assert_eq!(out.rows.len(), 2, "{:?}", out.rows);
    let cell = &out.rows[0];
    assert_eq!((cell.video.as_str(), cell.videos), ("texture", 2));
    assert_eq!(cell.accuracy, Accuracy { detected: 2 * hits, total: 22 });
    assert_eq!((cell.decoded_frames, cell.status.as_str()), (90, "complete"));
    let csv = std::fs::read_to_string(tmp.path().join("out/summary.csv")).unwrap();
    assert!(
        csv.lines().any(|l| l.starts_with("texture,yolox_nano,car,0.5,even 11,22,") && l.contains(",2,complete,")),
        "{csv}"
    );
    let frames_csv = std::fs::read_to_string(tmp.path().join("out/frames.csv")).unwrap();
    assert!(frames_csv.lines().next().unwrap().ends_with(",file"), "{frames_csv}");
    assert_eq!(frames_csv.lines().filter(|l| l.ends_with(",second.mp4")).count(), 11);

    // More frames than the video has: every frame is scored and the run says it fell short; a
    // pooled cell with a failed video says which one.
    let jobs = [job(fixture(), "texture"), job(tmp.path().join("gone.mp4"), "texture")];
    let out = run_frames(&jobs, &["yolox_nano"], &tmp.path().join("out2"), Frames::Even(60));
    let cell = &out.rows[0];
    assert_eq!((cell.accuracy.total, cell.videos), (45, 2));
    assert!(
        cell.status.starts_with("video 1: 60 frames asked, the video declares 45; video 2: failed:"),
        "{}",
        cell.status
    );
    assert!(out.failures.iter().any(|f| f.contains("60 frames asked")), "{:?}", out.failures);
}

#[test]
fn detectors_side_by_side_and_frames_at_once_write_the_same_reports() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let jobs = [VideoJob { path: fixture(), label: "orbit".into(), sidecar: None }];
    let names = ["yolox_nano", "yolov8n_int8", "yolov3-tiny"];
    let mut reports = Vec::new();
    for (parallel, lanes) in [(1, 1), (2, 1), (3, 1), (1, 2), (2, 3), (1, 4)] {
        let out = tmp.path().join(format!("p{parallel}l{lanes}"));
        let mut d = detectors(&names);
        let o = EvalOptions { parallel, lanes, ..opts(&out, Frames::Stride(3)) };
        let outcome = evaluate(&jobs, &mut d, &o, &pav::progress::Silent, &AtomicBool::new(false)).unwrap();
        assert!(outcome.failures.is_empty(), "{:?}", outcome.failures);
        assert_eq!(outcome.records.len(), 15 * names.len());
        let read = |f: &str| std::fs::read(out.join(f)).unwrap();
        reports.push((read("frames.csv"), read("summary.csv"), read("angles.csv")));
    }
    assert!(reports.windows(2).all(|w| w[0] == w[1]), "frames, summary or angles differ between settings");
}

/// A real detector that fails on one frame, known by its prepared input, whichever copy or
/// thread scores it.
struct FailsOn {
    inner: Box<dyn Detector>,
    poison: Vec<f32>,
}

impl Detector for FailsOn {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn input(&self) -> &InputConfig {
        self.inner.input()
    }
    fn propose_prepared(&mut self, input: Vec<f32>, map: InputMap) -> Result<Proposals, DetectError> {
        if input == self.poison {
            return Err(DetectError::Model { detector: self.name().into(), path: "-".into(), msg: "poisoned".into() });
        }
        self.inner.propose_prepared(input, map)
    }
    fn target_classes(&self) -> &[usize] {
        self.inner.target_classes()
    }
    fn nms_iou(&self) -> f32 {
        self.inner.nms_iou()
    }
    fn target_label(&self) -> String {
        self.inner.target_label()
    }
    fn replica(&self) -> Result<Box<dyn Detector>, DetectError> {
        Ok(Box::new(FailsOn { inner: self.inner.replica()?, poison: self.poison.clone() }))
    }
}

#[test]
fn a_detector_failing_mid_batch_stops_where_it_would_one_frame_at_a_time() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let jobs = [VideoJob { path: fixture(), label: "orbit".into(), sidecar: None }];
    let mut reader = pav::video::VideoReader::open(&fixture()).unwrap();
    let frame7 = (0..8).map(|_| reader.read().unwrap().unwrap().1).last().unwrap();
    let failing = |alone: bool| {
        let mut d = detectors(if alone { &["yolox_nano"][..] } else { &["yolox_nano", "yolov3-tiny"] });
        let poison = prepare(&frame7, d[0].input()).unwrap().0;
        let inner = d.remove(0);
        d.insert(0, Box::new(FailsOn { inner, poison }));
        d
    };
    for alone in [false, true] {
        let mut reports = Vec::new();
        // Frame 7 first, in the middle and last of a batch.
        for lanes in [1, 2, 3, 4] {
            let out = tmp.path().join(format!("a{alone}l{lanes}"));
            let mut d = failing(alone);
            let o = EvalOptions { lanes, ..opts(&out, Frames::Stride(1)) };
            let outcome = evaluate(&jobs, &mut d, &o, &pav::progress::Silent, &AtomicBool::new(false)).unwrap();
            let yolox: Vec<_> = outcome.records.iter().filter(|r| r.detector == "yolox_nano").collect();
            assert_eq!(yolox.last().unwrap().frame, 6, "lanes {lanes}: scored past the failure");
            assert_eq!(yolox.len(), 7);
            assert!(outcome.failures.iter().any(|f| f.contains("frame 7") && f.contains("poisoned")));
            if !alone {
                assert_eq!(outcome.records.len(), 7 + 45, "lanes {lanes}: the other detector scores every frame");
            }
            let read = |f: &str| std::fs::read(out.join(f)).unwrap();
            reports.push((read("frames.csv"), read("summary.csv"), outcome.failures));
        }
        assert!(reports.windows(2).all(|w| w[0] == w[1]), "alone {alone}: reports differ between lane counts");
    }
}
