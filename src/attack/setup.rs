//! Everything an optimization or a digital evaluation reads once: the normalized mesh, the
//! optimizable texels, the scene and the prepared views.

use super::config::{CameraConvention, Init, InitName, OptimizeConfig};
use super::view::View;
use crate::dataset::fca::CarlaSample;
use crate::detect::BBox;
use crate::geometry::camera::{fca, pav_camou};
use crate::geometry::mesh::Mesh;
use crate::geometry::parts::select_faces;
use crate::geometry::uv::paint_uv;
use crate::render::shade::vertex_normals;
use crate::render::texture::Texture;
use crate::scene::Scene;
use std::collections::HashMap;
use std::path::Path;

/// Edge of the random baseline's colour blocks, in texels.
pub const RANDOM_BLOCK: usize = 16;

/// Errors preparing an optimization.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct SetupError(pub String);

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
    /// Training views.
    pub train: Vec<View>,
    /// Held-out views.
    pub test: Vec<View>,
    /// Ground-truth car boxes by view name, in view pixels.
    pub boxes: HashMap<String, BBox>,
}

/// Nearest-neighbour resampling of a region mask to `size × size` texels.
pub fn resample_region(mask: &[f32], w: usize, h: usize, size: usize) -> Vec<f32> {
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
pub fn read_boxes(path: &Path) -> Result<HashMap<String, BBox>, SetupError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| SetupError(format!("cannot read labels {}: {e}", path.display())))?;
    let mut out = HashMap::new();
    for (i, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split('\t').collect();
        let bad = || SetupError(format!("{}:{}: expected npz and four box columns", path.display(), i + 1));
        if f.len() < 5 {
            return Err(bad());
        }
        let v: Vec<f32> = f[1..5].iter().map(|s| s.trim().parse()).collect::<Result<_, _>>().map_err(|_| bad())?;
        let stem = Path::new(f[0]).file_stem().map(|s| s.to_string_lossy().into_owned()).ok_or_else(bad)?;
        out.insert(stem, [v[0], v[1], v[2], v[3]]);
    }
    Ok(out)
}

impl Setup {
    /// Loads the config's mesh, region, scene and views, rendering views at `size` (default:
    /// the config's).
    pub fn load(cfg: &OptimizeConfig, size: Option<usize>) -> Result<Setup, SetupError> {
        let e = |x: &dyn std::fmt::Display| SetupError(x.to_string());
        let scene = Scene::load(&cfg.scene).map_err(|x| e(&x))?;
        let mut mesh = Mesh::load_obj(&cfg.mesh.obj).map_err(|x| e(&x))?;
        match cfg.mesh.camera {
            CameraConvention::Fca => mesh.normalize_bbox(),
            CameraConvention::PavCamou => {
                mesh.normalize();
            }
        }
        let normals = if scene.lighting.is_some() { vertex_normals(&mesh) } else { Vec::new() };
        let mask = Texture::load(&cfg.mesh.region).map_err(|x| e(&x))?;
        let ts = cfg.mesh.texture_size;
        let mut region = resample_region(&mask.white_mask(), mask.width, mask.height, ts);
        let parts = cfg.parts().map_err(|x| e(&x))?;
        if !parts.is_empty() {
            let up = match cfg.mesh.camera {
                CameraConvention::Fca => 2,
                CameraConvention::PavCamou => 1,
            };
            let faces = select_faces(&mesh, up, &parts, cfg.mesh.parts_min_cos);
            let painted = paint_uv(&mesh, &faces.iter().map(|&f| (f, [255u8; 3])).collect::<Vec<_>>(), ts, [0; 3]);
            for (r, px) in region.iter_mut().zip(painted.chunks(3)) {
                if px[0] == 0 {
                    *r = 0.0;
                }
            }
        }
        let region_values: Vec<u32> =
            (0..ts * ts).filter(|i| region[*i] > 0.5).flat_map(|i| (0..3).map(move |c| (i * 3 + c) as u32)).collect();
        if region_values.is_empty() {
            return Err(SetupError(format!(
                "{} has no pure-white texel{}: nothing to optimize",
                cfg.mesh.region.display(),
                if parts.is_empty() { String::new() } else { format!(" on the parts {:?}", cfg.mesh.parts) }
            )));
        }
        let size = size.unwrap_or(cfg.views.size);
        let lights = scene.lighting;
        let labels = match &cfg.views.labels {
            Some(p) => read_boxes(p)?,
            None => HashMap::new(),
        };
        let mut boxes = HashMap::new();
        let mut views = |files: &[std::path::PathBuf]| -> Result<Vec<View>, SetupError> {
            let mut out = Vec::new();
            for f in files {
                let s = CarlaSample::load(f).map_err(|x| e(&x))?;
                let cam = match cfg.mesh.camera {
                    CameraConvention::Fca => fca(s.cam_trans, s.veh_trans),
                    CameraConvention::PavCamou => pav_camou(s.cam_trans, s.veh_trans[1][1]),
                };
                let name = f.file_stem().map(|x| x.to_string_lossy().into_owned()).unwrap_or_default();
                let v = View::new(&name, &mesh, &normals, &cam, &s.image, size, &region, (ts, ts), lights.as_ref())
                    .map_err(|x| SetupError(format!("{}: {x}", f.display())))?;
                if v.active.is_empty() {
                    return Err(SetupError(format!(
                        "{}: the textured region is not visible in this view",
                        f.display()
                    )));
                }
                if let Some(b) = labels.get(&name) {
                    let (sx, sy) = (size as f32 / s.image.width as f32, size as f32 / s.image.height as f32);
                    boxes.insert(name.clone(), [b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy]);
                }
                out.push(v);
            }
            Ok(out)
        };
        let train = views(&cfg.views.train)?;
        let test = views(&cfg.views.test)?;
        Ok(Setup { mesh, tex_size: ts, region, region_values, scene, train, test, boxes })
    }

    /// The same problem over other views (cross-validation folds).
    pub fn with_views(&self, train: Vec<View>, test: Vec<View>) -> Setup {
        Setup {
            mesh: self.mesh.clone(),
            tex_size: self.tex_size,
            region: self.region.clone(),
            region_values: self.region_values.clone(),
            scene: self.scene.clone(),
            train,
            test,
            boxes: self.boxes.clone(),
        }
    }

    /// The "random" baseline: uniform random colours in `block × block` texel squares (at the
    /// default 1024² atlas a 16-texel block prints about 5 mm wide at 1:20, so the baseline is a
    /// printable pattern, not sub-pixel noise that aliases in the render).
    pub fn random_texture(&self, block: usize, seed: u64) -> Vec<f32> {
        let n = self.tex_size;
        let b = block.max(1);
        let cells = n.div_ceil(b);
        let mut rng = crate::rng::Rng::new(seed);
        let colours: Vec<f32> = (0..cells * cells * 3).map(|_| rng.unit()).collect();
        (0..n * n * 3).map(|i| colours[(((i / 3) / n / b) * cells + ((i / 3) % n) / b) * 3 + i % 3]).collect()
    }

    /// The starting texture; a random start draws its blocks from `seed`.
    pub fn initial_texture(&self, init: Init, seed: u64) -> Vec<f32> {
        match init {
            Init::Grey(g) => vec![g; self.tex_size * self.tex_size * 3],
            // Not seed itself: the random baselines of eval-digital and crossval draw small seeds.
            Init::Named(InitName::Random) => self.random_texture(RANDOM_BLOCK, seed ^ 0x1417_0000),
        }
    }
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
