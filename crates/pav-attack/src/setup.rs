//! Everything an optimization or a digital evaluation reads once: the normalized mesh, the
//! optimizable texels, the scene and the prepared views.

use super::config::{Init, InitName, OptimizeConfig};
use super::view::TrainView;
#[cfg(feature = "optimize")]
use super::whitebox::{Ensemble, WhiteBoxError};
use pav_core::geometry::camera::Camera;
use pav_core::geometry::camera::CameraConvention;
use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::parts::select_faces;
use pav_core::geometry::uv::faces_mask;
use pav_core::image::resize::{resize, Interpolation};
use pav_core::image::{to_u8, Frame, ImageError, Rgb};
use pav_core::step::Chain;
use pav_dataset::fca::CarlaSample;
use pav_detect::BBox;
use pav_print::channel::{region_texels, PrintChannel, Printing};
use pav_render::bake::{bake, BakeError, Plate, PosedPhoto, BAKE_SIZE};
use pav_render::mask::MaskError;
use pav_render::shade::{vertex_normals, Lights};
use pav_scene::Scene;
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The random baseline has this many colour blocks across the atlas side, whatever its
/// resolution (16 texels at 1024², about 5 mm when printed at 1:20), so baselines stay the same
/// printed pattern when `mesh.texture_size` changes.
pub const RANDOM_BLOCKS_PER_SIDE: usize = 64;

/// The paper's random baseline: a random image of this many pixels across, scaled up to the atlas.
pub const PAPER_RANDOM_SIDE: usize = 32;

/// Errors preparing an optimization.
#[derive(Debug, thiserror::Error)]
pub enum SetupError {
    /// The scene file.
    #[error(transparent)]
    Scene(#[from] pav_scene::SceneError),
    /// The mesh.
    #[error(transparent)]
    Mesh(#[from] pav_core::geometry::mesh::MeshError),
    /// The region image.
    #[error(transparent)]
    Image(#[from] pav_core::image::ImageError),
    /// `mesh.parts`.
    #[error("mesh.parts: {0}")]
    Parts(#[from] pav_core::geometry::parts::PartError),
    /// A view's npz file.
    #[error(transparent)]
    Sample(#[from] pav_dataset::npz::NpzError),
    /// The ground-truth box file.
    #[error("cannot read labels {path}: {source}")]
    Labels {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A line of the ground-truth box file.
    #[error("{path}:{line}: expected npz and four box columns")]
    LabelLine {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
    },
    /// The dual-render mask of a view.
    #[error("{view}: {source}")]
    Mask {
        /// The view (file or synthetic name).
        view: String,
        /// Why.
        source: MaskError,
    },
    /// Baking the car's appearance or painting it out of a photo, for synthetic views.
    #[error("{what}: {source}")]
    Bake {
        /// What was being done.
        what: String,
        /// Why.
        source: BakeError,
    },
    /// The views or the region do not make a problem (nothing to optimize, a view listed twice).
    #[error("{0}")]
    Views(String),
    /// A folder of rendered views that is not there yet, with the command that renders it.
    #[error("{0}")]
    NotRendered(super::config::MissingViews),
    /// A folder of rendered views (`views.pbr`).
    #[error("views.pbr: {0}")]
    Pbr(#[from] pav_scene::views::ViewsError),
    /// The `[print]` table's profile.
    #[error("print.profile: {0}")]
    Print(#[from] pav_print::proof::ProofError),
}

/// The prepared problem.
pub struct Setup {
    /// The normalized mesh.
    pub mesh: Mesh,
    /// Texture side.
    pub tex_size: usize,
    /// Per texel: 1 if optimizable.
    pub region: Vec<f32>,
    /// Indices of the optimizable values (texel × 3 + channel).
    pub region_values: Vec<u32>,
    /// Lighting and EoT.
    pub scene: Scene,
    /// Training views (photos).
    pub train: Vec<TrainView>,
    /// Synthetic training views (`views.turns`): trained on, never scored.
    pub synthetic: Vec<TrainView>,
    /// Rendered training views (`views.pbr`, Blender Cycles): trained on, never scored; with
    /// `views.stream` only their files are held, and each is rebuilt when stepped on.
    pub pbr: Vec<PbrView>,
    /// Held-out views.
    pub test: Vec<TrainView>,
    /// Ground-truth car boxes by view name, in view pixels.
    pub boxes: HashMap<String, BBox>,
    /// Rendered views laid over a photo's background plate: view name → the photo's stem.
    pub plates: HashMap<String, String>,
    /// The `[print]` table's channel: the white boxes see the texture through it in training.
    pub print: Option<PrintChannel>,
    /// The channel scores see textures through (the studies): the `[print]` table's unless a
    /// command names another.
    pub print_scored: Option<PrintChannel>,
    /// The optimizable texels (the region's, as texel indices), for the print channel's adjoint.
    pub region_texels: Vec<u32>,
    /// The photos behind `train` and `test` by view name, for synthetic views of any subset.
    samples: Arc<HashMap<String, CarlaSample>>,
    maker: ViewMaker,
}

/// A rendered view as its files: what rebuilds its [`TrainView`] (`views.stream`), and the texels it
/// reads, kept for [`Setup::region_views_shares`].
#[derive(Clone, Debug)]
pub struct StoredView {
    /// The view's name (`pbr:` and the manifest's name).
    pub name: String,
    /// The rendered image.
    image: PathBuf,
    /// Its camera, in the mesh's normalized frame.
    camera: Camera,
    /// [`TrainView::texels_read`] of the built view.
    texels: Vec<u32>,
}

/// A rendered training view: built and held in memory, or only its files (`views.stream`).
#[derive(Clone, Debug)]
pub enum PbrView {
    /// Built once at set-up, with its rendered image's file.
    Built(TrainView, PathBuf),
    /// Rebuilt from its files at each use.
    Stored(StoredView),
}

impl PbrView {
    /// The view's name.
    pub fn name(&self) -> &str {
        match self {
            PbrView::Built(v, _) => &v.name,
            PbrView::Stored(s) => &s.name,
        }
    }

    /// Its rendered image's file.
    pub fn image(&self) -> &Path {
        match self {
            PbrView::Built(_, image) => image,
            PbrView::Stored(s) => &s.image,
        }
    }

    /// The view as [`Setup::training_views`] lists it.
    pub fn as_ref(&self) -> ViewRef<'_> {
        match self {
            PbrView::Built(v, _) => ViewRef::Built(v),
            PbrView::Stored(s) => ViewRef::Stored(s),
        }
    }
}

/// A training view as listed: built, or to be rebuilt from its files by [`Setup::view`].
#[derive(Clone, Copy, Debug)]
pub enum ViewRef<'a> {
    /// A view held in memory.
    Built(&'a TrainView),
    /// A rendered view held as its files.
    Stored(&'a StoredView),
}

impl ViewRef<'_> {
    /// The view's name.
    pub fn name(&self) -> &str {
        match self {
            ViewRef::Built(v) => &v.name,
            ViewRef::Stored(s) => &s.name,
        }
    }
}

/// Why [`Setup::keep_detected_pbr`] failed.
#[cfg(feature = "optimize")]
#[derive(Debug, thiserror::Error)]
pub enum KeepError {
    /// Rebuilding a stored view.
    #[error(transparent)]
    TrainView(Box<SetupError>),
    /// A white box.
    #[error(transparent)]
    WhiteBox(#[from] WhiteBoxError),
    /// Reading a rendered image.
    #[error("reading {path}: {source}")]
    Read {
        /// The image.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Keeping the scores beside the images.
    #[error(transparent)]
    Scores(#[from] crate::view_scores::ViewScoresError),
    /// A stop was asked for; the scores computed so far are kept.
    #[error("stopped while scoring the rendered views ({scored} scored, {total} in all); the scores so far are kept beside the images, and the same command goes on from them")]
    Stopped {
        /// Views scored by this run before the stop.
        scored: usize,
        /// Rendered views in all.
        total: usize,
    },
}

/// What [`Setup::keep_detected_pbr`] kept.
#[derive(Clone, Debug, PartialEq)]
pub struct PbrKept {
    /// Rendered views kept.
    pub kept: usize,
    /// Rendered views before the filter.
    pub total: usize,
    /// The score a car needed.
    pub min_score: f32,
    /// Per white box: in how many of the `total` views it found the car.
    pub seen_by: Vec<(String, usize)>,
    /// Cached scores that did not read (a crash's torn rows), scored again.
    pub damaged: usize,
}

impl std::fmt::Display for PbrKept {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let by: Vec<String> = self.seen_by.iter().map(|(n, k)| format!("{n} {k}")).collect();
        write!(
            f,
            "kept {} of {} rendered views, those with a car scored ≥ {} by some white box as rendered (seen by {})",
            self.kept,
            self.total,
            self.min_score,
            by.join(", ")
        )?;
        if self.damaged > 0 {
            write!(f, "; {} damaged rows of the score cache scored again", self.damaged)?;
        }
        Ok(())
    }
}

/// What turns a CARLA sample into a [`TrainView`].
#[derive(Clone)]
struct ViewMaker {
    camera: CameraConvention,
    size: usize,
    normals: Vec<[f32; 3]>,
    lights: Option<Lights>,
    turns: Vec<f64>,
}

impl ViewMaker {
    /// The camera of `s` with the car turned in place by `turn_deg`.
    fn camera(&self, s: &CarlaSample, turn_deg: f64) -> Camera {
        self.camera.camera(s.cam_trans, s.veh_trans, turn_deg)
    }

    fn view(
        &self,
        name: &str,
        mesh: &Mesh,
        cam: &Camera,
        photo: &Frame,
        region: &[f32],
        ts: usize,
    ) -> Result<TrainView, MaskError> {
        TrainView::new(name, mesh, &self.normals, cam, photo, self.size, region, (ts, ts), self.lights.as_ref())
    }

    /// The view of a rendered image file seen from `cam`.
    fn rendered(
        &self,
        name: &str,
        mesh: &Mesh,
        image: &Path,
        cam: &Camera,
        region: &[f32],
        ts: usize,
    ) -> Result<TrainView, SetupError> {
        // A rig's landscape render holds the centre rows of the square the camera sees.
        let img = Rgb::load(image)?.into_square(true);
        let photo = Frame {
            width: img.width,
            height: img.height,
            bgr: img.rgb.chunks(3).flat_map(|c| [to_u8(c[2]), to_u8(c[1]), to_u8(c[0])]).collect(),
        };
        self.view(name, mesh, cam, &photo, region, ts).map_err(|source| SetupError::Mask { view: name.into(), source })
    }
}

/// Nearest-neighbour resampling of a region mask to `size × size` texels.
fn resample_region(mask: &[f32], w: usize, h: usize, size: usize) -> Vec<f32> {
    let mut out = vec![0f32; size * size];
    for y in 0..size {
        let sy = ((y as f64 + 0.5) * h as f64 / size as f64) as usize;
        for x in 0..size {
            let sx = ((x as f64 + 0.5) * w as f64 / size as f64) as usize;
            out[y * size + x] = mask[sy.min(h - 1) * w + sx.min(w - 1)];
        }
    }
    out
}

/// Reads FCA's derived_test_labels.tsv: npz file stem → GT box in photo pixels.
fn read_boxes(path: &Path) -> Result<HashMap<String, BBox>, SetupError> {
    let text = std::fs::read_to_string(path).map_err(|source| SetupError::Labels { path: path.into(), source })?;
    let mut out = HashMap::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split('\t').collect();
        let bad = || SetupError::LabelLine { path: path.into(), line: i + 1 };
        if f.len() < 5 {
            return Err(bad());
        }
        let v: Vec<f32> = f[1..5].iter().map(|s| s.trim().parse()).collect::<Result<_, _>>().map_err(|_| bad())?;
        let stem = Path::new(f[0]).file_stem().map(|s| s.to_string_lossy().into_owned()).ok_or_else(bad)?;
        out.insert(stem, [v[0], v[1], v[2], v[3]]);
    }
    Ok(out)
}

/// The views of the rendered folders `dirs` (`views.pbr` or `views.pbr_test`), after checking
/// each was rendered from this config's mesh in the normalization its camera convention uses
/// (the cameras are in that frame), each passed through `keep` as it is built (so that a caller
/// holding only its files never holds every view at once). Views that do not show the region
/// are left out. With `boxes`, each kept view's car box (its silhouette's, in view pixels) goes
/// in there.
#[allow(clippy::too_many_arguments)]
fn pbr_views<T>(
    cfg: &OptimizeConfig,
    dirs: &[PathBuf],
    maker: &ViewMaker,
    mesh: &Mesh,
    region: &[f32],
    mut boxes: Option<&mut HashMap<String, BBox>>,
    plates: &mut HashMap<String, String>,
    keep: impl Fn(TrainView, (PathBuf, Camera)) -> T,
) -> Result<Vec<T>, SetupError> {
    let mut out = Vec::new();
    let normalize = match cfg.mesh.camera {
        CameraConvention::Fca => "bbox",
        CameraConvention::PavCamou => "pav",
    };
    let missing = cfg.missing_views();
    for dir in dirs {
        // Named with the command that renders it, rather than as a file the reader lacks.
        if let Some(m) = missing.iter().find(|m| &m.dir == dir) {
            return Err(SetupError::NotRendered(m.clone()));
        }
        let (info, rows) = pav_scene::views::read_view_set(dir)?;
        if !info.shows(&cfg.mesh.obj) || info.normalize != normalize {
            return Err(SetupError::Views(format!(
                "views.pbr {}: rendered from {} normalized `{}`, but this config optimizes {} normalized `{normalize}`",
                dir.display(),
                info.obj.display(),
                info.normalize,
                cfg.mesh.obj.display()
            )));
        }
        for r in rows {
            let name = format!("pbr:{}", r.name);
            let (image, camera) = (dir.join(&r.image), r.camera());
            let v = maker.rendered(&name, mesh, &image, &camera, region, cfg.mesh.texture_size)?;
            // A pose that hides the region teaches nothing, and no texture can change its score.
            if v.active.is_empty() {
                continue;
            }
            if !r.plate.is_empty() {
                let stem = Path::new(&r.plate).file_stem().map(|s| s.to_string_lossy().into_owned());
                plates.insert(name.clone(), stem.unwrap_or_default());
            }
            if let Some(b) = boxes.as_deref_mut() {
                let mask = Rgb::load(&dir.join(&r.mask))?.into_square(false);
                if let Some(bb) = silhouette_box(&mask, v.size) {
                    b.insert(name.clone(), bb);
                }
            }
            out.push(keep(v, (image, camera)));
        }
    }
    Ok(out)
}

/// The box around a silhouette mask's lit pixels, scaled to a `size × size` view (None when
/// the mask is empty).
fn silhouette_box(mask: &Rgb, size: usize) -> Option<BBox> {
    let [x0, y0, x1, y1] = pav_core::image::set_bounds(mask.width, mask.rgb.chunks(3).map(|c| c[0] > 0.5))?;
    let (sx, sy) = (size as f32 / mask.width as f32, size as f32 / mask.height as f32);
    Some([x0 as f32 * sx, y0 as f32 * sy, x1 as f32 * sx, y1 as f32 * sy])
}

/// The config's region at a texture's size, for a texture read from a file; `None` when the
/// texture is not square (every texel counts).
pub fn region_at(cfg: &OptimizeConfig, width: usize, height: usize) -> Result<Option<Vec<f32>>, SetupError> {
    if width != height {
        return Ok(None);
    }
    let mut c = cfg.clone();
    c.mesh.texture_size = width;
    Ok(Some(mesh_and_region(&c)?.1))
}

/// The config's mesh in its camera convention's frame, and its optimizable region at the
/// texture size: the white texels of `mesh.region` on the faces of `mesh.parts` (1 or 0 per texel).
pub fn mesh_and_region(cfg: &OptimizeConfig) -> Result<(Mesh, Vec<f32>), SetupError> {
    let mut mesh = Mesh::load_obj(&cfg.mesh.obj)?;
    match cfg.mesh.camera {
        CameraConvention::Fca => mesh.normalize_bbox(),
        CameraConvention::PavCamou => {
            mesh.normalize();
        }
    }
    let mask = Rgb::load(&cfg.mesh.region)?;
    let ts = cfg.mesh.texture_size;
    let mut region = resample_region(&mask.white_mask(), mask.width, mask.height, ts);
    let parts = cfg.parts()?;
    if !parts.is_empty() {
        let faces = select_faces(&mesh, cfg.mesh.up_axis().index, &parts, cfg.mesh.parts_min_cos);
        // Conservative: a face thinner than a texel still keeps the texels its corners read.
        for (r, on) in region.iter_mut().zip(faces_mask(&mesh, &faces, ts)) {
            if !on {
                *r = 0.0;
            }
        }
    }
    Ok((mesh, region))
}

impl Setup {
    /// Loads the config's mesh, region, scene and views, rendering views at `size` (default:
    /// the config's), with the synthetic views of its training photos.
    pub fn load(cfg: &OptimizeConfig, size: Option<usize>) -> Result<Setup, SetupError> {
        let mut setup = Self::load_photos(cfg, size)?;
        let names: Vec<&str> = setup.train.iter().map(|v| v.name.as_str()).collect();
        setup.synthetic = setup.turned_views(&names)?;
        Ok(setup)
    }

    /// [`Setup::load`] without synthetic views: for scoring, which never uses them, and for
    /// cross-validation, which builds them per fold from [`Setup::turned_views`].
    pub fn load_photos(cfg: &OptimizeConfig, size: Option<usize>) -> Result<Setup, SetupError> {
        let scene = Scene::load(&cfg.scene)?;
        let (mesh, region) = mesh_and_region(cfg)?;
        let normals = if scene.lighting.is_some() { vertex_normals(&mesh) } else { Vec::new() };
        let (ts, parts) = (cfg.mesh.texture_size, cfg.parts()?);
        let region_values: Vec<u32> =
            (0..ts * ts).filter(|i| region[*i] > 0.5).flat_map(|i| (0..3).map(move |c| (i * 3 + c) as u32)).collect();
        if region_values.is_empty() {
            return Err(SetupError::Views(format!(
                "{} has no pure-white texel{}: nothing to optimize",
                cfg.mesh.region.display(),
                if parts.is_empty() { String::new() } else { format!(" on the parts {:?}", cfg.mesh.parts) }
            )));
        }
        let size = size.unwrap_or(cfg.views.size);
        let maker = ViewMaker {
            camera: cfg.mesh.camera,
            size,
            normals,
            lights: scene.lighting,
            turns: cfg.views.turns.clone(),
        };
        let labels = match &cfg.views.labels {
            Some(p) => read_boxes(p)?,
            None => HashMap::new(),
        };
        let mut boxes = HashMap::new();
        let mut samples = HashMap::new();
        let mut views = |files: &[std::path::PathBuf]| -> Result<Vec<TrainView>, SetupError> {
            let mut out = Vec::new();
            for f in files {
                let s = CarlaSample::load(f)?;
                let name = f.file_stem().map(|x| x.to_string_lossy().into_owned()).unwrap_or_default();
                let v = maker
                    .view(&name, &mesh, &maker.camera(&s, 0.0), &s.image, &region, ts)
                    .map_err(|source| SetupError::Mask { view: f.display().to_string(), source })?;
                if v.active.is_empty() {
                    return Err(SetupError::Views(format!(
                        "{}: the textured region is not visible in this view",
                        f.display()
                    )));
                }
                if let Some(b) = labels.get(&name) {
                    let (sx, sy) = (size as f32 / s.image.width as f32, size as f32 / s.image.height as f32);
                    boxes.insert(name.clone(), [b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy]);
                }
                if samples.insert(name.clone(), s).is_some() {
                    return Err(SetupError::Views(format!("{}: a view named {name} is listed twice", f.display())));
                }
                out.push(v);
            }
            Ok(out)
        };
        let train = views(&cfg.views.train)?;
        let mut test = views(&cfg.views.test)?;
        let mut plates = HashMap::new();
        let stream = cfg.views.stream;
        // Only a stored view needs its texel list: a built one reads it off its lookup.
        let held = |v: TrainView, (image, camera)| {
            if stream {
                PbrView::Stored(StoredView { texels: v.texels_read(), name: v.name, image, camera })
            } else {
                PbrView::Built(v, image)
            }
        };
        let pbr = pbr_views(cfg, &cfg.views.pbr, &maker, &mesh, &region, None, &mut plates, held)?;
        let built = |v, _| v;
        test.extend(pbr_views(cfg, &cfg.views.pbr_test, &maker, &mesh, &region, Some(&mut boxes), &mut plates, built)?);
        let print = cfg.print.as_ref().map(PrintChannel::open).transpose()?;
        Ok(Setup {
            mesh,
            tex_size: ts,
            print_scored: print.clone(),
            print,
            region_texels: region_texels(&region),
            region,
            region_values,
            scene,
            train,
            synthetic: Vec::new(),
            pbr,
            test,
            boxes,
            plates,
            samples: Arc::new(samples),
            maker,
        })
    }

    /// The photo of view `name` at the views' size with its car painted out: the same street
    /// without the car, where a detector should find none (`None` for a view without a photo).
    pub fn car_free(&self, name: &str) -> Option<Result<Frame, BakeError>> {
        let s = self.samples.get(name)?;
        let n = self.maker.size;
        let photo = if (s.image.width, s.image.height) == (n, n) {
            s.image.clone()
        } else {
            Frame::from_levels(n, n, &resize(&s.image, n, n, Interpolation::Antialias))
        };
        Some(Plate::new(&self.mesh, &photo, &self.maker.camera(s, 0.0), n / 50).map(|p| p.frame()))
    }

    /// The synthetic views of `views.turns` for the photos named `names`, from an appearance
    /// baked from those photos only (so a held-out photo never leaks into training).
    pub fn turned_views(&self, names: &[&str]) -> Result<Vec<TrainView>, SetupError> {
        if self.maker.turns.is_empty() || names.is_empty() {
            return Ok(Vec::new());
        }
        let samples: Vec<(&str, &CarlaSample)> = names
            .iter()
            .map(|n| {
                self.samples.get(*n).map(|s| (*n, s)).ok_or_else(|| SetupError::Views(format!("no view named {n}")))
            })
            .collect::<Result<_, _>>()?;
        let shots: Vec<PosedPhoto> =
            samples.iter().map(|(_, s)| PosedPhoto { cam: self.maker.camera(s, 0.0), photo: &s.image }).collect();
        let n = samples[0].1.image.width;
        let app = bake(&self.mesh, &shots, BAKE_SIZE, (n / 200).max(2))
            .map_err(|source| SetupError::Bake { what: "baking the car's appearance".into(), source })?;
        let mut out = Vec::new();
        for ((name, s), shot) in samples.iter().zip(&shots) {
            let plate = Plate::new(&self.mesh, &s.image, &shot.cam, n / 50)
                .map_err(|source| SetupError::Bake { what: format!("{name}: painting the car out"), source })?;
            for &turn in &self.maker.turns {
                let cam = self.maker.camera(s, turn);
                let photo = plate.with_car(&self.mesh, &app, &cam);
                let vname = format!("{name}@{turn:+}");
                let v = self
                    .maker
                    .view(&vname, &self.mesh, &cam, &photo, &self.region, self.tex_size)
                    .map_err(|source| SetupError::Mask { view: vname.clone(), source })?;
                // A turn can hide the region (the car end-on under a side-only region): no view.
                if !v.active.is_empty() {
                    out.push(v);
                }
            }
        }
        Ok(out)
    }

    /// The views an optimization steps through: the photos, the synthetic views, the rendered
    /// views, less those laid over a held-out photo's background (its street and camera must
    /// not be trained on).
    pub fn training_views(&self) -> Vec<ViewRef<'_>> {
        let pbr = self.pbr.iter().filter(|v| !self.over_held_out(v.name())).map(PbrView::as_ref);
        self.train.iter().chain(&self.synthetic).map(ViewRef::Built).chain(pbr).collect()
    }

    /// What the white boxes see of the texture on `view`, as one chain of steps: the print
    /// channel when the config has a `[print]` table (the gradient passing back to the region's
    /// texels only), then the view's render, composite and the scene's effects.
    pub fn chain<'a>(&'a self, view: &'a TrainView) -> Chain<'a> {
        let mut c = Chain::new();
        if let Some(p) = &self.print {
            let texels = self.tex_size * self.tex_size;
            c.push("print", Printing { channel: p, texels, region: Some(&self.region_texels) });
        }
        c.and(view.chain(&self.scene))
    }

    /// The view `v` lists: itself, or rebuilt from its files (the same view, bit for bit, as
    /// the one built at set-up).
    pub fn view<'a>(&self, v: ViewRef<'a>) -> Result<Cow<'a, TrainView>, SetupError> {
        match v {
            ViewRef::Built(v) => Ok(Cow::Borrowed(v)),
            ViewRef::Stored(s) => {
                let v = self.maker.rendered(&s.name, &self.mesh, &s.image, &s.camera, &self.region, self.tex_size)?;
                Ok(Cow::Owned(v))
            }
        }
    }

    /// Bytes the training views hold in memory (a stored view: its files' names and texel list).
    pub fn training_bytes(&self) -> usize {
        let stored = |s: &StoredView| s.name.len() + s.image.as_os_str().len() + s.texels.len() * 4;
        self.training_views()
            .iter()
            .map(|v| match v {
                ViewRef::Built(v) => v.heap_bytes(),
                ViewRef::Stored(s) => stored(s),
            })
            .sum()
    }

    /// Rendered views over photos' background plates (folders written by `pav views render`
    /// with `[plates]`), to be scored, never trained on: each kept view's car box (its
    /// silhouette's) goes into [`Setup::boxes`] and its photo into [`Setup::plates`]. A view
    /// without a plate is refused: it belongs to no photo's fold.
    pub fn rendered_over_plates(
        &mut self,
        cfg: &OptimizeConfig,
        dirs: &[PathBuf],
    ) -> Result<Vec<TrainView>, SetupError> {
        let (maker, mesh, region) = (&self.maker, &self.mesh, &self.region);
        let views = pbr_views(cfg, dirs, maker, mesh, region, Some(&mut self.boxes), &mut self.plates, |v, _| v)?;
        if let Some(v) = views.iter().find(|v| !self.plates.contains_key(&v.name)) {
            return Err(SetupError::Views(format!(
                "{}: not laid over a photo's plate; only views rendered with [plates] can be held out with their photo",
                v.name
            )));
        }
        Ok(views)
    }

    /// The photo whose background plate a rendered view lies over.
    pub fn plate_of(&self, view: &str) -> Option<&str> {
        self.plates.get(view).map(String::as_str)
    }

    /// Rendered training views left out because they lie over a held-out photo's background.
    pub fn plates_held_out(&self) -> usize {
        self.pbr.iter().filter(|v| self.over_held_out(v.name())).count()
    }

    fn over_held_out(&self, name: &str) -> bool {
        self.plates.get(name).is_some_and(|p| self.test.iter().any(|t| t.name == *p))
    }

    /// Shares of the optimizable texels that 0, 1 and 2 or more training views read: a texel
    /// only one view reads is free to fit that view alone.
    pub fn region_views_shares(&self) -> [f64; 3] {
        let mut count = vec![0u32; self.tex_size * self.tex_size];
        for v in self.training_views() {
            let texels = match v {
                ViewRef::Built(v) => Cow::Owned(v.texels_read()),
                ViewRef::Stored(s) => Cow::Borrowed(&s.texels),
            };
            for &t in texels.iter() {
                count[t as usize] += 1;
            }
        }
        let mut n = [0usize; 3];
        let texels: Vec<usize> = (0..count.len()).filter(|i| self.region[*i] > 0.5).collect();
        for &i in &texels {
            n[(count[i] as usize).min(2)] += 1;
        }
        n.map(|k| k as f64 / texels.len().max(1) as f64)
    }

    /// Drops the rendered views in which no white box of `wb` finds a car at `min_score` as they
    /// were rendered (`views.pbr_min_score`); the photos are kept whatever they score. Each
    /// white box's score of each image is kept beside the images ([`crate::view_scores`]) as
    /// it is computed, so a later run with the same white boxes reads it instead of running
    /// them again. A raised `stop` ends the scoring after the view in progress, keeping the
    /// scores so far, with [`KeepError::Stopped`].
    #[cfg(feature = "optimize")]
    pub fn keep_detected_pbr(
        &mut self,
        wb: &Ensemble,
        min_score: f32,
        stop: &std::sync::atomic::AtomicBool,
    ) -> Result<PbrKept, KeepError> {
        use crate::view_scores::ViewScores;
        let total = self.pbr.len();
        let mut seen_by = vec![0usize; wb.members.len()];
        let mut kept = Vec::with_capacity(total);
        let mut caches: HashMap<PathBuf, ViewScores> = HashMap::new();
        let (mut scored, mut saved) = (0, std::time::Instant::now());
        let all = std::mem::take(&mut self.pbr);
        for p in all {
            if stop.load(std::sync::atomic::Ordering::SeqCst) {
                for (folder, cache) in &mut caches {
                    cache.save(folder)?;
                }
                return Err(KeepError::Stopped { scored, total });
            }
            let image = p.image();
            let folder = image.parent().unwrap_or(Path::new(".")).to_path_buf();
            let file = image.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
            let bytes = std::fs::read(image).map_err(|source| KeepError::Read { path: image.to_path_buf(), source })?;
            let sha = pav_run::data::store::sha256_hex(&bytes);
            let cache = caches.entry(folder.clone()).or_insert_with(|| ViewScores::read(&folder));
            let mut built = None;
            let mut any = false;
            for (k, (m, _)) in wb.members.iter().enumerate() {
                let score = match cache.get(m.identity(), &file, &sha) {
                    Some(s) => s,
                    None => {
                        let v = match &built {
                            Some(v) => v,
                            None => built.insert(self.view(p.as_ref()).map_err(|e| KeepError::TrainView(Box::new(e)))?),
                        };
                        let s = m.loss(&v.photo, v.size)?.max_score;
                        cache.put(m.identity(), &file, &sha, s);
                        s
                    }
                };
                if pav_detect::detected(score, min_score) {
                    seen_by[k] += 1;
                    any = true;
                }
            }
            let fresh = built.is_some();
            drop(built);
            if any {
                kept.push(p);
            }
            if fresh {
                scored += 1;
                // Kept as they come (every 15 s at most: a save rewrites the folder's file), so
                // that a crash loses at most that much scoring.
                if saved.elapsed().as_secs() >= 15 {
                    caches.get_mut(&folder).expect("the folder's cache").save(&folder)?;
                    saved = std::time::Instant::now();
                }
            }
        }
        for (folder, cache) in &mut caches {
            cache.save(folder)?;
        }
        self.pbr = kept;
        let seen_by = wb.members.iter().map(|(m, _)| m.name().to_string()).zip(seen_by).collect();
        let damaged = caches.values().map(|c| c.damaged()).sum();
        Ok(PbrKept { kept: self.pbr.len(), total, min_score, seen_by, damaged })
    }

    /// The same problem over other views (cross-validation folds).
    pub fn with_views(&self, train: Vec<TrainView>, synthetic: Vec<TrainView>, test: Vec<TrainView>) -> Setup {
        Setup {
            mesh: self.mesh.clone(),
            tex_size: self.tex_size,
            region: self.region.clone(),
            region_values: self.region_values.clone(),
            scene: self.scene.clone(),
            train,
            synthetic,
            pbr: self.pbr.clone(),
            test,
            boxes: self.boxes.clone(),
            plates: self.plates.clone(),
            print: self.print.clone(),
            print_scored: self.print_scored.clone(),
            region_texels: self.region_texels.clone(),
            samples: self.samples.clone(),
            maker: self.maker.clone(),
        }
    }

    /// A texture as scores see it: through [`Setup::print_scored`] when set. Call it once per
    /// texture, not per view.
    pub fn scored<'a>(&self, tex: &'a [f32]) -> std::borrow::Cow<'a, [f32]> {
        match &self.print_scored {
            Some(p) => std::borrow::Cow::Owned(p.printed(tex)),
            None => std::borrow::Cow::Borrowed(tex),
        }
    }

    /// The deterministic scene that scores use: this run's lighting, no EoT.
    pub fn eval_scene(&self) -> Scene {
        Scene { lighting: self.scene.lighting, effects: Vec::new() }
    }

    /// Edge of the random baseline's blocks in texels at this atlas size.
    pub fn random_block(&self) -> usize {
        random_block_side(self.tex_size)
    }

    /// Block edge of the paper's random baseline ("random32", see [`PAPER_RANDOM_SIDE`]).
    pub fn paper_random_block(&self) -> usize {
        (self.tex_size / PAPER_RANDOM_SIDE).max(1)
    }

    /// The "random" baseline: uniform random colours in `block × block` texel squares (a
    /// printable pattern, not sub-pixel noise that aliases in the render).
    pub fn random_texture(&self, block: usize, seed: u64) -> Vec<f32> {
        random_blocks(self.tex_size, block, seed)
    }

    /// The starting texture; a random start draws its blocks from `seed`.
    pub fn initial_texture(&self, init: &Init, seed: u64) -> Result<Vec<f32>, ImageError> {
        Ok(match init {
            Init::Grey(g) => vec![*g; self.tex_size * self.tex_size * 3],
            // Not seed itself: the random baselines of eval-digital and crossval draw small seeds.
            Init::Named(InitName::Random) => self.random_texture(self.random_block(), seed ^ 0x1417_0000),
            Init::File(p) => self.load_texture(p)?,
        })
    }

    /// A texture image resampled to the atlas (antialiased when it shrinks, as PIL resizes), so
    /// textures made at any size, a peer's included, can be scored and fine-tuned.
    pub fn load_texture(&self, path: &Path) -> Result<Vec<f32>, ImageError> {
        let t = Rgb::load(path)?;
        let n = self.tex_size;
        if (t.width, t.height) == (n, n) {
            return Ok(t.rgb);
        }
        let frame = Frame { width: t.width, height: t.height, bgr: t.rgb.iter().map(|v| to_u8(*v)).collect() };
        Ok(resize(&frame, n, n, Interpolation::Antialias).into_iter().map(|v| v / 255.0).collect())
    }
}

/// An `n × n` RGB texture of uniform random colours in `block × block` squares drawn from
/// `seed` (the "random" baseline; [`random_block_side`] is its block edge at atlas size `n`).
pub fn random_blocks(n: usize, block: usize, seed: u64) -> Vec<f32> {
    let b = block.max(1);
    let cells = n.div_ceil(b);
    let mut rng = pav_core::rng::Rng::new(seed);
    let colours: Vec<f32> = (0..cells * cells * 3).map(|_| rng.unit()).collect();
    (0..n * n * 3).map(|i| colours[(((i / 3) / n / b) * cells + ((i / 3) % n) / b) * 3 + i % 3]).collect()
}

/// Edge of the random baseline's blocks in texels at atlas size `n`.
pub fn random_block_side(n: usize) -> usize {
    (n / RANDOM_BLOCKS_PER_SIDE).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_resampling_keeps_the_share() {
        let (w, h) = (40, 20);
        let mask: Vec<f32> = (0..w * h).map(|i| if (i % w) < 10 { 1.0 } else { 0.0 }).collect();
        let r = resample_region(&mask, w, h, 16);
        assert_eq!(r.iter().sum::<f32>(), 4.0 * 16.0);
        assert_eq!(r[..4], [1.0; 4]);
        assert_eq!(r[4], 0.0);
    }
}
