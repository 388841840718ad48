//! Results as data: each headline table of the README and the reports lives in a small JSON file
//! under `results/`, with the command that made it, its commit and seeds, and the sha256 of
//! every config and data file the run read. The documents' tables are generated from those
//! files between markers (`<!-- results:NAME -->` … `<!-- /results:NAME -->`), so a number
//! enters the documents only through a run. A table whose inputs have changed since its run (a
//! TOML config in its values, not its comments) is marked stale, with the command that reruns it; one copied from an older document rather than
//! made by its command says so.

use crate::data::manifest::Manifest;
use crate::provenance::{Input, Run};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The folder of results files, from the repository root.
pub const DIR: &str = "results";

/// One headline table and where it came from.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResultFile {
    /// What the table answers.
    pub title: String,
    /// The command that made it, as it ran.
    pub command: String,
    /// The commit it ran at.
    pub commit: String,
    /// The seeds it averaged over (none: no seed).
    #[serde(default)]
    pub seeds: Vec<u64>,
    /// Every config and data file it read, by path (repository-relative) or data store entry
    /// (`data:NAME`), with its sha256 then.
    pub inputs: BTreeMap<String, String>,
    /// Set when the numbers were copied from an older document, not made by the command here.
    #[serde(default)]
    pub transcribed: Option<Transcribed>,
    /// Column headings.
    pub columns: Vec<String>,
    /// The columns as taken from the run's CSV (see [`ResultFile::from_run`]), so that a fresh
    /// run can be compared cell by cell.
    #[serde(default)]
    pub from_columns: Vec<String>,
    /// The rows of the run's CSV the table keeps, as `HEADING=VALUE` conditions (none: all).
    #[serde(default)]
    pub from_rows: Vec<String>,
    /// Rows of cells, as the table shows them (intervals included).
    pub rows: Vec<Vec<String>>,
    /// A sentence printed under the table.
    #[serde(default)]
    pub note: Option<String>,
}

/// Where transcribed numbers were copied from.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Transcribed {
    /// The document they were copied from.
    pub from: String,
    /// The commit of the run that made them.
    pub commit: String,
}

/// Why results could not be read, written or generated.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A results file that is not one.
    #[error("{path}: {msg}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        msg: String,
    },
    /// A marker without its end, or naming no results file.
    #[error("{doc}: {msg}")]
    Marker {
        /// The document.
        doc: String,
        /// What is wrong.
        msg: String,
    },
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> ResultsError + '_ {
    move |source| ResultsError::Io { path: path.into(), source }
}

impl ResultFile {
    /// Reads `results/NAME.json` under `root`.
    pub fn load(root: &Path, name: &str) -> Result<ResultFile, ResultsError> {
        let path = root.join(DIR).join(format!("{name}.json"));
        let text = std::fs::read_to_string(&path).map_err(io(&path))?;
        serde_json::from_str(&text).map_err(|e| ResultsError::Parse { path, msg: e.to_string() })
    }

    /// Writes it as `results/NAME.json` under `root`.
    pub fn save(&self, root: &Path, name: &str) -> Result<PathBuf, ResultsError> {
        let dir = root.join(DIR);
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        let path = dir.join(format!("{name}.json"));
        let text = serde_json::to_string_pretty(self).expect("a results file serializes") + "\n";
        std::fs::write(&path, text).map_err(io(&path))?;
        Ok(path)
    }

    /// The table `title` of the CSV `table` written by the run recorded in `run` (its
    /// `run.toml`), with the run's command, commit, seeds and inputs (paths made relative to
    /// `root`), keeping the rows that meet every `HEADING=VALUE` of `rows_where`. Each of
    /// `columns` is `HEADING[+HEADING][=SHOWN][:FORMAT]`: one CSV column, or two
    /// shown as an interval `a–b`, under the heading SHOWN, formatted as `pct` (× 100, one
    /// decimal) or with a number of decimals.
    pub fn from_run(
        run: &Run,
        table: &Path,
        columns: &[String],
        rows_where: &[String],
        title: &str,
        root: &Path,
    ) -> Result<ResultFile, ResultsError> {
        let mut rd = csv::Reader::from_path(table)
            .map_err(|e| ResultsError::Parse { path: table.into(), msg: e.to_string() })?;
        let head = rd.headers().map_err(|e| ResultsError::Parse { path: table.into(), msg: e.to_string() })?.clone();
        let picks: Vec<Column> = columns.iter().map(|c| Column::parse(c, &head, table)).collect::<Result<_, _>>()?;
        let conditions: Vec<(usize, &str)> = rows_where
            .iter()
            .map(|w| {
                let (k, v) = w.split_once('=').unwrap_or((w, ""));
                let c = Column::parse(k, &head, table)?;
                Ok((c.at[0], v))
            })
            .collect::<Result<_, ResultsError>>()?;
        let mut rows = Vec::new();
        for r in rd.records() {
            let r = r.map_err(|e| ResultsError::Parse { path: table.into(), msg: e.to_string() })?;
            if conditions.iter().all(|(at, v)| r.get(*at) == Some(*v)) {
                rows.push(picks.iter().map(|c| c.cell(&r)).collect());
            }
        }
        let seeds =
            run.settings.get("seeds").or(run.settings.get("seed")).map_or(Vec::new(), |s| {
                s.split(|c: char| !c.is_ascii_digit()).filter_map(|v| v.parse().ok()).collect()
            });
        let mut inputs = BTreeMap::new();
        for i in run.config.iter().chain(&run.inputs) {
            let key = input_key(i, root);
            // A config still as the run read it is kept by its content, so that a comment
            // edited later does not make the table stale.
            let sha = match content_sha(&root.join(&key)) {
                Some(c) if crate::provenance::describe(&root.join(&key)).is_some_and(|now| now.sha256 == i.sha256) => c,
                _ => i.sha256.clone(),
            };
            inputs.insert(key, sha);
        }
        Ok(ResultFile {
            title: title.into(),
            command: shown_command(&run.command),
            commit: run.git_commit.chars().take(7).collect(),
            seeds,
            inputs,
            transcribed: None,
            columns: picks.into_iter().map(|p| p.shown).collect(),
            from_columns: columns.to_vec(),
            from_rows: rows_where.to_vec(),
            rows,
            note: None,
        })
    }

    /// The inputs whose sha256 under `root` (or in the data manifest) is no longer the one the
    /// run read, each with what changed.
    pub fn stale(&self, root: &Path) -> Vec<String> {
        let manifest = Manifest::builtin();
        self.inputs
            .iter()
            .filter_map(|(key, sha)| {
                let now = match key.strip_prefix("data:") {
                    Some(name) => manifest.get(name).ok().map(|e| e.sha256.clone()),
                    None if sha.starts_with(CONTENT) => content_sha(&root.join(key)),
                    None => crate::provenance::describe(&root.join(key)).map(|i| i.sha256),
                };
                match now {
                    Some(now) if &now == sha => None,
                    Some(_) => Some(format!("{key} changed")),
                    None => Some(format!("{key} is gone")),
                }
            })
            .collect()
    }

    /// The Markdown block of this table as results file `name` under `root`: the table, its
    /// note, where it came from, and a stale or transcribed mark.
    pub fn render(&self, name: &str, root: &Path) -> String {
        let mut md = format!("| {} |\n|{}\n", self.columns.join(" | "), "---|".repeat(self.columns.len()));
        for r in &self.rows {
            md.push_str(&format!("| {} |\n", r.join(" | ")));
        }
        md.push('\n');
        if let Some(n) = &self.note {
            md.push_str(&format!("{n}\n\n"));
        }
        let seeds = match self.seeds.as_slice() {
            [] => String::new(),
            s => format!(", seeds {}", s.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")),
        };
        match &self.transcribed {
            Some(t) => md.push_str(&format!(
                "*Transcribed from {} (run at commit {}), not regenerated: `results/{name}.json`; rerun with `{}`.*\n",
                t.from, t.commit, self.command
            )),
            None => md.push_str(&format!(
                "*Made by `{}` at commit {}{seeds}: `results/{name}.json`.*\n",
                self.command, self.commit
            )),
        }
        let stale = self.stale(root);
        if !stale.is_empty() {
            md.push_str(&format!(
                "\n**Stale since commit {}**: {}. Rerun `{}` and record it again.\n",
                self.commit,
                stale.join(", "),
                self.command
            ));
        }
        md
    }
}

/// A column of a results table taken from a CSV: its positions, heading and format.
struct Column {
    at: Vec<usize>,
    shown: String,
    format: Option<String>,
}

impl Column {
    /// `HEADING[+HEADING][=SHOWN][:FORMAT]` against the CSV's `head`.
    fn parse(spec: &str, head: &csv::StringRecord, table: &Path) -> Result<Column, ResultsError> {
        let (rest, format) = match spec.rsplit_once(':') {
            Some((r, f)) if f == "pct" || f.parse::<usize>().is_ok() => (r, Some(f.to_string())),
            _ => (spec, None),
        };
        let (keys, shown) = rest.split_once('=').unwrap_or((rest, rest));
        let at = keys
            .split('+')
            .map(|k| {
                head.iter().position(|h| h == k).ok_or_else(|| ResultsError::Parse {
                    path: table.into(),
                    msg: format!("no column `{k}` (columns: {})", head.iter().collect::<Vec<_>>().join(", ")),
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(Column { at, shown: shown.to_string(), format })
    }

    /// Its cell in `row`: the values formatted, two of them as an interval.
    fn cell(&self, row: &csv::StringRecord) -> String {
        let one = |at: usize| {
            let v = row.get(at).unwrap_or_default();
            match (self.format.as_deref(), v.parse::<f64>()) {
                (_, _) if v.is_empty() => "n/a".to_string(),
                (Some("pct"), Ok(x)) => format!("{:.1}", 100.0 * x),
                (Some(d), Ok(x)) => format!("{x:.*}", d.parse().unwrap_or(3)),
                _ => v.to_string(),
            }
        };
        self.at.iter().map(|&a| one(a)).collect::<Vec<_>>().join("–")
    }
}

/// The prefix of a TOML config's content hash (see [`content_sha`]).
const CONTENT: &str = "toml:";

/// For a TOML file, `toml:` and the sha256 of its values written out again: the same for any
/// comments and layout. None for anything else.
fn content_sha(path: &Path) -> Option<String> {
    if path.extension().is_none_or(|e| e != "toml") {
        return None;
    }
    let table: toml::Table = toml::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    Some(format!("{CONTENT}{}", crate::data::store::sha256_hex(toml::to_string(&table).ok()?.as_bytes())))
}

/// An input as a results file names it: a data store entry as `data:NAME`, a file inside
/// `root` by its relative path.
fn input_key(i: &Input, root: &Path) -> String {
    if let Some(d) = &i.data {
        return format!("data:{d}");
    }
    let p = Path::new(&i.path);
    let root = root.canonicalize().unwrap_or_else(|_| root.into());
    let abs = if p.is_absolute() { p.to_path_buf() } else { std::env::current_dir().unwrap_or_default().join(p) };
    let abs = abs.canonicalize().unwrap_or(abs);
    abs.strip_prefix(&root).map(|r| r.display().to_string()).unwrap_or_else(|_| i.path.clone())
}

/// A recorded command as a user types it: the binary by its name.
fn shown_command(words: &[String]) -> String {
    let mut w: Vec<String> = words.to_vec();
    if let Some(first) = w.first_mut() {
        *first = Path::new(first.as_str()).file_name().map_or(first.clone(), |n| n.to_string_lossy().into_owned());
    }
    w.join(" ")
}

const OPEN: &str = "<!-- results:";
const CLOSE: &str = "<!-- /results:";

/// Where the next marker that begins a line starts in `text` (a marker quoted inside a line is
/// text, not a marker).
fn next_marker(text: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(k) = text[from..].find(OPEN) {
        let at = from + k;
        if at == 0 || text.as_bytes()[at - 1] == b'\n' {
            return Some(at);
        }
        from = at + OPEN.len();
    }
    None
}

/// `text` with every results block (markers on lines of their own) regenerated from `root`'s
/// results files.
pub fn generate(text: &str, doc: &str, root: &Path) -> Result<String, ResultsError> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = next_marker(rest) {
        let after = &rest[at + OPEN.len()..];
        let end = after
            .find("-->")
            .ok_or_else(|| ResultsError::Marker { doc: doc.into(), msg: "an unclosed marker".into() })?;
        let name = after[..end].trim().to_string();
        let close = format!("\n{CLOSE}{name} -->");
        let body_start = at + OPEN.len() + end + 3;
        let close_at =
            1 + rest[body_start..].find(&close).ok_or_else(|| ResultsError::Marker {
                doc: doc.into(),
                msg: format!("`{OPEN}{name} -->` has no `{}` on a line of its own", close.trim()),
            })? + body_start;
        let file =
            ResultFile::load(root, &name).map_err(|e| ResultsError::Marker { doc: doc.into(), msg: e.to_string() })?;
        out.push_str(&rest[..body_start]);
        out.push('\n');
        out.push_str(&file.render(&name, root));
        rest = &rest[close_at..];
    }
    out.push_str(rest);
    Ok(out)
}

/// The documents under `root` a user reads, where results blocks may stand: README.md, then every
/// Markdown file under docs/, sorted.
pub fn documents(root: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![root.join("docs")];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else { continue };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out.insert(0, root.join("README.md"));
    out
}

/// Each document under `root` whose results blocks differ from what [`generate`] writes now,
/// with the regenerated text; with `write`, the documents are rewritten.
pub fn regenerate(root: &Path, write: bool) -> Result<Vec<(PathBuf, String)>, ResultsError> {
    let mut changed = Vec::new();
    for p in documents(root) {
        let text = std::fs::read_to_string(&p).map_err(io(&p))?;
        if next_marker(&text).is_none() {
            continue;
        }
        let doc = p.strip_prefix(root).unwrap_or(&p).display().to_string();
        let new = generate(&text, &doc, root)?;
        if new != text {
            if write {
                std::fs::write(&p, &new).map_err(io(&p))?;
            }
            changed.push((p, new));
        }
    }
    Ok(changed)
}
