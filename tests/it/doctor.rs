//! `pav doctor` on this machine, and with each piece hidden in turn: ONNX Runtime, Blender and
//! ffmpeg, the data store. (The serial port's permission is the doctor crate's unit test: the
//! tests run as root, who may open any port.)

use crate::common::{self, pav};

/// `pav doctor` with `env` set (`None`: removed): its exit code and what it printed.
fn doctor(env: &[(&str, Option<&str>)]) -> (Option<i32>, String) {
    let mut c = pav();
    c.arg("doctor");
    for (k, v) in env {
        match v {
            Some(v) => c.env(k, v),
            None => c.env_remove(k),
        };
    }
    let o = c.output().unwrap();
    (o.status.code(), common::output_text(&o))
}

/// The line of `piece` (its status word first).
fn line<'a>(text: &'a str, piece: &str) -> &'a str {
    text.lines().find(|l| l.split_whitespace().skip(1).collect::<Vec<_>>().join(" ").starts_with(piece)).unwrap_or("")
}

#[test]
fn the_doctor_finds_every_piece_the_set_up_installs_and_names_each_hidden_one_with_its_fix() {
    common::real_data();
    let (code, text) = doctor(&[]);
    assert_eq!(code, Some(0), "{text}");
    for piece in ["ONNX Runtime", "OpenCV", "data store", "detectors", "ffmpeg", "Blender", "print profile"] {
        assert!(line(&text, piece).starts_with("ok "), "{piece}: {text}");
    }
    assert!(line(&text, "detectors").contains("4 load"), "{text}");
    assert!(line(&text, "Blender").contains("Blender 3.4") && line(&text, "Blender").contains("(Cycles,"), "{text}");
    assert!(text.contains("the main job can run"), "{text}");

    // No ONNX Runtime: the main job cannot run, and the fix says where the library goes.
    let (code, text) = doctor(&[("ORT_DYLIB_PATH", Some("/nonexistent/libonnxruntime.so"))]);
    assert_eq!(code, Some(1), "{text}");
    assert!(line(&text, "ONNX Runtime").starts_with("MISSING"), "{text}");
    assert!(text.contains("fix: run scripts/setup.sh, or set ORT_DYLIB_PATH"), "{text}");
    assert!(text.contains("the main job cannot run"), "{text}");

    // Neither Blender nor ffmpeg on the PATH: both named with the package that brings them, and
    // the main job still runs.
    let (code, text) = doctor(&[("PATH", Some("/nonexistent")), ("PAV_BLENDER", None)]);
    assert_eq!(code, Some(0), "{text}");
    assert!(line(&text, "Blender").starts_with("MISSING"), "{text}");
    assert!(line(&text, "ffmpeg").starts_with("MISSING"), "{text}");
    assert!(text.contains("fix: apt-get install blender") && text.contains("fix: apt-get install ffmpeg"), "{text}");

    // An empty data store: every file missing, the detectors' models with them.
    let empty = tempfile::tempdir().unwrap();
    let (code, text) = doctor(&[("PAV_DATA", Some(empty.path().to_str().unwrap()))]);
    assert_eq!(code, Some(1), "{text}");
    assert!(line(&text, "data store").starts_with("MISSING") && text.contains("fix: pav data fetch"), "{text}");
    assert!(line(&text, "detectors").starts_with("MISSING"), "{text}");
}
