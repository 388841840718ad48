//! `pav data`: the external files pav reads, by manifest: list them, fetch them, find them.

use anyhow::{bail, Result};
use pav::data::manifest::Manifest;
use pav::data::store::{EntryState, Fetched, Origin, Store, ENV_MIRROR};

#[derive(clap::Subcommand)]
pub enum Cmd {
    /// Every manifest entry with its licence and whether the store holds it (present, missing,
    /// corrupt: sizes and sha256 are checked).
    #[command(after_help = "Examples:
  pav data list")]
    List {
        /// Only entries whose name starts with one of these.
        names: Vec<String>,
    },
    /// Fills the store (PAV_DATA, else the XDG cache) with verified files: from each entry's
    /// public source, or from a mirror.
    #[command(after_help = "Examples:
  pav data fetch
  pav data fetch --mirror ../shared/data")]
    Fetch {
        /// Entries or folders of them (`fca/`); all when none.
        names: Vec<String>,
        /// A folder laid out like the store (e.g. ../shared/data) or an http(s) URL of one;
        /// default $PAV_DATA_MIRROR, else upstream.
        #[arg(long)]
        mirror: Option<String>,
    },
    /// Prints the file of an entry (fails, saying how to fetch it, when the store lacks it).
    #[command(after_help = "Examples:
  pav data path rauca-e2e/RAUCA_E2E.png")]
    Path {
        /// The entry's name.
        name: String,
    },
}

pub fn run(cmd: &Cmd) -> Result<()> {
    let (store, manifest) = (Store::from_env(), Manifest::builtin());
    match cmd {
        Cmd::List { names } => {
            let entries = manifest.select(names)?;
            let mut counts = [0usize; 3];
            outln!("store: {}", store.root.display());
            outln!("{:<8} {:>9}  {:<46} {:<28} source", "state", "bytes", "name", "licence");
            for e in &entries {
                let state = store.state(e, true);
                let shown = match &state {
                    EntryState::Present => "present".to_string(),
                    EntryState::Missing => "missing".to_string(),
                    EntryState::Corrupt(why) => format!("corrupt ({why})"),
                };
                counts[match state {
                    EntryState::Present => 0,
                    EntryState::Missing => 1,
                    EntryState::Corrupt(_) => 2,
                }] += 1;
                let license: String = e.license.chars().take(28).collect();
                outln!("{shown:<8} {:>9}  {:<46} {license:<28} {}", e.bytes, e.name, e.source);
            }
            outln!("{} present, {} missing, {} corrupt", counts[0], counts[1], counts[2]);
            if counts[1] + counts[2] > 0 {
                outln!("fill the store: pav data fetch [--mirror DIR|URL]");
            }
        }
        Cmd::Fetch { names, mirror } => {
            let entries = manifest.select(names)?;
            let origin = match mirror.clone().or_else(|| std::env::var(ENV_MIRROR).ok().filter(|m| !m.is_empty())) {
                Some(m) => Origin::mirror(&m),
                None => Origin::Upstream,
            };
            if let Origin::Dir(d) = &origin {
                if !d.is_dir() {
                    bail!("mirror {} is not a folder", d.display());
                }
            }
            eprintln!("fetching {} files from {origin} into {}", entries.len(), store.root.display());
            let bar = crate::common::Bar::default();
            let results = store.fetch_all(&entries, &origin, &bar);
            let (mut kept, mut written, mut failed) = (0, 0, Vec::new());
            for (_, r) in &results {
                match r {
                    Ok(Fetched::Kept) => kept += 1,
                    Ok(Fetched::Written) => written += 1,
                    Err(err) => failed.push(format!("  {err}")),
                }
            }
            outln!("{written} written, {kept} already present, {} failed", failed.len());
            if !failed.is_empty() {
                bail!("{} of {} files could not be fetched:\n{}", failed.len(), entries.len(), failed.join("\n"));
            }
        }
        Cmd::Path { name } => outln!("{}", store.require(name)?.display()),
    }
    Ok(())
}
