//! The data manifest (`data/manifest.tsv`, compiled in): one row per external file.

use super::DataError;
use std::sync::OnceLock;

const BUILTIN: &str = include_str!("../../../../data/manifest.tsv");

/// Where an entry comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Source {
    /// A file of a public GitHub repository at a fixed commit.
    GitHub {
        /// `owner/name`.
        repo: String,
        /// The commit, 40 hex digits.
        commit: String,
        /// The path inside the repository.
        path: String,
    },
    /// Made by this project and shipped with it (the path is the repository's).
    Shipped(String),
}

impl Source {
    /// The download address (GitHub's raw file service), none for a shipped file.
    pub fn url(&self) -> Option<String> {
        match self {
            Source::GitHub { repo, commit, path } => {
                Some(format!("https://raw.githubusercontent.com/{repo}/{commit}/{path}"))
            }
            Source::Shipped(_) => None,
        }
    }

    /// The bytes of a shipped file.
    pub fn shipped_bytes(&self) -> Option<&'static [u8]> {
        match self {
            Source::Shipped(p) if p == "data/shipped/fca/carla_dataset/derived_test_labels.tsv" => {
                Some(include_bytes!("../../../../data/shipped/fca/carla_dataset/derived_test_labels.tsv"))
            }
            _ => None,
        }
    }
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Source::GitHub { repo, commit, path } => write!(f, "github.com/{repo} @ {} : {path}", &commit[..12]),
            Source::Shipped(p) => write!(f, "pav ({p})"),
        }
    }
}

/// One external file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Entry {
    /// Its name, which is also its path under a data root.
    pub name: String,
    /// Size in bytes.
    pub bytes: u64,
    /// sha256, lower-case hex.
    pub sha256: String,
    /// Licence as the source states it ("unknown" where it states none).
    pub license: String,
    /// Where it comes from.
    pub source: Source,
    /// What it is.
    pub what: String,
}

/// Every entry, in the file's order.
#[derive(Clone, Debug)]
pub struct Manifest {
    /// The rows.
    pub entries: Vec<Entry>,
}

impl Manifest {
    /// The manifest pav was built with.
    pub fn builtin() -> &'static Manifest {
        static M: OnceLock<Manifest> = OnceLock::new();
        M.get_or_init(|| Manifest::parse(BUILTIN).expect("data/manifest.tsv is checked by the unit tests"))
    }

    /// Parses the tab-separated text: `#` comments, a header, then name, bytes, sha256,
    /// licence, source, description.
    pub fn parse(text: &str) -> Result<Manifest, DataError> {
        let mut entries: Vec<Entry> = Vec::new();
        let mut header = false;
        for (i, line) in text.lines().enumerate() {
            let err = |msg: String| DataError::Manifest { line: i + 1, msg };
            if line.starts_with('#') || line.trim().is_empty() {
                continue;
            }
            let cols: Vec<&str> = line.split('\t').collect();
            if !header {
                if cols[..] != ["name", "bytes", "sha256", "license", "source", "what"] {
                    return Err(err(format!("header {cols:?}")));
                }
                header = true;
                continue;
            }
            let [name, bytes, sha, license, source, what] = cols[..] else {
                return Err(err(format!("{} columns, not 6", cols.len())));
            };
            if name.starts_with('/') || name.split('/').any(|s| s == ".." || s.is_empty()) {
                return Err(err(format!("name `{name}` must be a relative path inside the data root")));
            }
            if sha.len() != 64 || !sha.bytes().all(|b| b.is_ascii_hexdigit() && !b.is_ascii_uppercase()) {
                return Err(err(format!("sha256 `{sha}`")));
            }
            let bytes = bytes.parse().map_err(|_| err(format!("bytes `{bytes}`")))?;
            let source = if let Some(p) = source.strip_prefix("pav:") {
                Source::Shipped(p.to_string())
            } else if let Some(rest) = source.strip_prefix("github:") {
                let (repo, rest) = rest.split_once('@').ok_or_else(|| err(format!("source `{source}`")))?;
                let (commit, path) = rest.split_once(':').ok_or_else(|| err(format!("source `{source}`")))?;
                if commit.len() != 40 {
                    return Err(err(format!("commit `{commit}`")));
                }
                Source::GitHub { repo: repo.into(), commit: commit.into(), path: path.into() }
            } else {
                return Err(err(format!("source `{source}`: github:OWNER/REPO@COMMIT:PATH or pav:PATH")));
            };
            if entries.iter().any(|e| e.name == name) {
                return Err(err(format!("`{name}` listed twice")));
            }
            entries.push(Entry {
                name: name.into(),
                bytes,
                sha256: sha.into(),
                license: license.into(),
                source,
                what: what.into(),
            });
        }
        Ok(Manifest { entries })
    }

    /// The entry called `name`.
    pub fn get(&self, name: &str) -> Result<&Entry, DataError> {
        self.entries.iter().find(|e| e.name == name).ok_or_else(|| DataError::Unknown { name: name.into() })
    }

    /// The entries `names` pick, each an entry's name or a folder of them (`fca/`); all of them
    /// when `names` is empty.
    pub fn select(&self, names: &[String]) -> Result<Vec<&Entry>, DataError> {
        if names.is_empty() {
            return Ok(self.entries.iter().collect());
        }
        let mut out: Vec<&Entry> = Vec::new();
        for n in names {
            let folder = format!("{}/", n.trim_end_matches('/'));
            let picked: Vec<&Entry> =
                self.entries.iter().filter(|e| e.name == *n || e.name.starts_with(&folder)).collect();
            if picked.is_empty() {
                return Err(DataError::Unknown { name: n.clone() });
            }
            for e in picked {
                if !out.iter().any(|o| o.name == e.name) {
                    out.push(e);
                }
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_manifest_parses_and_selects_folders() {
        let m = Manifest::parse(BUILTIN).unwrap();
        assert!(m.entries.len() >= 50, "{}", m.entries.len());
        assert_eq!(m.select(&["fca/carla_dataset/test".into()]).unwrap().len(), 10);
        assert!(m.select(&["fca/carla".into()]).is_err(), "a prefix that is not a folder");
    }

    #[test]
    fn malformed_rows_are_refused_with_their_line() {
        let head = "name\tbytes\tsha256\tlicense\tsource\twhat\n";
        let sha = "a".repeat(64);
        let ok = format!("x/y.bin\t3\t{sha}\tMIT\tgithub:o/r@{}:p/y.bin\tthing\n", "0".repeat(40));
        assert_eq!(Manifest::parse(&format!("{head}{ok}")).unwrap().entries.len(), 1);
        for (bad, needle) in [
            (ok.replace("x/y.bin\t", "../y.bin\t"), "relative path"),
            (ok.replace(&sha, "abc"), "sha256"),
            (ok.replace("\t3\t", "\tthree\t"), "bytes"),
            (ok.replace("github:", "ftp:"), "source"),
            (ok.replace("\tthing", ""), "5 columns"),
            (format!("{ok}{ok}"), "listed twice"),
        ] {
            let e = Manifest::parse(&format!("{head}{bad}")).unwrap_err().to_string();
            assert!(e.contains(needle) && e.contains("manifest line "), "{needle}: {e}");
        }
    }
}
