//! Run provenance: a small `run.toml` in every output folder saying what made it (pav version
//! and commit, command line, config and its hash, the data files and models read with their
//! hashes, seeds, external tool versions), so results from two machines can be compared and a
//! figure can point to the run that made it.

use crate::data::manifest::Manifest;
use crate::data::store::{file_digest, Store};
use pav_core::path::tidy;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The file name written into output folders.
pub const FILE: &str = "run.toml";

/// One file (or folder) a run read.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Input {
    /// As given or resolved.
    pub path: String,
    /// The manifest entry it is, when it lies in the data store.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub data: Option<String>,
    /// Size in bytes (a folder: all its files).
    pub bytes: u64,
    /// sha256 of the file; of a folder, of its sorted `sha256  relative path` lines.
    pub sha256: String,
}

/// What made an output.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Run {
    /// pav's version.
    pub pav_version: String,
    /// The commit of the checkout pav was built from, as that checkout stands when the run
    /// starts ("unknown" outside one).
    pub git_commit: String,
    /// Whether that checkout had uncommitted changes to tracked files.
    pub git_dirty: bool,
    /// The command line.
    pub command: Vec<String>,
    /// The working directory.
    pub cwd: String,
    /// Start, seconds since the Unix epoch (UTC).
    pub started_unix_s: u64,
    /// Operating system, architecture and core count.
    pub host: BTreeMap<String, String>,
    /// Seeds and other settings worth comparing at a glance.
    pub settings: BTreeMap<String, String>,
    /// Versions of the external programs and libraries the run used.
    pub tools: BTreeMap<String, String>,
    /// The config, when there is one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config: Option<Input>,
    /// Every data file, model and input file read.
    pub inputs: Vec<Input>,
    /// Outcome figures added when the run ends (e.g. a capture's stated angle bound).
    pub result: BTreeMap<String, String>,
}

impl Run {
    /// Starts a record for the current process's command line.
    pub fn start() -> Run {
        let started_unix_s =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
        let (git_commit, git_dirty) = git_state();
        let host = BTreeMap::from([
            ("os".to_string(), std::env::consts::OS.to_string()),
            ("arch".to_string(), std::env::consts::ARCH.to_string()),
            ("cpus".to_string(), std::thread::available_parallelism().map(|n| n.get()).unwrap_or(0).to_string()),
        ]);
        Run {
            pav_version: env!("CARGO_PKG_VERSION").to_string(),
            git_commit,
            git_dirty,
            command: std::env::args().collect(),
            cwd: std::env::current_dir().map(|d| d.display().to_string()).unwrap_or_default(),
            started_unix_s,
            host,
            settings: BTreeMap::new(),
            tools: BTreeMap::new(),
            config: None,
            inputs: Vec::new(),
            result: BTreeMap::new(),
        }
    }

    /// Reads a record written by [`Run::write`].
    pub fn read(path: &Path) -> Result<Run, String> {
        let text = std::fs::read_to_string(path).map_err(|e| e.to_string())?;
        toml::from_str(&text).map_err(|e| format!("not a pav run record: {e}"))
    }

    /// Records the config file.
    pub fn config(mut self, path: &Path) -> Self {
        self.config = describe(path);
        self
    }

    /// Records files the run reads (each once; missing ones are skipped: the run reports them).
    pub fn inputs<'a>(mut self, paths: impl IntoIterator<Item = &'a Path>) -> Self {
        for p in paths {
            let shown = tidy(p).display().to_string();
            if !self.inputs.iter().any(|i| i.path == shown) {
                self.inputs.extend(describe(p));
            }
        }
        self
    }

    /// Records a setting (a seed, a threshold).
    pub fn setting(mut self, key: &str, value: impl ToString) -> Self {
        self.settings.insert(key.into(), value.to_string());
        self
    }

    /// Records a tool's version.
    pub fn tool(mut self, key: &str, version: Option<String>) -> Self {
        self.tools.insert(key.into(), version.unwrap_or_else(|| "not found".into()));
        self
    }

    /// Records an outcome figure.
    pub fn result(&mut self, key: &str, value: impl ToString) {
        self.result.insert(key.into(), value.to_string());
    }

    /// Records the process's peak resident memory so far as `peak_memory_mib`, where the
    /// system tells it (Linux's `VmHWM`): a job with a stated memory bound shows it kept it.
    pub fn peak_memory(&mut self) {
        if let Some(mib) = peak_memory_mib() {
            self.result("peak_memory_mib", format!("{mib:.0}"));
        }
    }

    /// Writes the record to `path` (a `run.toml` in a folder, or beside a file).
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        if let Some(d) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(d)?;
        }
        let text = toml::to_string(self).map_err(std::io::Error::other)?;
        pav_core::durable::write(path, format!("# What made this output (pav run provenance).\n{text}"))
    }
}

/// The config recorded in the `run.toml` of `dir` or of its parent (a crossval fold's texture
/// sits one folder below its run), resolved against the run's working directory; None when
/// there is none or it no longer exists.
pub fn recorded_config(dir: &Path) -> Option<PathBuf> {
    let run = [Some(dir), dir.parent()].into_iter().flatten().map(|d| d.join(FILE)).find(|p| p.exists())?;
    let v: toml::Value = toml::from_str(&std::fs::read_to_string(run).ok()?).ok()?;
    let path = Path::new(v.get("config")?.get("path")?.as_str()?);
    let full = Path::new(v.get("cwd")?.as_str()?).join(path);
    full.exists().then_some(full)
}

/// First line of `program args…`'s output (stdout, else stderr), when it runs.
pub fn tool_version(program: &str, args: &[&str]) -> Option<String> {
    let out = std::process::Command::new(program).args(args).output().ok()?;
    let text = if out.stdout.is_empty() { out.stderr } else { out.stdout };
    String::from_utf8_lossy(&text).lines().find(|l| !l.trim().is_empty()).map(|l| l.trim().to_string())
}

fn git_state() -> (String, bool) {
    git_state_in(Path::new("."))
}

/// What `git ARGS` run in `dir` prints, or why it failed (its error output).
pub fn git(dir: &Path, args: &[&str]) -> Result<Vec<u8>, String> {
    let o = std::process::Command::new("git").arg("-C").arg(dir).args(args).output().map_err(|e| e.to_string())?;
    if o.status.success() {
        Ok(o.stdout)
    } else {
        Err(String::from_utf8_lossy(&o.stderr).into_owned())
    }
}

/// The commit and dirty state of the pav checkout a command runs in (`cwd`), else of the one
/// this crate was built in. The build's own path alone is not enough: a build folder shared by
/// several checkouts keeps this crate as first compiled in any of them, that one's path baked in.
fn git_state_in(cwd: &Path) -> (String, bool) {
    let git =
        |dir: &Path, args: &[&str]| git(dir, args).ok().map(|out| String::from_utf8_lossy(&out).trim().to_string());
    let here = git(cwd, &["rev-parse", "--show-toplevel"])
        .map(PathBuf::from)
        .filter(|top| top.join("crates/pav-core/Cargo.toml").is_file());
    let dir = here.unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")));
    match git(&dir, &["rev-parse", "HEAD"]) {
        Some(c) => (c, git(&dir, &["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty())),
        None => ("unknown".into(), false),
    }
}

/// Size and hash of a file or folder, with its manifest name when it lies in the data store.
pub fn describe(path: &Path) -> Option<Input> {
    let (bytes, sha256) = if path.is_dir() {
        let mut files = Vec::new();
        walk(path, &mut files);
        files.sort();
        let mut listing = String::new();
        let mut total = 0;
        for f in &files {
            let (n, sha) = file_digest(f).ok()?;
            total += n;
            listing.push_str(&format!("{sha}  {}\n", f.strip_prefix(path).unwrap_or(f).display()));
        }
        (total, crate::data::store::sha256_hex(listing.as_bytes()))
    } else {
        file_digest(path).ok()?
    };
    let root = Store::from_env().root;
    let data = path
        .strip_prefix(&root)
        .ok()
        .map(|r| r.display().to_string())
        .filter(|name| Manifest::builtin().get(name).is_ok());
    Some(Input { path: tidy(path).display().to_string(), data, bytes, sha256 })
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            walk(&p, out);
        } else {
            out.push(p);
        }
    }
}

/// The process's peak resident memory so far, MiB (Linux's `VmHWM`; none elsewhere).
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_record_names_its_inputs_by_hash_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let (a, sub) = (dir.path().join("a.txt"), dir.path().join("views"));
        std::fs::write(&a, b"abc").unwrap();
        std::fs::create_dir_all(&sub).unwrap();
        std::fs::write(sub.join("1.png"), b"one").unwrap();
        let again = sub.join("..").join("a.txt");
        let mut run = Run::start().config(&a).inputs([a.as_path(), sub.as_path(), again.as_path()]).setting("seed", 7);
        run.result("angle_bound_deg", 0.12);
        let out = dir.path().join("out").join(FILE);
        run.write(&out).unwrap();
        let v: toml::Value = toml::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
        assert_eq!(v["config"]["sha256"].as_str().unwrap(), crate::data::store::sha256_hex(b"abc"));
        assert_eq!(v["inputs"].as_array().unwrap().len(), 2, "each input once");
        assert_eq!(v["inputs"][1]["bytes"].as_integer(), Some(3));
        assert_eq!(v["settings"]["seed"].as_str(), Some("7"));
        assert_eq!(v["result"]["angle_bound_deg"].as_str(), Some("0.12"));
        assert_eq!(v["git_commit"].as_str().unwrap().len(), 40, "built inside the repository");
    }

    /// A repository with one commit of `files`, and that commit.
    fn repo(dir: &Path, files: &[&str]) -> String {
        let git = |args: &[&str]| {
            let out = git(dir, &[&["-c", "user.name=t", "-c", "user.email=t@t"], args].concat()).unwrap();
            String::from_utf8_lossy(&out).trim().to_string()
        };
        git(&["init", "-q"]);
        for f in files {
            std::fs::create_dir_all(dir.join(f).parent().unwrap()).unwrap();
            std::fs::write(dir.join(f), "[package]\n").unwrap();
        }
        git(&["add", "."]);
        git(&["commit", "-q", "-m", "one"]);
        git(&["rev-parse", "HEAD"])
    }

    #[test]
    fn the_commit_is_the_pav_checkout_the_command_runs_in() {
        let own = git_state_in(Path::new(env!("CARGO_MANIFEST_DIR")));
        // Another pav checkout (it has crates/pav-core): its commit, and its dirty state.
        let tmp = tempfile::tempdir().unwrap();
        let head = repo(tmp.path(), &["crates/pav-core/Cargo.toml"]);
        assert_ne!(head, own.0);
        assert_eq!(git_state_in(tmp.path()), (head.clone(), false));
        assert_eq!(git_state_in(&tmp.path().join("crates")), (head.clone(), false), "from a subfolder");
        std::fs::write(tmp.path().join("crates/pav-core/Cargo.toml"), "[workspace]\n").unwrap();
        assert_eq!(git_state_in(tmp.path()), (head, true));
        // A repository that is not pav: the checkout this crate was built in.
        let other = tempfile::tempdir().unwrap();
        repo(other.path(), &["README"]);
        assert_eq!(git_state_in(other.path()).0, own.0);
    }
}
