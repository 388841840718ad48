//! Phong shading as PyTorch3D's SoftPhongShader computes it with `DirectionalLights`, and the
//! paper's "dark light" mode (ambient only).
//!
//! With white lights the shaded colour is `albedo·(ambient + diffuse) + specular` per pixel, an
//! affine map of the texture: [`Shading`] holds the per-pixel factor and offset, so the render
//! stays `mul ⊙ G·T + add` and its gradient `Gᵀ(mul ⊙ ∂L/∂I)` is exact.

use super::raster::{GBuffer, EMPTY};
use crate::geometry::camera::Camera;
use crate::geometry::mesh::Mesh;
use crate::geometry::vec3::{dot, normalize};

/// Light intensities (white light) and the material's shininess; a scene's `[lighting]` table.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lights {
    /// Ambient intensity.
    pub ambient: f32,
    /// Diffuse intensity of the directional light.
    pub diffuse: f32,
    /// Specular intensity.
    pub specular: f32,
    /// Direction towards the light, world space.
    pub direction: [f32; 3],
    /// Phong exponent (PyTorch3D's default 64 when a scene leaves it out).
    #[serde(default = "default_shininess")]
    pub shininess: f32,
}

fn default_shininess() -> f32 {
    64.0
}

impl Lights {
    /// The authors' scene: ambient 0.7, diffuse 0.4, specular 0.2, direction (1, 1, 1),
    /// PyTorch3D's default shininess 64.
    pub const PAV_CAMOU: Lights =
        Lights { ambient: 0.7, diffuse: 0.4, specular: 0.2, direction: [1.0, 1.0, 1.0], shininess: 64.0 };
    /// Dark light mode: no directional or point light, only ambient.
    pub const DARK: Lights =
        Lights { ambient: 1.0, diffuse: 0.0, specular: 0.0, direction: [1.0, 1.0, 1.0], shininess: 64.0 };
}

/// Area-weighted vertex normals from the faces (as PyTorch3D's `Meshes` computes them; the OBJ's
/// own normals are not used, like the authors' pipeline).
pub fn vertex_normals(mesh: &Mesh) -> Vec<[f32; 3]> {
    let mut n = vec![[0.0f32; 3]; mesh.positions.len()];
    for (fi, f) in mesh.faces.iter().enumerate() {
        let fnrm = mesh.face_cross(fi); // length = 2·area: area weighting for free
        for &i in f {
            for k in 0..3 {
                n[i as usize][k] += fnrm[k];
            }
        }
    }
    n.into_iter().map(normalize).collect()
}

/// Per-pixel affine shading terms: colour = albedo·mul + add.
#[derive(Clone, Debug, PartialEq)]
pub struct Shading {
    /// Factor on the albedo (ambient + diffuse), 0 where no surface.
    pub mul: Vec<f32>,
    /// Added light (specular), 0 where no surface.
    pub add: Vec<f32>,
}

impl Shading {
    /// Shades the G-buffer `g` of `mesh` seen by `cam`.
    pub fn new(g: &GBuffer, mesh: &Mesh, normals: &[[f32; 3]], cam: &Camera, lights: &Lights) -> Shading {
        let l = normalize(lights.direction);
        let n_px = g.face.len();
        let (mut mul, mut add) = (vec![0.0; n_px], vec![0.0; n_px]);
        for i in 0..n_px {
            let f = g.face[i];
            if f == EMPTY {
                continue;
            }
            let (vi, b) = (mesh.faces[f as usize], g.bary[i]);
            let mut nrm = [0.0f32; 3];
            let mut pos = [0.0f32; 3];
            for k in 0..3 {
                for d in 0..3 {
                    nrm[d] += b[k] * normals[vi[k] as usize][d];
                    pos[d] += b[k] * mesh.positions[vi[k] as usize][d];
                }
            }
            let nrm = normalize(nrm);
            let cos = dot(nrm, l);
            let diffuse = lights.diffuse * cos.max(0.0);
            let view = normalize([cam.eye[0] - pos[0], cam.eye[1] - pos[1], cam.eye[2] - pos[2]]);
            let refl = [2.0 * cos * nrm[0] - l[0], 2.0 * cos * nrm[1] - l[1], 2.0 * cos * nrm[2] - l[2]];
            let spec = if cos > 0.0 { lights.specular * dot(view, refl).max(0.0).powf(lights.shininess) } else { 0.0 };
            // Degenerate normals (zero-area neighbourhoods) give NaN: fall back to ambient only.
            mul[i] = if diffuse.is_finite() { lights.ambient + diffuse } else { lights.ambient };
            add[i] = if spec.is_finite() { spec } else { 0.0 };
        }
        Shading { mul, add }
    }

    /// In place: `img = img·mul + add` over `c` interleaved channels.
    pub fn apply(&self, img: &mut [f32], c: usize) {
        for (i, v) in img.iter_mut().enumerate() {
            *v = *v * self.mul[i / c] + self.add[i / c];
        }
    }

    /// Gradient through the shading: `∂L/∂albedo = mul ⊙ ∂L/∂colour`.
    pub fn adjoint(&self, grad: &mut [f32], c: usize) {
        for (i, v) in grad.iter_mut().enumerate() {
            *v *= self.mul[i / c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn facing_quad_gets_ambient_plus_lambert_and_degenerate_stays_finite() {
        let m = Mesh::from_triangles(
            vec![
                [-1.0, -1.0, 0.0],
                [1.0, -1.0, 0.0],
                [1.0, 1.0, 0.0],
                [-1.0, 1.0, 0.0],
                [0.0, 0.0, 0.5],
                [0.0, 0.0, 0.5],
                [0.0, 0.0, 0.5],
            ],
            vec![[0.0, 0.0]; 7],
            vec![[0, 1, 2], [0, 2, 3], [4, 5, 6]],
        );
        let n = vertex_normals(&m);
        assert_eq!(n[0], [0.0, 0.0, 1.0]);
        let cam = Camera::look_at([0.0, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0], 60.0);
        let g = GBuffer::render(&m, &cam, 32);
        let lights = Lights { direction: [0.0, 0.0, 1.0], ..Lights::PAV_CAMOU };
        let s = Shading::new(&g, &m, &n, &cam, &lights);
        let c = 16 * 32 + 16;
        assert!((s.mul[c] - 1.1).abs() < 1e-5, "{}", s.mul[c]);
        assert!(s.mul.iter().chain(&s.add).all(|v| v.is_finite()));
        let mut img = vec![0.5; 32 * 32];
        s.apply(&mut img, 1);
        assert!((img[c] - (0.55 + s.add[c])).abs() < 1e-6);
        let dark = Shading::new(&g, &m, &n, &cam, &Lights::DARK);
        assert!(dark.mul.iter().zip(&g.face).all(|(v, f)| if *f == EMPTY { *v == 0.0 } else { *v == 1.0 }));
    }
}
