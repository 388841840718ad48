//! Rasterization into a G-buffer: per pixel the nearest triangle, its perspective-correct
//! barycentrics and the view depth. Triangles crossing the near plane are clipped; degenerate,
//! sliver and behind-camera triangles never produce NaN or Inf.

use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;

/// Marks a pixel no triangle covers.
pub const EMPTY: u32 = u32::MAX;

/// Per-view rasterization result, computed once per pose and reused (the geometry is fixed).
#[derive(Clone, Debug)]
pub struct GBuffer {
    /// Image side in pixels (square).
    pub size: usize,
    /// Triangle index per pixel, or [`EMPTY`].
    pub face: Vec<u32>,
    /// Perspective-correct barycentrics of the original triangle.
    pub bary: Vec<[f32; 3]>,
    /// View-space depth.
    pub depth: Vec<f32>,
}

/// A clipped vertex: pixel position, 1/z, and barycentrics in the original triangle.
#[derive(Clone, Copy)]
struct Vtx {
    px: [f32; 2],
    inv_z: f32,
    b: [f32; 3],
}

/// Clips a view-space triangle against z = znear (Sutherland–Hodgman), returning ≤ 4 vertices
/// as (view position, original barycentrics).
fn clip_near(v: [[f32; 3]; 3], znear: f32) -> Vec<([f32; 3], [f32; 3])> {
    let eye = |i: usize| {
        let mut b = [0.0; 3];
        b[i] = 1.0;
        b
    };
    let input: Vec<([f32; 3], [f32; 3])> = (0..3).map(|i| (v[i], eye(i))).collect();
    let mut out = Vec::with_capacity(4);
    for i in 0..3 {
        let (a, b) = (input[i], input[(i + 1) % 3]);
        let (ina, inb) = (a.0[2] >= znear, b.0[2] >= znear);
        if ina {
            out.push(a);
        }
        if ina != inb {
            let t = (znear - a.0[2]) / (b.0[2] - a.0[2]);
            let lerp = |x: [f32; 3], y: [f32; 3]| {
                [x[0] + t * (y[0] - x[0]), x[1] + t * (y[1] - x[1]), x[2] + t * (y[2] - x[2])]
            };
            out.push((lerp(a.0, b.0), lerp(a.1, b.1)));
        }
    }
    out
}

impl GBuffer {
    /// Rasterizes `mesh` seen by `cam` into a `size × size` G-buffer.
    pub fn render(mesh: &Mesh, cam: &Camera, size: usize) -> GBuffer {
        let n = size * size;
        let mut g = GBuffer { size, face: vec![EMPTY; n], bary: vec![[0.0; 3]; n], depth: vec![f32::INFINITY; n] };
        for (fi, f) in mesh.faces.iter().enumerate() {
            let v = [0, 1, 2].map(|k| cam.to_view(mesh.positions[f[k] as usize]));
            if v.iter().all(|p| p[2] < cam.znear) {
                continue;
            }
            let poly: Vec<Vtx> = clip_near(v, cam.znear)
                .into_iter()
                .map(|(p, b)| Vtx { px: cam.to_pixel(p, size), inv_z: 1.0 / p[2], b })
                .collect();
            for k in 1..poly.len().saturating_sub(1) {
                g.fill(fi as u32, [poly[0], poly[k], poly[k + 1]]);
            }
        }
        g
    }

    fn fill(&mut self, face: u32, t: [Vtx; 3]) {
        let [a, b, c] = [t[0].px, t[1].px, t[2].px];
        let area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
        // Zero-area (degenerate or edge-on) triangles cover no pixel centre; skip them whole.
        if !area.is_finite() || area.abs() < 1e-12 {
            return;
        }
        let s = self.size as f32;
        let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as usize;
        let x1 = (a[0].max(b[0]).max(c[0]).ceil().min(s) as usize).min(self.size);
        let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as usize;
        let y1 = (a[1].max(b[1]).max(c[1]).ceil().min(s) as usize).min(self.size);
        for y in y0..y1 {
            for x in x0..x1 {
                let p = [x as f32 + 0.5, y as f32 + 0.5];
                let w0 = ((b[0] - p[0]) * (c[1] - p[1]) - (b[1] - p[1]) * (c[0] - p[0])) / area;
                let w1 = ((c[0] - p[0]) * (a[1] - p[1]) - (c[1] - p[1]) * (a[0] - p[0])) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                // Perspective-correct: interpolate attributes/z and 1/z linearly in screen space.
                let iz = w0 * t[0].inv_z + w1 * t[1].inv_z + w2 * t[2].inv_z;
                // Also rejects NaN (a sliver whose edge functions overflowed).
                if iz.is_nan() || iz <= 0.0 {
                    continue;
                }
                let z = 1.0 / iz;
                let i = y * self.size + x;
                if z >= self.depth[i] {
                    continue;
                }
                let bc: [f32; 3] = std::array::from_fn(|k| {
                    (w0 * t[0].inv_z * t[0].b[k] + w1 * t[1].inv_z * t[1].b[k] + w2 * t[2].inv_z * t[2].b[k]) * z
                });
                self.depth[i] = z;
                self.face[i] = face;
                self.bary[i] = bc;
            }
        }
    }

    /// Interpolated UV of every covered pixel, as `(pixel, uv)` samples for a texture gather.
    pub fn uv_samples<'a>(&'a self, mesh: &'a Mesh) -> impl Iterator<Item = (u32, [f32; 2])> + 'a {
        self.face.iter().enumerate().filter(|(_, f)| **f != EMPTY).map(move |(i, &f)| {
            let t = mesh.face_uvs[f as usize];
            let b = self.bary[i];
            let mut uv = [0.0; 2];
            for k in 0..3 {
                let c = mesh.uvs[t[k] as usize];
                uv[0] += b[k] * c[0];
                uv[1] += b[k] * c[1];
            }
            (i as u32, uv)
        })
    }

    /// Fraction of pixels covered.
    pub fn coverage(&self) -> f32 {
        self.face.iter().filter(|f| **f != EMPTY).count() as f32 / self.face.len().max(1) as f32
    }

    /// The box of the covered pixels (xyxy, pixel edges), or `None` where nothing is covered.
    pub fn bounds(&self) -> Option<[f32; 4]> {
        pav_core::image::set_bounds(self.size, self.face.iter().map(|f| *f != EMPTY)).map(|b| b.map(|v| v as f32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::geometry::camera::Camera;

    fn mesh(positions: Vec<[f32; 3]>, faces: Vec<[u32; 3]>) -> Mesh {
        let uvs = positions.iter().map(|p| [p[0], p[1]]).collect();
        Mesh::from_triangles(positions, uvs, faces)
    }

    fn cam() -> Camera {
        Camera::look_at([0.0, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0], 60.0)
    }

    fn finite(g: &GBuffer) -> bool {
        g.bary.iter().flatten().all(|v| v.is_finite()) && g.depth.iter().all(|d| d.is_finite() || *d == f32::INFINITY)
    }

    #[test]
    fn a_facing_square_covers_the_centre_with_valid_barycentrics() {
        let m = mesh(
            vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let g = GBuffer::render(&m, &cam(), 64);
        let c = 32 * 64 + 32;
        assert_ne!(g.face[c], EMPTY);
        assert!((g.depth[c] - 3.0).abs() < 1e-3);
        assert!(g
            .bary
            .iter()
            .zip(&g.face)
            .filter(|(_, f)| **f != EMPTY)
            .all(|(b, _)| (b.iter().sum::<f32>() - 1.0).abs() < 1e-4 && b.iter().all(|v| *v >= -1e-5)));
        // The square spans ±1 at distance 3 with a 60° view: 2/(2·3·tan 30°) = 57.7 % of the side.
        let side = (g.coverage()).sqrt();
        assert!((side - 0.577).abs() < 0.03, "{side}");
    }

    #[test]
    fn perspective_correct_barycentrics_follow_depth() {
        // A floor strip receding from the camera: its UV midpoint in depth is not the screen midpoint.
        let m = mesh(
            vec![[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [1.0, -1.0, -20.0], [-1.0, -1.0, -20.0]],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let g = GBuffer::render(&m, &cam(), 128);
        let uv: Vec<(u32, [f32; 2])> = g.uv_samples(&m).collect();
        for (i, _) in &uv {
            let b = g.bary[*i as usize];
            let f = m.faces[g.face[*i as usize] as usize];
            let z_world: f32 = (0..3).map(|k| b[k] * m.positions[f[k] as usize][2]).sum();
            // View depth of the interpolated world point equals the rasterized depth.
            assert!(((3.0 - z_world) - g.depth[*i as usize]).abs() < 1e-2 * g.depth[*i as usize], "pixel {i}");
        }
        assert!(!uv.is_empty());
    }

    #[test]
    fn degenerate_sliver_behind_and_crossing_triangles_stay_finite() {
        let m = mesh(
            vec![
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 0.0],
                [0.0, 0.0, 0.0], // degenerate (one point)
                [-1.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1e-7, 0.0], // sliver
                [-1.0, -1.0, 5.0],
                [1.0, -1.0, 5.0],
                [0.0, 1.0, 5.0], // behind the camera
                [-1.0, -1.0, 3.0],
                [1.0, -1.0, 3.0],
                [0.0, 1.0, -1.0], // crosses the camera plane
                [0.0, -1.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, -1.0], // edge-on (grazing)
            ],
            (0..5).map(|k| [3 * k, 3 * k + 1, 3 * k + 2]).collect(),
        );
        let g = GBuffer::render(&m, &cam(), 96);
        assert!(finite(&g));
        // Only the crossing triangle can be seen, and only its part in front of the camera.
        assert!(
            g.face.iter().all(|f| *f == EMPTY || *f == 3),
            "{:?}",
            g.face.iter().filter(|f| **f != EMPTY).collect::<std::collections::BTreeSet<_>>()
        );
        assert!(g.face.contains(&3));
        assert!(g.depth.iter().filter(|d| d.is_finite()).all(|d| *d >= 1e-3));
    }

    #[test]
    fn cameras_at_the_poles_render() {
        let m = mesh(vec![[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 0.0, 1.0]], vec![[0, 1, 2]]);
        for elev in [89.999f32, 90.0, -90.0, 0.0] {
            let c =
                Camera::look_at(pav_core::geometry::camera::spherical(3.0, elev, 0.0), [0.0; 3], [0.0, 1.0, 0.0], 60.0);
            let g = GBuffer::render(&m, &c, 48);
            assert!(finite(&g), "elev {elev}");
            if elev.abs() > 89.0 {
                assert!(g.coverage() > 0.05, "elev {elev}: coverage {}", g.coverage());
            }
        }
    }

    /// A UV seam: two triangles share a 3D edge but sit in far-apart UV islands (u near 1 on the
    /// left face, near 0 on the right one, as a wrap-around map does). Each pixel must take UVs
    /// from its own island only, never an interpolation across the atlas, and the gather over
    /// the seam stays finite with an exact adjoint.
    #[test]
    fn uvs_across_a_seam_stay_in_their_own_island() {
        let mut m = Mesh::from_triangles(
            vec![
                [-1.0, -1.0, 0.0],
                [0.0, -1.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, -1.0, 0.0],
                [1.0, -1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0.90, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0], [0.10, 0.0], [0.0, 1.0]],
            vec![[0, 1, 2], [3, 4, 5]],
        );
        // Weld the shared edge in 3D (one set of positions), keeping the two UV sets.
        m.faces[1] = [1, 4, 2];
        let g = GBuffer::render(&m, &cam(), 64);
        assert!(finite(&g));
        let (mut left, mut right) = (0, 0);
        for (p, uv) in g.uv_samples(&m) {
            assert!(uv[0].is_finite() && uv[1].is_finite());
            match g.face[p as usize] {
                0 => {
                    left += 1;
                    assert!(uv[0] >= 0.90 - 1e-5, "left face pixel {p} reads u = {}", uv[0]);
                }
                _ => {
                    right += 1;
                    assert!(uv[0] <= 0.10 + 1e-5, "right face pixel {p} reads u = {}", uv[0]);
                }
            }
        }
        assert!(left > 100 && right > 100, "{left} / {right} pixels");
        let gather = crate::texture::Gather::new(g.uv_samples(&m), 16, 16);
        let tex: Vec<f32> = (0..16 * 16).map(|i| (i % 7) as f32 / 7.0).collect();
        let mut img = vec![0.0; 64 * 64];
        gather.apply(&tex, 1, &mut img);
        assert!(img.iter().all(|v| v.is_finite() && (0.0..=1.0).contains(v)));
        let y: Vec<f32> = (0..64 * 64).map(|i| ((i * 31) % 11) as f32 - 5.0).collect();
        let mut aty = vec![0.0; 16 * 16];
        gather.adjoint(&y, 1, &mut aty);
        let lhs: f64 = img.iter().zip(&y).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
        let rhs: f64 = tex.iter().zip(&aty).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
        assert!((lhs - rhs).abs() < 1e-6 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
    }
}
