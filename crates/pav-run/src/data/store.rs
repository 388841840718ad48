//! The local data store: a folder holding manifest entries under their names, filled by
//! [`Store::fetch`] from upstream, a mirror folder or a mirror URL, and only ever with verified
//! bytes.

use super::manifest::{Entry, Manifest};
use super::DataError;
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// The environment variable naming the store's folder.
pub const ENV_ROOT: &str = "PAV_DATA";
/// The environment variable naming a mirror (a folder or an http(s) URL) `pav data fetch` uses
/// when given none.
pub const ENV_MIRROR: &str = "PAV_DATA_MIRROR";

/// sha256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn hex(d: &[u8]) -> String {
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// Size and sha256 of a file.
pub fn file_digest(path: &Path) -> std::io::Result<(u64, String)> {
    let mut f = std::fs::File::open(path)?;
    let (mut h, mut n, mut buf) = (Sha256::new(), 0u64, vec![0u8; 1 << 16]);
    loop {
        let k = f.read(&mut buf)?;
        if k == 0 {
            return Ok((n, hex(&h.finalize())));
        }
        h.update(&buf[..k]);
        n += k as u64;
    }
}

/// What the store holds of one entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EntryState {
    /// The file is there with the manifest's size (and hash, when checked).
    Present,
    /// No file.
    Missing,
    /// A file that is not the manifest's.
    Corrupt(String),
}

/// Where `fetch` takes files from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Origin {
    /// Each entry's own public source.
    Upstream,
    /// A folder laid out like the store (`../shared/data` is one).
    Dir(PathBuf),
    /// A URL under which each entry's name is a file (http or https).
    Url(String),
}

impl Origin {
    /// A mirror given on the command line: a URL when it starts with http:// or https://,
    /// otherwise a folder.
    pub fn mirror(s: &str) -> Origin {
        if s.starts_with("http://") || s.starts_with("https://") {
            Origin::Url(s.trim_end_matches('/').to_string())
        } else {
            Origin::Dir(PathBuf::from(s))
        }
    }
}

impl std::fmt::Display for Origin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Origin::Upstream => write!(f, "upstream"),
            Origin::Dir(d) => write!(f, "{}", d.display()),
            Origin::Url(u) => write!(f, "{u}"),
        }
    }
}

/// What `fetch` did with one entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fetched {
    /// The store already held it, verified.
    Kept,
    /// Written, verified.
    Written,
}

/// A data store at a folder.
#[derive(Clone, Debug)]
pub struct Store {
    /// Its folder.
    pub root: PathBuf,
}

impl Store {
    /// The store at `PAV_DATA`, else `$XDG_CACHE_HOME/pav/data`, else `~/.cache/pav/data`.
    pub fn from_env() -> Store {
        let var = |k: &str| std::env::var_os(k).filter(|v| !v.is_empty()).map(PathBuf::from);
        let root = var(ENV_ROOT)
            .or_else(|| var("XDG_CACHE_HOME").map(|c| c.join("pav/data")))
            .or_else(|| var("HOME").map(|h| h.join(".cache/pav/data")))
            .unwrap_or_else(|| PathBuf::from(".pav-data"));
        Store { root }
    }

    /// Where entry `name` lives.
    pub fn path(&self, name: &str) -> PathBuf {
        self.root.join(name)
    }

    /// The file of the built-in manifest's entry `name`, when the store holds it at its size.
    pub fn require(&self, name: &str) -> Result<PathBuf, DataError> {
        let e = Manifest::builtin().get(name)?;
        match self.state(e, false) {
            EntryState::Present => Ok(self.path(name)),
            EntryState::Missing => Err(DataError::Missing { name: name.into(), root: self.root.clone() }),
            EntryState::Corrupt(why) => Err(DataError::Damaged { name: name.into(), root: self.root.clone(), why }),
        }
    }

    /// The state of `e`; `hash` reads the whole file to compare its sha256 as well.
    pub fn state(&self, e: &Entry, hash: bool) -> EntryState {
        let p = self.path(&e.name);
        let Ok(meta) = std::fs::metadata(&p) else { return EntryState::Missing };
        if meta.len() != e.bytes {
            return EntryState::Corrupt(format!("{} bytes, not {}", meta.len(), e.bytes));
        }
        if hash {
            match file_digest(&p) {
                Ok((_, sha)) if sha == e.sha256 => {}
                Ok((_, sha)) => {
                    return EntryState::Corrupt(format!("sha256 {}…, not {}…", &sha[..12], &e.sha256[..12]))
                }
                Err(err) => return EntryState::Corrupt(format!("unreadable: {err}")),
            }
        }
        EntryState::Present
    }

    /// Makes the store hold `e`: kept when it already does (hash checked), otherwise taken from
    /// `origin` (a shipped entry from pav itself) into a partial file, verified, and only then
    /// moved into place; bytes that are not the manifest's are refused and left nowhere.
    pub fn fetch(&self, e: &Entry, origin: &Origin) -> Result<Fetched, DataError> {
        if self.state(e, true) == EntryState::Present {
            return Ok(Fetched::Kept);
        }
        let io = |what: String| move |source| DataError::Io { name: e.name.clone(), what, source };
        let dest = self.path(&e.name);
        let dir = dest.parent().unwrap_or(&self.root).to_path_buf();
        std::fs::create_dir_all(&dir).map_err(io(format!("creating {}", dir.display())))?;
        let part = dir.join(format!(
            ".{}.part-{}",
            dest.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
            std::process::id()
        ));
        let result = self.fill(e, origin, &part).and_then(|described| {
            let (n, sha) = file_digest(&part).map_err(io(format!("reading {}", part.display())))?;
            if n != e.bytes || sha != e.sha256 {
                return Err(DataError::Mismatch {
                    name: e.name.clone(),
                    origin: described,
                    got: format!("{n} bytes, sha256 {sha}"),
                    want: format!("{} bytes, sha256 {}", e.bytes, e.sha256),
                });
            }
            std::fs::rename(&part, &dest).map_err(io(format!("moving into {}", dest.display())))
        });
        if result.is_err() {
            let _ = std::fs::remove_file(&part);
        }
        result.map(|_| Fetched::Written)
    }

    /// Fetches every entry of `entries` (one failure does not stop the rest) and says how each
    /// went, in order.
    pub fn fetch_all<'a>(
        &self,
        entries: &[&'a Entry],
        origin: &Origin,
        progress: &dyn pav_core::progress::Progress,
    ) -> Vec<(&'a Entry, Result<Fetched, DataError>)> {
        progress.begin("fetch", entries.len() as u64);
        let out = entries
            .iter()
            .map(|e| {
                progress.status(&e.name);
                let r = self.fetch(e, origin);
                if let Err(err) = &r {
                    progress.note(&err.to_string());
                }
                progress.advance(1);
                (*e, r)
            })
            .collect();
        progress.end(None);
        out
    }

    /// Writes `e`'s bytes from `origin` to `part`; returns where they came from, for messages.
    fn fill(&self, e: &Entry, origin: &Origin, part: &Path) -> Result<String, DataError> {
        let io = |what: String| move |source| DataError::Io { name: e.name.clone(), what, source };
        if let Some(bytes) = e.source.shipped_bytes() {
            let mut f = std::fs::File::create(part).map_err(io(format!("creating {}", part.display())))?;
            f.write_all(bytes).map_err(io(format!("writing {}", part.display())))?;
            return Ok("pav's own copy".into());
        }
        match origin {
            Origin::Dir(d) => {
                let src = d.join(&e.name);
                std::fs::copy(&src, part).map_err(io(format!("copying {}", src.display())))?;
                Ok(src.display().to_string())
            }
            Origin::Url(base) => {
                let url = format!("{base}/{}", e.name);
                download(&e.name, &url, part)?;
                Ok(url)
            }
            Origin::Upstream => {
                let url = e.source.url().expect("only shipped entries have no URL");
                download(&e.name, &url, part)?;
                Ok(url)
            }
        }
    }
}

/// Downloads `url` to `part` with curl (redirects, proxies and TLS as the system has them).
fn download(name: &str, url: &str, part: &Path) -> Result<(), DataError> {
    let fail = |msg: String| DataError::Download { name: name.into(), url: url.into(), msg };
    let out = std::process::Command::new("curl")
        .args(["--fail", "--silent", "--show-error", "--location", "--retry", "2", "--connect-timeout", "20", "-o"])
        .arg(part)
        .arg(url)
        .output()
        .map_err(|e| fail(format!("curl could not be started ({e}): install curl, or fetch with --mirror DIR")))?;
    if !out.status.success() {
        return Err(fail(String::from_utf8_lossy(&out.stderr).trim().to_string()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::manifest::Source;
    use super::*;

    fn entry(name: &str, bytes: &[u8]) -> Entry {
        Entry {
            name: name.into(),
            bytes: bytes.len() as u64,
            sha256: sha256_hex(bytes),
            license: "MIT".into(),
            source: Source::GitHub { repo: "o/r".into(), commit: "0".repeat(40), path: name.into() },
            what: "test".into(),
        }
    }

    #[test]
    fn shipped_files_are_compiled_in_and_match_the_manifest() {
        for e in &Manifest::builtin().entries {
            if let Source::Shipped(p) = &e.source {
                let b = e.source.shipped_bytes().unwrap_or_else(|| panic!("{p} is not compiled in"));
                assert_eq!(b.len() as u64, e.bytes, "{p}");
                assert_eq!(sha256_hex(b), e.sha256, "{p}");
            }
        }
    }

    #[test]
    fn sha256_of_a_known_text() {
        // FIPS 180-2 example.
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }

    #[test]
    fn a_mirror_folder_fills_the_store_and_a_wrong_file_is_refused_and_never_lands() {
        let (mirror, root) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        std::fs::create_dir_all(mirror.path().join("a")).unwrap();
        std::fs::write(mirror.path().join("a/good.bin"), b"good bytes").unwrap();
        std::fs::write(mirror.path().join("a/bad.bin"), b"Bad bytes").unwrap();
        let store = Store { root: root.path().to_path_buf() };
        let origin = Origin::Dir(mirror.path().to_path_buf());
        let (good, bad) = (entry("a/good.bin", b"good bytes"), entry("a/bad.bin", b"bad bytes"));
        assert_eq!(store.state(&good, true), EntryState::Missing);
        assert_eq!(store.fetch(&good, &origin).unwrap(), Fetched::Written);
        assert_eq!(store.fetch(&good, &origin).unwrap(), Fetched::Kept);
        let e = store.fetch(&bad, &origin).unwrap_err().to_string();
        assert!(e.contains("refused"), "{e}");
        assert_eq!(store.state(&bad, true), EntryState::Missing);
        assert_eq!(std::fs::read_dir(root.path().join("a")).unwrap().count(), 1, "no partial file left");
        // Damage in place: same size, other bytes; only the hash check sees it.
        std::fs::write(store.path("a/good.bin"), b"gooD bytes").unwrap();
        assert_eq!(store.state(&good, false), EntryState::Present);
        assert!(matches!(store.state(&good, true), EntryState::Corrupt(_)));
        assert_eq!(store.fetch(&good, &origin).unwrap(), Fetched::Written);
        assert_eq!(std::fs::read(store.path("a/good.bin")).unwrap(), b"good bytes");
    }
}
