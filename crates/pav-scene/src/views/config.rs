//! The views config's schema (`configs/views/*.toml`), its loading and checks, and the mesh it names.

use super::*;
use crate::blender::TableTop;
use pav_core::geometry::camera::{Camera, CameraConvention};
use pav_core::geometry::mesh::Mesh;
use serde::Deserialize;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

/// How the mesh is normalized (which fixes the units of the pose grid).
#[derive(Clone, Copy, Debug, Default, Deserialize, serde::Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Normalize {
    /// PAV-Camou: vertex-mean centring, max-abs scaling.
    #[default]
    Pav,
    /// neural_renderer (FCA, DAS): bounding box centred, longest side 2.
    Bbox,
}

/// The car.
#[derive(Clone, Debug, Deserialize, serde::Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ViewMesh {
    /// OBJ with UVs.
    pub obj: PathBuf,
    /// Normalization.
    #[serde(default)]
    pub normalize: Normalize,
    /// The file's up axis: `+y` (pav's own), `-y`, `+z`, `-z`, `+x`, `-x`.
    #[serde(default = "plus_y")]
    pub up: String,
    /// Body texture; default: the first `map_Kd` of the mesh's materials.
    #[serde(default)]
    pub texture: Option<PathBuf>,
}

fn plus_y() -> String {
    "+y".into()
}

/// An effect the PBR render simulates; everything not listed is off.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Hash, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum PbrEffect {
    /// A shadow-catcher ground plane under the car.
    Shadows,
    /// Glossy paint (metallic flakes and a clear coat) reflecting the environment; without it
    /// the paint is diffuse.
    Reflections,
}

/// Image settings.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Image side in pixels (square).
    pub size: usize,
    /// Cycles samples per pixel (the rasterizer takes none).
    #[serde(default)]
    pub samples: u32,
    /// Effects to simulate.
    #[serde(default)]
    pub effects: Vec<PbrEffect>,
    /// The environment turns with the camera, so each view shows the car turned on a turntable
    /// in a fixed room, the table's angle being the view's azimuth (`pav views turntable`).
    #[serde(default)]
    pub turntable: bool,
    /// What draws the views.
    #[serde(default)]
    pub renderer: Renderer,
}

/// What draws a view set.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq, serde::Serialize, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Renderer {
    /// Blender Cycles: path-traced under the environment, with the listed effects.
    #[default]
    Cycles,
    /// pav's rasterizer: the body texture Phong-shaded under one room light and drawn at twice
    /// the size then averaged down; no environment light and no effects, but no Blender either
    /// and milliseconds a view (the low end of what a training view's fidelity costs).
    Rasterizer,
}

/// A lighting environment.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// A studio light name (`city`, `courtyard`, `forest`, `interior`, `night`, `studio`,
    /// `sunrise`, `sunset`) or a path to an .exr/.hdr map.
    pub name: String,
    /// Brightness multiplier.
    #[serde(default = "one")]
    pub strength: f64,
}

fn one() -> f64 {
    1.0
}

/// A grid of cameras on spheres around a target, looking at it with +Y up.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseGrid {
    /// Camera distances (normalized mesh units).
    pub distances: Vec<f32>,
    /// Elevations above the horizon, degrees.
    pub elevations: Vec<f32>,
    /// Azimuths, degrees.
    #[serde(default)]
    pub azimuths: Vec<f32>,
    /// Or every this many degrees from 0.
    #[serde(default)]
    pub azimuth_step: Option<f32>,
    /// Field of view, degrees.
    #[serde(default = "sixty")]
    pub fov_deg: f32,
    /// Look-at point.
    #[serde(default)]
    pub target: [f32; 3],
    /// Only these of the config's environments (by name) draw this grid; empty: all of them.
    #[serde(default)]
    pub environments: Vec<String>,
}

/// Whether a grid or the plates that name `only` (empty: every environment) draw in `env`.
pub(super) fn takes(only: &[String], env: &str) -> bool {
    only.is_empty() || only.iter().any(|e| e == env)
}

fn sixty() -> f32 {
    60.0
}

fn unmoved() -> Vec<f32> {
    vec![1.0]
}

/// Background plates: real photos with their car painted out, the rendered car laid over them.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Plates {
    /// FCA-format CARLA samples (`.npz`: photo and poses).
    pub photos: Vec<PathBuf>,
    /// The camera convention that fits the mesh to the samples' poses.
    pub camera: CameraConvention,
    /// Turns of the car in place, degrees (0: the photo's own pose).
    pub turns: Vec<f32>,
    /// The car moved along the ground, straight away from the camera, to these multiples of its
    /// distance in the photo (1: where it stood; needs `camera = "fca"`).
    #[serde(default = "unmoved")]
    pub distances: Vec<f32>,
    /// Pixels the painted-out hole extends past the car's silhouette (default: size / 50),
    /// since the fitted cameras are off by a few pixels at the edge.
    #[serde(default)]
    pub grow_px: Option<usize>,
    /// Each photo's (camera, vehicle) CARLA poses, read by [`ViewsConfig::load`].
    #[serde(skip)]
    pub poses: Vec<[[[f64; 3]; 2]; 2]>,
    /// The photos as the config names them (`data:` paths stay machine-independent).
    #[serde(skip)]
    pub sources: Vec<String>,
    /// Only these of the config's environments (by name) light the plates; empty: all of them.
    #[serde(default)]
    pub environments: Vec<String>,
}

/// A `pav views render` config.
#[derive(Clone, Debug, Deserialize, PartialEq, serde::Serialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ViewsConfig {
    /// The car.
    pub mesh: ViewMesh,
    /// Image settings and effects.
    pub render: RenderSettings,
    /// Lighting environments (every pose is rendered in each).
    pub environments: Vec<Environment>,
    /// Camera grids.
    #[serde(default)]
    pub poses: Vec<PoseGrid>,
    /// Background plates.
    #[serde(default)]
    pub plates: Option<Plates>,
    /// The rig whose turntable these views film (set by `RigConfig::views_config`): its table,
    /// backdrop and sticker replace the ground and the car paint.
    #[serde(skip)]
    pub rig: Option<Box<RigScene>>,
}

/// What a rig changes in a render, and what a view folder records of it.
#[derive(Clone, Debug, PartialEq)]
pub struct RigScene {
    /// The sticker's roughness, specular level and clear coat (metallic 0).
    pub surface: [f32; 3],
    /// What camera rays see behind the table, sRGB.
    pub backdrop: [f32; 3],
    /// The table top.
    pub table: TableTop,
    /// Rows of the square render the frame keeps (its centre rows).
    pub rows: usize,
    /// The rig config as TOML, for `views.toml` (the videos are cut with its effects).
    pub record: toml::Table,
    /// What two rigs must share to share rendered views (not their camera effects).
    pub key: String,
}

/// One view to render.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// Unique name, also the file stem.
    pub name: String,
    /// Index into the config's environments.
    pub environment: usize,
    /// Distance, elevation and azimuth (units, degrees, degrees).
    pub pose: [f32; 3],
    /// Look-at point, in pav's frame.
    pub target: [f32; 3],
    /// The camera, in pav's frame (+Y up), as Blender and the mask see it.
    pub camera: Camera,
    /// Degrees the environment turns with the camera: the azimuth on a turntable, else 0.
    pub env_turn_deg: f32,
    /// Index into the plates' photos of the background it is laid over, if any.
    pub plate: Option<usize>,
}

/// `R·p`: a mesh-file-frame vector in pav's frame.
pub(super) fn rotate(r: &[[f32; 3]; 3], p: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|k| r[k][0] * p[0] + r[k][1] * p[1] + r[k][2] * p[2])
}

/// `R^T·p`: a pav-frame vector in the mesh file's frame (the rotation is orthonormal).
pub(super) fn unrotate(r: &[[f32; 3]; 3], p: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|k| r[0][k] * p[0] + r[1][k] * p[1] + r[2][k] * p[2])
}

impl ViewsConfig {
    /// Reads a config; relative paths are taken from the config's folder.
    pub fn load(path: &Path) -> Result<ViewsConfig, ViewsError> {
        let err = |msg: String| ViewsError::Config { path: path.into(), msg };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        let mut c: ViewsConfig = toml::from_str(&text).map_err(|e| err(e.to_string()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let resolve = |p: &Path| pav_run::data::resolve(dir, p).map_err(|e| err(e.to_string()));
        c.mesh.obj = resolve(&c.mesh.obj)?;
        c.mesh.texture = c.mesh.texture.as_deref().map(resolve).transpose()?;
        for e in &mut c.environments {
            if e.name.contains('/') || e.name.contains('.') {
                e.name = resolve(Path::new(&e.name))?.display().to_string();
            }
        }
        if let Some(pl) = &mut c.plates {
            for p in &mut pl.photos {
                pl.sources.push(p.display().to_string());
                *p = resolve(p)?;
                let sample = pav_dataset::fca::CarlaSample::load(p).map_err(|e| err(e.to_string()))?;
                pl.poses.push([sample.cam_trans, sample.veh_trans]);
            }
        }
        c.check().map_err(err)?;
        Ok(c)
    }

    /// Refuses configs that would render nothing or something else than asked.
    pub fn check(&self) -> Result<(), String> {
        let r = &self.render;
        match r.renderer {
            Renderer::Cycles if r.size < 8 || r.samples == 0 => {
                return Err(format!(
                    "render: size {} and samples {}: need size ≥ 8 and samples ≥ 1",
                    r.size, r.samples
                ));
            }
            Renderer::Cycles => {}
            Renderer::Rasterizer => {
                if r.size < 8 {
                    return Err(format!("render: size {}: need size ≥ 8", r.size));
                }
                if r.samples != 0 {
                    return Err("render.samples: the rasterizer takes no samples (it draws at twice the size and averages down)".into());
                }
                if !r.effects.is_empty() {
                    return Err(format!(
                        "render.effects {:?}: the rasterizer simulates none of them; drop them, or render with Cycles",
                        r.effects
                    ));
                }
                if r.turntable || self.rig.is_some() {
                    return Err(
                        "the rasterizer draws no turntable here: `pav views turntable --rasterizer` does".into()
                    );
                }
                if self.environments.len() != 1 {
                    return Err(format!(
                        "the rasterizer lights the car with one room light whatever the environment, so {} environments would draw the same views: list one (it names the views)",
                        self.environments.len()
                    ));
                }
            }
        }
        if self.environments.is_empty() || (self.poses.is_empty() && self.plates.is_none()) {
            return Err("list at least one [[environments]] and one [[poses]] or [plates]".into());
        }
        if let Some(pl) = &self.plates {
            if pl.photos.is_empty() || pl.turns.is_empty() {
                return Err("plates: list at least one photo and one turn".into());
            }
            if pl.poses.len() != pl.photos.len() {
                return Err("plates: the photos' poses are not read (load the config with ViewsConfig::load)".into());
            }
            if pl.turns.iter().any(|t| !t.is_finite()) {
                return Err("plates: turns must be finite".into());
            }
            if pl.distances.is_empty() || pl.distances.iter().any(|d| !(0.7..=3.0).contains(d)) {
                return Err(format!(
                    "plates: distances {:?}: list factors from 0.7 to 3 (nearer, the camera can stand over the car in FCA's poses)",
                    pl.distances
                ));
            }
            if pl.distances.iter().any(|&d| d != 1.0) && !pl.camera.keeps_moved_cars() {
                return Err(format!(
                    "plates: distances other than 1 need camera = \"fca\": under {:?} the camera's elevation comes from its pitch and would not follow the moved car",
                    pl.camera
                ));
            }
        }
        up_rotation(&self.mesh.up)?;
        for (i, p) in self.poses.iter().enumerate() {
            let az = p.azimuths.len() + usize::from(p.azimuth_step.is_some());
            if p.distances.is_empty() || p.elevations.is_empty() || az == 0 {
                return Err(format!("poses #{}: needs distances, elevations and azimuths or azimuth_step", i + 1));
            }
            if p.distances.iter().any(|d| !(d.is_finite() && *d > 0.0)) {
                return Err(format!("poses #{}: distances must be positive", i + 1));
            }
            if p.azimuth_step.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
                return Err(format!("poses #{}: azimuth_step must be positive", i + 1));
            }
            if !(p.fov_deg > 1.0 && p.fov_deg < 170.0) {
                return Err(format!("poses #{}: fov_deg {} is not a field of view", i + 1, p.fov_deg));
            }
        }
        let names: Vec<String> = (0..self.environments.len()).map(|i| self.environment_name(i)).collect();
        let grids = self.poses.iter().enumerate().map(|(i, p)| (format!("poses #{}", i + 1), &p.environments));
        for (what, only) in grids.chain(self.plates.iter().map(|p| ("plates".to_string(), &p.environments))) {
            if let Some(e) = only.iter().find(|e| !names.contains(e)) {
                return Err(format!(
                    "{what}: environment `{e}` is not among the [[environments]] ({})",
                    names.join(", ")
                ));
            }
        }
        if let Some(e) = names.iter().find(|e| !self.draws(e)) {
            return Err(format!(
                "environment `{e}` draws no view: every [[poses]] and [plates] lists `environments` without it"
            ));
        }
        let mut seen = HashSet::new();
        if let Some(v) = self.views().into_iter().find(|v| !seen.insert(v.name.clone())) {
            return Err(format!("view {} comes twice (an environment listed twice, or grids that overlap)", v.name));
        }
        Ok(())
    }

    /// The environment map file of environment `i`.
    pub fn environment_path(&self, i: usize) -> Result<PathBuf, String> {
        let name = &self.environments[i].name;
        let p =
            if name.contains('/') { PathBuf::from(name) } else { Path::new(STUDIO_LIGHTS).join(format!("{name}.exr")) };
        if p.exists() {
            Ok(p)
        } else {
            Err(format!(
                "environment `{name}`: {} does not exist (studio lights: city, courtyard, forest, interior, night, studio, sunrise, sunset)",
                p.display()
            ))
        }
    }

    /// The name views and the manifest give environment `i`: a studio light's name, or a map
    /// file's stem.
    pub fn environment_name(&self, i: usize) -> String {
        environment_stem(&self.environments[i].name)
    }

    /// The mesh in pav's world frame: up axis turned to +Y, then normalized.
    pub fn load_mesh(&self) -> Result<Mesh, ViewsError> {
        // The loader refuses a face corner without a UV index.
        let mut m = Mesh::load_obj(&self.mesh.obj)?;
        let r = up_rotation(&self.mesh.up).expect("checked by load");
        for p in m.positions.iter_mut().chain(m.normals.iter_mut()) {
            *p = rotate(&r, *p);
        }
        match self.mesh.normalize {
            Normalize::Pav => {
                m.normalize();
            }
            Normalize::Bbox => m.normalize_bbox(),
        }
        Ok(m)
    }

    /// The body texture: the config's, else the mesh's first `map_Kd`.
    pub fn texture(&self, mesh: &Mesh) -> Result<PathBuf, ViewsError> {
        self.mesh.texture.clone().or_else(|| mesh.materials.iter().find_map(|m| m.map_kd.clone())).ok_or_else(|| {
            ViewsError::Config {
                path: self.mesh.obj.clone(),
                msg: "no texture: set mesh.texture (the mesh names no map_Kd)".into(),
            }
        })
    }
}

/// The name views, manifests and videos give an environment: a studio light's name, or a map
/// file's stem.
pub fn environment_stem(name: &str) -> String {
    Path::new(name).file_stem().map_or(name.to_string(), |s| s.to_string_lossy().into())
}

/// The rotation taking a file whose up axis is `up` to pav's +Y up (a proper rotation, so the
/// mesh is never mirrored).
pub fn up_rotation(up: &str) -> Result<[[f32; 3]; 3], String> {
    Ok(match up {
        "+y" => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        "-y" => [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        "+z" => [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]],
        "-z" => [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
        "+x" => [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        "-x" => [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        other => return Err(format!("mesh.up `{other}`: use +y, -y, +z, -z, +x or -x")),
    })
}
