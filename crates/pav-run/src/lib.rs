//! What a pav run reads and records: the external data by manifest and the verified store it is
//! fetched into ([`data`]), the record every output folder gets ([`provenance`], `run.toml`), and
//! the shards a long job splits into and merges from ([`shard`]), and how a signal stops it
//! ([`stop`]). These reach outside the process
//! (curl for the store, git for the commit), which is why they are not in `pav-core`.
#![warn(missing_docs)]

pub mod data;
pub mod provenance;
pub mod shard;
pub mod stop;
