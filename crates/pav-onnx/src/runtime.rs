//! ONNX Runtime, loaded once per process from a shared library, and session builders on it.

use crate::OnnxError;
use ort::session::builder::{GraphOptimizationLevel, SessionBuilder};
use ort::session::Session;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Where ONNX Runtime's shared library is looked for, in order: `ORT_DYLIB_PATH` alone when set,
/// else `.deps/onnxruntime/libonnxruntime.so` above the executable or the working directory.
pub fn library_candidates() -> Vec<PathBuf> {
    if let Some(p) = std::env::var_os("ORT_DYLIB_PATH") {
        return vec![PathBuf::from(p)];
    }
    let mut c = Vec::new();
    // A project's set-up puts the library in <repo>/.deps; look upward from the binary and the
    // working directory, so that tests, examples and installed binaries all find it.
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
    }
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().map(Path::to_path_buf));
    }
    for r in roots {
        let p = r.join(".deps/onnxruntime/libonnxruntime.so");
        if !c.contains(&p) {
            c.push(p);
        }
    }
    c
}

static ENV: OnceLock<Result<ort::environment::Environment, String>> = OnceLock::new();

/// Loads ONNX Runtime once per process; a missing or broken library is an error, never a panic.
pub fn runtime() -> Result<&'static ort::environment::Environment, OnnxError> {
    ENV.get_or_init(|| {
        let cands = library_candidates();
        let Some(lib) = cands.iter().find(|p| p.is_file()) else {
            return Err(format!(
                "ONNX Runtime library not found (looked for {}). Run scripts/setup.sh, or set ORT_DYLIB_PATH to libonnxruntime.so",
                cands.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
            ));
        };
        let builder = ort::init_from(lib).map_err(|e| format!("cannot load ONNX Runtime from {}: {e}", lib.display()))?;
        builder.with_name("pav").build().map_err(|e| format!("cannot start ONNX Runtime from {}: {e}", lib.display()))
    })
    .as_ref()
    .map_err(|e| OnnxError::Runtime(e.clone()))
}

/// The ONNX Runtime library file (symlinks followed: its name carries the version) and its
/// build string, once it loads; for provenance records.
pub fn runtime_version() -> Option<String> {
    runtime().ok()?;
    let lib = library_candidates().into_iter().find(|p| p.is_file())?;
    let file = std::fs::canonicalize(&lib).unwrap_or(lib);
    Some(format!("{} ({})", file.display(), ort::info()))
}

/// Wraps an ONNX Runtime error of model `name` while doing `what`.
pub fn session_err<'a, E: Into<ort::Error>>(name: &'a str, what: &'static str) -> impl Fn(E) -> OnnxError + 'a {
    move |e| OnnxError::Session { model: name.to_string(), what, source: e.into() }
}

/// A session builder for model `name`: every graph optimization, `threads` intra-op threads
/// (0 = the runtime's default).
pub fn session_builder(name: &str, threads: usize) -> Result<SessionBuilder, OnnxError> {
    let mut builder = Session::builder(runtime()?)
        .map_err(session_err(name, "creating a session"))?
        .with_optimization_level(GraphOptimizationLevel::All)
        .map_err(session_err(name, "setting the optimization level"))?;
    if threads > 0 {
        builder = builder.with_intra_threads(threads).map_err(session_err(name, "setting the thread count"))?;
    }
    Ok(builder)
}
