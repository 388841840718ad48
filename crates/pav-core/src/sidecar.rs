//! The per-frame angle sidecar written by `pav-rig capture` and read by `pav-rig evaluate`.
//!
//! Format: CSV with header `frame,timestamp_s,angle_deg`; one row per recorded frame, angle in
//! [0, 360) degrees of turntable rotation from the home position.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One sidecar row.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AngleSample {
    /// 0-based frame index in the video.
    pub frame: usize,
    /// Seconds since the first frame.
    pub timestamp_s: f64,
    /// Turntable angle in degrees.
    pub angle_deg: f64,
}

/// Errors reading or writing a sidecar.
#[derive(Debug, thiserror::Error)]
pub enum SidecarError {
    /// File-level failure.
    #[error("angle sidecar {path}: {source}")]
    Csv {
        /// Sidecar path.
        path: PathBuf,
        /// Underlying error.
        source: csv::Error,
    },
    /// A row is inconsistent.
    #[error("angle sidecar {path}, row {row}: {msg}")]
    Row {
        /// Sidecar path.
        path: PathBuf,
        /// 1-based data row.
        row: usize,
        /// What is wrong.
        msg: String,
    },
}

/// The conventional sidecar path for a video: `clip.mp4` → `clip.angles.csv`.
pub fn sidecar_path(video: &Path) -> PathBuf {
    video.with_extension("angles.csv")
}

/// Reads a sidecar; frames must be strictly increasing, timestamps finite and never going back,
/// and angles within [0, 360).
pub fn read(path: &Path) -> Result<Vec<AngleSample>, SidecarError> {
    let csv_err = |source| SidecarError::Csv { path: path.into(), source };
    let mut rd = csv::Reader::from_path(path).map_err(csv_err)?;
    let mut out: Vec<AngleSample> = Vec::new();
    for (i, rec) in rd.deserialize().enumerate() {
        let s: AngleSample = rec.map_err(csv_err)?;
        let row_err = |msg: String| SidecarError::Row { path: path.into(), row: i + 1, msg };
        if !s.angle_deg.is_finite() || !s.timestamp_s.is_finite() {
            return Err(row_err("non-finite timestamp or angle".into()));
        }
        if !(0.0..360.0).contains(&s.angle_deg) {
            return Err(row_err(format!("angle {}° is outside [0, 360)", s.angle_deg)));
        }
        if let Some(prev) = out.last() {
            if s.frame <= prev.frame {
                return Err(row_err(format!("frame {} does not follow frame {}", s.frame, prev.frame)));
            }
            if s.timestamp_s < prev.timestamp_s {
                return Err(row_err(format!(
                    "timestamp {} s goes back from {} s (frame {})",
                    s.timestamp_s, prev.timestamp_s, prev.frame
                )));
            }
        }
        out.push(s);
    }
    Ok(out)
}

/// Streams sidecar rows to disk, flushing each so a crash loses nothing already recorded.
pub struct Writer {
    inner: csv::Writer<std::fs::File>,
    path: PathBuf,
}

impl Writer {
    /// Creates (truncates) `path` and writes the header.
    pub fn create(path: &Path) -> Result<Self, SidecarError> {
        let inner = csv::Writer::from_path(path).map_err(|source| SidecarError::Csv { path: path.into(), source })?;
        Ok(Writer { inner, path: path.into() })
    }

    /// Appends one row and flushes it.
    pub fn push(&mut self, s: AngleSample) -> Result<(), SidecarError> {
        let path = self.path.clone();
        self.inner.serialize(s).map_err(|source| SidecarError::Csv { path: path.clone(), source })?;
        self.inner.flush().map_err(|e| SidecarError::Csv { path, source: e.into() })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_and_order_check() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("v.angles.csv");
        let mut w = Writer::create(&p).unwrap();
        w.push(AngleSample { frame: 0, timestamp_s: 0.0, angle_deg: 0.0 }).unwrap();
        w.push(AngleSample { frame: 2, timestamp_s: 0.066, angle_deg: 1.7 }).unwrap();
        drop(w);
        assert_eq!(read(&p).unwrap()[1], AngleSample { frame: 2, timestamp_s: 0.066, angle_deg: 1.7 });
        std::fs::write(&p, "frame,timestamp_s,angle_deg\n3,0,0\n1,0,0\n").unwrap();
        assert!(read(&p).unwrap_err().to_string().contains("row 2"));
        for (bad, needle) in [
            ("0,0,720\n", "row 1: angle 720° is outside [0, 360)"),
            ("0,0,-30\n", "angle -30° is outside"),
            ("0,0,NaN\n", "non-finite"),
            ("0,0.5,1\n1,0.2,2\n", "row 2: timestamp 0.2 s goes back from 0.5 s"),
            ("0,0\n", "angle sidecar"),
        ] {
            std::fs::write(&p, format!("frame,timestamp_s,angle_deg\n{bad}")).unwrap();
            let e = read(&p).unwrap_err().to_string();
            assert!(e.contains(needle), "{bad:?}: {e}");
        }
        assert_eq!(sidecar_path(Path::new("a/b.mp4")), Path::new("a/b.angles.csv"));
    }
}
