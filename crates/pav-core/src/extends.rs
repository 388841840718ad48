//! `extends = "base.toml"` in TOML configs: a file merged over the chain of files it extends,
//! tables key by key, each relative path kept meaning the file its config named.

use std::path::{Path, PathBuf};

/// A config chain that cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ExtendsError {
    /// A file could not be read.
    #[error("{path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file is not valid TOML.
    #[error("{path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: toml::de::Error,
    },
    /// The chain is broken: a cycle, too long, or `extends` not a path.
    #[error("{path}: {msg}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
}

/// `path` read as a `T` over the chain of configs it `extends`, and the files read, `path` first
/// (see [`read_merged`]). A file that extends nothing is parsed from its own text, so that an
/// error points at its line.
pub fn load<T: serde::de::DeserializeOwned>(
    path: &Path,
    path_keys: &[&[&str]],
    names: &[&str],
) -> Result<(T, Vec<PathBuf>), ExtendsError> {
    let parse = |source| ExtendsError::Parse { path: path.into(), source };
    let text = std::fs::read_to_string(path).map_err(|source| ExtendsError::Read { path: path.into(), source })?;
    let table: toml::Table = toml::from_str(&text).map_err(parse)?;
    if !table.contains_key("extends") {
        return Ok((toml::from_str(&text).map_err(parse)?, vec![path.to_path_buf()]));
    }
    let (merged, files) = read_merged(path, path_keys, names)?;
    Ok((toml::Value::Table(merged).try_into().map_err(parse)?, files))
}

/// The longest `extends` chain followed; a longer one is almost surely a mistake.
const MAX_EXTENDS: usize = 16;

/// The TOML of `path` merged over the configs it `extends` (the key removed), and the files read,
/// `path` first. A base's relative paths are rewritten relative to `path`'s folder, so each path
/// means what it meant in the file that set it.
///
/// `path_keys` lists the keys whose values are paths (through tables, arrays of tables and
/// arrays of paths); `names` are values at those keys that are not paths (`random`, `coco80`).
pub fn read_merged(
    path: &Path,
    path_keys: &[&[&str]],
    names: &[&str],
) -> Result<(toml::Table, Vec<PathBuf>), ExtendsError> {
    let mut chain: Vec<(PathBuf, toml::Table)> = Vec::new();
    let mut next = Some(path.to_path_buf());
    // Where the current file lies, relative to the first file's folder.
    let mut rel = PathBuf::new();
    while let Some(file) = next.take() {
        if chain.iter().any(|(f, _)| crate::path::tidy(f) == crate::path::tidy(&file)) {
            let chain: Vec<String> = chain.iter().map(|(f, _)| f.display().to_string()).collect();
            return Err(ExtendsError::Invalid {
                path: path.into(),
                msg: format!("extends: {} comes back to {}", chain.join(" → "), file.display()),
            });
        }
        if chain.len() == MAX_EXTENDS {
            return Err(ExtendsError::Invalid {
                path: path.into(),
                msg: format!("extends: more than {MAX_EXTENDS} configs in the chain"),
            });
        }
        let text =
            std::fs::read_to_string(&file).map_err(|source| ExtendsError::Read { path: file.clone(), source })?;
        let mut table: toml::Table =
            toml::from_str(&text).map_err(|source| ExtendsError::Parse { path: file.clone(), source })?;
        if !chain.is_empty() {
            for key in path_keys {
                anchor(&mut table, key, &rel, names);
            }
        }
        match table.remove("extends") {
            None => {}
            Some(toml::Value::String(base)) => {
                let dir = file.parent().unwrap_or(Path::new(""));
                rel = crate::path::tidy(&rel.join(Path::new(&base).parent().unwrap_or(Path::new(""))));
                next = Some(crate::path::tidy(&dir.join(&base)));
            }
            Some(other) => {
                return Err(ExtendsError::Invalid {
                    path: file.clone(),
                    msg: format!("extends must be a config's path, got {other}"),
                })
            }
        }
        chain.push((file, table));
    }
    let files = chain.iter().map(|(f, _)| f.clone()).collect();
    let mut merged = toml::Table::new();
    for (_, t) in chain.into_iter().rev() {
        merge(&mut merged, t);
    }
    Ok((merged, files))
}

/// `over`'s keys win; tables merge key by key.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Prefixes `rel` to the relative paths at `key` (through arrays of tables and arrays of paths).
fn anchor(table: &mut toml::Table, key: &[&str], rel: &Path, names: &[&str]) {
    let Some(v) = table.get_mut(key[0]) else { return };
    anchor_value(v, &key[1..], rel, names);
}

fn anchor_value(v: &mut toml::Value, key: &[&str], rel: &Path, names: &[&str]) {
    match v {
        toml::Value::Array(items) => items.iter_mut().for_each(|i| anchor_value(i, key, rel, names)),
        toml::Value::Table(t) if !key.is_empty() => anchor(t, key, rel, names),
        toml::Value::String(s) if key.is_empty() => {
            let p = Path::new(s.as_str());
            // `data:` entries, absolute paths and names are not relative paths.
            if !(s.starts_with(crate::path::DATA_SCHEME) || p.is_absolute() || names.contains(&s.as_str())) {
                *s = crate::path::tidy(&rel.join(p)).display().to_string();
            }
        }
        _ => {}
    }
}
