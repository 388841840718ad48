//! What rendering costs in time: the G-buffer per view, the texture gather and its adjoint, and
//! shading, at several image sizes (`pav bench-render`).

use super::raster::GBuffer;
use super::shade::{vertex_normals, Lights, Shading};
use super::texture::Gather;
use pav_core::geometry::camera::{spherical, Camera};
use pav_core::geometry::mesh::Mesh;
use pav_core::progress::Progress;
use std::time::Instant;

/// Mean milliseconds per view of each stage at one image size.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RenderTiming {
    /// Image side.
    pub size: usize,
    /// Views timed.
    pub views: usize,
    /// Rasterizing the G-buffer.
    pub gbuffer_ms: f64,
    /// Mean share of the image the mesh covers.
    pub coverage: f64,
    /// Texture gather.
    pub gather_ms: f64,
    /// Its adjoint (scatter).
    pub adjoint_ms: f64,
    /// Phong shading.
    pub shade_ms: f64,
}

fn ms_per(views: usize, t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3 / views as f64
}

/// Times every stage on the normalized `mesh` seen from `views` orbit cameras at each of `sizes`,
/// with a 2048² texture; each size's result is a note on `progress`.
pub fn time_stages(mesh: &Mesh, sizes: &[usize], views: usize, progress: &dyn Progress) -> Vec<RenderTiming> {
    let normals = vertex_normals(mesh);
    let (tw, th) = (2048, 2048);
    let tex: Vec<f32> = (0..tw * th * 3).map(|i| (i % 251) as f32 / 250.0).collect();
    let views = views.max(1);
    let cams: Vec<Camera> = (0..views)
        .map(|k| {
            Camera::look_at(spherical(2.2, 20.0, k as f32 * 360.0 / views as f32), [0.0; 3], [0.0, 1.0, 0.0], 60.0)
        })
        .collect();
    let mut rows = Vec::new();
    for &size in sizes {
        let t = Instant::now();
        let gb: Vec<GBuffer> = cams.iter().map(|c| GBuffer::render(mesh, c, size)).collect();
        let gbuffer_ms = ms_per(views, t);
        let gathers: Vec<Gather> = gb.iter().map(|g| Gather::new(g.uv_samples(mesh), tw, th)).collect();
        let mut img = vec![0.0; size * size * 3];
        let t = Instant::now();
        for g in &gathers {
            g.apply(&tex, 3, &mut img);
        }
        let gather_ms = ms_per(views, t);
        let mut grad = vec![0.0; tw * th * 3];
        let t = Instant::now();
        for g in &gathers {
            g.adjoint(&img, 3, &mut grad);
        }
        let adjoint_ms = ms_per(views, t);
        let t = Instant::now();
        for (g, c) in gb.iter().zip(&cams) {
            Shading::new(g, mesh, &normals, c, &Lights::PAV_CAMOU).apply(&mut img, 3);
        }
        let shade_ms = ms_per(views, t);
        let coverage = gb.iter().map(|g| g.coverage() as f64).sum::<f64>() / views as f64;
        progress.note(&format!(
            "{size}²: G-buffer {gbuffer_ms:.1} ms/view, gather {gather_ms:.2} ms, adjoint {adjoint_ms:.2} ms, shading {shade_ms:.2} ms (car covers {:.0} %)",
            100.0 * coverage
        ));
        rows.push(RenderTiming { size, views, gbuffer_ms, coverage, gather_ms, adjoint_ms, shade_ms });
    }
    rows
}
