//! The car score each white box gives each rendered view as rendered, kept in a file beside the
//! images. `views.pbr_min_score` filters the rendered views before every training run; a study
//! trains dozens of units on thousands of views, and scoring each view once per white box,
//! instead of once per unit, takes that filter from minutes to the time it takes to read the file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The file, in the folder of the images it scores.
pub const FILE: &str = "white_box_scores.csv";

/// One cached score.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
struct Row {
    /// [`crate::whitebox::WhiteBox::identity`].
    white_box: String,
    /// The image's file name.
    image: String,
    /// sha256 of the image's bytes: a view drawn again differently is scored again.
    image_sha256: String,
    /// The white box's highest car score on the image.
    max_score: f32,
}

/// Why the cache could not be written (reading never fails: an unreadable file is an empty cache).
#[derive(Debug, thiserror::Error)]
pub enum ViewScoresError {
    /// Writing the file.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// The cached scores of the images of one folder.
#[derive(Debug, Default)]
pub struct ViewScores {
    /// (white box, image) → (image sha256, score).
    rows: HashMap<(String, String), (String, f32)>,
    /// Scores added since reading.
    added: Vec<Row>,
    /// Rows of the file that did not read (a crash's torn tail): their views are scored again.
    damaged: usize,
}

impl ViewScores {
    /// The scores cached in `folder` (none when the file is missing or unreadable).
    pub fn read(folder: &Path) -> Self {
        let mut out = ViewScores::default();
        let (rows, damaged) = read_rows(&folder.join(FILE));
        for r in rows {
            out.rows.insert((r.white_box, r.image), (r.image_sha256, r.max_score));
        }
        out.damaged = damaged;
        out
    }

    /// Rows of the file that did not read when it was read, and are scored again.
    pub fn damaged(&self) -> usize {
        self.damaged
    }

    /// The score `white_box` gave `image` when its bytes hashed to `sha256`.
    pub fn get(&self, white_box: &str, image: &str, sha256: &str) -> Option<f32> {
        self.rows.get(&(white_box.to_string(), image.to_string())).and_then(|(h, s)| (h == sha256).then_some(*s))
    }

    /// Records a score.
    pub fn put(&mut self, white_box: &str, image: &str, sha256: &str, max_score: f32) {
        let key = (white_box.to_string(), image.to_string());
        self.rows.insert(key, (sha256.to_string(), max_score));
        self.added.push(Row {
            white_box: white_box.into(),
            image: image.into(),
            image_sha256: sha256.into(),
            max_score,
        });
    }

    /// Writes the scores added since reading into `folder`'s file, with what the file holds now
    /// (another process may have added its own), atomically. Nothing added: nothing written.
    pub fn save(&mut self, folder: &Path) -> Result<(), ViewScoresError> {
        if self.added.is_empty() {
            return Ok(());
        }
        let path = folder.join(FILE);
        let mut rows: Vec<Row> = read_rows(&path).0;
        let fresh: std::collections::HashSet<(&str, &str)> =
            self.added.iter().map(|r| (r.white_box.as_str(), r.image.as_str())).collect();
        rows.retain(|r| !fresh.contains(&(r.white_box.as_str(), r.image.as_str())));
        rows.extend(self.added.iter().cloned());
        let write = pav_core::durable::write_with(&path, |f| {
            let mut w = csv::Writer::from_writer(f);
            for r in &rows {
                w.serialize(r).map_err(std::io::Error::other)?;
            }
            w.flush()
        });
        write.map_err(|source| ViewScoresError::Write { path: path.clone(), source })?;
        self.added.clear();
        Ok(())
    }
}

/// The rows of a cache file that read, and how many did not: a damaged row (a torn last line
/// after a crash) costs only its own score. A missing file, or one whose header is not the
/// cache's, reads as none.
fn read_rows(path: &Path) -> (Vec<Row>, usize) {
    let Ok(mut r) = csv::Reader::from_path(path) else { return (Vec::new(), 0) };
    let (mut rows, mut bad) = (Vec::new(), 0);
    for row in r.deserialize::<Row>() {
        match row {
            Ok(row) => rows.push(row),
            Err(_) => bad += 1,
        }
    }
    (rows, bad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_survive_a_save_keep_other_writers_rows_and_miss_on_changed_images() {
        let dir = tempfile::tempdir().unwrap();
        let mut a = ViewScores::read(dir.path());
        assert_eq!(a.get("wb", "v.png", "h1"), None);
        a.put("wb", "v.png", "h1", 0.123_456_79);
        // Another process saves its own score in between.
        let mut b = ViewScores::read(dir.path());
        b.put("wb2", "v.png", "h1", 0.5);
        b.save(dir.path()).unwrap();
        a.save(dir.path()).unwrap();
        let back = ViewScores::read(dir.path());
        assert_eq!(back.get("wb", "v.png", "h1"), Some(0.123_456_79));
        assert_eq!(back.get("wb2", "v.png", "h1"), Some(0.5));
        // The same image name with other bytes is not the same view.
        assert_eq!(back.get("wb", "v.png", "h2"), None);
        // A torn last row costs only itself.
        let text = std::fs::read_to_string(dir.path().join(FILE)).unwrap();
        std::fs::write(dir.path().join(FILE), &text[..text.rfind(",h1,").unwrap() + 2]).unwrap();
        let torn = ViewScores::read(dir.path());
        assert_eq!(torn.damaged(), 1);
        assert_eq!(torn.get("wb2", "v.png", "h1").is_some() as u8 + torn.get("wb", "v.png", "h1").is_some() as u8, 1);
        // A file that is not the cache reads as empty, and a save replaces it.
        std::fs::write(dir.path().join(FILE), "white_box,image\nx").unwrap();
        let mut c = ViewScores::read(dir.path());
        assert_eq!(c.get("wb", "v.png", "h1"), None);
        c.put("wb", "v.png", "h1", 0.25);
        c.save(dir.path()).unwrap();
        assert_eq!(ViewScores::read(dir.path()).get("wb", "v.png", "h1"), Some(0.25));
    }
}
