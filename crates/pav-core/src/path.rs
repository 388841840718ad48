//! Paths as configs and run records write them, compared without the file system (the file may
//! be gone, or on another machine).

use std::path::{Path, PathBuf};

/// The prefix of a path that names an entry of pav's data manifest instead of a file
/// (`data:NAME`): configs keep it as written wherever they are read from.
pub const DATA_SCHEME: &str = "data:";

/// `a/b/../c` → `a/c` without touching the file system, so one file reached two ways is one input.
pub fn tidy(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir if matches!(out.components().next_back(), Some(Component::Normal(_))) => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}
