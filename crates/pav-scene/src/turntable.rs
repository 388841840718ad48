//! The simulated turntable, two back-ends. Offline: Blender views rendered with the environment
//! turning with the camera (`render.turntable`), so each shows the car turned on a table in a
//! fixed room, cut into one video per environment, distance and elevation with the angle sidecar
//! `pav-rig evaluate` reads. Live: [`CarScene`] draws the car with pav's rasterizer at any table
//! angle, fast enough for `pav-rig capture`'s simulated camera. Both are simulated, not
//! predicted: nothing here is calibrated against a capture.

#[cfg(feature = "video")]
use super::camera_effects::codec_kbps;
use super::camera_effects::{behind, cut, develop, noise_seed, Behind};
use super::rig::{RigConfig, Shot};
#[cfg(feature = "video")]
use super::views::{read_manifest, ViewRecord, ViewSetInfo};
use super::views::{ViewsConfig, ViewsError};
use pav_core::geometry::camera::{spherical, Camera};
use pav_core::geometry::mesh::Mesh;
use pav_core::image::{Frame, Rgb};
#[cfg(feature = "video")]
use pav_core::sidecar::{self, AngleSample};
#[cfg(feature = "video")]
use pav_core::video::VideoWriter;
use pav_render::raster::EMPTY;
use pav_render::shade::{draw_textured, vertex_normals, Lights};
use std::path::Path;
#[cfg(feature = "video")]
use std::path::PathBuf;

/// One video written.
#[cfg(feature = "video")]
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

#[cfg(feature = "video")]
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
#[cfg(feature = "video")]
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
    // A rig's views are cut to its frame and get its camera effects, from the same cameras
    // (found by view name) and the same mesh the views were rendered from.
    let rig = match &info.rig {
        Some(record) => {
            let rig = RigConfig::from_record(record).map_err(|e| refuse(&info_path, format!("its rig: {e}")))?;
            let (cfg, mesh) = rig.views_config()?;
            let shot = rig.shot(&mesh);
            let cams: std::collections::HashMap<String, pav_core::geometry::camera::Camera> =
                cfg.views().into_iter().map(|v| (v.name, v.camera)).collect();
            Some((Box::new(rig), mesh, shot, cams))
        }
        None => None,
    };
    let mut out = Vec::new();
    for mut g in groups {
        g.sort_by(|a, b| a.azimuth_deg.total_cmp(&b.azimuth_deg));
        if let Some(w) = g.windows(2).find(|w| w[0].azimuth_deg == w[1].azimuth_deg) {
            return Err(refuse(&manifest, format!("views {} and {} share an azimuth", w[0].name, w[1].name)));
        }
        let f = &g[0];
        let name = video_stem(&f.environment, f.distance, f.elevation_deg);
        let path = out_dir.join(format!("{name}.mp4"));
        let fps = g.len() as f64 / period_s;
        let mut video: Option<VideoWriter> = None;
        let side = sidecar::sidecar_path(&path);
        let mut angles = sidecar::Writer::create(&side)?;
        for (i, r) in g.iter().enumerate() {
            let mut img = Rgb::load(&dir.join(&r.image))?;
            let frame = match &rig {
                Some((rig, mesh, shot, cams)) => {
                    let cam = cams.get(&r.name).ok_or_else(|| {
                        refuse(&manifest, format!("view {} is not one of the rig's: render into a new folder", r.name))
                    })?;
                    let side = shot.size.0.max(shot.size.1);
                    if img.width != side || !(img.height == side || img.height == shot.size.1) {
                        return Err(refuse(
                            &manifest,
                            format!("view {} is {}x{}, not the rig's render", r.name, img.width, img.height),
                        ));
                    }
                    // Rendered as the frame's rows alone: back into the square the optics see.
                    img = img.into_square(false);
                    let seed = noise_seed(r.azimuth_deg, r.elevation_deg);
                    develop(rig, shot, mesh, cam, &mut img.rgb, side, shot.size, true, seed)
                }
                None => cut(&img.rgb, img.width, (img.width, img.height)),
            };
            let v = match &mut video {
                Some(v) => v,
                None => video.insert(film(
                    rig.as_ref().map(|(rig, ..)| rig.as_ref()),
                    &path,
                    fps,
                    (frame.width, frame.height),
                )?),
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

/// The video a simulated turntable films into: at the rig's bitrate when it lists the codec
/// ([`codec_kbps`]), else H.264 at the writer's own quality; the same for both back-ends.
#[cfg(feature = "video")]
fn film(rig: Option<&RigConfig>, path: &Path, fps: f64, size: (usize, usize)) -> Result<VideoWriter, ViewsError> {
    Ok(match rig.and_then(codec_kbps) {
        Some(kbps) => VideoWriter::create_at_bitrate(path, fps, size, kbps)?,
        None => VideoWriter::create(path, ['a', 'v', 'c', '1'], fps, size)?,
    })
}

/// A turntable video's file stem: its environment, camera distance and elevation, the same for
/// both back-ends so their videos of one shot are named alike.
#[cfg(feature = "video")]
fn video_stem(environment: &str, distance: f32, elevation_deg: f32) -> String {
    format!("{environment}_d{distance:.2}_e{elevation_deg:.0}")
}

/// The rasterizer's turntable of a rig: for each camera position the same frames, angles,
/// camera effects, codec, file names and sidecars as Blender's (`pav views turntable --rig`),
/// drawn by [`CarScene`] in `dir/videos`, the model painted with `texture` (else its own).
#[cfg(feature = "video")]
pub fn write_raster_videos(
    rig: &RigConfig,
    texture: Option<&Path>,
    dir: &Path,
    period_s: f64,
) -> Result<Vec<TurntableVideo>, ViewsError> {
    if !(period_s.is_finite() && period_s > 0.0) {
        return Err(refuse(dir, format!("a turn of {period_s} s is no turn")));
    }
    let out_dir = dir.join("videos");
    std::fs::create_dir_all(&out_dir).map_err(io(&out_dir))?;
    let n = rig.render.frames;
    let fps = n as f64 / period_s;
    let env = super::views::environment_stem(&rig.room.environment);
    let mut out = Vec::new();
    for k in 0..rig.positions() {
        let scene = CarScene::from_rig(rig, texture, k)?;
        let size = rig.frame_size();
        let name = video_stem(&env, scene.distance, scene.elevation_deg);
        let path = out_dir.join(format!("{name}.mp4"));
        let mut video = film(Some(rig), &path, fps, size)?;
        let mut angles = sidecar::Writer::create(&sidecar::sidecar_path(&path))?;
        for i in 0..n {
            // The same angles as the views of RigConfig::views_config.
            let a = i as f32 * (360.0 / n as f32);
            video.write(&scene.frame(a, size.0, size.1))?;
            angles.push(AngleSample { frame: i, timestamp_s: i as f64 / fps, angle_deg: f64::from(a) })?;
        }
        video.finish()?;
        out.push(TurntableVideo {
            path,
            environment: env.clone(),
            distance: scene.distance,
            elevation_deg: scene.elevation_deg,
            frames: n,
        });
    }
    Ok(out)
}

/// The textured car on the table, seen by a fixed camera, drawn by pav's rasterizer with Phong
/// shading under one light that stays in the room while the car turns.
pub struct CarScene {
    mesh: Mesh,
    normals: Vec<[f32; 3]>,
    texture: Rgb,
    /// Camera distance (normalized mesh units).
    pub distance: f32,
    /// Camera elevation (the paper's polar angle), degrees.
    pub elevation_deg: f32,
    fov_deg: f32,
    target: [f32; 3],
    lights: Lights,
    background: [f32; 3],
    /// The rig the scene films, with its shot in the mesh's units.
    rig: Option<(Box<RigConfig>, Shot)>,
}

impl CarScene {
    /// The car of a views config, painted with `texture` (else the config's), filmed from the
    /// config's first pose grid at its first distance and at `elevation_deg` (else its first).
    pub fn new(cfg: &ViewsConfig, texture: Option<&Path>, elevation_deg: Option<f32>) -> Result<CarScene, ViewsError> {
        let mesh = cfg.load_mesh()?;
        let texture = match texture {
            Some(t) => t.to_path_buf(),
            None => cfg.texture(&mesh)?,
        };
        let g = &cfg.poses[0];
        let elevation_deg = elevation_deg.unwrap_or(g.elevations[0]);
        if !(elevation_deg.is_finite() && elevation_deg.abs() < 90.0) {
            return Err(refuse(&texture, format!("elevation {elevation_deg}° must lie within (−90°, 90°)")));
        }
        Ok(CarScene {
            normals: vertex_normals(&mesh),
            texture: Rgb::load(&texture)?,
            mesh,
            distance: g.distances[0],
            elevation_deg,
            fov_deg: g.fov_deg,
            target: g.target,
            lights: Lights::ROOM,
            background: [0.45, 0.45, 0.45],
            rig: None,
        })
    }

    /// The model of a rig config at model size, painted with `texture` (else the config's), on
    /// the rig's table before its backdrop, filmed by its camera from camera height `k` (an
    /// index into `placement`'s heights or elevations).
    pub fn from_rig(rig: &RigConfig, texture: Option<&Path>, k: usize) -> Result<CarScene, ViewsError> {
        let (cfg, mesh) = rig.views_config()?;
        let texture = match texture {
            Some(t) => t.to_path_buf(),
            None => cfg.texture(&mesh)?,
        };
        let shot = rig.shot(&mesh);
        let Some(&(distance, elevation_deg)) = shot.poses.get(k) else {
            return Err(refuse(
                &rig.mesh.obj,
                format!("the rig has {} camera heights, not {}", shot.poses.len(), k + 1),
            ));
        };
        Ok(CarScene {
            normals: vertex_normals(&mesh),
            texture: Rgb::load(&texture)?,
            mesh,
            distance,
            elevation_deg,
            fov_deg: shot.fov_deg,
            target: shot.target,
            lights: Lights::ROOM,
            background: rig.room.backdrop,
            rig: Some((Box::new(rig.clone()), shot)),
        })
    }

    /// The camera at table angle `angle_deg`.
    fn camera(&self, angle_deg: f32) -> Camera {
        let eye = spherical(self.distance, self.elevation_deg, angle_deg);
        let eye = [eye[0] + self.target[0], eye[1] + self.target[1], eye[2] + self.target[2]];
        Camera::look_at(eye, self.target, [0.0, 1.0, 0.0], self.fov_deg)
    }

    /// The car turned by the table's `angle_deg` as the same camera sees it in the room
    /// (`size × size` RGB in [0, 1]). As in Blender's turntable views, the camera goes round by
    /// the angle and the room's light with it.
    pub fn render(&self, angle_deg: f32, size: usize) -> Vec<f32> {
        let cam = self.camera(angle_deg);
        let (s, c) = angle_deg.to_radians().sin_cos();
        let [x, y, z] = self.lights.direction;
        let lights = Lights { direction: [x * c + z * s, y, -x * s + z * c], ..self.lights };
        let (g, mut rgb) = draw_textured(&self.mesh, &self.normals, &self.texture, &cam, &lights, size);
        // The table top, lit as a matte surface facing up by the same light.
        let l = lights.direction;
        let up = l[1] / (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        let table_light = (lights.ambient + lights.diffuse * up.max(0.0)).min(1.0);
        for (i, f) in g.face.iter().enumerate() {
            let px = &mut rgb[3 * i..3 * i + 3];
            if *f == EMPTY {
                match &self.rig {
                    Some((rig, shot)) => match behind(rig, shot, &cam, size, i % size, i / size) {
                        Behind::Table(_) => px.copy_from_slice(&rig.table.surface.map(|c| c * table_light)),
                        Behind::Backdrop(_) => px.copy_from_slice(&self.background),
                    },
                    None => px.copy_from_slice(&self.background),
                }
            } else {
                px.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
            }
        }
        rgb
    }

    /// The same as a `width × height` BGR frame: the centre of a square render of the larger
    /// side, drawn at twice the resolution and averaged down, so edges are smooth as a lens
    /// makes them; a rig's scene then gets the camera effects the rig lists (but the codec,
    /// which is the video writer's).
    pub fn frame(&self, angle_deg: f32, width: usize, height: usize) -> Frame {
        self.frame_exposed(angle_deg, width, height, true)
    }

    /// [`CarScene::frame`], with the rig's automatic exposure only when `auto_exposure` (a real
    /// camera's exposure locked has none).
    pub fn frame_exposed(&self, angle_deg: f32, width: usize, height: usize, auto_exposure: bool) -> Frame {
        let side = width.max(height);
        let mut rgb = pav_core::image::halve(&self.render(angle_deg, 2 * side), 2 * side, 2 * side);
        let Some((rig, shot)) = &self.rig else { return cut(&rgb, side, (width, height)) };
        let seed = noise_seed(angle_deg.rem_euclid(360.0), self.elevation_deg);
        develop(rig, shot, &self.mesh, &self.camera(angle_deg), &mut rgb, side, (width, height), auto_exposure, seed)
    }

    /// The rig this scene films, if it was made from one.
    pub fn rig(&self) -> Option<&RigConfig> {
        self.rig.as_ref().map(|(r, _)| r.as_ref())
    }
}
