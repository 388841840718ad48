//! Physical-world metrics: A_physical = f_d / f_o with a Wilson interval, overall and per angle bin.

/// One scored frame for one detector.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrameRecord {
    /// Video label.
    pub video: String,
    /// 0-based frame index in the video.
    pub frame: usize,
    /// Seconds from the first frame.
    pub time_s: f64,
    /// Turntable angle in degrees, when known.
    pub angle_deg: Option<f64>,
    /// Detector name.
    pub detector: String,
    /// Whether a target-class box scored at or above the threshold.
    pub detected: bool,
    /// Highest target-class score in the frame (0 when the model proposed nothing).
    pub max_score: f32,
    /// Box of that proposal `[x1, y1, x2, y2]` in frame pixels.
    pub x1: Option<f32>,
    /// See `x1`.
    pub y1: Option<f32>,
    /// See `x1`.
    pub x2: Option<f32>,
    /// See `x1`.
    pub y2: Option<f32>,
    /// The video file's name: videos that share a label are pooled, and this tells them apart.
    pub file: String,
}

#[cfg(test)]
impl FrameRecord {
    /// `detector`'s best car score on frame `frame` of `video` (no box, no angle), for tests.
    pub(crate) fn scored(video: &str, frame: usize, detector: &str, score: f32) -> FrameRecord {
        FrameRecord {
            video: video.into(),
            frame,
            time_s: 0.0,
            angle_deg: None,
            detector: detector.into(),
            detected: score >= 0.5,
            max_score: score,
            x1: None,
            y1: None,
            x2: None,
            y2: None,
            file: format!("{video}.mp4"),
        }
    }
}

/// Detected / total frame counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Accuracy {
    /// f_d: frames where the car was detected.
    pub detected: usize,
    /// f_o: frames scored.
    pub total: usize,
}

/// z for a two-sided 95 % interval.
pub const Z95: f64 = 1.959_963_984_540_054;

impl Accuracy {
    /// Counts detected frames in `records`.
    pub fn of<'a>(records: impl IntoIterator<Item = &'a FrameRecord>) -> Self {
        records.into_iter().fold(Accuracy::default(), |a, r| Accuracy {
            detected: a.detected + r.detected as usize,
            total: a.total + 1,
        })
    }

    /// A_physical in [0, 1]; `None` when no frame was scored.
    pub fn rate(&self) -> Option<f64> {
        (self.total > 0).then(|| self.detected as f64 / self.total as f64)
    }

    /// Wilson score interval at `z` (stays inside [0, 1] and is defined at 0 % and 100 %).
    pub fn wilson(&self, z: f64) -> Option<(f64, f64)> {
        let n = self.total as f64;
        let p = self.rate()?;
        let z2 = z * z;
        let denom = 1.0 + z2 / n;
        let centre = (p + z2 / (2.0 * n)) / denom;
        let half = z * (p * (1.0 - p) / n + z2 / (4.0 * n * n)).sqrt() / denom;
        Some(((centre - half).max(0.0), (centre + half).min(1.0)))
    }
}

/// Accuracy in one angular sector `[start, end)` degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AngleBin {
    /// Sector start in degrees.
    pub start_deg: f64,
    /// Sector end in degrees.
    pub end_deg: f64,
    /// Counts inside the sector.
    pub accuracy: Accuracy,
}

/// Splits 360° into `n` equal sectors and counts the records whose angle falls in each.
pub fn angle_bins<'a>(records: impl IntoIterator<Item = &'a FrameRecord>, n: usize) -> Vec<AngleBin> {
    let n = n.max(1);
    let width = 360.0 / n as f64;
    let mut bins: Vec<AngleBin> = (0..n)
        .map(|i| AngleBin {
            start_deg: i as f64 * width,
            end_deg: (i + 1) as f64 * width,
            accuracy: Accuracy::default(),
        })
        .collect();
    for r in records {
        if let Some(a) = r.angle_deg {
            let k = ((a.rem_euclid(360.0) / width) as usize).min(n - 1);
            bins[k].accuracy.total += 1;
            bins[k].accuracy.detected += r.detected as usize;
        }
    }
    bins
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(angle: f64, detected: bool) -> FrameRecord {
        FrameRecord {
            video: "v".into(),
            frame: 0,
            time_s: 0.0,
            angle_deg: Some(angle),
            detector: "d".into(),
            detected,
            max_score: 0.0,
            x1: None,
            y1: None,
            x2: None,
            y2: None,
            file: "v.mp4".into(),
        }
    }

    #[test]
    fn wilson_matches_reference_values() {
        // Reference: 8/10 -> (0.4902, 0.9433); 0/10 -> (0, 0.2775); 10/10 -> (0.7225, 1).
        let (lo, hi) = Accuracy { detected: 8, total: 10 }.wilson(Z95).unwrap();
        assert!((lo - 0.4902).abs() < 1e-4 && (hi - 0.9433).abs() < 1e-4, "{lo} {hi}");
        let (lo, hi) = Accuracy { detected: 0, total: 10 }.wilson(Z95).unwrap();
        assert!(lo.abs() < 1e-12 && (hi - 0.2775).abs() < 1e-4);
        let (lo, hi) = Accuracy { detected: 10, total: 10 }.wilson(Z95).unwrap();
        assert!((lo - 0.7225).abs() < 1e-4 && (hi - 1.0).abs() < 1e-12);
        assert_eq!(Accuracy::default().wilson(Z95), None);
    }

    #[test]
    fn bins_wrap_angles_and_skip_unknown() {
        let mut rs = vec![rec(10.0, true), rec(370.0, false), rec(-90.0, true), rec(359.999, true)];
        rs.push(FrameRecord { angle_deg: None, ..rec(0.0, true) });
        let b = angle_bins(&rs, 4);
        assert_eq!(b[0].accuracy, Accuracy { detected: 1, total: 2 });
        assert_eq!(b[3].accuracy, Accuracy { detected: 2, total: 2 });
        assert_eq!(Accuracy::of(&rs), Accuracy { detected: 4, total: 5 });
    }
}
