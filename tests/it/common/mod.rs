//! Helpers shared by the integration tests: where the real data and installed models are.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

pub mod cli;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `pav` binary under test, run in the repository root with backtraces off (a test that
/// reads an error reads the message a user sees).
pub fn pav() -> std::process::Command {
    binary(env!("CARGO_BIN_EXE_pav"))
}

/// The `pav-rig` binary under test, as [`pav`] runs.
pub fn pav_rig() -> std::process::Command {
    binary(env!("CARGO_BIN_EXE_pav-rig"))
}

fn binary(path: &str) -> std::process::Command {
    let mut c = std::process::Command::new(path);
    c.current_dir(repo()).env("RUST_BACKTRACE", "0");
    c
}

/// pav's data store (`PAV_DATA`, else the XDG cache), checked against the manifest once per test
/// binary: a test that needs it fails, naming the missing files and the command that fetches
/// them (a test that skipped would pass without having checked anything).
pub fn shared_data() -> PathBuf {
    static CHECKED: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    let checked = CHECKED.get_or_init(|| {
        use pav::data::store::{EntryState, Store};
        let store = Store::from_env();
        let bad: Vec<String> = pav::data::manifest::Manifest::builtin()
            .entries
            .iter()
            .filter_map(|e| match store.state(e, false) {
                EntryState::Present => None,
                EntryState::Missing => Some(format!("{} (missing)", e.name)),
                EntryState::Corrupt(why) => Some(format!("{} ({why})", e.name)),
            })
            .collect();
        if bad.is_empty() {
            Ok(store.root)
        } else {
            Err(format!(
                "this test needs pav's data, and the store {} lacks {} of its files ({}{}). Fill it with \
                 `cargo run --release --bin pav -- data fetch --mirror ../shared/data` from a copy of the data, or \
                 `pav data fetch` to download; PAV_DATA picks another store",
                store.root.display(),
                bad.len(),
                bad.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
                if bad.len() > 3 { ", …" } else { "" }
            ))
        }
    });
    checked.clone().unwrap_or_else(|msg| panic!("{msg}"))
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

/// An image of the reference tables by its label: one of FCA's photos (`data1.npz`, the training
/// photo, or `data12501.npz` … `data12510.npz`) or frame K of a fixture video (`turntable.mp4#K`).
#[cfg(feature = "eval")]
pub fn reference_image(label: &str) -> pav::image::Frame {
    let spec = match label.split_once('#') {
        Some(_) => repo().join("fixtures").join(label),
        None => {
            let dir = if label == "data1.npz" { "train" } else { "test" };
            real_data().join("fca/carla_dataset").join(dir).join(label)
        }
    };
    pav::detect::check::read_input(&spec.display().to_string()).unwrap_or_else(|e| panic!("{e}"))
}

/// A finished command's stdout and stderr, one after the other, for assertions and messages.
pub fn output_text(o: &std::process::Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
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
            (shared.join(cols[0].strip_prefix("data/").unwrap_or(cols[0])), map)
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

/// Mean absolute difference per byte of two images of one size: how far a decoded frame is from
/// the one it should be.
pub fn mean_abs_diff(a: &[u8], b: &[u8]) -> f64 {
    assert_eq!(a.len(), b.len(), "images of different sizes");
    a.iter().zip(b).map(|(x, y)| (f64::from(*x) - f64::from(*y)).abs()).sum::<f64>() / a.len() as f64
}

/// Waits until a running capture's angle sidecar holds `rows` rows (it is flushed row by row):
/// progress to act on that does not depend on how busy the machine is. Panics after `limit`.
pub fn wait_for_sidecar_rows(sidecar: &Path, rows: usize, limit: std::time::Duration) {
    let start = std::time::Instant::now();
    loop {
        // A row still being written fails to parse: count none until it is whole.
        let have = pav::sidecar::read(sidecar).map_or(0, |rows| rows.len());
        if have >= rows {
            return;
        }
        assert!(start.elapsed() < limit, "{} holds {have} rows after {limit:?}, waited for {rows}", sidecar.display());
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Reads a `run.toml` and checks what every record holds: pav's version and commit, the command
/// line, the host. Returns it for the caller's own checks.
pub fn run_record(path: &Path) -> toml::Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let v: toml::Value = toml::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}\n{text}", path.display()));
    assert_eq!(v["pav_version"].as_str(), Some(env!("CARGO_PKG_VERSION")), "{text}");
    assert_eq!(v["git_commit"].as_str().map(str::len), Some(40), "{text}");
    assert!(v["command"].as_array().is_some_and(|c| c.len() > 1), "{text}");
    assert!(v["host"]["cpus"].as_str().is_some_and(|c| c != "0"), "{text}");
    v
}

/// The input of a run record whose path ends with `suffix`.
pub fn record_input<'a>(v: &'a toml::Value, suffix: &str) -> &'a toml::Value {
    v["inputs"]
        .as_array()
        .and_then(|a| a.iter().find(|i| i["path"].as_str().is_some_and(|p| p.ends_with(suffix))))
        .unwrap_or_else(|| panic!("no input ending in {suffix}: {v}"))
}

/// The derivative of Σ w·f(x) along `dir` by central differences of the graph's first output at
/// step `eps`, each output differenced before the weighted sum (which would otherwise cancel most
/// of f32's digits). `extrapolate`: also at 3·eps, and the two combined to cancel the error that
/// is first order in the step (where max-pool and SiLU kinks make it so).
#[cfg(feature = "eval")]
pub fn central_difference(
    g: &mut pav_onnx::session::GradSession,
    w: &[f32],
    x: &[f32],
    dir: &[f32],
    eps: f32,
    extrapolate: bool,
) -> f64 {
    let mut at = |s: f32| -> f64 {
        let step = |s: f32| x.iter().zip(dir).map(|(x, v)| x + s * v).collect::<Vec<_>>();
        let (a, _) = g.forward(step(s)).unwrap();
        let (b, _) = g.forward(step(-s)).unwrap();
        let d: f64 = a[0].iter().zip(&b[0]).zip(w).map(|((a, b), w)| (*a as f64 - *b as f64) * *w as f64).sum();
        d / (2.0 * s as f64)
    };
    let fd1 = at(eps);
    if extrapolate {
        (3.0 * fd1 - at(3.0 * eps)) / 2.0
    } else {
        fd1
    }
}

/// A direction that moves every input value by a different amount in (−3, 1]. The index arithmetic
/// wraps in i32 on purpose: the gradient tests were measured along exactly this direction (their
/// `7919·i` once overflowed an inferred i32 silently in release builds), and YOLOv8n's agreement
/// depends on it (see `tests/it/ortgrad_yolov8n.rs`).
pub fn whole_image_direction(n: usize) -> Vec<f32> {
    (0..n as i32).map(|i| (i.wrapping_mul(7919) % 101) as f32 / 50.0 - 1.0).collect()
}

/// A two-fold cross-validation of the tests into `out`, YOLOv3-tiny the white box (ASR at 0.5,
/// 16-texel random blocks), and YOLOv3-tiny loaded to score it.
#[cfg(feature = "optimize")]
pub fn two_folds(
    out: &Path,
    random_seeds: u64,
    references: Vec<(String, Vec<f32>)>,
    rendered: Vec<pav::attack::view::TrainView>,
) -> (pav::studies::crossval::CrossvalOptions, Vec<Box<dyn pav::detect::Detector>>) {
    let opts = pav::studies::crossval::CrossvalOptions {
        folds: 2,
        random_seeds,
        random_block: 16,
        out: out.into(),
        threshold: 0.5,
        white_box: vec!["yolov3-tiny".into()],
        references,
        rendered,
        curve: Default::default(),
        run: pav::studies::crossval::Folds::All,
    };
    (opts, pav::detect::load::load_detectors(&[detector_config("yolov3-tiny")], &[], &[], 1).unwrap())
}

/// A shipped rig made small: `width` pixels wide, `frames` a turn (a config in `dir` that
/// extends `configs/rig/NAME`).
pub fn small_rig(dir: &Path, name: &str, width: usize, frames: usize) -> PathBuf {
    let shipped = repo().join("configs/rig").join(name);
    let path = dir.join(name);
    let text = format!("extends = {:?}\n[render]\nwidth = {width}\nframes = {frames}\n", shipped.display().to_string());
    std::fs::write(&path, text).unwrap();
    path
}

/// The files under `dir` (recursively) whose names end in `.ext`, sorted.
pub fn files_with_extension(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())).flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == ext) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The documents under `root` a user reads: README.md and every Markdown file under docs/, sorted.
pub fn doc_files(root: &Path) -> Vec<PathBuf> {
    pav::results::documents(root)
}

/// `line` without its string and character literals and its `//` comment, so that only code's
/// braces are left.
pub fn code_of(line: &str) -> String {
    let (mut out, mut chars) = (String::new(), line.chars().peekable());
    while let Some(c) = chars.next() {
        match c {
            '/' if chars.peek() == Some(&'/') => break,
            '"' => {
                while let Some(s) = chars.next() {
                    match s {
                        '\\' => {
                            chars.next();
                        }
                        '"' => break,
                        _ => {}
                    }
                }
            }
            // A char literal ('{', '\''); a lifetime ('a) has no closing quote two places on.
            '\'' => {
                let rest: String = chars.clone().take(3).collect();
                if rest.starts_with('\\') {
                    chars.nth(2);
                } else if rest.chars().nth(1) == Some('\'') {
                    chars.nth(1);
                } else {
                    out.push(c);
                }
            }
            _ => out.push(c),
        }
    }
    out
}

/// Each function in `text` with a body, nested ones too: (name, first line, lines). Braces are
/// counted on [`code_of`]'s lines, so braces in literals and comments do not end a body.
pub fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let code = code_of(line);
        let words: Vec<&str> = code.split_whitespace().collect();
        let Some(at) = words.iter().position(|w| *w == "fn") else { continue };
        let qualifiers = ["pub", "pub(crate)", "pub(super)", "const", "async", "unsafe", "extern"];
        if !words[..at].iter().all(|w| qualifiers.contains(w)) || at + 1 >= words.len() {
            continue;
        }
        let name = words[at + 1].split(['(', '<']).next().unwrap_or("").to_string();
        let mut depth = 0i32;
        let mut opened = false;
        for (j, l) in lines.iter().enumerate().skip(i) {
            let c = code_of(l);
            if !opened && c.contains(';') && !c.contains('{') {
                break; // a declaration without a body
            }
            for ch in c.chars() {
                match ch {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    _ => {}
                }
            }
            if opened && depth <= 0 {
                out.push((name.clone(), i + 1, j - i + 1));
                break;
            }
        }
    }
    out
}
