//! Files written whole or not at all: what a resumed job trusts (checkpoints, caches, manifests,
//! run records, shard records) must never be found half-written after a crash, a kill or a full
//! disk. The bytes go to a temporary file beside the target, are flushed to the disk, and only
//! then take the target's name; the folder is flushed too, so that the new name survives a power
//! cut. A failed write leaves the old file as it was and no temporary file behind.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary file a write of `path` goes through: hidden, beside it, named for this process
/// so that two processes writing one file do not share it.
fn temporary(path: &Path) -> PathBuf {
    let name = path.file_name().map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.{}.part", std::process::id()))
}

/// Writes whatever `fill` writes to `path`, whole or not at all.
pub fn write_with(path: &Path, fill: impl FnOnce(&mut File) -> std::io::Result<()>) -> std::io::Result<()> {
    let tmp = temporary(path);
    let done = File::create(&tmp).and_then(|mut f| {
        fill(&mut f)?;
        f.flush()?;
        f.sync_all()
    });
    let renamed = done.and_then(|()| std::fs::rename(&tmp, path));
    if renamed.is_err() {
        let _ = std::fs::remove_file(&tmp);
        return renamed;
    }
    // The rename is durable once the folder's entry is; a folder that cannot be opened (some
    // file systems) still has the file whole.
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Writes `bytes` to `path`, whole or not at all.
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> std::io::Result<()> {
    write_with(path, |f| f.write_all(bytes.as_ref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        v.sort();
        v
    }

    #[test]
    fn a_write_that_fails_midway_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("checkpoint.bin");
        write(&p, b"old and whole").unwrap();
        let e = write_with(&p, |f| {
            f.write_all(b"new but ha")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(e.to_string(), "disk full");
        assert_eq!(std::fs::read(&p).unwrap(), b"old and whole");
        assert_eq!(names(dir.path()), vec!["checkpoint.bin"]);
        write(&p, b"new and whole").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new and whole");
        assert_eq!(names(dir.path()), vec!["checkpoint.bin"]);
        // Into a folder that does not exist: an error, nothing written.
        assert!(write(&dir.path().join("no/such/file"), b"x").is_err());
        assert_eq!(names(dir.path()), vec!["checkpoint.bin"]);
    }
}
