//! The reference pages of docs/reference/, written from pav's own definitions so that they
//! cannot drift from what the binaries and loaders take: a page per command from its clap
//! definition ([`commands`]), and a page per kind of config file from the config types' JSON
//! Schemas ([`config`]).

pub mod commands;
pub mod config;

/// Why a reference page could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReferenceError {
    /// Writing a page failed.
    #[error("writing {path}: {source}")]
    Write {
        /// The page.
        path: std::path::PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A config type's schema does not show the default of some optional keys.
    #[error("{page}: optional keys whose default the schema cannot show (derive Serialize on their type): {}", keys.join(", "))]
    NoDefault {
        /// The page.
        page: String,
        /// The keys, as dotted paths.
        keys: Vec<String>,
    },
}
