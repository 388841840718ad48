//! Helpers shared by the integration tests: where the real data and installed models are.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `../shared/data`; a test that needs it fails, saying where it must be, when it is absent (a
/// test that skipped would pass without having checked anything).
pub fn shared_data() -> PathBuf {
    let p = repo().join("../shared/data");
    assert!(
        p.join("MANIFEST.tsv").is_file(),
        "../shared/data (with its MANIFEST.tsv) is absent next to the repository at {}: this test needs the real \
         data there",
        p.display()
    );
    p
}

/// Panics with the fix when scripts/setup.sh has not installed ONNX Runtime and the models.
pub fn require_setup() {
    let deps = repo().join(".deps");
    for f in ["onnxruntime/libonnxruntime.so", "models/yolov3-tiny/yolov3-tiny.onnx"] {
        assert!(
            deps.join(f).exists() || std::env::var_os("ORT_DYLIB_PATH").is_some() && f.starts_with("onnx"),
            ".deps/{f} is missing: run scripts/setup.sh before the tests"
        );
    }
}

/// The shared data with the installed models; fails with the fix when either is missing.
pub fn real_data() -> PathBuf {
    let s = shared_data();
    require_setup();
    s
}

/// A detector config from configs/detectors.
pub fn detector_config(name: &str) -> PathBuf {
    repo().join("configs/detectors").join(format!("{name}.toml"))
}

/// Reads `derived_test_labels.tsv` as (npz path, column → value).
pub fn reference_labels(shared: &Path) -> Vec<(PathBuf, std::collections::HashMap<String, String>)> {
    let text = std::fs::read_to_string(shared.join("fca/carla_dataset/derived_test_labels.tsv")).expect("labels tsv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split('\t').collect();
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let cols: Vec<&str> = l.split('\t').collect();
            let map = header.iter().zip(&cols).map(|(h, c)| (h.to_string(), c.to_string())).collect();
            (shared.join("..").join(cols[0]), map)
        })
        .collect()
}

/// Frames `video` decodes to, read to the end; a decode error is an error.
pub fn decoded_frames(video: &Path) -> Result<usize, pav::video::VideoError> {
    let mut r = pav::video::VideoReader::open(video)?;
    let mut n = 0;
    while r.read()?.is_some() {
        n += 1;
    }
    Ok(n)
}
