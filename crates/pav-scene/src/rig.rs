//! A rig config: the shot of a physical turntable rig (its camera, where it stands, the model
//! car's scale, the table and the room) from which both simulated turntables film the model at
//! model size, and which a real capture records so that a capture and its simulation name the
//! same shot.
//!
//! A rig config may `extends = "other.toml"` and set only what differs.
//!
//! ```toml
//! effects = ["defocus", "motion-blur", "noise", "codec"]   # only these are simulated (also "auto-exposure")
//!
//! [mesh]                       # the car, as in a views config
//! obj = "data:rauca-e2e/pytorch3d_Etron.obj"
//! normalize = "bbox"
//! up = "+z"
//!
//! [camera]
//! focal_mm = 4.75              # with sensor_mm, or fov_deg (horizontal)
//! sensor_mm = [6.4, 3.6]       # the active area at this video mode
//! width = 1920                 # the capture's frames
//! height = 1080
//! fps = 30
//! exposure_s = 0.0167          # at most 1 / fps
//! f_number = 1.8
//! focus_m = 0.55               # default: the distance to the model's centre
//! auto_exposure = 0.5          # the `auto-exposure` effect's strength, 0 to 1
//!
//! [camera.controls]            # what `pav-rig capture` locks on a real camera (each optional)
//! exposure = 166               # × 100 µs
//! gain = 0
//! white_balance = 4600         # K
//! focus = 30
//!
//! [placement]
//! distance_m = 0.55            # horizontal, camera to the table's axis
//! elevations_deg = [0, 20]     # of the line of sight to the model's centre; or heights_m
//!
//! [model]
//! scale = 20                   # 1:20
//! car_length_m = 4.9           # the real car's length
//!
//! [table]
//! period_s = 28                # one turn
//! radius_m = 0.2
//! surface = [0.8, 0.8, 0.8]    # sRGB in [0, 1]
//!
//! [room]
//! environment = "interior"     # lights the model; never seen by the camera
//! backdrop = [0.9, 0.9, 0.9]   # what the camera sees behind the table
//! backdrop_m = 0.6             # how far behind the table's axis
//!
//! [sticker]
//! material = "paper-matte"     # paper-matte, paper-glossy, vinyl-matte, vinyl-laminated
//!
//! [render]
//! width = 640                  # the simulation's frame width (height keeps the aspect)
//! samples = 16
//! frames = 44                  # per turn and camera position
//! ```

use super::blender::TableTop;
use super::views::{
    Environment, PbrEffect, PoseGrid, RenderSettings, Renderer, RigScene, ViewMesh, ViewsConfig, ViewsError,
};
use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The camera of the rig.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RigCamera {
    /// Focal length, mm (with `sensor_mm`).
    #[serde(default)]
    pub focal_mm: Option<f64>,
    /// The sensor's active area at the capture's video mode, mm (width, height).
    #[serde(default)]
    pub sensor_mm: Option<[f64; 2]>,
    /// Or the horizontal field of view, degrees.
    #[serde(default)]
    pub fov_deg: Option<f64>,
    /// Frame width, pixels.
    pub width: usize,
    /// Frame height, pixels.
    pub height: usize,
    /// Frames per second.
    pub fps: f64,
    /// Exposure time, seconds (at most one frame).
    pub exposure_s: f64,
    /// Aperture, f-number.
    pub f_number: f64,
    /// Focus distance from the camera, metres; default: the distance to the model's centre.
    #[serde(default)]
    pub focus_m: Option<f64>,
    /// Sensor read noise, standard deviation in 8-bit levels (the `noise` effect).
    #[serde(default = "read_noise")]
    pub read_noise: f64,
    /// Shot noise gain: a level `v` gets variance `shot_gain · v` on top (the `noise` effect).
    #[serde(default = "shot_gain")]
    pub shot_gain: f64,
    /// The video's bitrate at the capture's resolution, kbit/s (the `codec` effect).
    #[serde(default = "bitrate")]
    pub bitrate_kbps: f64,
    /// How strongly an automatic exposure pulls each frame's mean level to mid-grey, 0 (held) to 1
    /// (every frame brought to it): the `auto-exposure` effect.
    #[serde(default = "auto_exposure")]
    pub auto_exposure: f64,
    /// The settings a real capture locks before the table turns (`pav-rig capture --rig`).
    #[serde(default)]
    pub controls: Controls,
}

/// A real camera's settings, each locked with its automatic mode off when given.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Controls {
    /// Exposure time in V4L2's units of 100 µs.
    #[serde(default)]
    pub exposure: Option<i64>,
    /// Gain, in the camera's units.
    #[serde(default)]
    pub gain: Option<i64>,
    /// White balance, kelvin.
    #[serde(default)]
    pub white_balance: Option<i64>,
    /// Focus position, in the camera's units.
    #[serde(default)]
    pub focus: Option<i64>,
}

fn auto_exposure() -> f64 {
    0.5
}

fn read_noise() -> f64 {
    2.0
}
fn shot_gain() -> f64 {
    0.3
}
fn bitrate() -> f64 {
    17_000.0
}

/// Where the camera stands.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Horizontal distance from the camera to the table's axis, metres.
    pub distance_m: f64,
    /// Camera heights above the table top, metres (one video each).
    #[serde(default)]
    pub heights_m: Vec<f64>,
    /// Or the elevations of the line of sight to the model's centre, degrees.
    #[serde(default)]
    pub elevations_deg: Vec<f64>,
}

/// The model car.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ModelCar {
    /// The model is 1:`scale`.
    pub scale: f64,
    /// The real car's length, metres.
    pub car_length_m: f64,
}

/// The turntable.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Table {
    /// Seconds per turn.
    pub period_s: f64,
    /// The top's radius, metres.
    pub radius_m: f64,
    /// The top's colour, sRGB in [0, 1].
    pub surface: [f32; 3],
}

/// The room.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Room {
    /// The light map that lights the model (a studio light's name or an .exr/.hdr path); the
    /// camera never sees it, so no car in it can be detected.
    pub environment: String,
    /// Its brightness.
    #[serde(default = "one")]
    pub strength: f64,
    /// The backdrop's colour as the camera sees it, sRGB in [0, 1].
    pub backdrop: [f32; 3],
    /// The backdrop's distance behind the table's axis, metres (for defocus).
    #[serde(default = "backdrop_m")]
    pub backdrop_m: f64,
}

fn one() -> f64 {
    1.0
}
fn backdrop_m() -> f64 {
    0.6
}

/// What the texture is printed on.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum StickerMaterial {
    /// Uncoated paper: diffuse, a faint sheen.
    #[default]
    PaperMatte,
    /// Photo paper: a gloss layer.
    PaperGlossy,
    /// Matte vinyl.
    VinylMatte,
    /// Vinyl under a clear laminate.
    VinylLaminated,
}

/// A surface's Principled BSDF settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// Roughness.
    pub roughness: f32,
    /// Specular level.
    pub specular: f32,
    /// Clear coat weight.
    pub clearcoat: f32,
}

impl StickerMaterial {
    /// Its surface: printed stock is a dielectric (metallic 0), its sheen set by the coating.
    pub fn surface(self) -> Surface {
        match self {
            StickerMaterial::PaperMatte => Surface { roughness: 0.85, specular: 0.3, clearcoat: 0.0 },
            StickerMaterial::PaperGlossy => Surface { roughness: 0.35, specular: 0.5, clearcoat: 0.3 },
            StickerMaterial::VinylMatte => Surface { roughness: 0.6, specular: 0.4, clearcoat: 0.0 },
            StickerMaterial::VinylLaminated => Surface { roughness: 0.25, specular: 0.5, clearcoat: 0.6 },
        }
    }
}

/// The sticker.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Sticker {
    /// Its stock.
    #[serde(default)]
    pub material: StickerMaterial,
}

/// How the simulation renders.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RigRender {
    /// Simulated frame width (height keeps the camera's aspect); default the camera's.
    #[serde(default)]
    pub width: Option<usize>,
    /// Cycles samples per pixel.
    #[serde(default = "sixteen")]
    pub samples: u32,
    /// Frames rendered per turn and camera height.
    #[serde(default = "frames")]
    pub frames: usize,
}

fn sixteen() -> u32 {
    16
}
fn frames() -> usize {
    44
}

impl Default for RigRender {
    fn default() -> Self {
        RigRender { width: None, samples: sixteen(), frames: frames() }
    }
}

/// A camera effect; each is simulated only when the rig lists it.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, Hash, schemars::JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum CameraEffect {
    /// Thin-lens blur at the aperture and focus distance.
    Defocus,
    /// The model's motion during the exposure.
    MotionBlur,
    /// Read and shot noise.
    Noise,
    /// H.264 at the capture's bitrate.
    Codec,
    /// An automatic exposure that follows the frame: each frame's levels scaled towards a mean
    /// of mid-grey, by `camera.auto_exposure`.
    AutoExposure,
}

/// A rig config.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RigConfig {
    /// The car.
    pub mesh: ViewMesh,
    /// The camera.
    pub camera: RigCamera,
    /// Where it stands.
    pub placement: Placement,
    /// The model's scale.
    pub model: ModelCar,
    /// The turntable.
    pub table: Table,
    /// The room.
    pub room: Room,
    /// The sticker.
    #[serde(default)]
    pub sticker: Sticker,
    /// The simulation's settings.
    #[serde(default)]
    pub render: RigRender,
    /// Camera effects to simulate; everything not listed is off.
    #[serde(default)]
    pub effects: Vec<CameraEffect>,
    /// The configs this one `extends`, nearest first (read by [`RigConfig::load`]).
    #[serde(skip)]
    pub bases: Vec<PathBuf>,
}

/// The keys of a rig config that hold paths (rewritten when another config extends it).
const PATH_KEYS: &[&[&str]] = &[&["mesh", "obj"], &["mesh", "texture"], &["room", "environment"]];

/// Whether the config at `path`, over the configs it extends, is a rig config (it places a
/// camera: `[placement]`) rather than a views config.
pub fn is_rig_config(path: &Path) -> bool {
    pav_core::extends::read_merged(path, &[], &[]).is_ok_and(|(t, _)| t.contains_key("placement"))
}

/// The views config at `path`, or the turntable views of the rig config there: what
/// `pav views render` and `pav views turntable --rig` draw.
pub fn load_views_config(path: &Path) -> Result<ViewsConfig, ViewsError> {
    if is_rig_config(path) {
        RigConfig::load(path)?.views_config().map(|(cfg, _)| cfg)
    } else {
        ViewsConfig::load(path)
    }
}

/// The rig's geometry in the normalized mesh's units, derived once the mesh is known.
#[derive(Clone, Debug, PartialEq)]
pub struct Shot {
    /// Normalized mesh units per metre.
    pub units_per_m: f32,
    /// The table top's height (the mesh's lowest y).
    pub ground_y: f32,
    /// The model's centre, where the camera looks.
    pub target: [f32; 3],
    /// Per camera height: (distance to the target along the line of sight, elevation in
    /// degrees), in normalized units.
    pub poses: Vec<(f32, f32)>,
    /// Field of view of the square render of the frame's larger side, degrees.
    pub fov_deg: f32,
    /// Simulated frame size.
    pub size: (usize, usize),
}

impl RigConfig {
    /// Reads a rig config; relative paths are taken from the config's folder.
    pub fn load(path: &Path) -> Result<RigConfig, ViewsError> {
        let err = |msg: String| ViewsError::Config { path: path.into(), msg };
        let (mut c, files): (RigConfig, _) = pav_core::extends::load(path, PATH_KEYS, super::views::STUDIO_LIGHT_NAMES)
            .map_err(|e| err(e.to_string()))?;
        c.bases = files.into_iter().skip(1).collect();
        let dir = path.parent().unwrap_or(Path::new("."));
        let resolve = |p: &Path| pav_run::data::resolve(dir, p).map_err(|e| err(e.to_string()));
        c.mesh.obj = resolve(&c.mesh.obj)?;
        c.mesh.texture = c.mesh.texture.as_deref().map(resolve).transpose()?;
        if c.room.environment.contains('/') || c.room.environment.contains('.') {
            c.room.environment = resolve(Path::new(&c.room.environment))?.display().to_string();
        }
        c.check().map_err(err)?;
        Ok(c)
    }

    /// Refuses a shot no camera could take.
    pub fn check(&self) -> Result<(), String> {
        let c = &self.camera;
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(format!("{name} = {v}: must be positive"))
            }
        };
        if !(0.0..=1.0).contains(&c.auto_exposure) {
            return Err(format!("camera.auto_exposure = {}: a strength from 0 (held) to 1", c.auto_exposure));
        }
        match (c.focal_mm, c.sensor_mm, c.fov_deg) {
            (Some(f), Some([w, h]), None) => {
                positive("camera.focal_mm", f)?;
                positive("camera.sensor_mm width", w)?;
                positive("camera.sensor_mm height", h)?;
            }
            (None, None, Some(fov)) => {
                if !(fov > 1.0 && fov < 170.0) {
                    return Err(format!("camera.fov_deg = {fov}: a field of view lies in (1°, 170°)"));
                }
            }
            _ => return Err("camera: give focal_mm with sensor_mm, or fov_deg alone".into()),
        }
        if c.width < 16 || c.height < 16 {
            return Err(format!("camera: {}x{} pixels is no video frame", c.width, c.height));
        }
        positive("camera.fps", c.fps)?;
        positive("camera.exposure_s", c.exposure_s)?;
        if c.exposure_s > 1.0 / c.fps + 1e-9 {
            return Err(format!(
                "camera: an exposure of {} s does not fit in a frame at {} fps (at most {:.4} s)",
                c.exposure_s,
                c.fps,
                1.0 / c.fps
            ));
        }
        positive("camera.f_number", c.f_number)?;
        if let Some(f) = c.focus_m {
            if !(f.is_finite() && f > 0.0) {
                return Err(format!("camera.focus_m = {f}: the focus lies in front of the camera (> 0)"));
            }
            if let Some(fl) = c.focal_mm {
                if f <= fl / 1000.0 {
                    return Err(format!(
                        "camera.focus_m = {f}: a lens of {fl} mm cannot focus nearer than its focal length"
                    ));
                }
            }
        }
        if !(c.read_noise.is_finite() && c.read_noise >= 0.0 && c.shot_gain.is_finite() && c.shot_gain >= 0.0) {
            return Err("camera.read_noise and camera.shot_gain must be ≥ 0".into());
        }
        positive("camera.bitrate_kbps", c.bitrate_kbps)?;
        let p = &self.placement;
        positive("placement.distance_m", p.distance_m)?;
        match (p.heights_m.is_empty(), p.elevations_deg.is_empty()) {
            (false, true) => {
                if let Some(h) = p.heights_m.iter().find(|h| !(h.is_finite() && **h >= 0.0)) {
                    return Err(format!("placement.heights_m: {h} is below the table top"));
                }
            }
            (true, false) => {
                if let Some(e) = p.elevations_deg.iter().find(|e| !(e.is_finite() && e.abs() < 80.0)) {
                    return Err(format!("placement.elevations_deg: {e}° is not a turntable shot (|e| < 80°)"));
                }
            }
            _ => return Err("placement: give heights_m or elevations_deg (one of them)".into()),
        }
        positive("model.scale", self.model.scale)?;
        positive("model.car_length_m", self.model.car_length_m)?;
        positive("table.period_s", self.table.period_s)?;
        positive("table.radius_m", self.table.radius_m)?;
        if self.table.radius_m >= p.distance_m {
            return Err(format!(
                "table.radius_m = {} reaches the camera at placement.distance_m = {}",
                self.table.radius_m, p.distance_m
            ));
        }
        positive("room.strength", self.room.strength)?;
        positive("room.backdrop_m", self.room.backdrop_m)?;
        for (name, rgb) in [("table.surface", self.table.surface), ("room.backdrop", self.room.backdrop)] {
            if rgb.iter().any(|v| !(0.0..=1.0).contains(v)) {
                return Err(format!("{name} = {rgb:?}: an sRGB colour lies in [0, 1]"));
            }
        }
        if self.render.samples == 0 || self.render.frames < 2 {
            return Err("render: need samples ≥ 1 and frames ≥ 2".into());
        }
        if self.render.width.is_some_and(|w| !(16..=c.width).contains(&w)) {
            return Err(format!("render.width must lie in [16, camera.width = {}]", c.width));
        }
        if self.effects.contains(&CameraEffect::Defocus) && c.focal_mm.is_none() {
            return Err("effects: defocus needs the lens: give camera.focal_mm and camera.sensor_mm".into());
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(e) = self.effects.iter().find(|e| !seen.insert(**e)) {
            return Err(format!("effects: {e:?} is listed twice"));
        }
        super::views::up_rotation(&self.mesh.up)?;
        Ok(())
    }

    /// The rig without its camera effects and what only they read (exposure, aperture, focus,
    /// noise, bitrate), as TOML: equal for rigs whose views are the same renders, so a view
    /// folder of one can be cut into videos with the other's effects.
    fn render_key(&self) -> String {
        let mut r = self.clone();
        r.effects.clear();
        r.bases.clear();
        let c = &mut r.camera;
        (c.exposure_s, c.f_number, c.focus_m, c.read_noise, c.shot_gain, c.bitrate_kbps) =
            (0.0, 0.0, None, 0.0, 0.0, 0.0);
        toml::to_string(&r).expect("a rig serializes")
    }

    /// The rig as `views.toml` records it (which configs it extended is the run record's business).
    pub fn record(&self) -> toml::Table {
        toml::Table::try_from(RigConfig { bases: Vec::new(), ..self.clone() }).expect("a rig serializes")
    }

    /// The rig a view folder recorded ([`Self::record`]).
    pub fn from_record(t: &toml::Table) -> Result<RigConfig, String> {
        toml::Value::Table(t.clone()).try_into().map_err(|e: toml::de::Error| e.to_string())
    }

    /// How many camera positions the rig lists (heights or elevations).
    pub fn positions(&self) -> usize {
        self.placement.heights_m.len().max(self.placement.elevations_deg.len())
    }

    /// The model's length, metres.
    pub fn model_length_m(&self) -> f64 {
        self.model.car_length_m / self.model.scale
    }

    /// Horizontal field of view, degrees.
    pub fn fov_deg(&self) -> f64 {
        match (self.camera.focal_mm, self.camera.sensor_mm, self.camera.fov_deg) {
            (Some(f), Some([w, _]), _) => (2.0 * (w / (2.0 * f)).atan()).to_degrees(),
            (_, _, Some(fov)) => fov,
            _ => unreachable!("checked by RigConfig::check"),
        }
    }

    /// The focal length in pixels of a frame `width` wide.
    pub fn focal_px(&self, width: usize) -> f64 {
        width as f64 / 2.0 / (self.fov_deg().to_radians() / 2.0).tan()
    }

    /// The simulated frame size.
    pub fn frame_size(&self) -> (usize, usize) {
        let w = self.render.width.unwrap_or(self.camera.width);
        let h = (self.camera.height as f64 * w as f64 / self.camera.width as f64).round() as usize;
        (w, h)
    }

    /// Whether `e` is simulated.
    pub fn has(&self, e: CameraEffect) -> bool {
        self.effects.contains(&e)
    }

    /// The views config for the car (loaded and normalized once here) that carries the mesh.
    fn mesh_only(&self) -> ViewsConfig {
        ViewsConfig {
            mesh: self.mesh.clone(),
            render: RenderSettings {
                size: 8,
                samples: self.render.samples,
                effects: vec![PbrEffect::Shadows],
                turntable: true,
                renderer: Renderer::Cycles,
            },
            environments: vec![Environment { name: self.room.environment.clone(), strength: self.room.strength }],
            poses: Vec::new(),
            plates: None,
            rig: None,
        }
    }

    /// The shot in the units of `mesh` (normalized as the config says, +Y up).
    pub fn shot(&self, mesh: &Mesh) -> Shot {
        let (lo, hi) = mesh.bounds();
        // The car's length is its longest horizontal side.
        let length_units = (hi[0] - lo[0]).max(hi[2] - lo[2]);
        let units_per_m = (length_units as f64 / self.model_length_m()) as f32;
        let target = [0.0, (lo[1] + hi[1]) / 2.0, 0.0];
        let centre_h = f64::from(target[1] - lo[1]) / f64::from(units_per_m);
        let d = self.placement.distance_m;
        let poses = if self.placement.heights_m.is_empty() {
            self.placement
                .elevations_deg
                .iter()
                .map(|e| ((d / e.to_radians().cos()) as f32 * units_per_m, *e as f32))
                .collect()
        } else {
            self.placement
                .heights_m
                .iter()
                .map(|h| {
                    let rise = h - centre_h;
                    ((d.hypot(rise)) as f32 * units_per_m, rise.atan2(d).to_degrees() as f32)
                })
                .collect()
        };
        // The render is a square of the frame's larger side: its field of view spans that side.
        let size = self.frame_size();
        let half = (self.fov_deg().to_radians() / 2.0).tan() * size.0.max(size.1) as f64 / size.0 as f64;
        Shot { units_per_m, ground_y: lo[1], target, poses, fov_deg: (2.0 * half.atan()).to_degrees() as f32, size }
    }

    /// The camera at pose `k` of `shot` with the table turned by `angle_deg` (the camera goes
    /// round the model by as much, which is the same picture).
    pub fn camera(shot: &Shot, k: usize, angle_deg: f32) -> Camera {
        let (d, e) = shot.poses[k];
        let eye = pav_core::geometry::camera::spherical(d, e, angle_deg);
        let t = shot.target;
        Camera::look_at([eye[0] + t[0], eye[1] + t[1], eye[2] + t[2]], t, [0.0, 1.0, 0.0], shot.fov_deg)
    }

    /// The views config that renders this rig's turntable: one grid per camera height,
    /// `render.frames` angles a turn, square renders of the frame's larger side (cut to the
    /// frame when the video is written).
    pub fn views_config(&self) -> Result<(ViewsConfig, Mesh), ViewsError> {
        let mut cfg = self.mesh_only();
        let mesh = cfg.load_mesh()?;
        let shot = self.shot(&mesh);
        cfg.render.size = shot.size.0.max(shot.size.1);
        cfg.poses = shot
            .poses
            .iter()
            .map(|&(d, e)| PoseGrid {
                distances: vec![d],
                elevations: vec![e],
                azimuths: Vec::new(),
                azimuth_step: Some(360.0 / self.render.frames as f32),
                fov_deg: shot.fov_deg,
                target: shot.target,
                environments: Vec::new(),
            })
            .collect();
        let s = self.sticker.material.surface();
        let (w, h) = shot.size;
        cfg.rig = Some(Box::new(RigScene {
            surface: [s.roughness, s.specular, s.clearcoat],
            backdrop: self.room.backdrop,
            table: TableTop { radius: self.table.radius_m as f32 * shot.units_per_m, colour: self.table.surface },
            rows: if h < w { h } else { cfg.render.size },
            record: self.record(),
            key: self.render_key(),
        }));
        cfg.check().map_err(|msg| ViewsError::Config { path: self.mesh.obj.clone(), msg })?;
        Ok((cfg, mesh))
    }

    /// The files the shot is made of (for `run.toml`): the configs it extends, the mesh and
    /// its texture.
    pub fn inputs(&self) -> Vec<PathBuf> {
        let mut v = self.bases.clone();
        v.push(self.mesh.obj.clone());
        v.extend(self.mesh.texture.clone());
        v
    }
}
