//! Simulated turntable videos: views rendered with the environment turning with the camera
//! (`render.turntable`), so each shows the car turned on a table in a fixed room, cut into one
//! video per environment, distance and elevation, with the angle sidecar `pav-rig evaluate`
//! reads. The result is simulated, not predicted: nothing here is calibrated against a capture.

use super::views::{read_manifest, ViewRecord, ViewSetInfo, ViewsError};
use crate::image::{to_u8, Frame, Rgb};
use crate::sidecar::{self, AngleSample};
use crate::video::VideoWriter;
use std::path::{Path, PathBuf};

/// One video written.
#[derive(Clone, Debug, PartialEq)]
pub struct TurntableVideo {
    /// The MP4; its sidecar is [`sidecar::sidecar_path`] of it.
    pub path: PathBuf,
    /// Environment name.
    pub environment: String,
    /// Camera distance (normalized mesh units).
    pub distance: f32,
    /// Camera elevation (the paper's polar angle), degrees.
    pub elevation_deg: f32,
    /// Frames, one per view, in angle order.
    pub frames: usize,
}

fn io(p: &Path) -> impl Fn(std::io::Error) -> ViewsError + '_ {
    move |source| ViewsError::Io { path: p.into(), source }
}

fn refuse(p: &Path, msg: String) -> ViewsError {
    ViewsError::Config { path: p.into(), msg }
}

/// Writes `DIR/videos/<environment>_d<distance>_e<elevation>.mp4` and its sidecar for each
/// group of views in `dir`'s manifest, frames in azimuth order, a turn taking `period_s`
/// seconds (the table's angle is the view's azimuth). Refuses a view set whose environment did
/// not turn with the camera: going round a car in a fixed room is not a turntable.
pub fn write_videos(dir: &Path, period_s: f64) -> Result<Vec<TurntableVideo>, ViewsError> {
    let info_path = dir.join("views.toml");
    let text = std::fs::read_to_string(&info_path).map_err(io(&info_path))?;
    let info: ViewSetInfo = toml::from_str(&text).map_err(|e| refuse(&info_path, e.to_string()))?;
    if !info.turntable {
        return Err(refuse(
            &info_path,
            "these views went round a car in a fixed room, not a car turned in it: render them with \
             render.turntable = true (pav views turntable does)"
                .into(),
        ));
    }
    if !(period_s.is_finite() && period_s > 0.0) {
        return Err(refuse(dir, format!("a turn of {period_s} s is no turn")));
    }
    let manifest = dir.join("manifest.csv");
    let rows = read_manifest(&manifest)?;
    let mut groups: Vec<Vec<ViewRecord>> = Vec::new();
    for r in rows {
        let same = |g: &Vec<ViewRecord>| {
            let f = &g[0];
            f.environment == r.environment && f.distance == r.distance && f.elevation_deg == r.elevation_deg
        };
        match groups.iter_mut().find(|g| same(g)) {
            Some(g) => g.push(r),
            None => groups.push(vec![r]),
        }
    }
    let out_dir = dir.join("videos");
    std::fs::create_dir_all(&out_dir).map_err(io(&out_dir))?;
    let mut out = Vec::new();
    for mut g in groups {
        g.sort_by(|a, b| a.azimuth_deg.total_cmp(&b.azimuth_deg));
        if let Some(w) = g.windows(2).find(|w| w[0].azimuth_deg == w[1].azimuth_deg) {
            return Err(refuse(&manifest, format!("views {} and {} share an azimuth", w[0].name, w[1].name)));
        }
        let f = &g[0];
        let name = format!("{}_d{:.2}_e{:.0}", f.environment, f.distance, f.elevation_deg);
        let path = out_dir.join(format!("{name}.mp4"));
        let fps = g.len() as f64 / period_s;
        let mut video: Option<VideoWriter> = None;
        let side = sidecar::sidecar_path(&path);
        let mut angles = sidecar::Writer::create(&side)?;
        for (i, r) in g.iter().enumerate() {
            let img = Rgb::load(&dir.join(&r.image))?;
            let frame = Frame {
                width: img.width,
                height: img.height,
                bgr: img.rgb.chunks_exact(3).flat_map(|p| [to_u8(p[2]), to_u8(p[1]), to_u8(p[0])]).collect(),
            };
            let v = match &mut video {
                Some(v) => v,
                None => video.insert(VideoWriter::create(&path, ['a', 'v', 'c', '1'], fps, (img.width, img.height))?),
            };
            v.write(&frame)?;
            let s = AngleSample {
                frame: i,
                timestamp_s: i as f64 / fps,
                angle_deg: f64::from(r.azimuth_deg).rem_euclid(360.0),
            };
            angles.push(s)?;
        }
        if let Some(v) = video {
            v.finish()?;
        }
        out.push(TurntableVideo {
            path,
            environment: f.environment.clone(),
            distance: f.distance,
            elevation_deg: f.elevation_deg,
            frames: g.len(),
        });
    }
    Ok(out)
}
