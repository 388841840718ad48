//! Shards of a long job, so a cluster's job array can run it: `--shard K/N` (1-based) picks units
//! `K-1, K-1+N, …` of the job's fixed unit list and writes them into `<out>/shard-K-of-N/` with
//! that shard's `run.toml`; a merge run with the same arguments finds the shards, refuses any that
//! another config, commit or data made, names the missing ones, and writes the result the same job
//! run in one process would have written.

use crate::provenance::{Input, Run, FILE};
use std::path::{Path, PathBuf};

/// One slice of a job: shard `k` of `n`, 1-based like a job array's task ids.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Shard {
    /// Which shard, 1 ..= n.
    pub k: usize,
    /// How many shards the job is cut into.
    pub n: usize,
}

/// Why shards cannot be run or merged.
#[derive(Debug, thiserror::Error)]
pub enum ShardError {
    /// A `--shard` value that names no shard.
    #[error("--shard {spec}: {why}")]
    Spec {
        /// As given.
        spec: String,
        /// What is wrong with it.
        why: String,
    },
    /// The output folder holds no shard folders.
    #[error("{0}: no shard folders (shard-K-of-N) to merge; run the job with --shard K/N first")]
    None(PathBuf),
    /// Shard folders of different cuts of the job lie side by side.
    #[error("{dir}: shard folders of different cuts ({cuts}); remove the ones of the cut not wanted")]
    Mixed {
        /// The output folder.
        dir: PathBuf,
        /// The shard counts found.
        cuts: String,
    },
    /// Shards of the cut that have not written their folder.
    #[error("{dir}: missing {missing} of {n} shards: {names}; run them (or requeue them) before merging")]
    Missing {
        /// The output folder.
        dir: PathBuf,
        /// How many are missing.
        missing: usize,
        /// The cut.
        n: usize,
        /// Their folder names.
        names: String,
    },
    /// A shard that started but did not finish a unit.
    #[error("{shard}: has not finished {what}; rerun that shard before merging")]
    Unfinished {
        /// The shard's folder.
        shard: PathBuf,
        /// The unit.
        what: String,
    },
    /// A unit that two shard folders both hold.
    #[error("{what} is in two shards: {a} and {b}")]
    Duplicate {
        /// The unit.
        what: String,
        /// One folder.
        a: PathBuf,
        /// The other.
        b: PathBuf,
    },
    /// A shard made by another run than the merge describes.
    #[error("{shard}: its {what} is {theirs}, this merge's is {ours}; shards of different runs cannot be merged")]
    Differs {
        /// The shard's folder.
        shard: PathBuf,
        /// What differs.
        what: String,
        /// The shard's value.
        theirs: String,
        /// The merge's value.
        ours: String,
    },
    /// A shard's run record cannot be read.
    #[error("{path}: {why}")]
    Record {
        /// The record.
        path: PathBuf,
        /// Why.
        why: String,
    },
}

impl std::str::FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, ShardError> {
        let bad = |why: &str| ShardError::Spec { spec: s.to_string(), why: why.to_string() };
        let (k, n) = s.split_once('/').ok_or_else(|| bad("expected K/N, e.g. 2/8"))?;
        let k: usize = k.trim().parse().map_err(|_| bad("K is not a whole number"))?;
        let n: usize = n.trim().parse().map_err(|_| bad("N is not a whole number"))?;
        if n == 0 {
            return Err(bad("N must be at least 1"));
        }
        if k == 0 || k > n {
            return Err(bad(&format!("K must be within 1..={n} (shards count from 1)")));
        }
        Ok(Shard { k, n })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.k, self.n)
    }
}

impl Shard {
    /// The shard of `n` that runs unit `unit` (0-based) of a job.
    pub fn owner(unit: usize, n: usize) -> Shard {
        Shard { k: unit % n + 1, n }
    }

    /// Whether this shard runs unit `unit` (0-based).
    pub fn picks(&self, unit: usize) -> bool {
        unit % self.n == self.k - 1
    }

    /// The units of `0..count` this shard runs.
    pub fn units(&self, count: usize) -> Vec<usize> {
        (0..count).filter(|&u| self.picks(u)).collect()
    }

    /// The shard's folder name, `shard-K-of-N`.
    pub fn dir_name(&self) -> String {
        format!("shard-{}-of-{}", self.k, self.n)
    }

    /// The shard's folder inside a job's output folder.
    pub fn dir(&self, out: &Path) -> PathBuf {
        out.join(self.dir_name())
    }

    fn parse_dir_name(name: &str) -> Option<Shard> {
        let rest = name.strip_prefix("shard-")?;
        let (k, n) = rest.split_once("-of-")?;
        let s = Shard { k: k.parse().ok()?, n: n.parse().ok()? };
        (s.n >= 1 && (1..=s.n).contains(&s.k)).then_some(s)
    }
}

/// Every shard folder of one cut in `out`, in shard order: refused when there are none, when
/// folders of different cuts lie side by side, or when any shard of the cut is missing (all named).
pub fn find(out: &Path) -> Result<Vec<(Shard, PathBuf)>, ShardError> {
    let io = |e: std::io::Error| ShardError::Record { path: out.to_path_buf(), why: e.to_string() };
    if !out.is_dir() {
        return Err(ShardError::None(out.to_path_buf()));
    }
    let mut found: Vec<(Shard, PathBuf)> = Vec::new();
    for e in std::fs::read_dir(out).map_err(io)? {
        let e = e.map_err(io)?;
        if let Some(s) = e.file_name().to_str().and_then(Shard::parse_dir_name) {
            if e.path().is_dir() {
                found.push((s, e.path()));
            }
        }
    }
    found.sort();
    let Some(&(first, _)) = found.first() else { return Err(ShardError::None(out.to_path_buf())) };
    let mut cuts: Vec<usize> = found.iter().map(|(s, _)| s.n).collect();
    cuts.dedup();
    if cuts.len() > 1 {
        let cuts = cuts.iter().map(|n| format!("of {n}")).collect::<Vec<_>>().join(", ");
        return Err(ShardError::Mixed { dir: out.to_path_buf(), cuts });
    }
    let n = first.n;
    let missing: Vec<String> =
        (1..=n).map(|k| Shard { k, n }).filter(|s| !found.iter().any(|(f, _)| f == s)).map(|s| s.dir_name()).collect();
    if !missing.is_empty() {
        return Err(ShardError::Missing {
            dir: out.to_path_buf(),
            missing: missing.len(),
            n,
            names: missing.join(", "),
        });
    }
    Ok(found)
}

/// Settings that differ between the shards of one job and its merge by design.
const OWN_SETTINGS: [&str; 2] = ["shard", "shards"];

/// Checks that the shard in `dir` was made by the run `merge` describes: the same pav version and
/// commit (and uncommitted changes), config, inputs by hash, tools and settings (except which
/// shard it is). The host, command line, working folder and start time may differ.
pub fn check_record(dir: &Path, merge: &Run) -> Result<(), ShardError> {
    let path = dir.join(FILE);
    let shard = Run::read(&path).map_err(|why| ShardError::Record { path: path.clone(), why })?;
    let differs = |what: &str, theirs: String, ours: String| {
        if theirs == ours {
            Ok(())
        } else {
            Err(ShardError::Differs { shard: dir.to_path_buf(), what: what.into(), theirs, ours })
        }
    };
    differs("pav", shard.pav_version.clone(), merge.pav_version.clone())?;
    differs("commit", shard.git_commit.clone(), merge.git_commit.clone())?;
    let dirty = |r: &Run| if r.git_dirty { "modified (uncommitted changes)" } else { "clean" }.to_string();
    differs("checkout", dirty(&shard), dirty(merge))?;
    let config =
        |r: &Run| r.config.as_ref().map_or("no config".into(), |c| format!("{} (sha256 {})", c.path, c.sha256));
    differs("config", config(&shard), config(merge))?;
    // Inputs are compared by content: nodes may keep the data store elsewhere, or run from
    // another folder.
    let has = |r: &Run, i: &Input| r.inputs.iter().any(|x| x.sha256 == i.sha256);
    if let Some(i) = merge.inputs.iter().find(|i| !has(&shard, i)) {
        differs(&format!("input {}", i.path), "another file or none".into(), format!("sha256 {}", i.sha256))?;
    }
    if let Some(i) = shard.inputs.iter().find(|i| !has(merge, i)) {
        differs(&format!("input {}", i.path), format!("sha256 {}", i.sha256), "another file or none".into())?;
    }
    let keys: std::collections::BTreeSet<&String> = shard.settings.keys().chain(merge.settings.keys()).collect();
    for key in keys.into_iter().filter(|k| !OWN_SETTINGS.contains(&k.as_str())) {
        let value = |r: &Run| r.settings.get(key).map_or("none".to_string(), |v| format!("`{v}`"));
        differs(&format!("setting {key}"), value(&shard), value(merge))?;
    }
    let tools = |r: &Run| r.tools.iter().map(|(k, v)| format!("{k} {v}")).collect::<Vec<_>>().join(", ");
    differs("tools", tools(&shard), tools(merge))
}

/// Finds the shards in `out` and checks each against `merge` ([`find`], [`check_record`]).
pub fn find_checked(out: &Path, merge: &Run) -> Result<Vec<(Shard, PathBuf)>, ShardError> {
    let shards = find(out)?;
    for (_, dir) in &shards {
        check_record(dir, merge)?;
    }
    Ok(shards)
}

/// The folder of the shard among `shards` (one whole cut, as [`find`] returns it) that owns unit
/// `unit` ([`Shard::owner`]).
pub fn owner_dir(shards: &[(Shard, PathBuf)], unit: usize) -> PathBuf {
    let owner = Shard::owner(unit, shards.first().map_or(1, |s| s.0.n));
    shards.iter().find(|s| s.0 == owner).map_or_else(|| owner.dir_name().into(), |s| s.1.clone())
}

/// Writes `value` as JSON to `path` whole or not at all (`durable::write`), so a shard killed
/// mid-write never leaves a file that a merge would read as finished.
pub fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<(), ShardError> {
    let bad = |path: &Path, why: String| ShardError::Record { path: path.to_path_buf(), why };
    let text = serde_json::to_vec(value).map_err(|e| bad(path, e.to_string()))?;
    pav_core::durable::write(path, text).map_err(|e| bad(path, e.to_string()))
}

/// Reads a file written by [`write_json`].
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, ShardError> {
    let bad = |why: String| ShardError::Record { path: path.to_path_buf(), why };
    let text = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    serde_json::from_slice(&text).map_err(|e| bad(e.to_string()))
}

/// One unit of a job: what to call it in errors, and its folder relative to a shard's folder
/// (and to the job's output folder once gathered).
pub struct Unit {
    /// Its name in messages ("fold 2/3 of seed 1").
    pub what: String,
    /// Its folder, relative.
    pub dir: PathBuf,
}

/// Gathers the units of a job from its shards into `out`: unit `u` must be finished (`done`) in
/// the folder of the shard that owns it ([`Shard::owner`]) and in no other; then each unit's
/// folder is linked into `out` ([`link_tree`]). Nothing is linked unless every unit passes.
pub fn gather(
    shards: &[(Shard, PathBuf)],
    units: &[Unit],
    done: &dyn Fn(&Path) -> bool,
    out: &Path,
) -> Result<(), ShardError> {
    let mut links = Vec::new();
    for (u, unit) in units.iter().enumerate() {
        let own = owner_dir(shards, u);
        if !done(&own.join(&unit.dir)) {
            return Err(ShardError::Unfinished { shard: own, what: unit.what.clone() });
        }
        if let Some((_, other)) = shards.iter().find(|(_, d)| *d != own && done(&d.join(&unit.dir))) {
            return Err(ShardError::Duplicate { what: unit.what.clone(), a: own, b: other.clone() });
        }
        links.push((own.join(&unit.dir), out.join(&unit.dir)));
    }
    for (from, to) in links {
        link_tree(&from, &to)?;
    }
    Ok(())
}

/// Makes `to` hold the files of `from` (folders recreated, files hard-linked, or copied where
/// the two lie on different file systems), replacing what `to` had under the same names.
pub fn link_tree(from: &Path, to: &Path) -> Result<(), ShardError> {
    let io = |path: &Path, e: std::io::Error| ShardError::Record { path: path.to_path_buf(), why: e.to_string() };
    std::fs::create_dir_all(to).map_err(|e| io(to, e))?;
    for e in std::fs::read_dir(from).map_err(|e| io(from, e))? {
        let e = e.map_err(|e| io(from, e))?;
        let (src, dst) = (e.path(), to.join(e.file_name()));
        if src.is_dir() {
            link_tree(&src, &dst)?;
            continue;
        }
        if dst.exists() {
            std::fs::remove_file(&dst).map_err(|e| io(&dst, e))?;
        }
        if std::fs::hard_link(&src, &dst).is_err() {
            std::fs::copy(&src, &dst).map_err(|e| io(&dst, e))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shard_is_k_of_n_counted_from_one() {
        assert_eq!("2/3".parse::<Shard>().unwrap(), Shard { k: 2, n: 3 });
        for (bad, why) in
            [("0/2", "within 1..=2"), ("3/2", "within 1..=2"), ("1/0", "at least 1"), ("1", "K/N"), ("a/2", "K is")]
        {
            let e = bad.parse::<Shard>().unwrap_err().to_string();
            assert!(e.contains(why) && e.contains(bad), "{bad}: {e}");
        }
    }

    #[test]
    fn the_shards_of_a_cut_run_every_unit_once() {
        let n = 3;
        let mut seen = [0; 10];
        for k in 1..=n {
            let s = Shard { k, n };
            for u in s.units(10) {
                seen[u] += 1;
                assert_eq!(Shard::owner(u, n), s);
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert_eq!(Shard { k: 1, n: 1 }.units(3), [0, 1, 2]);
    }

    #[test]
    fn find_names_missing_shards_and_refuses_mixed_cuts() {
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(find(dir.path()), Err(ShardError::None(_))));
        assert!(matches!(find(&dir.path().join("not-there")), Err(ShardError::None(_))));
        for name in ["shard-1-of-4", "shard-3-of-4", "shard-9-of-4", "other"] {
            std::fs::create_dir(dir.path().join(name)).unwrap();
        }
        let e = find(dir.path()).unwrap_err().to_string();
        assert!(e.contains("missing 2 of 4 shards: shard-2-of-4, shard-4-of-4"), "{e}");
        std::fs::create_dir(dir.path().join("shard-1-of-2")).unwrap();
        let e = find(dir.path()).unwrap_err().to_string();
        assert!(e.contains("different cuts (of 2, of 4)"), "{e}");
    }

    #[test]
    fn a_shard_of_another_commit_or_config_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("a.toml");
        std::fs::write(&cfg, "x = 1\n").unwrap();
        let merge = Run::start().config(&cfg).setting("seed", 0).setting("shards", 2);
        let shard = dir.path().join("shard-1-of-2");
        merge.clone().setting("shard", "1/2").write(&shard.join(FILE)).unwrap();
        check_record(&shard, &merge).unwrap();
        let mut other = merge.clone();
        other.git_commit = "0123".into();
        other.write(&shard.join(FILE)).unwrap();
        let e = check_record(&shard, &merge).unwrap_err().to_string();
        assert!(e.contains("its commit is 0123"), "{e}");
        merge.clone().setting("seed", 1).write(&shard.join(FILE)).unwrap();
        let e = check_record(&shard, &merge).unwrap_err().to_string();
        assert!(e.contains("its setting seed is `1`, this merge's is `0`"), "{e}");
        std::fs::write(&cfg, "x = 2\n").unwrap();
        Run::start().config(&cfg).setting("seed", 0).write(&shard.join(FILE)).unwrap();
        let e = check_record(&shard, &merge).unwrap_err().to_string();
        assert!(e.contains("config") && e.contains("sha256"), "{e}");
    }
}
