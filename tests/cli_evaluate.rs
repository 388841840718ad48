//! `pav-rig evaluate` as a user runs it: reports on success, clear errors (never a panic) on bad
//! setup, and partial results kept on failures and Ctrl-C.

mod common;

use std::path::Path;
use std::process::{Command, Output, Stdio};

fn pav_rig() -> Command {
    Command::new(env!("CARGO_BIN_EXE_pav-rig"))
}

fn fixture() -> String {
    common::repo().join("fixtures/carla_orbit.mp4").display().to_string()
}

fn cfg(name: &str) -> String {
    common::detector_config(name).display().to_string()
}

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

fn assert_clean_failure(o: &Output, needle: &str) {
    let (out, err) = text(o);
    assert!(!o.status.success(), "expected failure\n{out}\n{err}");
    assert!(err.contains(needle), "stderr lacks `{needle}`:\n{err}");
    assert!(!err.contains("panicked"), "panicked:\n{err}");
}

#[test]
fn evaluate_prints_table_and_writes_reports() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--stride", "3", "-o"])
        .arg(tmp.path())
        .output()
        .unwrap();
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(out.contains("A_physical at score threshold 0.5"), "{out}");
    assert!(out.lines().any(|l| l.starts_with("carla_orbit") && l.contains(" 10 ") && l.contains(" 15 ")), "{out}");
    assert!(err.contains("stride 3"), "{err}");
    assert!(tmp.path().join("accuracy.png").exists());
}

#[test]
fn missing_or_broken_onnx_runtime_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let o = pav_rig()
        .env("ORT_DYLIB_PATH", tmp.path().join("nope/libonnxruntime.so"))
        .args(["evaluate", &fixture(), "-d", &cfg("yolov3-tiny"), "-o"])
        .arg(tmp.path().join("o1"))
        .output()
        .unwrap();
    if common::repo().join(".deps/models/yolov3-tiny/yolov3-tiny.onnx").exists() {
        assert_clean_failure(&o, "ONNX Runtime library not found");
        let fake = tmp.path().join("libonnxruntime.so");
        std::fs::write(&fake, "not a shared library").unwrap();
        let o = pav_rig()
            .env("ORT_DYLIB_PATH", &fake)
            .args(["evaluate", &fixture(), "-d", &cfg("yolov3-tiny"), "-o"])
            .arg(tmp.path().join("o2"))
            .output()
            .unwrap();
        assert_clean_failure(&o, "cannot load ONNX Runtime");
    } else {
        assert_clean_failure(&o, "run scripts/setup.sh");
    }
}

fn write_cfg(dir: &Path, model: &str, layout: &str) -> String {
    let p = dir.join(format!("{layout}.toml"));
    std::fs::write(
        &p,
        format!("name = 'x'\nmodel = '{model}'\n[input]\nwidth = 32\nheight = 32\nchannels = 'rgb'\nresize = 'stretch'\n[output]\nlayout = '{layout}'\n"),
    )
    .unwrap();
    p.display().to_string()
}

#[test]
fn bad_configs_name_the_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let missing_model = write_cfg(tmp.path(), "no/such/model.onnx", "ultralytics");
    let o = pav_rig().args(["evaluate", &fixture(), "-d", &missing_model]).output().unwrap();
    assert_clean_failure(&o, "no/such/model.onnx does not exist");
    let bad_layout = write_cfg(tmp.path(), "m.onnx", "retinanet");
    let o = pav_rig().args(["evaluate", &fixture(), "-d", &bad_layout]).output().unwrap();
    assert_clean_failure(&o, "unknown variant `retinanet`");
    let o =
        pav_rig().args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--classes", "hovercraft"]).output().unwrap();
    assert_clean_failure(&o, "`hovercraft`");
    let o = pav_rig().args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--threshold", "1.5"]).output().unwrap();
    assert_clean_failure(&o, "--threshold 1.5");
}

#[test]
fn a_missing_video_fails_the_run_but_keeps_the_others() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let o = pav_rig()
        .args([
            "evaluate",
            "no_such_video.mp4",
            &fixture(),
            "-d",
            &cfg("yolox_nano"),
            "--stride",
            "5",
            "--no-plots",
            "-o",
        ])
        .arg(tmp.path())
        .output()
        .unwrap();
    assert_clean_failure(&o, "no_such_video.mp4 does not exist");
    let summary = std::fs::read_to_string(tmp.path().join("summary.csv")).unwrap();
    assert!(summary.lines().any(|l| l.starts_with("carla_orbit,yolox_nano") && l.ends_with("complete")), "{summary}");
}

#[test]
fn ctrl_c_keeps_every_scored_frame_and_a_summary() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let fx = fixture();
    let child = pav_rig()
        .args(["evaluate", &fx, &fx, &fx, "--label", "a", "--label", "b", "--label", "c"])
        .args(["-d", &cfg("yolov8n_int8"), "-d", &cfg("deimv2_atto_int8"), "--no-plots", "-o"])
        .arg(tmp.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let frames = tmp.path().join("frames.csv");
    let t0 = std::time::Instant::now();
    while std::fs::read_to_string(&frames).map(|s| s.lines().count()).unwrap_or(0) < 5 {
        assert!(t0.elapsed().as_secs() < 120, "no frames scored within 2 minutes");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let ok = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(ok.success());
    let o = child.wait_with_output().unwrap();
    assert_clean_failure(&o, "interrupted");
    let scored = std::fs::read_to_string(&frames).unwrap().lines().count() - 1;
    assert!((4..3 * 45 * 2).contains(&scored), "{scored} rows");
    let summary = std::fs::read_to_string(tmp.path().join("summary.csv")).unwrap();
    assert!(summary.contains("interrupted after"), "{summary}");
    // The summary counts exactly the frames that were written.
    let counted: usize = summary.lines().skip(1).map(|l| l.split(',').nth(5).unwrap().parse::<usize>().unwrap()).sum();
    assert_eq!(counted, scored);
}
