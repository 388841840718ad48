//! `pav results`.

use anyhow::{bail, Context, Result};
use pav::provenance::Run;
use pav::results::{regenerate, ResultFile, Shape};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Record a headline table from a finished run as results/NAME.json: columns of a CSV it
    /// wrote, with the command, commit, seeds and input hashes of its run.toml.
    Add(Box<AddArgs>),
    /// Regenerate every results block in README.md and docs/ from results/.
    Write,
    /// Fail, naming each document whose results blocks differ from what `pav results write`
    /// makes now (a number edited by hand, a table gone stale).
    Check,
}

/// `pav results add`.
#[derive(clap::Args)]
pub struct AddArgs {
    /// The table's name (its file is results/NAME.json; a document shows it between
    /// `<!-- results:NAME -->` and `<!-- /results:NAME -->`).
    name: String,
    /// The run's output folder (holding its run.toml) or the run.toml itself.
    #[arg(long, required_unless_present = "bench")]
    run: Option<PathBuf>,
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

pub fn run(c: &Cmd) -> Result<()> {
    let root = PathBuf::from(".");
    match c {
        Cmd::Add(a) => {
            let AddArgs { name, run, bench, command, table, columns, rows_where, pivot, title, note } = a.as_ref();
            let r = match (run, bench) {
                (Some(run), _) => {
                    let record = if run.is_dir() { run.join("run.toml") } else { run.clone() };
                    let r = Run::read(&record)
                        .map_err(anyhow::Error::msg)
                        .with_context(|| format!("reading {}", record.display()))?;
                    if r.git_dirty {
                        eprintln!("warning: {} ran on a checkout with uncommitted changes", record.display());
                    }
                    r
                }
                (None, Some(cmd)) => {
                    let mut r = Run::start().inputs([table.as_path()]);
                    r.command = vec![cmd.clone()];
                    if let Some(c) = last_commit(table) {
                        r.git_commit = c;
                    }
                    r
                }
                (None, None) => bail!("give --run or --bench"),
            };
            let shape = Shape { columns: columns.clone(), rows_where: rows_where.clone(), pivot: pivot.clone() };
            let mut file = ResultFile::from_run(&r, table, &shape, title, &root)?;
            if let Some(cmd) = bench.as_ref().or(command.as_ref()) {
                file.command = cmd.clone();
            }
            file.note = note.clone();
            let path = file.save(&root, name)?;
            println!(
                "wrote {} ({} rows); `pav results write` puts it in the documents",
                path.display(),
                file.rows.len()
            );
        }
        Cmd::Write => {
            for (p, _) in regenerate(&root, true)? {
                println!("regenerated {}", p.display());
            }
        }
        Cmd::Check => {
            let stale = regenerate(&root, false)?;
            if !stale.is_empty() {
                let names: Vec<String> = stale.iter().map(|(p, _)| p.display().to_string()).collect();
                bail!("results blocks differ from results/ in {}: run `pav results write`", names.join(", "));
            }
            println!("every results block matches results/");
        }
    }
    Ok(())
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
