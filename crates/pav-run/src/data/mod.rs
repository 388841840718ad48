//! External data by manifest: every file pav reads that does not ship with it (models, meshes,
//! CARLA samples, textures) with its public source, size, sha256 and licence
//! ([`manifest`]); the local store it is fetched into and verified in ([`store`]); and the
//! `data:NAME` paths configs name it by ([`resolve`]).

pub mod manifest;
pub mod store;

use std::path::{Path, PathBuf};

/// A data file that is unknown, absent, damaged or could not be fetched; each message says
/// which `pav data` command fixes it.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// The manifest itself is malformed.
    #[error("data manifest line {line}: {msg}")]
    Manifest {
        /// 1-based line.
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// A name the manifest does not list.
    #[error("`{name}` is not in pav's data manifest (data/manifest.tsv): `pav data list` shows the names")]
    Unknown {
        /// The name asked for.
        name: String,
    },
    /// Listed, but not in the store.
    #[error(
        "{name} is missing from pav's data store {root}: run `pav data fetch {name}` (or `pav data fetch --mirror DIR` \
         from a copy of the data; PAV_DATA picks another store)"
    )]
    Missing {
        /// The entry.
        name: String,
        /// The store's root.
        root: PathBuf,
    },
    /// In the store with the wrong size (a full check of the hash is `pav data list`).
    #[error("{name} in {root} is damaged ({why}): run `pav data fetch {name}` to replace it")]
    Damaged {
        /// The entry.
        name: String,
        /// The store's root.
        root: PathBuf,
        /// What differs.
        why: String,
    },
    /// Fetched bytes that are not the manifest's: nothing was written.
    #[error("{name} from {origin}: {got} where the manifest says {want}; refused, nothing written")]
    Mismatch {
        /// The entry.
        name: String,
        /// Where it came from.
        origin: String,
        /// Size and hash received.
        got: String,
        /// Size and hash expected.
        want: String,
    },
    /// Reading the origin or writing the store failed.
    #[error("{name}: {what}: {source}")]
    Io {
        /// The entry.
        name: String,
        /// What was being done.
        what: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The download program failed or is absent.
    #[error("{name}: downloading {url} failed: {msg}")]
    Download {
        /// The entry.
        name: String,
        /// What was asked for.
        url: String,
        /// curl's message, or how to get curl.
        msg: String,
    },
}

/// clap's parser for path arguments: `data:NAME` becomes the entry's file in the store (an
/// error saying how to fetch it when absent), any other path stays as given.
pub fn arg_path(s: &str) -> Result<PathBuf, String> {
    resolve(Path::new(""), Path::new(s)).map_err(|e| e.to_string())
}

/// Resolves a path from a config file in `dir`: `data:NAME` to the entry's file in the default
/// store (refused when the manifest does not list it or the store lacks it), a relative path
/// against `dir`, an absolute one as it is.
pub fn resolve(dir: &Path, p: &Path) -> Result<PathBuf, DataError> {
    match p.to_str().and_then(|s| s.strip_prefix(pav_core::path::DATA_SCHEME)) {
        Some(name) => store::Store::from_env().require(name),
        None if p.is_relative() => Ok(dir.join(p)),
        None => Ok(p.to_path_buf()),
    }
}
