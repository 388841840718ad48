//! `pav-rig capture` and `pav-rig turntable` as a user runs them, against the simulator; the
//! captured video and sidecar feed straight into `pav-rig evaluate`.

use crate::common;
use crate::common::pav_rig;

#[test]
fn capture_on_the_simulator_then_evaluate_uses_the_sidecar() {
    let tmp = tempfile::tempdir().unwrap();
    let video = tmp.path().join("spin.mp4");
    let o = pav_rig()
        .args([
            "capture",
            "--port",
            "sim",
            "--time-scale",
            "10",
            "--camera",
            "sim",
            "--width",
            "320",
            "--height",
            "240",
            "--codec",
            "mp4v",
            "-o",
        ])
        .arg(&video)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    let out = common::output_text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("table ended at 360.000°"), "{out}");
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap();
    assert!((80..=90).contains(&rows.len()), "{} frames for 2.8 s at 30 fps", rows.len());
    // In simulated time the capture is the same run however busy the machine: a second one
    // writes the same sidecar, every frame at the same instant and angle.
    let again = tmp.path().join("again.mp4");
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--time-scale", "10", "--camera", "sim", "--width", "320"])
        .args(["--height", "240", "--codec", "mp4v", "-o"])
        .arg(&again)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let sidecar = |v: &std::path::Path| std::fs::read(pav::sidecar::sidecar_path(v)).unwrap();
    assert!(sidecar(&video) == sidecar(&again), "two simulated captures placed their frames differently");
    // The capture's record states its bound and the link's round trip, as the summary printed.
    let run = common::run_record(&tmp.path().join("spin.run.toml"));
    let bound: f64 = run["result"]["angle_bound_deg"].as_str().unwrap().parse().unwrap();
    assert!(bound > 0.0 && bound <= 0.5, "{run}");
    assert!(run["result"]["round_trip_ms"].as_str().unwrap().parse::<f64>().is_ok(), "{run}");
    assert_eq!(run["result"]["frames"].as_str(), Some(rows.len().to_string().as_str()), "{run}");
    assert!(run["tools"]["ffmpeg"].as_str().unwrap().starts_with("ffmpeg version"), "{run}");
    common::real_data();
    let o = pav_rig()
        .args(["evaluate"])
        .arg(&video)
        .args(["-d", &common::detector_config("yolox_nano").display().to_string(), "--no-plots", "-o"])
        .arg(tmp.path().join("eval"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let md = std::fs::read_to_string(tmp.path().join("eval/summary.md")).unwrap();
    assert!(md.contains("Angles for **spin**: sidecar"), "{md}");
    let run = common::run_record(&tmp.path().join("eval/run.toml"));
    let (video_sha, sidecar_sha) = (
        pav::data::store::file_digest(&video).unwrap().1,
        pav::data::store::file_digest(&pav::sidecar::sidecar_path(&video)).unwrap().1,
    );
    assert_eq!(common::record_input(&run, "spin.mp4")["sha256"].as_str(), Some(video_sha.as_str()));
    assert_eq!(common::record_input(&run, "spin.angles.csv")["sha256"].as_str(), Some(sidecar_sha.as_str()));
    assert_eq!(common::record_input(&run, "yolox_nano.onnx")["data"].as_str(), Some("models-yolox/yolox_nano.onnx"));
    assert!(run["tools"]["opencv"].as_str().unwrap().starts_with('4'), "{run}");
    // The synthetic disc is no car: nothing is detected.
    assert!(md.contains("| spin | 0.0 |"), "{md}");
}

#[test]
fn missing_hardware_is_a_clear_error() {
    let o = pav_rig()
        .args(["turntable", "--port", "/dev/no-such-tty", "status"])
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    assert!(!o.status.success());
    let out = common::output_text(&o);
    assert!(out.contains("cannot open turntable port /dev/no-such-tty"), "{out}");
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--camera", "v4l2:/dev/video-none", "-o", "/tmp/never.mp4"])
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(common::output_text(&o).contains("no V4L2 camera at /dev/video-none"), "{}", common::output_text(&o));
    assert!(!std::path::Path::new("/tmp/never.mp4").exists());
    let o = pav_rig()
        .args(["capture", "--port", "/dev/ttyS99", "--camera", "sim", "-o", "/tmp/never.mp4"])
        .output()
        .unwrap();
    assert!(
        common::output_text(&o).contains("--camera sim films the simulated turntable"),
        "{}",
        common::output_text(&o)
    );
    // Without --camera, the one camera there is is taken and said; none or several are refused,
    // never guessed. The port does not exist, so nothing is filmed whatever the machine has.
    let o = pav_rig().args(["capture", "--port", "/dev/no-such-tty", "-o", "/tmp/never.mp4"]).output().unwrap();
    let said = common::output_text(&o);
    let why = match pav::rig::v4l2::capture_devices().len() {
        0 => "no V4L2 camera found",
        1 => "the only one; name it with --camera",
        _ => "pav does not guess",
    };
    assert!(!o.status.success() && said.contains(why), "{said}");
    assert!(!std::path::Path::new("/tmp/never.mp4").exists());
}

#[test]
fn turntable_commands_on_the_simulator() {
    let o =
        pav_rig().args(["turntable", "--port", "sim", "--time-scale", "20", "rotate", "--", "-90"]).output().unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    assert!(common::output_text(&o).contains("done at -800 microsteps = -90.000°"), "{}", common::output_text(&o));
    let o = pav_rig().args(["turntable", "--port", "sim", "status"]).output().unwrap();
    assert!(common::output_text(&o).contains("state Idle  position 0 microsteps"), "{}", common::output_text(&o));
}

#[test]
fn simulator_options_out_of_range_are_refused() {
    // `--disconnect-after 1e300` once panicked in `Duration::from_secs_f64`.
    for (flag, value, needle) in [
        ("--disconnect-after", "1e300", "--disconnect-after = 1e300 s is beyond any time"),
        ("--stall-after", "-1", "--stall-after must be a number of seconds ≥ 0, not -1.0"),
        ("--stall-after", "NaN", "--stall-after must be a number of seconds ≥ 0, not NaN"),
        ("--drop-rate", "1.5", "drop rate is a probability in [0, 1], not 1.5"),
        ("--time-scale", "0", "time scale must be positive and finite, not 0"),
    ] {
        let o = pav_rig().args(["simulate", &format!("{flag}={value}")]).env("RUST_BACKTRACE", "0").output().unwrap();
        let out = common::output_text(&o);
        assert_eq!(o.status.code(), Some(1), "{flag} {value}: {out}");
        assert!(out.contains(needle), "{flag} {value}: {out}");
        assert!(!out.contains("panicked"), "{out}");
    }
}

#[test]
fn a_killed_capture_leaves_a_playable_video() {
    // OpenCV's MP4 writer left 44 undecodable bytes after SIGKILL: the index comes at the end.
    let tmp = tempfile::tempdir().unwrap();
    let video = tmp.path().join("killed.mp4");
    // A live source in real time: a simulated camera would film the whole turn in simulated
    // time before the kill.
    let mut child = pav_rig()
        .args(["capture", "--port", "sim", "--time-scale", "4", "--camera", "gst-test", "--width", "160"])
        .args(["--height", "120", "--codec", "mp4v", "-o"])
        .arg(&video)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Two seconds of frames placed, however long a busy machine takes to film them.
    common::wait_for_sidecar_rows(&pav::sidecar::sidecar_path(&video), 60, std::time::Duration::from_secs(60));
    child.kill().unwrap(); // SIGKILL: pav gets no say
    child.wait().unwrap();
    // The encoder, orphaned, sees its input end and finishes the file.
    let mut frames = None;
    for _ in 0..100 {
        std::thread::sleep(std::time::Duration::from_millis(100));
        frames = common::decoded_frames(&video).ok().filter(|&n| n > 0);
        if frames.is_some() && common::decoded_frames(&video).ok() == frames {
            break;
        }
    }
    let frames = frames.expect("the video decodes after SIGKILL");
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap();
    eprintln!("after SIGKILL: {frames} frames decode, {} sidecar rows", rows.len());
    assert!(frames >= 30, "{frames} frames after 60 placed rows at 30 fps");
    // Rows follow frames as their angles become known, and frames may still have been queued for
    // the encoder: the two agree to within two seconds of frames (evaluate names the difference).
    assert!(frames.abs_diff(rows.len()) <= 60, "{} rows for {frames} frames", rows.len());
}

#[test]
fn sigterm_stops_the_table_and_closes_the_files() {
    use std::io::BufRead;
    let tmp = tempfile::tempdir().unwrap();
    let mut sim = pav_rig()
        .args(["simulate", "--time-scale", "4"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut port = String::new();
    std::io::BufReader::new(sim.stdout.take().unwrap()).read_line(&mut port).unwrap();
    let port = port.trim().to_string();
    let video = tmp.path().join("term.mp4");
    let cap = pav_rig()
        .args(["capture", "--port", &port, "--camera", "gst-test", "--width", "160", "--height", "120"])
        .args(["--codec", "mp4v", "--no-home", "-o"])
        .arg(&video)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    common::wait_for_sidecar_rows(&pav::sidecar::sidecar_path(&video), 40, std::time::Duration::from_secs(60));
    // SAFETY: kill(2) on a child's pid.
    assert_eq!(unsafe { libc::kill(cap.id() as i32, libc::SIGTERM) }, 0);
    let o = cap.wait_with_output().unwrap();
    let out = common::output_text(&o);
    assert!(!o.status.success(), "{out}");
    assert!(out.contains("interrupted (Ctrl-C or SIGTERM)") && out.contains("saved"), "{out}");
    // The table was told to stop, and both files hold every frame.
    std::thread::sleep(std::time::Duration::from_millis(500));
    let st = pav_rig().args(["turntable", "--port", &port, "status"]).output().unwrap();
    let _ = sim.kill();
    let _ = sim.wait();
    assert!(common::output_text(&st).contains("Idle"), "{}", common::output_text(&st));
    // Every frame decodes; each has a sidecar row, but for the frames after the last angle
    // report, which the error counts.
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap();
    let unplaced = out
        .split(" frames after the last angle report")
        .next()
        .filter(|_| out.contains("frames after the last angle report"))
        .and_then(|s| s.rsplit('(').next())
        .map_or(0, |n| n.trim().parse::<usize>().unwrap());
    assert_eq!(common::decoded_frames(&video).unwrap(), rows.len() + unplaced, "{out}");
    assert!(rows.len() > 20 && unplaced <= 2, "{out}");
}

#[test]
fn the_simulated_car_is_filmed_at_the_angles_its_sidecar_states() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let video = tmp.path().join("car.mp4");
    let cfg = common::repo().join("configs/views/turntable.toml");
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--time-scale", "8", "--camera", "sim", "--car"])
        .arg(&cfg)
        .args(["--elevation", "20", "--width", "256", "--height", "192", "--fps", "10", "-o"])
        .arg(&video)
        .output()
        .unwrap();
    let out = common::output_text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("pav's rasterizer, car at distance 5, elevation 20°"), "{out}");
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap();
    assert!(rows.len() >= 10, "{} frames", rows.len());
    let views = pav::scene::views::ViewsConfig::load(&cfg).unwrap();
    let car = pav::scene::turntable::CarScene::new(&views, None, Some(20.0)).unwrap();
    let diff = common::mean_abs_diff;
    // Each recorded frame is the car drawn at its sidecar angle, not 20° off it. H.264's 4:2:0
    // colour and compression leave about 3 per byte even at the right angle (measured 2.7–2.8);
    // at distance 5 the car fills less of the frame, so 20° off adds about 2 (measured 4.8–5.9).
    let mut r = pav::video::VideoReader::open(&video).unwrap();
    let (mut at, mut off) = (Vec::new(), Vec::new());
    while let Some((i, f)) = r.read().unwrap() {
        let a = rows[i].angle_deg as f32;
        at.push(diff(&f.bgr, &car.frame(a, 256, 192).bgr));
        off.push(diff(&f.bgr, &car.frame(a + 20.0, 256, 192).bgr));
    }
    assert_eq!(at.len(), rows.len());
    let worst = at.iter().cloned().fold(0.0, f64::max);
    let closest_off = off.iter().cloned().fold(f64::INFINITY, f64::min);
    eprintln!("mean |Δ| per byte: at the sidecar angle ≤ {worst:.2}, 20° off ≥ {closest_off:.2}");
    assert!(worst < 3.5 && closest_off > worst + 1.2, "at {at:?}\noff {off:?}");
    // The car needs the simulated camera; its paint and elevation need the car.
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--camera", "gst-test", "--car"])
        .arg(&cfg)
        .arg("-o")
        .arg(tmp.path().join("x.mp4"))
        .output()
        .unwrap();
    assert!(
        !o.status.success() && common::output_text(&o).contains("filmed by --camera sim only"),
        "{}",
        common::output_text(&o)
    );
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--camera", "sim", "--elevation", "20", "-o"])
        .arg(tmp.path().join("y.mp4"))
        .output()
        .unwrap();
    assert!(!o.status.success() && common::output_text(&o).contains("--car"), "{}", common::output_text(&o));
}

/// A simulated capture with its controls locked: each set before the turn and read back after,
/// both in run.toml; a value the camera refuses stops the capture before the table turns, naming
/// the control and the camera's range, or with `--allow-auto` is recorded as left automatic.
#[test]
fn capture_locks_the_cameras_controls_and_records_them() {
    let tmp = tempfile::tempdir().unwrap();
    let capture = |name: &str, extra: &[&str]| {
        let video = tmp.path().join(format!("{name}.mp4"));
        let o = sim_capture(&video, (160, 120), extra);
        (o.status.success(), common::output_text(&o), tmp.path().join(format!("{name}.run.toml")), video)
    };
    let (ok, out, record, _) = capture("locked", &["--exposure", "120", "--white-balance", "4000", "--focus", "30"]);
    assert!(ok, "{out}");
    assert!(out.contains("locked exposure at 120"), "{out}");
    let run = common::run_record(&record);
    for (k, v) in [("exposure", "120"), ("white_balance", "4000"), ("focus", "30")] {
        assert_eq!(run["settings"][format!("{k}_set")].as_str(), Some(v), "{run}");
        assert_eq!(run["result"][format!("{k}_read")].as_str(), Some(v), "{run}");
    }
    assert!(run["settings"].get("gain_set").is_none(), "gain was not asked for: {run}");

    // Off the camera's range: refused before the table turns, nothing recorded.
    let (ok, out, _, video) = capture("refused", &["--white-balance", "9000"]);
    assert!(
        !ok && out.contains("white_balance from 2800 to 6500 in steps of 10") && out.contains("--allow-auto"),
        "{out}"
    );
    assert!(!video.exists(), "no video for a refused control");
    // With --allow-auto: recorded as left automatic, the others locked.
    let (ok, out, record, _) = capture("auto", &["--white-balance", "9000", "--gain", "12", "--allow-auto"]);
    assert!(ok && out.contains("warning: left automatic"), "{out}");
    let run = common::run_record(&record);
    assert!(run["result"]["white_balance_warning"].as_str().unwrap().contains("not 9000"), "{run}");
    assert_eq!(run["result"]["white_balance_read"].as_str(), Some("none"), "{run}");
    assert_eq!(run["result"]["gain_read"].as_str(), Some("12"), "{run}");
    // Without controls asked for, the record says they were left automatic.
    let (ok, out, record, _) = capture("plain", &[]);
    assert!(ok && out.contains("left automatic"), "{out}");
    assert_eq!(common::run_record(&record)["settings"]["controls"].as_str(), Some("automatic"));
}

/// The rig's simulated automatic exposure, filmed by the simulated camera: `evaluate` flags the
/// drift it causes at full strength, with either detector, not at strength zero, and not once
/// the capture locks the exposure; the turntable fixture is steady.
#[test]
fn a_simulated_automatic_exposure_is_flagged_unless_the_exposure_is_locked() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let base = common::repo().join("configs/rig/fixture.toml");
    let drift = |name: &str, strength: f64, extra: &[&str]| {
        let rig = tmp.path().join(format!("{name}.toml"));
        std::fs::write(
            &rig,
            format!(
                "extends = {:?}\neffects = [\"codec\", \"auto-exposure\"]\n[camera]\nauto_exposure = {strength}\n",
                base.display().to_string()
            ),
        )
        .unwrap();
        let video = tmp.path().join(format!("{name}.mp4"));
        let rig = rig.display().to_string();
        let o = sim_capture(&video, (320, 180), &[&["--rig", rig.as_str()], extra].concat());
        assert!(o.status.success(), "{}", common::output_text(&o));
        evaluated(&video, &tmp.path().join(format!("{name}-eval")))
    };
    let (flag, luminance) = drift("auto", 1.0, &[]);
    assert!(flag && luminance > 0.05, "full strength: {luminance}");
    // The flag is the video's: another detector finds the car in other boxes, and the drift
    // stays to the last digit.
    let other = evaluated_by(&tmp.path().join("auto.mp4"), &tmp.path().join("auto-other"), "yolov3-tiny");
    assert_eq!(other, (flag, luminance), "the drift with another detector");
    let (flag, luminance) = drift("held", 0.0, &[]);
    assert!(!flag && luminance < 0.05, "strength zero: {luminance}");
    let (flag, luminance) = drift("locked", 1.0, &["--exposure", "166"]);
    assert!(!flag, "a locked exposure does not follow the car: {luminance}");
    let (flag, luminance) = evaluated(&common::repo().join("fixtures/turntable.mp4"), &tmp.path().join("fixture"));
    assert!(!flag, "the turntable fixture: {luminance}");
}

/// A ten-times-fast capture of the simulated table by the simulated camera into `video`, at
/// `size`, with `extra` arguments.
fn sim_capture(video: &std::path::Path, size: (usize, usize), extra: &[&str]) -> std::process::Output {
    pav_rig()
        .args(["capture", "--port", "sim", "--time-scale", "10", "--max-angle-error", "2", "--camera", "sim"])
        .args(["--width", &size.0.to_string(), "--height", &size.1.to_string(), "--codec", "mp4v"])
        .args(extra)
        .arg("-o")
        .arg(video)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap()
}

/// `evaluate`'s drift flag and luminance drift for `video` with YOLOX-Nano, as summary.csv has
/// them, the flag also marked in summary.md.
fn evaluated(video: &std::path::Path, out: &std::path::Path) -> (bool, f64) {
    evaluated_by(video, out, "yolox_nano")
}

/// [`evaluated`] with the shipped `detector`.
fn evaluated_by(video: &std::path::Path, out: &std::path::Path, detector: &str) -> (bool, f64) {
    let o = pav_rig()
        .arg("evaluate")
        .arg(video)
        .args(["-d", &common::detector_config(detector).display().to_string(), "--no-plots", "-o"])
        .arg(out)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let mut rd = csv::Reader::from_path(out.join("summary.csv")).unwrap();
    let head = rd.headers().unwrap().clone();
    let row = rd.records().next().unwrap().unwrap();
    let get = |k: &str| row[head.iter().position(|h| h == k).unwrap()].to_string();
    let flag = get("drift_flag") == "true";
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert_eq!(md.contains("⚠ drifted"), flag, "{md}");
    eprintln!("{}: luminance drift {}, flagged {flag}", video.display(), get("luminance_drift"));
    (flag, get("luminance_drift").parse().unwrap())
}

/// A reader that has gone (`pav-rig model check … | head -1`) ends either binary quietly with
/// 141, as SIGPIPE would, not with a panic: stdout's read end is closed before the command starts,
/// so its first line already meets the closed pipe.
#[test]
fn a_closed_stdout_ends_either_binary_quietly() {
    common::real_data();
    let detector = common::detector_config("yolox_nano").display().to_string();
    let runs: [(std::process::Command, &[&str]); 2] = [
        (pav_rig(), &["model", "check", "--config", &detector, "fixtures/turntable.mp4#0"]),
        (common::pav(), &["data", "list"]),
    ];
    for (mut cmd, args) in runs {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let o = cmd.args(args).stdout(writer).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(141), "{args:?}: {err}");
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
    }
}
