//! Rendering a config's views by Blender's Cycles or pav's rasterizer, resuming what a folder holds.

use super::*;
use crate::blender::{Blender, Job, JobView, Mode};
use pav_core::geometry::mesh::Mesh;
use pav_core::image::resize::{resize, Interpolation};
use pav_core::image::{halve, Frame, Rgb};
use pav_core::progress::Progress;
use pav_render::bake::Plate;
use pav_render::raster::{GBuffer, EMPTY};
use pav_render::shade::{draw_textured, Lights};
use pav_run::shard::Shard;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

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
        None => rasterize(&mut writer, &mesh, &tex, &todo, &mut advance)?,
        Some((blender, envs)) => {
            let job = Cycles { blender, envs, obj: &obj, texture: &texture, tex: &tex, dir, views_dir: &views_dir };
            render_cycles(&job, &mut writer, &mesh, &todo, &mut advance)?
        }
    }
    std::fs::remove_file(&unfinished).map_err(io(&unfinished))?;
    progress.end(None);
    Ok(RenderSummary { total, resumed, rendered: rendered_now, manifest })
}

/// Draws the views of `todo` with pav's rasterizer, the car over the background as Cycles lays it.
fn rasterize(
    writer: &mut ViewWriter,
    mesh: &Mesh,
    tex: &Rgb,
    todo: &[&View],
    advance: &mut dyn FnMut(&str, f64),
) -> Result<(), ViewsError> {
    let normals = pav_render::shade::vertex_normals(mesh);
    let n = writer.cfg.render.size;
    for &v in todo {
        let t = std::time::Instant::now();
        let (g, mut rgb) = draw_textured(mesh, &normals, tex, &v.camera, &Lights::ROOM, 2 * n);
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
    Ok(())
}

/// What a Cycles render of a folder's views needs beside the views.
struct Cycles<'a> {
    blender: &'a Blender,
    /// Each environment's map.
    envs: Vec<PathBuf>,
    /// The mesh as written into the folder.
    obj: &'a Path,
    texture: &'a Path,
    tex: &'a Rgb,
    dir: &'a Path,
    views_dir: &'a Path,
}

/// Renders the views of `todo` with Blender's Cycles: one Blender process per environment for
/// its grid views, and one for its plate views on a transparent film.
fn render_cycles(
    c: &Cycles,
    writer: &mut ViewWriter,
    mesh: &Mesh,
    todo: &[&View],
    advance: &mut dyn FnMut(&str, f64),
) -> Result<(), ViewsError> {
    let ground_y = mesh.bounds().0[1];
    let cfg = writer.cfg;
    let effects: HashSet<PbrEffect> = cfg.render.effects.iter().copied().collect();
    let n = cfg.render.size;
    for (ei, env) in c.envs.iter().enumerate() {
        // Grid views over the environment, then plate views on a transparent film.
        for on_plates in [false, true] {
            let todo: Vec<&View> =
                todo.iter().copied().filter(|v| v.environment == ei && v.plate.is_some() == on_plates).collect();
            if todo.is_empty() {
                continue;
            }
            let mut job = Job::new(Mode::Pbr, c.obj.to_path_buf(), n, cfg.render.samples, ground_y);
            job.texture = Some(std::fs::canonicalize(c.texture).map_err(io(c.texture))?);
            job.tex_size = [c.tex.width, c.tex.height];
            job.environment = Some(env.clone());
            job.env_strength = cfg.environments[ei].strength;
            job.shadows = effects.contains(&PbrEffect::Shadows);
            job.transparent = on_plates;
            if effects.contains(&PbrEffect::Reflections) {
                (job.metallic, job.roughness, job.clearcoat) = (0.3, 0.35, 0.5);
            }
            if let Some(rig) = &cfg.rig {
                let [roughness, specular, clearcoat] = rig.surface;
                (job.metallic, job.roughness, job.clearcoat, job.specular) = (0.0, roughness, clearcoat, specular);
                job.backdrop = Some(rig.backdrop);
                job.table = Some(rig.table);
                job.shadows = false;
                job.rows = (rig.rows < n).then_some(rig.rows);
            }
            let out_name = |v: &View| if on_plates { format!("{}_car.png", v.name) } else { format!("{}.png", v.name) };
            job.views = todo
                .iter()
                .map(|v| JobView {
                    env_turn_deg: v.env_turn_deg,
                    ..JobView::new(&v.name, &v.camera, c.views_dir.join(out_name(v)))
                })
                .collect();
            let mut failure = None;
            c.blender.run(&job, c.dir, |name, secs| {
                let Some(v) = todo.iter().find(|v| v.name == name) else { return };
                let mut done_one = || -> Result<(), ViewsError> {
                    pav_core::image::strip_png_text(&c.views_dir.join(out_name(v)))?;
                    if v.plate.is_some() {
                        let (rgb, alpha) = pav_core::image::load_rgba(&c.views_dir.join(out_name(v)))?;
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
    Ok(())
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
