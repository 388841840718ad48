//! The UV-map tools that make a texture printable at one scale (`pav uv check`, `pav uv adjust`):
//! per-face distortion of the optimizable patch with heat maps, and its automatic re-flattening.

use pav_core::geometry::camera::{spherical, Camera};
use pav_core::geometry::mesh::{Mesh, MeshError};
use pav_core::geometry::uv::{distortion, faces_in_mask, faces_mask, heat_colour, paint_uv, summary};
use pav_core::image::{save_rgb8, tile, ImageError, Rgb};
use pav_core::table::{write_csv, TableError};
use pav_render::preview::face_colours;
use pav_uv::adjust::adjust;
use pav_uv::charts::{adjust_charts, UvChartError};
use std::path::{Path, PathBuf};

/// Why a UV tool failed.
#[derive(Debug, thiserror::Error)]
pub enum UvError {
    /// The mesh.
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The mask or an output image.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// The mask marks nothing on the mesh.
    #[error("{mask} marks no face of {mesh} (no pure-white texel under any face centroid)")]
    NoPatch {
        /// The mask.
        mask: PathBuf,
        /// The mesh.
        mesh: PathBuf,
    },
    /// The mask is not square.
    #[error("the UV mask must be square, got {0}x{1}")]
    NotSquare(usize, usize),
    /// The chart method could not pack the patch.
    #[error(transparent)]
    Charts(#[from] UvChartError),
    /// The distortion table.
    #[error(transparent)]
    Table(#[from] TableError),
    /// A file or folder.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// The distortion of a patch, area-weighted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvCheck {
    /// Faces in the patch.
    pub faces: usize,
    /// Mean |log₂ stretch| (1.0 = a factor of 2).
    pub mean_abs_log2_stretch: f64,
    /// 95th-percentile anisotropy σ₁/σ₂.
    pub p95_anisotropy: f64,
}

/// How `pav uv adjust` re-flattens the patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AdjustMode {
    /// Charts cut by the 3D surface (a door is one piece), packed into the texels no other face reads.
    Charts {
        /// Largest angle in degrees between a face's normal and its chart's seed normal.
        max_angle_deg: f64,
    },
    /// LSCM per original UV island, kept inside its original box.
    Islands,
}

/// What an adjustment did.
#[derive(Clone, Debug, PartialEq)]
pub struct UvAdjust {
    /// The patch before.
    pub before: UvCheck,
    /// The patch after.
    pub after: UvCheck,
    /// Texel density relative to the original.
    pub density: f64,
    /// For charts: (charts, most original islands one chart joins, folded faces).
    pub charts: Option<(usize, usize, usize)>,
    /// [`check`] of the written `after/` and `before/` folders, in that order.
    pub written: [UvCheck; 2],
}

fn create_dir(dir: &Path) -> Result<(), UvError> {
    std::fs::create_dir_all(dir).map_err(|source| UvError::Io { path: dir.into(), source })
}

/// The patch faces of `mesh`: those whose UV centroid is pure white in `mask`.
fn patch(mesh: &Mesh, mesh_path: &Path, mask: &Rgb, mask_path: &Path) -> Result<Vec<usize>, UvError> {
    let faces = faces_in_mask(mesh, &mask.white_mask(), mask.width, mask.height);
    if faces.is_empty() {
        return Err(UvError::NoPatch { mask: mask_path.into(), mesh: mesh_path.into() });
    }
    Ok(faces)
}

fn check_of(mesh: &Mesh, faces: &[usize]) -> UvCheck {
    let (mean, p95) = summary(&distortion(mesh, faces));
    UvCheck { faces: faces.len(), mean_abs_log2_stretch: mean, p95_anisotropy: p95 }
}

/// Measures the patch that `mask` marks on `mesh` and writes `uv_distortion.csv`, the heat map
/// in UV space (`uv_heat_uv.png`) and on the mesh from four sides (`uv_heat_mesh.png`) into `out`.
pub fn check(mesh_path: &Path, mask_path: &Path, out: &Path) -> Result<UvCheck, UvError> {
    let mut m = Mesh::load_obj(mesh_path)?;
    m.normalize();
    let mask = Rgb::load(mask_path)?;
    let faces = patch(&m, mesh_path, &mask, mask_path)?;
    let d = distortion(&m, &faces);
    create_dir(out)?;
    write_csv(&out.join("uv_distortion.csv"), &d)?;
    let colours: Vec<(usize, [u8; 3])> = d.iter().map(|r| (r.face, heat_colour(r.log2_stretch))).collect();
    let size = 1024;
    save_rgb8(&out.join("uv_heat_uv.png"), size, size, paint_uv(&m, &colours, size, [255, 255, 255]))?;
    // On the mesh: patch faces in their heat colour, the rest light grey, from four sides.
    let mut face_col = vec![[225u8, 225, 225]; m.faces.len()];
    for (f, c) in &colours {
        face_col[*f] = *c;
    }
    let views: Vec<Vec<u8>> = [45.0f32, 135.0, 225.0, 315.0]
        .iter()
        .map(|&azim| {
            let cam = Camera::look_at(spherical(2.2, 25.0, azim), [0.0; 3], [0.0, 1.0, 0.0], 60.0);
            face_colours(&m, &face_col, &cam, 400, [255, 255, 255])
        })
        .collect();
    let (w, h, grid) = tile(&views, 400, 400, 2, 255);
    save_rgb8(&out.join("uv_heat_mesh.png"), w, h, grid)?;
    Ok(check_of(&m, &faces))
}

/// Re-flattens the patch that `mask` marks on `mesh` at one common texel density; writes
/// `adjusted.obj`, `adjusted_mask.png` (the new region, white) and [`check`]'s outputs for the
/// mesh `before/` and `after/` into `out`.
pub fn adjust_patch(mesh_path: &Path, mask_path: &Path, mode: AdjustMode, out: &Path) -> Result<UvAdjust, UvError> {
    let original = Mesh::load_obj(mesh_path)?;
    let mask = Rgb::load(mask_path)?;
    let faces = patch(&original, mesh_path, &mask, mask_path)?;
    let before = check_of(&original, &faces);
    let mut m = original.clone();
    if mask.width != mask.height {
        return Err(UvError::NotSquare(mask.width, mask.height));
    }
    let (density, charts) = match mode {
        AdjustMode::Islands => (adjust(&mut m, &faces), None),
        AdjustMode::Charts { max_angle_deg } => {
            // One packing cell per 4 texels, one free cell around each chart.
            let r = adjust_charts(&mut m, &faces, max_angle_deg, (mask.width / 4).max(64), 1)?;
            (r.density, Some((r.charts, r.max_islands_joined, r.flipped)))
        }
    };
    let after = check_of(&m, &faces);
    create_dir(out)?;
    let obj = out.join("adjusted.obj");
    m.write_obj(&obj, None).map_err(|source| UvError::Io { path: obj.clone(), source })?;
    // The new mask: the original map with the patch painted over in the body colour, then the
    // adjusted islands painted white.
    let was_white = mask.white_mask();
    let mut rgb: Vec<u8> = mask.rgb.iter().map(|v| (v * 255.0).round() as u8).collect();
    let body = [67u8, 74, 114];
    for (i, px) in rgb.chunks_mut(3).enumerate() {
        if was_white[i] == 1.0 {
            px.copy_from_slice(&body);
        }
    }
    for (px, white) in rgb.chunks_mut(3).zip(faces_mask(&m, &faces, mask.width)) {
        if white {
            px.copy_from_slice(&[255, 255, 255]);
        }
    }
    let new_mask = out.join("adjusted_mask.png");
    save_rgb8(&new_mask, mask.width, mask.height, rgb)?;
    let written = [check(&obj, &new_mask, &out.join("after"))?, check(mesh_path, mask_path, &out.join("before"))?];
    Ok(UvAdjust { before, after, density, charts, written })
}
