//! `pav results`.

use anyhow::{bail, Context, Result};
use pav::provenance::Run;
#[cfg(feature = "plot")]
use pav::results::PlotSpec;
use pav::results::{moved, regenerate, ResultFile, Shape};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Record a headline table from a finished run as results/NAME.json: columns of a CSV it
    /// wrote, with the command, commit, seeds and input hashes of its run.toml.
    #[command(after_help = "Examples:
  pav results add main-job --run out/evaluate --table summary.csv --columns video,detector,a_physical --title \"A_physical of the bundled clip\"")]
    Add(Box<AddArgs>),
    /// Regenerate every results block in README.md and docs/ from results/.
    #[command(after_help = "Examples:
  pav results write")]
    Write,
    /// Draw a results table as a PNG: one column against another, one line per value of a
    /// third, each point with its interval, so that a figure shows the recorded numbers only.
    #[cfg(feature = "plot")]
    #[command(after_help = "Examples:
  pav results plot load-test --x test --y failures -o out/load-test.png")]
    Plot(PlotArgs),
    /// Record that a config or data file moved from OLD to NEW without a change to what the runs
    /// read (NEW's values are OLD's as recorded), so that the tables that read it stay fresh: each
    /// results file naming OLD is made to name NEW, and a config that now extends NEW instead of
    /// OLD is taken as unchanged. Then `pav results write`.
    #[command(after_help = "Examples:
  pav results moved fixtures/old.mp4 fixtures/turntable.mp4")]
    Moved {
        /// The path the runs read, relative to the repository root.
        old: String,
        /// Where that file is now.
        new: String,
    },
    /// Fail, naming each document whose results blocks differ from what `pav results write`
    /// makes now (a number edited by hand, a table gone stale).
    #[command(after_help = "Examples:
  pav results check")]
    Check,
}

/// `pav results add`.
#[derive(clap::Args)]
pub struct AddArgs {
    /// The table's name (its file is results/NAME.json; a document shows it between
    /// `<!-- results:NAME -->` and `<!-- /results:NAME -->`).
    name: String,
    /// The run's output folder (holding its run.toml) or the run.toml itself. Repeatable, for a
    /// table a script made from several runs (give `--command`): the table keeps every run's
    /// inputs, and the first run's commit and seeds.
    #[arg(long, required_unless_present = "bench")]
    run: Vec<PathBuf>,
    /// Instead of a run: the benchmark command that wrote `--table` (a CSV committed under
    /// bench/, which becomes the table's input, so that rewriting it marks the table stale).
    #[arg(long, conflicts_with = "run")]
    bench: Option<String>,
    /// The command a reader reruns, when it is not the run's own (a script that made the run
    /// among others).
    #[arg(long, conflicts_with = "bench")]
    command: Option<String>,
    /// The CSV the run wrote, whose rows the table shows.
    #[arg(long)]
    table: PathBuf,
    /// Columns: `HEADING[+HEADING|/HEADING][=SHOWN][:FORMAT]` (two headings make an interval
    /// `a–b` or a ratio; FORMAT `pct`, a number of decimals, or `+` and one for a signed
    /// difference), comma-separated.
    #[arg(long, value_delimiter = ',', required = true)]
    columns: Vec<String>,
    /// Keep only the CSV's rows where HEADING has VALUE (`HEADING=VALUE`, comma-separated).
    #[arg(long = "where", value_delimiter = ',')]
    rows_where: Vec<String>,
    /// `KEY=VALUE`: each distinct KEY becomes a column holding VALUE (the smallest, where
    /// rows repeat, as for repeated timings).
    #[arg(long)]
    pivot: Option<String>,
    /// What the table answers.
    #[arg(long)]
    title: String,
    /// A sentence printed under the table.
    #[arg(long)]
    note: Option<String>,
}

/// `pav results plot`.
#[cfg(feature = "plot")]
#[derive(clap::Args)]
pub struct PlotArgs {
    /// The table's name (results/NAME.json).
    name: String,
    /// The column on the x axis (as the table heads it).
    #[arg(long)]
    x: String,
    /// The column on the y axis.
    #[arg(long)]
    y: String,
    /// The column holding y's intervals (`[a, b]` or `a–b`), drawn as whiskers.
    #[arg(long)]
    interval: Option<String>,
    /// One line per distinct value of this column.
    #[arg(long)]
    series: Option<String>,
    /// A text beside each point, from this column.
    #[arg(long)]
    label: Option<String>,
    /// Keep only rows where HEADING has VALUE (`HEADING=VALUE`, comma-separated).
    #[arg(long = "where", value_delimiter = ',')]
    rows_where: Vec<String>,
    /// A logarithmic x axis (for costs that span decades).
    #[arg(long)]
    log_x: bool,
    /// The PNG to write.
    #[arg(long, short = 'o')]
    out: PathBuf,
}

pub fn run(c: &Cmd) -> Result<()> {
    let root = PathBuf::from(".");
    match c {
        Cmd::Add(a) => {
            let AddArgs { name, run, bench, command, table, columns, rows_where, pivot, title, note } = a.as_ref();
            let mut others = Vec::new();
            let r = match (run.as_slice(), bench) {
                ([_, _, ..], _) if command.is_none() => {
                    bail!("a table from several runs needs --command: the script a reader reruns to make them all")
                }
                ([first, rest @ ..], _) => {
                    let r = read_run(first)?;
                    for other in rest {
                        let o = read_run(other)?;
                        if o.git_commit != r.git_commit {
                            eprintln!(
                                "warning: {} ran at commit {:.7}, the table records the first run's {:.7}",
                                other.display(),
                                o.git_commit,
                                r.git_commit
                            );
                        }
                        others.push(o);
                    }
                    r
                }
                ([], Some(cmd)) => {
                    let mut r = Run::start().inputs([table.as_path()]);
                    r.command = vec![cmd.clone()];
                    if let Some(c) = last_commit(table) {
                        r.git_commit = c;
                    }
                    r
                }
                ([], None) => bail!("give --run or --bench"),
            };
            let shape = Shape { columns: columns.clone(), rows_where: rows_where.clone(), pivot: pivot.clone() };
            let mut file = ResultFile::from_runs(&r, &others, table, &shape, title, &root)?;
            if let Some(cmd) = bench.as_ref().or(command.as_ref()) {
                file.command = cmd.clone();
            }
            file.note = note.clone();
            let path = file.save(&root, name)?;
            outln!("wrote {} ({} rows); `pav results write` puts it in the documents", path.display(), file.rows.len());
        }
        Cmd::Write => {
            for (p, _) in regenerate(&root, true)? {
                outln!("regenerated {}", p.display());
            }
        }
        #[cfg(feature = "plot")]
        Cmd::Plot(a) => {
            let file = ResultFile::load(&root, &a.name)?;
            let spec = PlotSpec {
                x: a.x.clone(),
                y: a.y.clone(),
                interval: a.interval.clone(),
                series: a.series.clone(),
                label: a.label.clone(),
                rows_where: a.rows_where.clone(),
            };
            file.plot(&spec, &a.name, a.log_x, &a.out)?;
            outln!("wrote {}", a.out.display());
        }
        Cmd::Moved { old, new } => {
            let changed = moved(&root, old, new)?;
            if changed.is_empty() {
                bail!("no results file read {old}");
            }
            for (name, what) in changed {
                outln!("results/{name}.json: {}", what.join("; "));
            }
            outln!("`pav results write` puts the new paths in the documents");
        }
        Cmd::Check => {
            let stale = regenerate(&root, false)?;
            if !stale.is_empty() {
                let names: Vec<String> = stale.iter().map(|(p, _)| p.display().to_string()).collect();
                bail!("results blocks differ from results/ in {}: run `pav results write`", names.join(", "));
            }
            outln!("every results block matches results/");
        }
    }
    Ok(())
}

/// The record of a run: its output folder's run.toml, or the file itself.
fn read_run(run: &std::path::Path) -> Result<Run> {
    let record = if run.is_dir() { run.join("run.toml") } else { run.to_path_buf() };
    let r = Run::read(&record).map_err(anyhow::Error::msg).with_context(|| format!("reading {}", record.display()))?;
    if r.git_dirty {
        eprintln!("warning: {} ran on a checkout with uncommitted changes", record.display());
    }
    Ok(r)
}

/// The commit that last wrote `file`, when it is committed as it stands (a benchmark's CSV was
/// measured with the binaries of that commit, not of today's).
fn last_commit(file: &std::path::Path) -> Option<String> {
    let git = |args: &[&std::ffi::OsStr]| std::process::Command::new("git").args(args).output().ok();
    let clean = git(&["diff".as_ref(), "--quiet".as_ref(), "HEAD".as_ref(), "--".as_ref(), file.as_os_str()])?;
    if !clean.status.success() {
        return None;
    }
    let log = git(&["log".as_ref(), "-1".as_ref(), "--format=%H".as_ref(), "--".as_ref(), file.as_os_str()])?;
    let c = String::from_utf8_lossy(&log.stdout).trim().to_string();
    (!c.is_empty()).then_some(c)
}
