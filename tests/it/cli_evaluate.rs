//! `pav-rig evaluate` as a user runs it: reports on success, clear errors (never a panic) on bad
//! setup, and partial results kept on failures and Ctrl-C.

use crate::common;
use crate::common::pav_rig;

use std::path::Path;
use std::process::{Command, Output, Stdio};

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
    assert!(err.contains("one frame in 3"), "{err}");
    // stderr is a pipe here, as in a log file: the bar's stage still shows as plain lines.
    assert!(err.lines().any(|l| l.starts_with("carla_orbit: 0/45, ")), "{err}");
    assert!(err.lines().any(|l| l.starts_with("carla_orbit: 45/45, ") && l.ends_with(", done")), "{err}");
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
    assert!(summary.lines().any(|l| l.starts_with("carla_orbit,yolox_nano") && l.contains(",complete,")), "{summary}");
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
    assert!(text(&o).1.contains("stopping after the unit in progress (Ctrl-C again to stop at once)"));
    let scored = std::fs::read_to_string(&frames).unwrap().lines().count() - 1;
    assert!((4..3 * 45 * 2).contains(&scored), "{scored} rows");
    let summary = std::fs::read_to_string(tmp.path().join("summary.csv")).unwrap();
    assert!(summary.contains("interrupted after"), "{summary}");
    // The summary counts exactly the frames that were written.
    let counted: usize = summary.lines().skip(1).map(|l| l.split(',').nth(5).unwrap().parse::<usize>().unwrap()).sum();
    assert_eq!(counted, scored);
}

/// The fixture video under another name, with `sidecar` (its text) beside it.
fn video_with_sidecar(dir: &Path, name: &str, sidecar: &str) -> String {
    let v = dir.join(format!("{name}.mp4"));
    std::fs::copy(common::repo().join("fixtures/carla_orbit.mp4"), &v).unwrap();
    std::fs::write(dir.join(format!("{name}.angles.csv")), sidecar).unwrap();
    v.display().to_string()
}

#[test]
fn bad_or_incomplete_sidecars_get_error_rows_and_fail_the_run() {
    // Each of these used to vanish from the summary or pass as "complete" with exit 0.
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let good = std::fs::read_to_string(common::repo().join("fixtures/carla_orbit.angles.csv")).unwrap();
    let lines: Vec<&str> = good.lines().collect();
    let header = lines[0];
    let keep = |skip: &dyn Fn(usize) -> bool| {
        let mut s = String::from(header) + "\n";
        for (i, l) in lines[1..].iter().enumerate() {
            if !skip(i) {
                s += l;
                s += "\n";
            }
        }
        s
    };
    let videos = [
        video_with_sidecar(tmp.path(), "backwards", &format!("{header}\n0,0,0\n2,0.1,5\n1,0.2,10\n")),
        video_with_sidecar(tmp.path(), "nan", &format!("{header}\n0,0,NaN\n")),
        video_with_sidecar(tmp.path(), "short", &format!("{header}\n0,0\n")),
        video_with_sidecar(tmp.path(), "wide", &format!("{header}\n0,0,720\n")),
        video_with_sidecar(tmp.path(), "gaps", &keep(&|i| (10..20).contains(&i))),
    ];
    let out_dir = tmp.path().join("out");
    let o = pav_rig()
        .arg("evaluate")
        .args(&videos)
        .args(["-d", &cfg("yolox_nano"), "--stride", "5", "--no-plots", "-o"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert_clean_failure(&o, "5 problem(s)");
    let (_, err) = text(&o);
    assert!(err.contains("frame 1 does not follow frame 2"), "{err}");
    assert!(err.contains("angle 720° is outside [0, 360)"), "{err}");
    assert!(err.contains("gaps: angles incomplete: 2 of"), "{err}");
    let summary = std::fs::read_to_string(out_dir.join("summary.csv")).unwrap();
    for name in ["backwards", "nan", "short", "wide"] {
        let row = summary.lines().find(|l| l.starts_with(&format!("{name},yolox_nano"))).expect(name);
        assert!(row.contains("failed: angle sidecar"), "{row}");
    }
    // Frames 10–19 lack rows; stride 5 scores two of them (10 and 15).
    let row = summary.lines().find(|l| l.starts_with("gaps,yolox_nano")).unwrap();
    assert!(row.contains("angles incomplete: 2 of"), "{row}");
    let md = std::fs::read_to_string(out_dir.join("summary.md")).unwrap();
    assert!(md.contains("backwards") && md.contains("gaps"), "{md}");
}

/// A clip without a sidecar that spans part of a turn at the period given says so in its status
/// and lists the sectors it holds; at its own length as the period it is a whole turn. Neither
/// fails the run.
#[test]
fn a_clip_shorter_than_the_period_says_which_part_of_the_turn_it_holds() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let clip = tmp.path().join("clip.mp4");
    std::fs::copy(fixture(), &clip).unwrap();
    let eval = |period: &str, out: &str| {
        let o = pav_rig()
            .args(["evaluate", &clip.display().to_string(), "-d", &cfg("yolox_nano")])
            .args(["--period", period, "--no-plots", "-o"])
            .arg(tmp.path().join(out))
            .output()
            .unwrap();
        let (stdout, err) = text(&o);
        assert!(o.status.success(), "{stdout}\n{err}");
        let md = std::fs::read_to_string(tmp.path().join(out).join("summary.md")).unwrap();
        (std::fs::read_to_string(tmp.path().join(out).join("summary.csv")).unwrap(), md, stdout)
    };
    // 45 frames at 10 fps: 4.5 s of a 28 s turn.
    let (csv, md, stdout) = eval("28s", "short");
    let want = "less than one turn: 4.5 s of a 28 s period, 0–58° (no sidecar; is --period right?)";
    assert!(csv.contains(want) && md.contains(want) && stdout.contains("less than one turn"), "{csv}\n{stdout}");
    assert!(md.contains("Frames in 2 of 12 sectors: 0–30°, 30–60°."), "{md}");
    let (csv, md, _) = eval("4.5", "whole");
    assert!(csv.contains(",complete,") && !md.contains("Frames in"), "{csv}\n{md}");
}

/// YOLOX-Nano's rows described as a custom layout with the given box `encoding` and objectness
/// `column`, written into `dir`.
fn yolox_as_custom(dir: &Path, name: &str, encoding: &str, column: usize) -> String {
    let shipped = std::fs::read_to_string(common::detector_config("yolox_nano")).unwrap();
    let inputs =
        shipped.split("[output]").next().unwrap().replace("name = \"yolox_nano\"", &format!("name = \"{name}\""));
    let levels = "[[output.levels]]\nstride = 8\n[[output.levels]]\nstride = 16\n[[output.levels]]\nstride = 32\n";
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(
        &path,
        format!("{inputs}[output]\nlayout = \"custom\"\n{levels}[output.boxes]\nencoding = \"{encoding}\"\n[output.objectness]\ncolumn = {column}\n[output.scores]\ncolumn = 5\n"),
    )
    .unwrap();
    path.display().to_string()
}

/// A description whose scores leave [0, 1] (the objectness read from a box column) stops that
/// detector at its first frame and fails the run, the right one scoring on; one whose confident
/// boxes have no area (the wrong box encoding) is scored, and its status says so.
#[test]
fn evaluate_refuses_scores_outside_0_1_and_doubts_boxes_without_area() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let wrong = yolox_as_custom(tmp.path(), "column", "grid", 2);
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &wrong, "-d", &cfg("yolox_nano"), "--stride", "9", "--no-plots", "-o"])
        .arg(tmp.path().join("column"))
        .output()
        .unwrap();
    assert_clean_failure(&o, "column: frame 0: scores run from");
    let summary = std::fs::read_to_string(tmp.path().join("column/summary.csv")).unwrap();
    let row = |who: &str| summary.lines().find(|l| l.starts_with(&format!("carla_orbit,{who},"))).unwrap().to_string();
    assert!(
        row("column").contains("stopped at frame 0: scores run from") && row("column").contains("outside [0, 1]"),
        "{summary}"
    );
    assert!(row("yolox_nano").contains(",complete,"), "{summary}");
    let encoding = yolox_as_custom(tmp.path(), "encoding", "xyxy", 4);
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &encoding, "--stride", "9", "--no-plots", "-o"])
        .arg(tmp.path().join("encoding"))
        .output()
        .unwrap();
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    let summary = std::fs::read_to_string(tmp.path().join("encoding/summary.csv")).unwrap();
    assert!(summary.contains("detection(s) with a doubtful box, first at frame 0: the best box, ["), "{summary}");
    assert!(summary.contains("the box encoding or the columns' order is likely wrong"), "{summary}");
}

#[test]
fn out_of_range_settings_are_refused_before_any_work() {
    for (flag, value, needle) in [
        ("--start-angle", "NaN", "--start-angle NaN must be a number"),
        ("--period", "0", "a period is a non-zero number of seconds"),
        ("--threshold", "1.01", "--threshold 1.01 must be within [0, 1]"),
    ] {
        let o = pav_rig().args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), flag, value]).output().unwrap();
        assert_clean_failure(&o, needle);
    }
    // Threads beyond the cores only take turns (1.2 s became over 60 s): said before anything.
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--threads", "1000", "--start-angle", "NaN"])
        .output()
        .unwrap();
    assert_clean_failure(&o, "warning: --threads 1000 is more than this machine's");
}

#[test]
fn sample_spreads_frames_and_a_repeated_label_pools_videos() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let fx = fixture();
    let o = pav_rig()
        .args(["evaluate", &fx, &fx, "--label", "camo", "--label", "camo", "--sample", "5"])
        .args(["-d", &cfg("yolox_nano"), "--no-plots", "-o"])
        .arg(tmp.path())
        .output()
        .unwrap();
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(err.contains("5 evenly spaced frames per video"), "{err}");
    let summary = std::fs::read_to_string(tmp.path().join("summary.csv")).unwrap();
    assert_eq!(summary.lines().count(), 2, "{summary}");
    assert!(summary.lines().nth(1).unwrap().starts_with("camo,yolox_nano,car,0.5,even 5,10,"), "{summary}");
    let md = std::fs::read_to_string(tmp.path().join("summary.md")).unwrap();
    assert!(md.contains("Videos that share a label are pooled into one row."), "{md}");
    // Two ways of choosing frames at once is refused, and so is pooling by accident.
    let o =
        pav_rig().args(["evaluate", &fx, "-d", &cfg("yolox_nano"), "--sample", "5", "--stride", "2"]).output().unwrap();
    assert_clean_failure(&o, "cannot be used with");
    let o = pav_rig().args(["evaluate", &fx, &fx, "-d", &cfg("yolox_nano")]).output().unwrap();
    assert_clean_failure(&o, "the same --label to pool them");
}

/// `--defence` adds each detector behind each defence beside the undefended one: the same frames
/// scored, the defences recorded in run.toml, and a defence that wipes the input (one bit per
/// channel) leaves no car on the fixture where the plain model finds it in 10 of 15 frames.
#[test]
fn defended_detectors_are_scored_beside_the_original() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--stride", "3", "--no-plots"])
        .args(["--defence", "bits:b=1", "--defence", "median:k=3+jpeg:q=75", "-o"])
        .arg(tmp.path())
        .output()
        .unwrap();
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    let summary = std::fs::read_to_string(tmp.path().join("summary.csv")).unwrap();
    let row = |det: &str| -> (usize, usize) {
        let line = summary
            .lines()
            .find(|l| l.split(',').nth(1) == Some(det))
            .unwrap_or_else(|| panic!("no {det} row:\n{summary}"));
        let header: Vec<&str> = summary.lines().next().unwrap().split(',').collect();
        let col = |name: &str| line.split(',').nth(header.iter().position(|h| *h == name).unwrap()).unwrap();
        (col("detected").parse().unwrap(), col("frames").parse().unwrap())
    };
    assert_eq!(row("yolox_nano"), (10, 15), "{summary}");
    assert_eq!(row("yolox_nano+bits1"), (0, 15), "{summary}");
    assert_eq!(row("yolox_nano+median3+jpeg75").1, 15, "{summary}");
    assert!(out.contains("yolox_nano+median3+jpeg75 car"), "columns fit the longest name:\n{out}");
    let frames = std::fs::read_to_string(tmp.path().join("frames.csv")).unwrap();
    assert_eq!(frames.lines().filter(|l| l.contains(",yolox_nano+bits1,")).count(), 15);
    let run = common::run_record(&tmp.path().join("run.toml"));
    assert_eq!(run["settings"]["defences"].as_str(), Some("bits1;median3+jpeg75"), "{run}");
}

/// A bad defence is refused before any work, naming the spec or the detector config.
#[test]
fn bad_defences_are_refused_naming_the_config() {
    let tmp = tempfile::tempdir().unwrap();
    for (spec, needle) in [
        ("median:k=4", "k = 4 must be odd and at least 3"),
        ("jpeg:q=101", "q = 101 must be a quality from 1 to 100"),
        ("bits:b=9", "b = 9 must be 1 to 8 bits"),
        ("blur:k=3", "unknown variant `blur`"),
    ] {
        let o = pav_rig().args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--defence", spec]).output().unwrap();
        assert_clean_failure(&o, &format!("defence `{spec}`"));
        assert_clean_failure(&o, needle);
    }
    // YOLOX-Nano's input is 416 px: a wider median window fits no input.
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--defence", "median:k=417"])
        .output()
        .unwrap();
    assert_clean_failure(&o, "yolox_nano.toml: defence 1 (median417): k = 417 is wider than the 416x416 input");
    // A clipping layer the graph does not have: named with the config, before any frame.
    let out = tmp.path().join("clip");
    let o = pav_rig()
        .args(["evaluate", &fixture(), "-d", &cfg("yolox_nano"), "--defence", "clip:layers=['781','dark9']", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert_clean_failure(&o, "yolox_nano.toml: feature norm clipping");
    assert_clean_failure(&o, "the graph has no tensor `dark9` to clip");
    assert!(!out.exists(), "nothing runs half-configured");
    let base = std::fs::read_to_string(common::detector_config("yolox_nano")).unwrap();
    for (entry, needle) in [
        ("kind = 'jpeg'\nq = 0\n", "defence 1 (jpeg0): q = 0 must be a quality from 1 to 100"),
        ("kind = 'median'\n", "missing field `k`"),
        ("kind = 'cutout'\nn = 2\ns = 0\n", "defence 1 (cutout2x0): n = 2 and s = 0 must be positive"),
    ] {
        let p = tmp.path().join("defended.toml");
        // The shipped config names its model by data-store entry, so it loads from any folder.
        std::fs::write(&p, format!("{base}\n[[defence]]\n{entry}")).unwrap();
        let out = tmp.path().join("o");
        let o = pav_rig().args(["evaluate", &fixture(), "-d"]).arg(&p).arg("-o").arg(&out).output().unwrap();
        assert_clean_failure(&o, "defended.toml");
        assert_clean_failure(&o, needle);
        assert!(!out.exists(), "nothing runs half-configured");
    }
}

/// `--squeeze` (feature squeezing as an attack detector): each detector is also scored behind bit
/// depth 4 and a 3×3 median; a frame's gap is the largest change of its best car score under
/// them, and the threshold set on the clean video flags at most 5 % of its frames.
#[test]
fn squeeze_flags_frames_whose_car_score_moves_under_squeezing() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let turntable = common::repo().join("fixtures/turntable.mp4").display().to_string();
    let run = |extra: &[&str]| {
        pav_rig()
            .args(["evaluate", &turntable, &fixture(), "--label", "original", "--label", "orbit"])
            .args(["-d", &cfg("yolov3-tiny"), "--stride", "1", "--no-plots", "-o"])
            .arg(tmp.path())
            .args(extra)
            .env("RUST_BACKTRACE", "0")
            .output()
            .unwrap()
    };
    let o = run(&["--squeeze", "--squeeze-clean", "original"]);
    assert!(o.status.success(), "{}", common::output_text(&o));
    let frames = std::fs::read_to_string(tmp.path().join("frames.csv")).unwrap();
    let header: Vec<&str> = frames.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let mut score = std::collections::HashMap::new();
    for l in frames.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        score.insert(
            (c[col("video")].to_string(), c[col("frame")].to_string(), c[col("detector")].to_string()),
            c[col("max_score")].parse::<f32>().unwrap(),
        );
    }
    let squeeze = std::fs::read_to_string(tmp.path().join("squeeze.csv")).unwrap();
    let (mut clean, mut flagged) = (0, 0);
    for l in squeeze.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        let (video, frame, det, gap) = (c[0], c[2], c[3], c[4].parse::<f32>().unwrap());
        let s = |d: &str| score[&(video.to_string(), frame.to_string(), d.to_string())];
        let want = (s(det) - s(&format!("{det}+bits4"))).abs().max((s(det) - s(&format!("{det}+median3"))).abs());
        assert!((gap - want).abs() < 1e-6, "{l}: gap {gap}, scores say {want}");
        if video == "original" {
            clean += 1;
            flagged += usize::from(c[5] == "true");
        }
    }
    assert!(clean >= 40 && flagged * 20 <= clean, "{flagged} of {clean} clean frames flagged");
    let md = std::fs::read_to_string(tmp.path().join("squeeze.md")).unwrap();
    assert!(md.contains("| yolov3-tiny |") && md.contains("original: flagged"), "{md}");
    let record = std::fs::read_to_string(tmp.path().join("run.toml")).unwrap();
    assert!(record.contains("squeeze = \"0.05 of the frames of original flagged\""), "{record}");
    assert_clean_failure(&run(&["--squeeze"]), "--squeeze needs --squeeze-clean");
    assert_clean_failure(
        &run(&["--squeeze", "--squeeze-clean", "nope"]),
        "no video has that label (labels: original, orbit)",
    );
}
