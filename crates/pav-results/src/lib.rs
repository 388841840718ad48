//! Results as data: each headline table of the README and the reports lives in a small JSON file
//! under `results/`, with the command that made it, its commit and seeds, and the sha256 of
//! every config and data file the run read. The documents' tables are generated from those
//! files between markers (`<!-- results:NAME -->` … `<!-- /results:NAME -->`), so a number
//! enters the documents only through a run. A table whose inputs have changed since its run (a
//! TOML config in its values, not its comments) is marked stale, with the command that reruns it; one copied from an older document rather than
//! made by its command says so.

pub mod verdict;

use pav_core::path::tidy;
use pav_run::data::manifest::Manifest;
use pav_run::provenance::{Input, Run};
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
    /// What it read that pav made and the repository does not hold (rendered views under
    /// `out/`), with its sha256 then: kept so that runs on two machines can be compared input by
    /// input, but never checked, as a fresh clone has not made them yet.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub generated: BTreeMap<String, String>,
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
    /// `KEY=VALUE` when the CSV's long rows were turned wide (see [`Shape::pivot`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_pivot: Option<String>,
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
    /// A plot that could not be drawn.
    #[cfg(feature = "plot")]
    #[error(transparent)]
    Plot(#[from] pav_core::plot::PlotError),
    /// A file said to have moved that no longer holds what a results file recorded of it.
    #[error("results/{name}.json: {msg}")]
    Moved {
        /// The results file.
        name: String,
        /// What differs.
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
        pav_core::durable::write(&path, text).map_err(io(&path))?;
        Ok(path)
    }

    /// [`ResultFile::from_run`] of `first`, with the inputs of `rest` too: a table one script
    /// made from several runs. Each input is taken as the run that read it recorded it (a config
    /// by its values at that run's commit); where two runs read the same file, the first names it.
    pub fn from_runs(
        first: &Run,
        rest: &[Run],
        table: &Path,
        shape: &Shape,
        title: &str,
        root: &Path,
    ) -> Result<ResultFile, ResultsError> {
        let mut file = Self::from_run(first, table, shape, title, root)?;
        for run in rest {
            keep_inputs(run, root, &mut file.inputs, &mut file.generated);
        }
        Ok(file)
    }

    /// The table `title` of the CSV `table` written by the run recorded in `run` (its
    /// `run.toml`), shaped by `shape`, with the run's command, commit, seeds and inputs (paths
    /// made relative to `root`).
    pub fn from_run(
        run: &Run,
        table: &Path,
        shape: &Shape,
        title: &str,
        root: &Path,
    ) -> Result<ResultFile, ResultsError> {
        let parse = |e: csv::Error| ResultsError::Parse { path: table.into(), msg: e.to_string() };
        let mut rd = csv::Reader::from_path(table).map_err(parse)?;
        let head = rd.headers().map_err(parse)?.clone();
        let records: Vec<csv::StringRecord> = rd.records().collect::<Result<_, _>>().map_err(parse)?;
        let conditions = conditions(&shape.rows_where, &head, table)?;
        let kept = records.into_iter().filter(|r| conditions.iter().all(|(at, v)| r.get(*at) == Some(*v)));
        let (head, records) = match &shape.pivot {
            Some(p) => pivot(&head, kept, p, &shape.columns, table)?,
            None => (head.clone(), kept.collect()),
        };
        let picks: Vec<Column> =
            shape.columns.iter().map(|c| Column::parse(c, &head, table)).collect::<Result<_, _>>()?;
        let rows = records.iter().map(|r| picks.iter().map(|c| c.cell(r)).collect()).collect();
        let seeds =
            run.settings.get("seeds").or(run.settings.get("seed")).map_or(Vec::new(), |s| {
                s.split(|c: char| !c.is_ascii_digit()).filter_map(|v| v.parse().ok()).collect()
            });
        let (mut inputs, mut generated) = (BTreeMap::new(), BTreeMap::new());
        keep_inputs(run, root, &mut inputs, &mut generated);
        Ok(ResultFile {
            title: title.into(),
            command: shown_command(&run.command),
            commit: run.git_commit.chars().take(7).collect(),
            seeds,
            inputs,
            generated,
            transcribed: None,
            columns: picks.into_iter().map(|p| p.shown).collect(),
            from_columns: shape.columns.clone(),
            from_rows: shape.rows_where.clone(),
            from_pivot: shape.pivot.clone(),
            rows,
            note: None,
        })
    }

    /// The table's rows as points, grouped by the `spec.series` column's values in the order
    /// they first come (one group, named after y, without it). A row whose x or y is not a
    /// number ("n/a", text) is left out; a column not in the table is refused by name.
    pub fn points(&self, spec: &PlotSpec, name: &str) -> Result<Vec<(String, Vec<Point>)>, ResultsError> {
        let (head, file) = (csv::StringRecord::from(self.columns.clone()), Path::new(DIR).join(format!("{name}.json")));
        let at = |heading: &str| position(&head, heading, &file);
        let (x, y) = (at(&spec.x)?, at(&spec.y)?);
        let interval = spec.interval.as_deref().map(at).transpose()?;
        let series = spec.series.as_deref().map(at).transpose()?;
        let label = spec.label.as_deref().map(at).transpose()?;
        let conditions = conditions(&spec.rows_where, &head, &file)?;
        let mut out: Vec<(String, Vec<Point>)> = Vec::new();
        for row in self.rows.iter().filter(|r| conditions.iter().all(|(c, v)| r[*c] == *v)) {
            let (Some(px), Some(py)) = (cell_number(&row[x]), cell_number(&row[y])) else { continue };
            let group = series.map_or_else(|| spec.y.clone(), |s| row[s].clone());
            let point = Point {
                x: px,
                y: py,
                interval: interval.and_then(|i| cell_interval(&row[i])),
                label: label.map_or_else(String::new, |l| row[l].clone()),
            };
            match out.iter_mut().find(|(g, _)| *g == group) {
                Some((_, pts)) => pts.push(point),
                None => out.push((group, vec![point])),
            }
        }
        Ok(out)
    }

    /// Draws [`ResultFile::points`] as a PNG at `path`: each group a line of points with their
    /// intervals, titled with the table's title.
    #[cfg(feature = "plot")]
    pub fn plot(&self, spec: &PlotSpec, name: &str, log_x: bool, path: &Path) -> Result<(), ResultsError> {
        let series: Vec<pav_core::plot::IntervalSeries> = self
            .points(spec, name)?
            .into_iter()
            .map(|(name, pts)| pav_core::plot::IntervalSeries {
                name,
                points: pts
                    .into_iter()
                    .map(|p| pav_core::plot::IntervalPoint { x: p.x, y: p.y, interval: p.interval, label: p.label })
                    .collect(),
            })
            .collect();
        Ok(pav_core::plot::intervals(path, &self.title, (&spec.x, &spec.y), log_x, &series)?)
    }

    /// How this table was taken from its CSV, to take it again from a fresh run.
    pub fn shape(&self) -> Shape {
        Shape { columns: self.from_columns.clone(), rows_where: self.from_rows.clone(), pivot: self.from_pivot.clone() }
    }

    /// The inputs whose sha256 under `root` (or in the data manifest) is no longer the one the
    /// run read, each with what changed.
    pub fn stale(&self, root: &Path) -> Vec<String> {
        let manifest = Manifest::builtin();
        self.inputs
            .iter()
            .filter_map(|(key, sha)| match sha_now(manifest, root, key, sha) {
                Some(now) if &now == sha => None,
                Some(_) => Some(format!("{key} changed")),
                None => Some(format!("{key} is gone")),
            })
            .collect()
    }

    /// The Markdown block of this table as results file `name` under `root`: the table, its
    /// note, where it came from, and a stale or transcribed mark.
    pub fn render(&self, name: &str, root: &Path) -> String {
        // Numbers align right, as a reader compares them digit by digit.
        let align: String = (0..self.columns.len())
            .map(|c| {
                let mut cells = self.rows.iter().filter_map(|r| r.get(c)).filter(|v| !v.is_empty() && *v != "n/a");
                let numeric = |v: &String| {
                    v.trim_start_matches(['*', '[']).starts_with(|ch: char| ch.is_ascii_digit() || "+-−.".contains(ch))
                };
                if cells.clone().next().is_some() && cells.all(numeric) {
                    "---:|"
                } else {
                    "---|"
                }
            })
            .collect();
        let mut md = format!("| {} |\n|{align}\n", self.columns.join(" | "));
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

/// How a results table is taken from a run's CSV.
#[derive(Clone, Debug, Default)]
pub struct Shape {
    /// `HEADING[+HEADING|/HEADING][=SHOWN][:FORMAT]` each: one CSV column, two shown as an
    /// interval `a–b` (`+`) or as their ratio (`/`), under the heading SHOWN, formatted as `pct`
    /// (× 100, one decimal), with a number of decimals, or signed with `+` before that number
    /// (a difference; an interval of differences then reads `[−a, +b]`).
    pub columns: Vec<String>,
    /// Keep only the rows where every `HEADING=VALUE` holds (none: all).
    pub rows_where: Vec<String>,
    /// `KEY=VALUE`: long rows made wide, each distinct KEY becoming a column holding VALUE,
    /// one row per combination of the other columns the table shows; a cell met by several
    /// rows (repeated timings) keeps the smallest value.
    pub pivot: Option<String>,
}

/// Where `key` stands in `head`.
fn position(head: &csv::StringRecord, key: &str, table: &Path) -> Result<usize, ResultsError> {
    head.iter().position(|h| h == key).ok_or_else(|| ResultsError::Parse {
        path: table.into(),
        msg: format!("no column `{key}` (columns: {})", head.iter().collect::<Vec<_>>().join(", ")),
    })
}

/// `HEADING=VALUE` conditions on rows as (the heading's position in `head`, the value).
fn conditions<'a>(
    rows_where: &'a [String],
    head: &csv::StringRecord,
    table: &Path,
) -> Result<Vec<(usize, &'a str)>, ResultsError> {
    rows_where
        .iter()
        .map(|w| {
            let (k, v) = w.split_once('=').unwrap_or((w, ""));
            Ok((position(head, k, table)?, v))
        })
        .collect()
}

/// The rows `records` (under `head`) made wide by `spec` (`KEY=VALUE`), grouped by the other
/// columns that `columns` names, in the order they first appear.
fn pivot(
    head: &csv::StringRecord,
    records: impl Iterator<Item = csv::StringRecord>,
    spec: &str,
    columns: &[String],
    table: &Path,
) -> Result<(csv::StringRecord, Vec<csv::StringRecord>), ResultsError> {
    let bad = |msg: String| ResultsError::Parse { path: table.into(), msg };
    let (key, value) = spec.split_once('=').ok_or_else(|| bad(format!("a pivot is KEY=VALUE, not `{spec}`")))?;
    let (key, value) = (position(head, key, table)?, position(head, value, table)?);
    let named: Vec<&str> = columns.iter().flat_map(|c| Column::keys(c)).collect();
    let group: Vec<usize> = (0..head.len()).filter(|&i| i != key && i != value && named.contains(&&head[i])).collect();
    let mut wide: Vec<String> = Vec::new();
    let mut cells: Vec<(Vec<String>, BTreeMap<String, f64>)> = Vec::new();
    for r in records {
        let k = r.get(key).unwrap_or_default().to_string();
        let v: f64 = r.get(value).unwrap_or_default().parse().map_err(|_| {
            bad(format!(
                "`{}` is not a number in the pivot's column {}",
                r.get(value).unwrap_or_default(),
                &head[value]
            ))
        })?;
        if !wide.contains(&k) {
            wide.push(k.clone());
        }
        let id: Vec<String> = group.iter().map(|&g| r.get(g).unwrap_or_default().to_string()).collect();
        let at = match cells.iter().position(|(g, _)| *g == id) {
            Some(at) => at,
            None => {
                cells.push((id, BTreeMap::new()));
                cells.len() - 1
            }
        };
        let cell = cells[at].1.entry(k).or_insert(v);
        *cell = cell.min(v);
    }
    let mut new_head: csv::StringRecord = group.iter().map(|&g| &head[g]).collect();
    for w in &wide {
        new_head.push_field(w);
    }
    let rows = cells
        .into_iter()
        .map(|(id, vals)| {
            let mut r: csv::StringRecord = id.iter().collect();
            for w in &wide {
                r.push_field(&vals.get(w).map_or(String::new(), |v| v.to_string()));
            }
            r
        })
        .collect();
    Ok((new_head, rows))
}

/// Which columns of a results table [`ResultFile::points`] reads, by their shown headings.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlotSpec {
    /// The x axis.
    pub x: String,
    /// The y axis.
    pub y: String,
    /// The y values' intervals (`[a, b]` or `a–b` cells).
    pub interval: Option<String>,
    /// One line per distinct value of this column.
    pub series: Option<String>,
    /// A text beside each point.
    pub label: Option<String>,
    /// Only rows where HEADING has VALUE (`HEADING=VALUE`).
    pub rows_where: Vec<String>,
}

/// One row of a results table as a point.
#[derive(Clone, Debug, PartialEq)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// y's interval.
    pub interval: Option<(f64, f64)>,
    /// Its label.
    pub label: String,
}

/// A shown cell read back as a number: the true minus of a signed difference, a leading `+`,
/// and a trailing `%` or `×` are understood; None for text, "n/a" and intervals.
pub fn cell_number(cell: &str) -> Option<f64> {
    let t = cell.trim().replace('−', "-");
    let t = t.trim_end_matches(['%', '×']).trim();
    t.parse::<f64>().ok().filter(|v| v.is_finite())
}

/// A shown interval, `[a, b]` (signed ends) or `a–b`, read back as its ends.
pub fn cell_interval(cell: &str) -> Option<(f64, f64)> {
    let t = cell.trim();
    let (a, b) = match t.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        Some(inner) => inner.split_once(',')?,
        None => t.split_once('–')?,
    };
    Some((cell_number(a)?, cell_number(b)?))
}

/// A column of a results table taken from a CSV: its positions, heading and format.
struct Column {
    at: Vec<usize>,
    ratio: bool,
    shown: String,
    format: Option<String>,
}

impl Column {
    /// The spec split into its CSV headings and the rest (`=SHOWN`, `:FORMAT`).
    fn split(spec: &str) -> (&str, &str, Option<&str>) {
        let (rest, format) = match spec.rsplit_once(':') {
            Some((r, f)) if f == "pct" || f.trim_start_matches('+').parse::<usize>().is_ok() => (r, Some(f)),
            _ => (spec, None),
        };
        let (keys, shown) = rest.split_once('=').unwrap_or((rest, rest));
        (keys, shown, format)
    }

    /// The CSV headings a spec reads.
    fn keys(spec: &str) -> impl Iterator<Item = &str> {
        Column::split(spec).0.split(['+', '/'])
    }

    /// `HEADING[+HEADING|/HEADING][=SHOWN][:FORMAT]` against the CSV's `head`.
    fn parse(spec: &str, head: &csv::StringRecord, table: &Path) -> Result<Column, ResultsError> {
        let (keys, shown, format) = Column::split(spec);
        let at = Column::keys(spec).map(|k| position(head, k, table)).collect::<Result<Vec<_>, _>>()?;
        let ratio = keys.contains('/');
        if ratio && at.len() != 2 {
            return Err(ResultsError::Parse { path: table.into(), msg: format!("a ratio is A/B, not `{keys}`") });
        }
        Ok(Column { at, ratio, shown: shown.to_string(), format: format.map(str::to_string) })
    }

    /// Its cell in `row`: the values formatted, two of them as an interval or a ratio.
    fn cell(&self, row: &csv::StringRecord) -> String {
        let signed = self.format.as_deref().is_some_and(|f| f.starts_with('+'));
        let shown = |v: &str| match (self.format.as_deref(), v.parse::<f64>()) {
            (_, _) if v.is_empty() => "n/a".to_string(),
            (Some("pct"), Ok(x)) => format!("{:.1}", 100.0 * x),
            // A difference shows its sign, with a true minus.
            (Some(d), Ok(x)) if signed => format!("{x:+.*}", d[1..].parse().unwrap_or(3)).replace('-', "−"),
            (Some(d), Ok(x)) => format!("{x:.*}", d.parse().unwrap_or(3)),
            _ => v.to_string(),
        };
        let get = |at: usize| row.get(at).unwrap_or_default();
        if self.ratio {
            return match (get(self.at[0]).parse::<f64>(), get(self.at[1]).parse::<f64>()) {
                (Ok(a), Ok(b)) if b != 0.0 => shown(&(a / b).to_string()),
                _ => "n/a".to_string(),
            };
        }
        let cells: Vec<String> = self.at.iter().map(|&a| shown(get(a))).collect();
        match cells.as_slice() {
            // Signed ends would run into the dash: bracketed, as intervals of differences are.
            [lo, hi] if signed => format!("[{lo}, {hi}]"),
            _ => cells.join("–"),
        }
    }
}

/// Where pav writes what it makes (rendered views, runs): inputs there are recorded, not checked.
const GENERATED: &str = "out/";

/// The prefix of a TOML config's content hash (see [`content_sha`]).
const CONTENT: &str = "toml:";

/// For a TOML file, `toml:` and the sha256 of its values written out again: the same for any
/// comments and layout. None for anything else.
fn content_sha(path: &Path) -> Option<String> {
    if path.extension().is_none_or(|e| e != "toml") {
        return None;
    }
    table_sha(&toml::from_str(&std::fs::read_to_string(path).ok()?).ok()?)
}

/// Adds the inputs of `run` that `inputs` and `generated` do not name yet, keyed by path under
/// `root` (files under `out/` into `generated`), each with the sha256 a table keeps for it.
fn keep_inputs(
    run: &Run,
    root: &Path,
    inputs: &mut BTreeMap<String, String>,
    generated: &mut BTreeMap<String, String>,
) {
    for i in run.config.iter().chain(&run.inputs) {
        let key = input_key(i, root);
        if inputs.contains_key(&key) || generated.contains_key(&key) {
            continue;
        }
        if key.starts_with(GENERATED) {
            generated.insert(key, i.sha256.clone());
            continue;
        }
        // A config is kept by its content, so that a comment edited later does not make the
        // table stale: its content now when it is still as the run read it, else its content
        // at the run's commit when that commit holds what the run read.
        let sha = match content_sha(&root.join(&key)) {
            Some(c) if pav_run::provenance::describe(&root.join(&key)).is_some_and(|now| now.sha256 == i.sha256) => c,
            _ => content_sha_at(root, &run.git_commit, &key, &i.sha256).unwrap_or_else(|| i.sha256.clone()),
        };
        inputs.insert(key, sha);
    }
}

/// The content sha of TOML config `key` as the repository at `root` holds it at `commit`, when
/// those are the bytes whose sha256 a run recorded (`read`); None otherwise, and outside git.
fn content_sha_at(root: &Path, commit: &str, key: &str, read: &str) -> Option<String> {
    if !key.ends_with(".toml") {
        return None;
    }
    let shown = pav_run::provenance::git(root, &["show", &format!("{commit}:./{key}")]).ok()?;
    if pav_run::data::store::sha256_hex(&shown) != read {
        return None;
    }
    table_sha(&toml::from_str(std::str::from_utf8(&shown).ok()?).ok()?)
}

/// Config keys no table's numbers depend on, left out of a config's content hash: setting
/// them marks nothing stale. `mesh.front` names the car's front for the printed pieces' panel
/// names, arrows and placement views; no count, score or size reads it.
const NOT_IN_RESULTS: &[[&str; 2]] = &[["mesh", "front"]];

/// `toml:` and the sha256 of `table`'s values written out, less [`NOT_IN_RESULTS`].
fn table_sha(table: &toml::Table) -> Option<String> {
    let mut table = table.clone();
    for [section, key] in NOT_IN_RESULTS {
        if let Some(toml::Value::Table(t)) = table.get_mut(*section) {
            t.remove(*key);
        }
    }
    Some(format!("{CONTENT}{}", pav_run::data::store::sha256_hex(toml::to_string(&table).ok()?.as_bytes())))
}

/// The sha256 of input `key` (a path under `root`, or `data:NAME` in `manifest`) now, taken the
/// way `recorded` was: a TOML config's by its values when `recorded` is, else the file's bytes.
fn sha_now(manifest: &Manifest, root: &Path, key: &str, recorded: &str) -> Option<String> {
    match key.strip_prefix("data:") {
        Some(name) => manifest.get(name).ok().map(|e| e.sha256.clone()),
        None if recorded.starts_with(CONTENT) => content_sha(&root.join(key)),
        None => pav_run::provenance::describe(&root.join(key)).map(|i| i.sha256),
    }
}

/// The path from the folder `from` to `to`, both relative to one root, as `extends` writes it.
fn relative(from: &Path, to: &Path) -> PathBuf {
    let (from, to) = (tidy(from), tidy(to));
    let common = from.components().zip(to.components()).take_while(|(a, b)| a == b).count();
    let mut out: PathBuf = from.components().skip(common).map(|_| "..").collect();
    out.extend(to.components().skip(common));
    out
}

/// The values of the TOML config `key` (under `root`) when it `extends` the file `path`.
fn extends(root: &Path, key: &str, path: &str) -> Option<toml::Table> {
    let table: toml::Table = toml::from_str(&std::fs::read_to_string(root.join(key)).ok()?).ok()?;
    let dir = Path::new(key).parent().unwrap_or(Path::new(""));
    let target = table.get("extends")?.as_str()?;
    (tidy(&dir.join(target)) == tidy(Path::new(path))).then_some(table)
}

/// The recorded sha256 of the TOML config `key` (under `root`) if it now `extends` `new` where
/// the run read it extending `old`: its values with `extends` pointed back at `old`.
fn extending_old(root: &Path, key: &str, old: &str, new: &str) -> Option<String> {
    let mut table = extends(root, key, new)?;
    let dir = Path::new(key).parent().unwrap_or(Path::new(""));
    table.insert("extends".into(), relative(dir, Path::new(old)).display().to_string().into());
    table_sha(&table)
}

impl ResultFile {
    /// This table made to name `new` (a path relative to `root`) wherever it named `old`: a file
    /// moved without a change to what the run read. An input `old` becomes `new` when `new` now
    /// has the sha256 recorded for `old`; a config whose one change is that it now `extends`
    /// `new` instead of `old` is recorded as it is now; the path is replaced in the command,
    /// title, note and cells, where it names the file that ran (also in a transcribed table,
    /// which records no inputs). Returns what changed (nothing: the table never named `old`);
    /// refuses, naming the table, when `new` is not what `old` was or a config the run read
    /// still extends `old`.
    pub fn moved(&mut self, root: &Path, name: &str, old: &str, new: &str) -> Result<Vec<String>, ResultsError> {
        let mut changed = Vec::new();
        if let Some(sha) = self.inputs.get(old).cloned() {
            let manifest = Manifest::builtin();
            let refuse = |msg: String| ResultsError::Moved { name: name.into(), msg };
            match sha_now(manifest, root, new, &sha) {
                Some(now) if now == sha => {}
                None if !root.join(new).exists() => return Err(refuse(format!("{new} is not there"))),
                // Another file, or one that no longer parses as the config it was.
                _ => return Err(refuse(format!("{new} is not {old} as its run read it"))),
            }
            // A config still extending `old` reads whatever `old` holds now, not what its run read.
            if let Some(key) = self.inputs.keys().find(|k| extends(root, k, old).is_some()) {
                return Err(refuse(format!("{key} still extends {old}: point it at {new} first")));
            }
            changed.push(format!("{old} → {new}"));
            self.inputs.remove(old);
            self.inputs.insert(new.into(), sha);
            for (key, sha) in self.inputs.iter_mut() {
                match sha_now(manifest, root, key, sha) {
                    Some(now) if now != *sha && extending_old(root, key, old, new).as_ref() == Some(sha) => {
                        *sha = now;
                        changed.push(format!("{key} extends {new}"));
                    }
                    _ => {}
                }
            }
        }
        // A table copied from an older report records no inputs but may still name the file.
        let texts = [&mut self.command, &mut self.title].into_iter().chain(self.note.as_mut());
        let mut named = false;
        for text in texts.chain(self.rows.iter_mut().flatten()) {
            if text.contains(old) {
                *text = text.replace(old, new);
                named = true;
            }
        }
        if named {
            changed.push(format!("the text names {new}"));
        }
        Ok(changed)
    }
}

/// [`ResultFile::moved`] for every results file under `root`, each rewritten where it changed:
/// the names of those changed, with what changed. Nothing is written unless every file can move.
pub fn moved(root: &Path, old: &str, new: &str) -> Result<Vec<(String, Vec<String>)>, ResultsError> {
    let dir = root.join(DIR);
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .map_err(io(&dir))?
        .flatten()
        .filter_map(|e| e.file_name().to_str()?.strip_suffix(".json").map(str::to_string))
        .collect();
    names.sort();
    let mut files = Vec::new();
    for name in names {
        let mut file = ResultFile::load(root, &name)?;
        let changed = file.moved(root, &name, old, new)?;
        if !changed.is_empty() {
            files.push((name, file, changed));
        }
    }
    files
        .into_iter()
        .map(|(name, file, changed)| {
            file.save(root, &name)?;
            Ok((name, changed))
        })
        .collect()
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

/// Where the next `<!-- KIND:` marker (`open`) that begins a line starts in `text` (a marker
/// quoted inside a line is text, not a marker).
fn next_marker(text: &str, open: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(k) = text[from..].find(open) {
        let at = from + k;
        if at == 0 || text.as_bytes()[at - 1] == b'\n' {
            return Some(at);
        }
        from = at + open.len();
    }
    None
}

/// `text` with the body of every `kind` block regenerated: between `<!-- KIND:SPEC -->` and
/// `<!-- /KIND:NAME -->`, each on a line of its own (NAME is the spec's first word), the text
/// `body(spec)` gives. Results tables and verdicts are both such blocks.
fn regenerate_blocks(
    text: &str,
    kind: &str,
    doc: &str,
    body: impl Fn(&str) -> Result<String, String>,
) -> Result<String, ResultsError> {
    let bad = |msg: String| ResultsError::Marker { doc: doc.into(), msg };
    let (open, close) = (format!("<!-- {kind}:"), format!("<!-- /{kind}:"));
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = next_marker(rest, &open) {
        let after = &rest[at + open.len()..];
        let end = after.find("-->").ok_or_else(|| bad(format!("an unclosed `{open}` marker")))?;
        let spec = after[..end].trim();
        let name = spec.split_whitespace().next().unwrap_or("");
        let closing = format!("\n{close}{name} -->");
        let body_start = at + open.len() + end + 3;
        let close_at = 1
            + body_start
            + rest[body_start..]
                .find(&closing)
                .ok_or_else(|| bad(format!("`{open}{spec} -->` has no `{}` on a line of its own", closing.trim())))?;
        out.push_str(&rest[..body_start]);
        out.push('\n');
        out.push_str(&body(spec).map_err(bad)?);
        rest = &rest[close_at..];
    }
    out.push_str(rest);
    Ok(out)
}

/// Whether `text` holds a block of any kind [`generate`] regenerates.
fn has_blocks(text: &str) -> bool {
    ["results", verdict::KIND].iter().any(|k| next_marker(text, &format!("<!-- {k}:")).is_some())
}

/// `text` with every results block (markers on lines of their own) and every verdict
/// ([`verdict`]) regenerated from `root`'s results files.
pub fn generate(text: &str, doc: &str, root: &Path) -> Result<String, ResultsError> {
    let tables = regenerate_blocks(text, "results", doc, |name| {
        let file = ResultFile::load(root, name).map_err(|e| e.to_string())?;
        Ok(file.render(name, root))
    })?;
    regenerate_blocks(&tables, verdict::KIND, doc, |spec| verdict::block(spec, root))
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
        if !has_blocks(&text) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_format_intervals_ratios_and_signed_differences() {
        let head = csv::StringRecord::from(vec!["d", "lo", "hi", "a", "b"]);
        let row = csv::StringRecord::from(vec!["-0.0044", "-0.0116", "0.0028", "3", "4"]);
        let cell = |spec: &str| Column::parse(spec, &head, Path::new("t.csv")).unwrap().cell(&row);
        assert_eq!(cell("d:+3"), "−0.004");
        assert_eq!(cell("lo+hi:+3"), "[−0.012, +0.003]");
        assert_eq!(cell("lo+hi:3"), "-0.012–0.003");
        assert_eq!(cell("a/b=ratio:2"), "0.75");
        assert_eq!(cell("a:pct"), "300.0");
        assert!(Column::parse("a/b/d", &head, Path::new("t.csv")).is_err());
        let e = Column::parse("nope", &head, Path::new("t.csv")).err().unwrap().to_string();
        assert!(e.contains("no column `nope`") && e.contains("d, lo, hi, a, b"), "{e}");
    }

    #[test]
    fn a_configs_hash_ignores_the_mesh_front_and_nothing_else() {
        let t = |s: &str| table_sha(&toml::from_str(s).unwrap()).unwrap();
        let base = "[mesh]\nobj = \"a.obj\"\ntexture_size = 256\n";
        assert_eq!(t(base), t(&format!("{base}front = \"+x\"\n")));
        assert_ne!(t(base), t(&format!("{base}up = \"+y\"\n")));
        assert_ne!(t(base), t("[mesh]\nobj = \"a.obj\"\ntexture_size = 512\n"));
    }

    #[test]
    fn paths_between_configs_are_written_as_extends_writes_them() {
        assert_eq!(tidy(Path::new("configs/studies/../optimize/./a.toml")), Path::new("configs/optimize/a.toml"));
        let rel = |from: &str, to: &str| relative(Path::new(from), Path::new(to)).display().to_string();
        assert_eq!(rel("configs/studies/lofo", "configs/optimize/recommended.toml"), "../../optimize/recommended.toml");
        assert_eq!(rel("configs/optimize", "configs/optimize/small.toml"), "small.toml");
        assert_eq!(rel("configs/studies/../optimize", "configs/a.toml"), "../a.toml");
    }

    #[test]
    fn shown_cells_read_back_as_the_numbers_they_show() {
        assert_eq!(cell_number("−0.004"), Some(-0.004));
        assert_eq!(cell_number("+0.017"), Some(0.017));
        assert_eq!(cell_number("24.5 %"), Some(24.5));
        assert_eq!(cell_number("0.80×"), Some(0.8));
        for text in ["n/a", "yolox_nano", "[−0.012, +0.003]", "", "NaN"] {
            assert_eq!(cell_number(text), None, "{text}");
        }
        assert_eq!(cell_interval("[−0.012, +0.003]"), Some((-0.012, 0.003)));
        assert_eq!(cell_interval("−0.5–1.5"), Some((-0.5, 1.5)));
        assert_eq!(cell_interval("0.3"), None);
    }

    #[test]
    fn rows_become_points_grouped_by_series_in_the_order_they_come() {
        let cells = |r: &[&str]| r.iter().map(|c| c.to_string()).collect::<Vec<_>>();
        let file = ResultFile {
            title: "t".into(),
            command: "c".into(),
            commit: "0".into(),
            seeds: vec![],
            inputs: BTreeMap::new(),
            generated: BTreeMap::new(),
            transcribed: None,
            columns: cells(&["level", "s/view", "family", "against", "difference", "interval"]),
            from_columns: vec![],
            from_rows: vec![],
            from_pivot: None,
            rows: vec![
                cells(&["c64", "14.1", "yolox", "rauca", "−0.010", "[−0.020, +0.001]"]),
                cells(&["c4", "1.2", "yolox", "rauca", "+0.004", "[−0.006, +0.013]"]),
                cells(&["c4", "1.2", "nanodet", "rauca", "+0.020", "[+0.010, +0.031]"]),
                cells(&["c4", "1.2", "nanodet", "random", "−0.030", "[−0.040, −0.020]"]),
                cells(&["c16", "n/a", "nanodet", "rauca", "+0.011", "[+0.001, +0.021]"]),
            ],
            note: None,
        };
        let spec = PlotSpec {
            x: "s/view".into(),
            y: "difference".into(),
            interval: Some("interval".into()),
            series: Some("family".into()),
            label: Some("level".into()),
            rows_where: vec!["against=rauca".into()],
        };
        let groups = file.points(&spec, "t").unwrap();
        let names: Vec<&str> = groups.iter().map(|(g, _)| g.as_str()).collect();
        assert_eq!(names, ["yolox", "nanodet"]);
        // The random row is filtered out, and the row without a cost has no x to stand at.
        assert_eq!(groups[1].1, [Point { x: 1.2, y: 0.02, interval: Some((0.01, 0.031)), label: "c4".into() }]);
        assert_eq!(groups[0].1.iter().map(|p| p.x).collect::<Vec<_>>(), [14.1, 1.2]);
        let bad = PlotSpec { series: Some("famliy".into()), ..spec };
        let e = file.points(&bad, "t").unwrap_err().to_string();
        assert!(e.contains("no column `famliy`") && e.contains("results/t.json"), "{e}");
    }
}
