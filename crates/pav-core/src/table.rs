//! Tables: rows of any serializable type to a CSV file, and the first-seen order of keys that
//! report tables use for their rows and columns.

use std::path::{Path, PathBuf};

/// Errors writing a CSV file.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {path}: {source}")]
pub struct TableError {
    /// The file.
    pub path: PathBuf,
    /// The CSV writer's error.
    pub source: csv::Error,
}

/// Writes serializable rows as a CSV file with a header.
pub fn write_csv<T: serde::Serialize>(path: &Path, rows: &[T]) -> Result<(), TableError> {
    let err = |source| TableError { path: path.into(), source };
    let mut w = csv::Writer::from_path(path).map_err(err)?;
    for r in rows {
        w.serialize(r).map_err(err)?;
    }
    w.flush().map_err(|e| err(e.into()))
}

/// The distinct items of `it` in first-seen order.
pub fn unique<T: PartialEq>(it: impl IntoIterator<Item = T>) -> Vec<T> {
    let mut out = Vec::new();
    for x in it {
        if !out.contains(&x) {
            out.push(x);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unique_keeps_first_seen_order_and_csv_has_a_header() {
        assert_eq!(unique([3, 1, 3, 2, 1]), vec![3, 1, 2]);
        #[derive(serde::Serialize)]
        struct Row {
            a: u32,
            b: &'static str,
        }
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.csv");
        write_csv(&p, &[Row { a: 1, b: "x" }, Row { a: 2, b: "y" }]).unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "a,b\n1,x\n2,y\n");
        let e = write_csv(&dir.path().join("no/such/dir.csv"), &[Row { a: 1, b: "x" }]).unwrap_err();
        assert!(e.to_string().contains("dir.csv"), "{e}");
    }
}
