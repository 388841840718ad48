//! Physically based training and test views rendered by Blender Cycles, run headless.
//!
//! pav computes every camera itself ([`pav_core::geometry::camera`]) and hands Blender the mesh
//! already in its own world frame, so the two renderers share one camera convention by
//! construction; [`super::align`] checks that they agree to the pixel. A config lists the mesh,
//! the pose grid, the environments and the effects; only listed effects are simulated.
//!
//! ```toml
//! [mesh]
//! obj = "data:pav-camou/xfl_yxz.obj"
//! normalize = "pav"            # PAV-Camou's (vertex mean, max-abs) or "bbox" (FCA/DAS)
//! up = "+y"                    # the file's up axis; pav's world is +Y up
//! texture = "paint.png"        # body texture; default: the mesh's first map_Kd
//!
//! [render]
//! size = 416
//! samples = 32
//! effects = ["shadows"]        # "shadows" (a shadow-catcher ground), "reflections" (clear coat)
//!
//! [[environments]]             # a Blender studio light by name, or an .exr/.hdr path
//! name = "city"
//!
//! [[poses]]                    # distances in normalized mesh units, angles in degrees
//! distances = [2.2]
//! elevations = [10, 30]
//! azimuth_step = 90            # or azimuths = [...]
//!
//! [plates]                     # and/or: the car over real photos with their car painted out
//! photos = ["data:fca/carla_dataset/train/data1.npz"]
//! camera = "fca"               # the convention that fits the mesh to the photos' CARLA poses
//! turns = [-30, 0, 30]         # the car turned in place on the plate's ground, degrees
//! distances = [1.0, 1.4]       # and moved away along it (× the camera's distance; default [1])
//! ```
//!
//! A grid or the plates may name `environments = ["courtyard"]`: only those of the config's
//! environments draw it (by default all do), so one config mixes kinds of views.
//!
//! A plate view is Cycles' car with its caught shadow on a transparent film (`<name>_car.png`),
//! laid over the photo's [`pav_render::bake::Plate`] at the photo's own camera with the car
//! turned, so background, camera and ground are real and only the car is rendered. The
//! environment then only lights the car; the photo's own car shadow stays on the plate.

use super::blender::{Blender, BlenderError, Job, JobView, Mode, TableTop};
use pav_core::geometry::camera::{moved_away, spherical, Camera, CameraConvention};
use pav_core::geometry::mesh::{Mesh, MeshError};
use pav_core::image::resize::{resize, Interpolation};
use pav_core::image::{halve, Frame, Rgb};
use pav_core::progress::Progress;
use pav_render::bake::Plate;
use pav_render::raster::{GBuffer, EMPTY};
use pav_render::shade::{draw_textured, Lights};
use pav_run::shard::{Shard, ShardError};
use serde::Deserialize;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

/// Where Debian's `blender` package puts its HDR environments.
pub const STUDIO_LIGHTS: &str = "/usr/share/blender/datafiles/studiolights/world";

/// The studio lights Blender ships, by name.
pub const STUDIO_LIGHT_NAMES: &[&str] =
    &["city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset"];

/// Errors making views.
#[derive(Debug, thiserror::Error)]
pub enum ViewsError {
    /// The config file could not be read or parsed.
    #[error("{path}: {msg}")]
    Config {
        /// Config file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// The mesh could not be used.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// Blender could not render.
    #[error(transparent)]
    Blender(#[from] BlenderError),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// An image could not be written.
    #[error(transparent)]
    Image(#[from] pav_core::image::ImageError),
    /// A turntable video could not be written.
    #[cfg(feature = "video")]
    #[error(transparent)]
    Video(#[from] pav_core::video::VideoError),
    /// Its angle sidecar could not be written.
    #[error(transparent)]
    Sidecar(#[from] pav_core::sidecar::SidecarError),
    /// Shards of a view set that cannot be joined.
    #[error(transparent)]
    Shard(#[from] ShardError),
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ViewsError + '_ {
    move |source| ViewsError::Io { path: path.into(), source }
}

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
fn takes(only: &[String], env: &str) -> bool {
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
fn rotate(r: &[[f32; 3]; 3], p: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|k| r[k][0] * p[0] + r[k][1] * p[1] + r[k][2] * p[2])
}

/// `R^T·p`: a pav-frame vector in the mesh file's frame (the rotation is orthonormal).
fn unrotate(r: &[[f32; 3]; 3], p: [f32; 3]) -> [f32; 3] {
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

    /// Whether environment `name` draws any view (a grid or the plates take it).
    fn draws(&self, name: &str) -> bool {
        self.poses.iter().any(|g| takes(&g.environments, name))
            || self.plates.as_ref().is_some_and(|p| takes(&p.environments, name))
    }

    /// Every view of the config, in a fixed order: environments, then grids, distances,
    /// elevations, azimuths.
    pub fn views(&self) -> Vec<View> {
        let mut out = Vec::new();
        for ei in 0..self.environments.len() {
            let env_name = self.environment_name(ei);
            for g in self.poses.iter().filter(|g| takes(&g.environments, &env_name)) {
                let mut az = g.azimuths.clone();
                if let Some(step) = g.azimuth_step {
                    az.extend((0..).map(|k| k as f32 * step).take_while(|a| *a < 360.0 - 1e-3));
                }
                for &d in &g.distances {
                    for &e in &g.elevations {
                        for &a in &az {
                            let name = format!("{env_name}_d{d:.2}_e{e:.0}_a{a:05.1}");
                            let eye = spherical(d, e, a);
                            let eye = [eye[0] + g.target[0], eye[1] + g.target[1], eye[2] + g.target[2]];
                            let camera = Camera::look_at(eye, g.target, [0.0, 1.0, 0.0], g.fov_deg);
                            let env_turn_deg = if self.render.turntable { a } else { 0.0 };
                            out.push(View {
                                name,
                                environment: ei,
                                pose: [d, e, a],
                                target: g.target,
                                camera,
                                env_turn_deg,
                                plate: None,
                            });
                        }
                    }
                }
            }
            out.extend(self.plate_views(ei));
        }
        out
    }

    /// The camera of plate `pi` with the car turned by `turn` degrees and moved away to
    /// `distance` times its distance, in pav's frame.
    pub fn plate_camera(&self, pi: usize, turn: f32, distance: f32) -> Camera {
        let pl = self.plates.as_ref().expect("plate_camera needs plates");
        let r = up_rotation(&self.mesh.up).expect("checked by load");
        let [cam, veh] = pl.poses[pi];
        let c = pl.camera.camera(moved_away(cam, distance as f64), veh, turn as f64);
        Camera { axes: c.axes.map(|a| rotate(&r, a)), eye: rotate(&r, c.eye), ..c }
    }

    /// The plate views in environment `ei`: every photo, every turn and distance, at the photo's
    /// camera. A view at distance 1 keeps the name it had before distances existed, so renders resume.
    fn plate_views(&self, ei: usize) -> Vec<View> {
        let Some(pl) = &self.plates else { return Vec::new() };
        let env_name = self.environment_name(ei);
        if !takes(&pl.environments, &env_name) {
            return Vec::new();
        }
        let mut out = Vec::new();
        for (pi, photo) in pl.photos.iter().enumerate() {
            let stem = photo.file_stem().map_or_else(|| format!("plate{pi}"), |s| s.to_string_lossy().into());
            for (&dist, &turn) in pl.distances.iter().flat_map(|d| pl.turns.iter().map(move |t| (d, t))) {
                let camera = self.plate_camera(pi, turn, dist);
                let e = camera.eye;
                let d = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
                // A look-at point on the optical axis, as far as the car's centre.
                let target = [0, 1, 2].map(|k| e[k] + camera.axes[2][k] * d);
                out.push(View {
                    name: if dist == 1.0 {
                        format!("{env_name}_{stem}_t{turn:+.0}")
                    } else {
                        format!("{env_name}_{stem}_t{turn:+.0}_d{dist:.2}")
                    },
                    environment: ei,
                    pose: [d, (e[1] / d).asin().to_degrees(), e[0].atan2(e[2]).to_degrees().rem_euclid(360.0)],
                    target,
                    camera,
                    env_turn_deg: 0.0,
                    plate: Some(pi),
                });
            }
        }
        out
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
fn append_row(path: &Path, row: &ViewRecord) -> Result<(), ViewsError> {
    let file = std::fs::OpenOptions::new().append(true).open(path).map_err(io(path))?;
    let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(file);
    w.serialize(row)
        .and_then(|_| w.flush().map_err(csv::Error::from))
        .map_err(|e| ViewsError::Config { path: path.into(), msg: e.to_string() })
}

/// Writes a whole manifest, its header and `rows`, at once (`durable::write_with`): a kill in
/// mid-write leaves the old manifest, never a header without its rows.
fn write_manifest(path: &Path, rows: &[ViewRecord]) -> Result<(), ViewsError> {
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

/// What a `render_views` run did.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSummary {
    /// Views this run (or shard) covers.
    pub total: usize,
    /// Of them, already rendered by an earlier run.
    pub resumed: usize,
    /// Rendered now.
    pub rendered: usize,
    /// The manifest written.
    pub manifest: PathBuf,
}

/// Renders the config's views (only a shard's, when given) into `dir`: per view
/// `views/<name>.png` (by Cycles through `blender`, or by pav's rasterizer when the config says
/// so) and `views/<name>_mask.png` (the car's silhouette from pav's rasterizer, which the
/// alignment test ties to Blender's), and a manifest row written as each view finishes, so a
/// crash loses at most the view in progress and a rerun resumes.
pub fn render_views(
    cfg: &ViewsConfig,
    dir: &Path,
    shard: Option<Shard>,
    blender: Option<&Blender>,
    progress: &dyn Progress,
) -> Result<RenderSummary, ViewsError> {
    let mesh = cfg.load_mesh()?;
    let texture = cfg.texture(&mesh)?;
    let tex = pav_core::image::Rgb::load(&texture)?;
    // Cycles' environments are found before anything is written.
    let cycles = match cfg.render.renderer {
        Renderer::Cycles => {
            let blender = blender
                .ok_or_else(|| ViewsError::Config { path: dir.into(), msg: "Cycles views need Blender".into() })?;
            let envs: Vec<PathBuf> = (0..cfg.environments.len())
                .map(|i| cfg.environment_path(i))
                .collect::<Result<_, _>>()
                .map_err(|msg| ViewsError::Config { path: dir.into(), msg })?;
            Some((blender, envs))
        }
        Renderer::Rasterizer => None,
    };
    let views_dir = dir.join("views");
    std::fs::create_dir_all(&views_dir).map_err(io(&views_dir))?;
    let obj = dir.join("mesh.obj");
    mesh.write_obj(&obj, None).map_err(io(&obj))?;
    let info = ViewSetInfo {
        obj: std::fs::canonicalize(&cfg.mesh.obj).map_err(io(&cfg.mesh.obj))?,
        obj_sha256: Some(pav_run::data::store::file_digest(&cfg.mesh.obj).map_err(io(&cfg.mesh.obj))?.1),
        normalize: format!("{:?}", cfg.mesh.normalize).to_lowercase(),
        up: cfg.mesh.up.clone(),
        texture_sha256: Some(pav_run::data::store::file_digest(&texture).map_err(io(&texture))?.1),
        turntable: cfg.render.turntable,
        rig: cfg.rig.as_ref().map(|r| r.record.clone()),
        rig_key: cfg.rig.as_ref().map(|r| r.key.clone()),
    };
    let info_path = dir.join("views.toml");
    let info_text = toml::to_string(&info).expect("view set info serializes");
    let other = || ViewsError::Config {
        path: info_path.clone(),
        msg: "this folder holds views of another mesh or frame: use another output folder".into(),
    };
    match std::fs::read_to_string(&info_path) {
        Ok(old) => {
            let old: ViewSetInfo = toml::from_str(&old).map_err(|_| other())?;
            if !(old.shows(&cfg.mesh.obj) && old.normalize == info.normalize && old.up == info.up) {
                return Err(other());
            }
            // Resuming would mix two paints, or cars turned and not turned, in one set.
            let same_rig = old.rig_key == info.rig_key;
            if old.texture_sha256.as_ref().is_some_and(|t| Some(t) != info.texture_sha256.as_ref())
                || old.turntable != info.turntable
                || !same_rig
            {
                return Err(ViewsError::Config {
                    path: info_path.clone(),
                    msg: "this folder holds views with another texture, turntable setting or rig: use another output folder"
                        .into(),
                });
            }
        }
        Err(_) => pav_core::durable::write(&info_path, &info_text).map_err(io(&info_path))?,
    }
    // A rig's camera effects may differ from the folder's: the videos are cut with these.
    if info.rig.is_some() {
        pav_core::durable::write(&info_path, &info_text).map_err(io(&info_path))?;
    }
    let rot = up_rotation(&cfg.mesh.up).expect("checked by load");
    let all = cfg.views();
    let mine: Vec<&View> = match shard {
        Some(s) => all.iter().enumerate().filter(|(i, _)| s.picks(*i)).map(|(_, v)| v).collect(),
        None => all.iter().collect(),
    };
    let unfinished = dir.join(UNFINISHED);
    std::fs::write(
        &unfinished,
        "a render into this folder has not finished; rerun it to render the views still missing\n",
    )
    .map_err(io(&unfinished))?;
    let manifest = manifest_path(dir);
    let done = rendered(&manifest, dir)?;
    if std::fs::metadata(&manifest).map_or(true, |m| m.len() == 0) {
        write_manifest(&manifest, &[])?;
    }
    let total = mine.len();
    let resumed = mine.iter().filter(|v| done.contains(&v.name)).count();
    progress.begin("rendering views", total as u64);
    progress.set_position(resumed as u64);
    let mut writer =
        ViewWriter { cfg, mesh: &mesh, rot, views_dir: &views_dir, manifest: &manifest, plates: HashMap::new() };
    let mut rendered_now = 0;
    let mut advance = |name: &str, secs: f64| {
        rendered_now += 1;
        progress.advance(1);
        progress.status(&format!("{name}: {secs:.1} s"));
    };
    let todo: Vec<&View> = mine.iter().copied().filter(|v| !done.contains(&v.name)).collect();
    match cycles {
        None => {
            let normals = pav_render::shade::vertex_normals(&mesh);
            let n = cfg.render.size;
            for v in todo {
                let t = std::time::Instant::now();
                let (g, mut rgb) = draw_textured(&mesh, &normals, &tex, &v.camera, &Lights::ROOM, 2 * n);
                let mut cover = vec![0f32; rgb.len()];
                for (i, f) in g.face.iter().enumerate() {
                    if *f != EMPTY {
                        cover[3 * i..3 * i + 3].fill(1.0);
                        rgb[3 * i..3 * i + 3].iter_mut().for_each(|c| *c = c.clamp(0.0, 1.0));
                    }
                }
                // Averaged down, an edge pixel holds the car's share of it: the colour is
                // un-premultiplied so that `over` blends it with the background once.
                let (rgb, cover) = (halve(&rgb, 2 * n, 2 * n), halve(&cover, 2 * n, 2 * n));
                let alpha: Vec<f32> = cover.iter().step_by(3).copied().collect();
                let car = Rgb {
                    width: n,
                    height: n,
                    rgb: rgb.iter().zip(&cover).map(|(c, a)| if *a > 0.0 { c / a } else { 0.0 }).collect(),
                };
                writer.lay_over(v, &car, &alpha)?;
                let secs = t.elapsed().as_secs_f64();
                writer.record(v, v.environment, secs)?;
                advance(&v.name, secs);
            }
        }
        Some((blender, envs)) => {
            let ground_y = mesh.bounds().0[1];
            let effects: HashSet<PbrEffect> = cfg.render.effects.iter().copied().collect();
            let n = cfg.render.size;
            for (ei, env) in envs.iter().enumerate() {
                // Grid views over the environment, then plate views on a transparent film.
                for on_plates in [false, true] {
                    let todo: Vec<&View> = todo
                        .iter()
                        .copied()
                        .filter(|v| v.environment == ei && v.plate.is_some() == on_plates)
                        .collect();
                    if todo.is_empty() {
                        continue;
                    }
                    let mut job = Job::new(Mode::Pbr, obj.clone(), n, cfg.render.samples, ground_y);
                    job.texture = Some(std::fs::canonicalize(&texture).map_err(io(&texture))?);
                    job.tex_size = [tex.width, tex.height];
                    job.environment = Some(env.clone());
                    job.env_strength = cfg.environments[ei].strength;
                    job.shadows = effects.contains(&PbrEffect::Shadows);
                    job.transparent = on_plates;
                    if effects.contains(&PbrEffect::Reflections) {
                        (job.metallic, job.roughness, job.clearcoat) = (0.3, 0.35, 0.5);
                    }
                    if let Some(rig) = &cfg.rig {
                        let [roughness, specular, clearcoat] = rig.surface;
                        (job.metallic, job.roughness, job.clearcoat, job.specular) =
                            (0.0, roughness, clearcoat, specular);
                        job.backdrop = Some(rig.backdrop);
                        job.table = Some(rig.table);
                        job.shadows = false;
                        job.rows = (rig.rows < n).then_some(rig.rows);
                    }
                    let out_name =
                        |v: &View| if on_plates { format!("{}_car.png", v.name) } else { format!("{}.png", v.name) };
                    job.views = todo
                        .iter()
                        .map(|v| JobView {
                            env_turn_deg: v.env_turn_deg,
                            ..JobView::new(&v.name, &v.camera, views_dir.join(out_name(v)))
                        })
                        .collect();
                    let mut failure = None;
                    blender.run(&job, dir, |name, secs| {
                        let Some(v) = todo.iter().find(|v| v.name == name) else { return };
                        let mut done_one = || -> Result<(), ViewsError> {
                            pav_core::image::strip_png_text(&views_dir.join(out_name(v)))?;
                            if v.plate.is_some() {
                                let (rgb, alpha) = pav_core::image::load_rgba(&views_dir.join(out_name(v)))?;
                                writer.lay_over(v, &rgb, &alpha)?;
                            }
                            writer.record(v, ei, secs)
                        };
                        match done_one() {
                            Ok(()) => advance(name, secs),
                            Err(e) => {
                                failure.get_or_insert(e);
                            }
                        }
                    })?;
                    if let Some(e) = failure {
                        return Err(e);
                    }
                }
            }
        }
    }
    std::fs::remove_file(&unfinished).map_err(io(&unfinished))?;
    progress.end(None);
    Ok(RenderSummary { total, resumed, rendered: rendered_now, manifest })
}

/// Writes a drawn view's image, silhouette mask and manifest row.
struct ViewWriter<'a> {
    cfg: &'a ViewsConfig,
    mesh: &'a Mesh,
    rot: [[f32; 3]; 3],
    views_dir: &'a Path,
    manifest: &'a Path,
    /// Plates by index, each painted out once.
    plates: HashMap<usize, Frame>,
}

impl ViewWriter<'_> {
    /// Writes `views/<name>.png`: the car (`rgb`, covering each pixel by `alpha`) over the view's
    /// plate, or over a grey backdrop when it has none.
    fn lay_over(&mut self, v: &View, rgb: &Rgb, alpha: &[f32]) -> Result<(), ViewsError> {
        let n = self.cfg.render.size;
        let backdrop;
        let under = match v.plate {
            Some(pi) => match self.plates.entry(pi) {
                std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
                std::collections::hash_map::Entry::Vacant(e) => e.insert(plate_frame(self.cfg, self.mesh, pi)?),
            },
            None => {
                backdrop = Frame { width: n, height: n, bgr: vec![115; n * n * 3] };
                &backdrop
            }
        };
        pav_core::image::over(rgb, alpha, under).save_png(&self.views_dir.join(format!("{}.png", v.name)))?;
        Ok(())
    }

    /// Writes the view's silhouette mask and appends its manifest row (`secs` to draw it).
    fn record(&self, v: &View, ei: usize, secs: f64) -> Result<(), ViewsError> {
        let (cfg, n, name) = (self.cfg, self.cfg.render.size, &v.name);
        let g = GBuffer::render(self.mesh, &v.camera, n);
        let mask: Vec<f32> = g.face.iter().flat_map(|f| [if *f == EMPTY { 0.0 } else { 1.0 }; 3]).collect();
        // A rig's mask is cut as its view is: the centre rows of the square.
        let rows = cfg.rig.as_ref().map_or(n, |r| r.rows.min(n));
        let y0 = (n - rows) / 2;
        let mask = &mask[3 * n * y0..3 * n * (y0 + rows)];
        pav_core::image::save_rgb(&self.views_dir.join(format!("{name}_mask.png")), n, rows, mask)?;
        let [d, e, a] = v.pose;
        let up = if v.plate.is_some() { v.camera.axes[1] } else { [0.0, 1.0, 0.0] };
        let rot = &self.rot;
        let (eye, target, up) = (unrotate(rot, v.camera.eye), unrotate(rot, v.target), unrotate(rot, up));
        let row = ViewRecord {
            name: name.clone(),
            environment: cfg.environment_name(ei),
            image: format!("views/{name}.png").into(),
            mask: format!("views/{name}_mask.png").into(),
            distance: d,
            elevation_deg: e,
            azimuth_deg: a,
            eye_x: eye[0],
            eye_y: eye[1],
            eye_z: eye[2],
            target_x: target[0],
            target_y: target[1],
            target_z: target[2],
            up_x: up[0],
            up_y: up[1],
            up_z: up[2],
            fov_deg: v.camera.fov_deg,
            size: n,
            samples: cfg.render.samples,
            seconds: (secs * 1000.0).round() / 1000.0,
            plate: v.plate.map_or_else(String::new, |pi| {
                let pl = cfg.plates.as_ref().expect("a plate view has plates");
                pl.sources.get(pi).cloned().unwrap_or_else(|| pl.photos[pi].display().to_string())
            }),
        };
        append_row(self.manifest, &row)
    }
}

/// Plate `pi` of the config at the render size: the photo, resized if it is not already, with
/// its car (as the plates' camera sees the mesh) painted out.
fn plate_frame(cfg: &ViewsConfig, mesh: &Mesh, pi: usize) -> Result<Frame, ViewsError> {
    let pl = cfg.plates.as_ref().expect("a plate view has plates");
    let path = &pl.photos[pi];
    let bad = |msg: String| ViewsError::Config { path: path.clone(), msg };
    let sample = pav_dataset::fca::CarlaSample::load(path).map_err(|e| bad(e.to_string()))?;
    let n = cfg.render.size;
    let mut photo = sample.image;
    if photo.width != photo.height {
        return Err(bad(format!("a plate must be square; this photo is {}x{}", photo.width, photo.height)));
    }
    if photo.width != n {
        photo = Frame::from_levels(n, n, &resize(&photo, n, n, Interpolation::Antialias));
    }
    let plate = Plate::new(mesh, &photo, &cfg.plate_camera(pi, 0.0, 1.0), pl.grow_px.unwrap_or(n / 50))
        .map_err(|e| bad(format!("painting the car out: {e}")))?;
    Ok(plate.frame())
}

/// Joins the shards of a view set (found and checked by `shard::find_checked`) into `out`:
/// every shard's images linked into `out/views`, and one `manifest.csv` in the order one process
/// renders them (environment by environment, grid views before plate views). Refused before
/// anything is linked: a view of the config that no shard rendered (named with its shard), or one
/// that two shards list. Returns the number of views.
pub fn merge_shards(cfg: &ViewsConfig, shards: &[(Shard, PathBuf)], out: &Path) -> Result<usize, ViewsError> {
    let all = cfg.views();
    let order: HashMap<&str, (usize, bool, usize)> =
        all.iter().enumerate().map(|(i, v)| (v.name.as_str(), (v.environment, v.plate.is_some(), i))).collect();
    let mut rows: HashMap<String, (ViewRecord, PathBuf)> = HashMap::new();
    for (_, dir) in shards {
        let manifest = manifest_path(dir);
        let listed = if manifest.exists() { read_manifest(&manifest)? } else { Vec::new() };
        for row in listed.into_iter().filter(|r| dir.join(&r.image).exists()) {
            if !order.contains_key(row.name.as_str()) {
                return Err(ViewsError::Config {
                    path: manifest.clone(),
                    msg: format!("view {} is not one of the config's", row.name),
                });
            }
            if let Some((_, other)) = rows.get(&row.name) {
                return Err(ShardError::Duplicate {
                    what: format!("view {}", row.name),
                    a: other.clone(),
                    b: dir.clone(),
                }
                .into());
            }
            rows.insert(row.name.clone(), (row, dir.clone()));
        }
    }
    if let Some((i, v)) = all.iter().enumerate().find(|(_, v)| !rows.contains_key(&v.name)) {
        let dir = pav_run::shard::owner_dir(shards, i);
        let missing = all.iter().filter(|v| !rows.contains_key(&v.name)).count();
        let what = format!("view {} ({missing} of {} views missing)", v.name, all.len());
        return Err(ShardError::Unfinished { shard: dir, what }.into());
    }
    for (_, dir) in shards {
        pav_run::shard::link_tree(&dir.join("views"), &out.join("views"))?;
    }
    if let Some((_, first)) = shards.first() {
        for f in ["views.toml", "mesh.obj"] {
            let to = out.join(f);
            let _ = std::fs::remove_file(&to);
            std::fs::copy(first.join(f), &to).map_err(io(&to))?;
        }
    }
    let mut rows: Vec<ViewRecord> = rows.into_values().map(|r| r.0).collect();
    rows.sort_by_key(|r| order[r.name.as_str()]);
    let path = manifest_path(out);
    write_manifest(&path, &rows)?;
    Ok(rows.len())
}

/// Writes `contact.png` in `dir`: up to `max` views of its manifest side by side, each beside
/// its mask, evenly picked, so a glance shows poses, lighting and alignment.
pub fn contact_sheet(dir: &Path, max: usize) -> Result<PathBuf, ViewsError> {
    let manifest = manifest_path(dir);
    let rows: Vec<(PathBuf, PathBuf)> = read_manifest(&manifest)?.into_iter().map(|r| (r.image, r.mask)).collect();
    let pick: Vec<&(PathBuf, PathBuf)> =
        if rows.len() <= max { rows.iter().collect() } else { (0..max).map(|k| &rows[k * rows.len() / max]).collect() };
    let mut tiles = Vec::new();
    let mut size = (0, 0);
    for (img, mask) in pick {
        for p in [img, mask] {
            let t = pav_core::image::Rgb::load(&dir.join(p))?;
            size = (t.width, t.height);
            tiles.push(t.rgb);
        }
    }
    let path = dir.join("contact.png");
    if tiles.is_empty() || tiles.iter().any(|t| t.len() != size.0 * size.1 * 3) {
        return Err(ViewsError::Config { path: manifest, msg: "no views of one size to show".into() });
    }
    let (w, h, px) = pav_core::image::tile(&tiles, size.0, size.1, 8, 1.0);
    pav_core::image::save_rgb(&path, w, h, &px)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The workspace root, where `configs/` lives.
    fn repo() -> &'static Path {
        Path::new(env!("CARGO_MANIFEST_DIR")).parent().and_then(Path::parent).unwrap()
    }

    fn shipped(name: &str) -> ViewsConfig {
        ViewsConfig::load(&repo().join("configs/views").join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
    }

    #[test]
    fn shipped_configs_give_the_views_they_promise() {
        assert_eq!(shipped("ci.toml").views().len(), 6);
        assert_eq!(shipped("etron-64.toml").views().len(), 64);
        // Plates: 2 environments × 11 photos × 5 turns, each at its photo's camera.
        let plates = shipped("etron-plates.toml");
        let views = plates.views();
        assert_eq!(views.len(), 110);
        assert!(views.iter().all(|v| v.plate.is_some()));
        let (a, b) = (&views[0].camera, &plates.plate_camera(0, -40.0, 1.0));
        assert_eq!((a.eye, a.axes), (b.eye, b.axes));
        // The paper's grid: 4 distances × (3 elevations × 20 azimuths + 2 × 8) per environment.
        let grid = shipped("paper-grid.toml");
        assert_eq!(grid.views().len(), 304 * grid.environments.len());
        let v = &grid.views()[0];
        // A camera on the grid looks at the target from its distance.
        let d = v.camera.to_view(v.target);
        assert!(d[0].abs() < 1e-4 && d[1].abs() < 1e-4 && (d[2] - v.pose[0]).abs() < 1e-4, "{d:?}");
    }

    #[test]
    fn grids_and_plates_draw_only_the_environments_they_name() {
        let scale = shipped("scale.toml");
        let views = scale.views();
        // 2 environments × 3 distances × 4 elevations × 36 azimuths; 4 × 6 photos × 3 × 31 turns.
        assert_eq!(views.len(), 864 + 2232);
        let env = |v: &View| scale.environment_name(v.environment);
        assert!(views
            .iter()
            .filter(|v| v.plate.is_none())
            .all(|v| ["courtyard", "interior"].contains(&env(v).as_str())));
        assert_eq!(views.iter().filter(|v| v.plate.is_some() && env(v) == "city").count(), 558);
        // No view of the held-out set is among them.
        let held: HashSet<String> = shipped("heldout.toml").views().into_iter().map(|v| v.name).collect();
        assert!(views.iter().all(|v| !held.contains(&v.name)));
        let mut typo = scale.clone();
        typo.poses[0].environments = vec!["courtyrd".into()];
        let e = typo.check().unwrap_err();
        assert!(e.contains("poses #1: environment `courtyrd` is not among"), "{e}");
        let mut idle = scale.clone();
        idle.plates.as_mut().unwrap().environments = vec!["courtyard".into()];
        let e = idle.check().unwrap_err();
        assert!(e.contains("environment `city` draws no view"), "{e}");
    }

    #[test]
    fn a_manifest_from_before_the_plate_column_reads_and_is_brought_up_to_date() {
        let dir = tempfile::tempdir().unwrap();
        let old_header = MANIFEST_HEADER.trim_end_matches(",plate");
        let row = "v1,city,views/v1.png,views/v1_mask.png,2.2,15,0,0,1,2,0,0,0,0,1,0,60,64,4,1.5";
        let manifest = dir.path().join("manifest.csv");
        std::fs::write(&manifest, format!("{old_header}\n{row}\n")).unwrap();
        std::fs::create_dir_all(dir.path().join("views")).unwrap();
        std::fs::write(dir.path().join("views/v1.png"), b"").unwrap();
        let done = rendered(&manifest, dir.path()).unwrap();
        assert!(done.contains("v1"));
        let text = std::fs::read_to_string(&manifest).unwrap();
        assert_eq!(text.lines().next(), Some(MANIFEST_HEADER));
        let rows = read_manifest(&manifest).unwrap();
        assert_eq!((rows.len(), rows[0].plate.as_str(), rows[0].seconds), (1, "", 1.5));
    }

    #[test]
    fn a_view_set_whose_render_did_not_finish_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("views.toml"), "obj = \"m.obj\"\nnormalize = \"bbox\"\nup = \"+y\"\n").unwrap();
        let row = "v1,city,views/v1.png,views/v1_mask.png,2.2,15,0,0,1,2,0,0,0,0,1,0,60,64,4,1.5,";
        std::fs::write(manifest_path(dir.path()), format!("{MANIFEST_HEADER}\n{row}\n")).unwrap();
        assert_eq!(read_view_set(dir.path()).unwrap().1.len(), 1);
        // A stopped render leaves its marker: the one view written is not the set.
        std::fs::write(dir.path().join(UNFINISHED), "").unwrap();
        let e = read_view_set(dir.path()).unwrap_err().to_string();
        assert!(e.contains("has not finished") && e.contains("rerun"), "{e}");
    }

    #[test]
    fn plates_without_turns_or_unread_poses_are_refused() {
        let text = |turns: &str| {
            format!(
                "[mesh]\nobj = \"m.obj\"\n[render]\nsize = 64\nsamples = 1\n[[environments]]\nname = \"city\"\n\
                 [plates]\nphotos = [\"a.npz\"]\ncamera = \"fca\"\nturns = [{turns}]\n"
            )
        };
        let no_turns: ViewsConfig = toml::from_str(&text("")).unwrap();
        assert!(no_turns.check().unwrap_err().contains("one turn"));
        // Parsed but not loaded: the photos' poses were never read.
        let unread: ViewsConfig = toml::from_str(&text("0")).unwrap();
        assert!(unread.check().unwrap_err().contains("poses are not read"));
        let missing = tempfile::tempdir().unwrap();
        let path = missing.path().join("v.toml");
        std::fs::write(&path, text("0").replace("m.obj", "/dev/null")).unwrap();
        let e = ViewsConfig::load(&path).unwrap_err().to_string();
        assert!(e.contains("a.npz"), "{e}");
    }

    #[test]
    fn moved_plates_are_named_apart_and_drawn_from_the_same_camera() {
        let moved = shipped("etron-plates-moved.toml");
        let views = moved.views();
        // 2 environments × 11 photos × 2 distances × 3 turns.
        assert_eq!(views.len(), 132);
        assert_eq!(views.iter().map(|v| &v.name).collect::<HashSet<_>>().len(), 132);
        let v = views.iter().find(|v| v.name == "city_data12501_t+40_d1.40").expect("named by distance");
        let c = moved.plate_camera(1, 40.0, 1.4);
        assert_eq!((v.camera.eye, v.camera.axes), (c.eye, c.axes));
        // Moved away, the eye is farther and the camera still looks where the photo's did.
        let (near, far) = (moved.plate_camera(1, 40.0, 1.0), moved.plate_camera(1, 40.0, 1.4));
        let norm = |e: [f32; 3]| e.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!(norm(far.eye) > 1.3 * norm(near.eye));
        assert!(far.axes.iter().flatten().zip(near.axes.iter().flatten()).all(|(a, b)| (a - b).abs() < 1e-6));
        // Distance 1 keeps the names of etron-plates-wide.toml, so that folder is not redrawn.
        let mut one = moved.clone();
        one.plates.as_mut().unwrap().distances = vec![1.0];
        assert!(one
            .views()
            .iter()
            .all(|v| v.name.ends_with("_t-40") || v.name.ends_with("_t+0") || v.name.ends_with("_t+40")));
        // Factors out of range, or a convention whose camera cannot follow a moved car, are refused.
        for (d, conv, says) in
            [(0.5, CameraConvention::Fca, "0.7 to 3"), (1.4, CameraConvention::PavCamou, "need camera")]
        {
            let mut c = moved.clone();
            let pl = c.plates.as_mut().unwrap();
            (pl.distances, pl.camera) = (vec![d], conv);
            let e = c.check().unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }

    #[test]
    fn up_rotations_are_proper_and_bring_the_axis_up() {
        for (up, axis) in [
            ("+y", [0.0, 1.0, 0.0]),
            ("-y", [0.0, -1.0, 0.0]),
            ("+z", [0.0, 0.0, 1.0]),
            ("-z", [0.0, 0.0, -1.0]),
            ("+x", [1.0, 0.0, 0.0]),
            ("-x", [-1.0, 0.0, 0.0]),
        ] {
            let r = up_rotation(up).unwrap();
            let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
                - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
                + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
            assert_eq!(det, 1.0, "{up} mirrors");
            let y: Vec<f32> = (0..3).map(|k| r[k][0] * axis[0] + r[k][1] * axis[1] + r[k][2] * axis[2]).collect();
            assert_eq!(y, [0.0, 1.0, 0.0], "{up}");
            assert_eq!(unrotate(&r, [0.0, 1.0, 0.0]), axis, "{up}");
        }
        assert!(up_rotation("up").is_err());
    }
}
