//! `pav results`.

use anyhow::{bail, Context, Result};
use pav::provenance::Run;
use pav::results::{regenerate, ResultFile};
use std::path::PathBuf;

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Record a headline table from a finished run as results/NAME.json: columns of a CSV it
    /// wrote, with the command, commit, seeds and input hashes of its run.toml.
    Add {
        /// The table's name (its file is results/NAME.json; a document shows it between
        /// `<!-- results:NAME -->` and `<!-- /results:NAME -->`).
        name: String,
        /// The run's output folder (holding its run.toml) or the run.toml itself.
        #[arg(long)]
        run: PathBuf,
        /// The CSV the run wrote, whose rows the table shows.
        #[arg(long)]
        table: PathBuf,
        /// Columns: `HEADING[+HEADING][=SHOWN][:FORMAT]` (two headings make an interval `a–b`;
        /// FORMAT `pct` or a number of decimals), comma-separated.
        #[arg(long, value_delimiter = ',', required = true)]
        columns: Vec<String>,
        /// Keep only the CSV's rows where HEADING has VALUE (`HEADING=VALUE`, comma-separated).
        #[arg(long = "where", value_delimiter = ',')]
        rows_where: Vec<String>,
        /// What the table answers.
        #[arg(long)]
        title: String,
        /// A sentence printed under the table.
        #[arg(long)]
        note: Option<String>,
    },
    /// Regenerate every results block in README.md and docs/ from results/.
    Write,
    /// Fail, naming each document whose results blocks differ from what `pav results write`
    /// makes now (a number edited by hand, a table gone stale).
    Check,
}

pub fn run(c: &Cmd) -> Result<()> {
    let root = PathBuf::from(".");
    match c {
        Cmd::Add { name, run, table, columns, rows_where, title, note } => {
            let record = if run.is_dir() { run.join("run.toml") } else { run.clone() };
            let r = Run::read(&record)
                .map_err(anyhow::Error::msg)
                .with_context(|| format!("reading {}", record.display()))?;
            if r.git_dirty {
                eprintln!("warning: {} ran on a checkout with uncommitted changes", record.display());
            }
            let mut file = ResultFile::from_run(&r, table, columns, rows_where, title, &root)?;
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
