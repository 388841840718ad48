//! What a view folder records and how a render resumes: the manifest of views, `views.toml` and
//! the unfinished marker.

use super::*;
use pav_core::geometry::camera::Camera;
use serde::Deserialize;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// The manifest's columns. The camera (`eye`, `target`, `up`, `fov_deg`: `Camera::look_at` of
/// them) is in the normalized mesh file's own frame, the frame `pav optimize` loads it in.
pub const MANIFEST_HEADER: &str = "name,environment,image,mask,distance,elevation_deg,azimuth_deg,eye_x,eye_y,eye_z,\
target_x,target_y,target_z,up_x,up_y,up_z,fov_deg,size,samples,seconds,plate";

/// One manifest row.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
pub struct ViewRecord {
    /// View name.
    pub name: String,
    /// Environment name.
    pub environment: String,
    /// Image, relative to the view folder.
    pub image: PathBuf,
    /// pav's silhouette mask, relative to the view folder.
    pub mask: PathBuf,
    /// Camera distance (normalized units).
    pub distance: f32,
    /// Elevation, degrees.
    pub elevation_deg: f32,
    /// Azimuth, degrees.
    pub azimuth_deg: f32,
    /// Eye.
    pub eye_x: f32,
    /// Eye.
    pub eye_y: f32,
    /// Eye.
    pub eye_z: f32,
    /// Look-at point.
    pub target_x: f32,
    /// Look-at point.
    pub target_y: f32,
    /// Look-at point.
    pub target_z: f32,
    /// Up vector.
    pub up_x: f32,
    /// Up vector.
    pub up_y: f32,
    /// Up vector.
    pub up_z: f32,
    /// Field of view, degrees.
    pub fov_deg: f32,
    /// Image side.
    pub size: usize,
    /// Cycles samples (0: drawn by pav's rasterizer).
    pub samples: u32,
    /// The view's render time, seconds (Blender's, or the rasterizer's).
    pub seconds: f64,
    /// The photo whose background plate the car is laid over; empty over the environment
    /// (manifests written before plates lack the column).
    #[serde(default)]
    pub plate: String,
}

impl ViewRecord {
    /// The camera in the mesh file's normalized frame.
    pub fn camera(&self) -> Camera {
        Camera::look_at(
            [self.eye_x, self.eye_y, self.eye_z],
            [self.target_x, self.target_y, self.target_z],
            [self.up_x, self.up_y, self.up_z],
            self.fov_deg,
        )
    }
}

/// What a view folder was rendered from (`views.toml`), so a consumer can check that its own
/// mesh is the one in the pictures.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq)]
pub struct ViewSetInfo {
    /// The mesh file.
    pub obj: PathBuf,
    /// Its sha256 (folders rendered before it was recorded lack it), so the same mesh at
    /// another path (a data store elsewhere) is still recognized.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub obj_sha256: Option<String>,
    /// Its normalization.
    pub normalize: String,
    /// Its up axis.
    pub up: String,
    /// The body texture's sha256 (folders rendered before it was recorded lack it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_sha256: Option<String>,
    /// Whether the environment turned with the camera.
    #[serde(default)]
    pub turntable: bool,
    /// The rig whose turntable the views film, if any (its config).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig: Option<toml::Table>,
    /// What views of another rig must share to be resumed here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rig_key: Option<String>,
}

impl ViewSetInfo {
    /// Whether `obj` (a mesh file) is the mesh these views show: the same path, or the same
    /// bytes as the recorded hash or as the recorded file.
    pub fn shows(&self, obj: &Path) -> bool {
        let digest = |p: &Path| pav_run::data::store::file_digest(p).ok().map(|d| d.1);
        let ours = std::fs::canonicalize(obj).unwrap_or_else(|_| obj.to_path_buf());
        if self.obj == ours {
            return true;
        }
        let Some(sha) = digest(obj) else { return false };
        self.obj_sha256.as_ref().map_or_else(|| digest(&self.obj) == Some(sha.clone()), |s| *s == sha)
    }
}

/// The file a render keeps in its folder until every view it covers is written: a folder that
/// holds it is still being rendered, or its render was stopped, and lacks views.
pub const UNFINISHED: &str = "unfinished";

/// Whether `dir` holds a view set whose render finished (what `views.pbr` may name).
pub fn is_rendered(dir: &Path) -> bool {
    dir.join("views.toml").is_file() && !dir.join(UNFINISHED).exists()
}

/// A rendered view folder: its metadata and the manifest's rows. Refuses a folder whose render
/// has not finished, since training on part of a view set would pass without a word.
pub fn read_view_set(dir: &Path) -> Result<(ViewSetInfo, Vec<ViewRecord>), ViewsError> {
    if dir.join(UNFINISHED).exists() {
        return Err(ViewsError::Config {
            path: dir.into(),
            msg: "its render has not finished: rerun the `pav views` command that made it, which \
                  renders only the views still missing"
                .into(),
        });
    }
    let info_path = dir.join("views.toml");
    let text = std::fs::read_to_string(&info_path).map_err(io(&info_path))?;
    let info: ViewSetInfo =
        toml::from_str(&text).map_err(|e| ViewsError::Config { path: info_path.clone(), msg: e.to_string() })?;
    let manifest = manifest_path(dir);
    let rows = read_manifest(&manifest)?;
    if rows.is_empty() {
        return Err(ViewsError::Config { path: manifest, msg: "no views listed".into() });
    }
    Ok((info, rows))
}

/// The manifest of a view folder (a shard's folder has its own).
pub fn manifest_path(dir: &Path) -> PathBuf {
    dir.join("manifest.csv")
}

/// The rows of a manifest (a shard's or a merged one).
pub fn read_manifest(path: &Path) -> Result<Vec<ViewRecord>, ViewsError> {
    let bad = |e: csv::Error| ViewsError::Config { path: path.into(), msg: e.to_string() };
    csv::Reader::from_path(path).map_err(bad)?.deserialize().collect::<Result<Vec<ViewRecord>, _>>().map_err(bad)
}

/// Appends one row to a manifest (its header is already there).
pub(super) fn append_row(path: &Path, row: &ViewRecord) -> Result<(), ViewsError> {
    let file = std::fs::OpenOptions::new().append(true).open(path).map_err(io(path))?;
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(file);
    w.serialize(row)
        .and_then(|_| w.flush().map_err(csv::Error::from))
        .map_err(|e| ViewsError::Config { path: path.into(), msg: e.to_string() })
}

/// Writes a whole manifest, its header and `rows`, at once (`durable::write_with`): a kill in
/// mid-write leaves the old manifest, never a header without its rows.
pub(super) fn write_manifest(path: &Path, rows: &[ViewRecord]) -> Result<(), ViewsError> {
    pav_core::durable::write_with(path, |f| {
        use std::io::Write as _;
        writeln!(f, "{MANIFEST_HEADER}")?;
        let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(f);
        for r in rows {
            w.serialize(r).map_err(std::io::Error::other)?;
        }
        w.flush()
    })
    .map_err(io(path))
}

/// Names in a manifest whose image exists (what a resumed run skips). A manifest missing is an
/// empty one; a row cut short by a kill in mid-write is dropped first, so the next row does not
/// run into it, and an older header is brought up to date.
pub fn rendered(manifest: &Path, dir: &Path) -> Result<HashSet<String>, ViewsError> {
    let Ok(text) = std::fs::read_to_string(manifest) else { return Ok(HashSet::new()) };
    if !text.ends_with('\n') {
        let keep = text.rfind('\n').map_or(0, |i| i + 1);
        pav_core::durable::write(manifest, &text[..keep]).map_err(io(manifest))?;
    }
    let rows = read_manifest(manifest)?;
    if text.lines().next().is_some_and(|h| h != MANIFEST_HEADER) {
        // Written before a column was added: rewritten under today's header so new rows fit.
        write_manifest(manifest, &rows)?;
    }
    Ok(rows.into_iter().filter(|r| dir.join(&r.image).exists()).map(|r| r.name).collect())
}
