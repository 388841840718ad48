//! Whole-image renders for looking at a mesh: its own texture with the textured-region mask
//! (`pav render`), and flat per-face colours (heat maps on the mesh).

use super::raster::{GBuffer, EMPTY};
use super::texture::Gather;
use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use pav_core::image::Rgb;

/// A textured render and its region mask.
pub struct Textured {
    /// RGB in [0, 1], white where no face is hit.
    pub rgb: Vec<f32>,
    /// 1 where the texture is pure white (the optimizable region), bilinearly sampled.
    pub mask: Vec<f32>,
    /// Share of the image the mesh covers.
    pub coverage: f32,
}

/// Renders `mesh` with `tex` (unlit) from `cam` at `size × size`.
pub fn textured(mesh: &Mesh, tex: &Rgb, cam: &Camera, size: usize) -> Textured {
    let g = GBuffer::render(mesh, cam, size);
    let gather = Gather::new(g.uv_samples(mesh), tex.width, tex.height);
    let mut rgb = vec![1.0f32; size * size * 3];
    gather.apply(&tex.rgb, 3, &mut rgb);
    let mut mask = vec![0.0f32; size * size];
    gather.apply(&tex.white_mask(), 1, &mut mask);
    Textured { rgb, mask, coverage: g.coverage() }
}

/// Renders `mesh` from `cam` at `size × size` with face `f` in `colours[f]` and `background`
/// elsewhere, as interleaved 8-bit RGB.
pub fn face_colours(mesh: &Mesh, colours: &[[u8; 3]], cam: &Camera, size: usize, background: [u8; 3]) -> Vec<u8> {
    GBuffer::render(mesh, cam, size)
        .face
        .iter()
        .flat_map(|f| if *f == EMPTY { background } else { colours[*f as usize] })
        .collect()
}
