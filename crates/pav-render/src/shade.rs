//! Phong shading as PyTorch3D's SoftPhongShader computes it with `DirectionalLights`, and the
//! paper's "dark light" mode (ambient only).
//!
//! With white lights the shaded colour is `albedo·(ambient + diffuse) + specular` per pixel, an
//! affine map of the texture: [`Shading`] holds the per-pixel factor and offset, so the render
//! stays `mul ⊙ G·T + add` and its gradient `Gᵀ(mul ⊙ ∂L/∂I)` is exact.

use super::raster::{GBuffer, EMPTY};
use super::texture::Gather;
use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::vec3::{dot, normalize};
use pav_core::image::Rgb;
use pav_core::rng::Rng;
use pav_core::step::{accumulate, Step};

/// Light intensities (white light) and the material's shininess; a scene's `[lighting]` table.
#[derive(Clone, Copy, Debug, PartialEq, serde::Deserialize, serde::Serialize, schemars::JsonSchema)]
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
    /// A room's light for pav's own views of the car: a key light from above the camera's left
    /// shoulder and some ambient. Of the few settings tried, this one's contrast got the
    /// rasterized car detected most (docs/reports/simulated-turntable.md).
    pub const ROOM: Lights =
        Lights { ambient: 0.35, diffuse: 0.8, specular: 0.3, direction: [0.6, 1.0, 0.8], shininess: 32.0 };
}

/// The textured `mesh` as `cam` sees it at `size × size`, Phong-shaded under `lights` (RGB in
/// [0, 1] where the mesh is, 0 elsewhere), with the G-buffer that says which pixels it covers.
pub fn draw_textured(
    mesh: &Mesh,
    normals: &[[f32; 3]],
    texture: &Rgb,
    cam: &Camera,
    lights: &Lights,
    size: usize,
) -> (GBuffer, Vec<f32>) {
    let g = GBuffer::render(mesh, cam, size);
    let mut rgb = vec![0.0f32; size * size * 3];
    Gather::new(g.uv_samples(mesh), texture.width, texture.height).apply(&texture.rgb, 3, &mut rgb);
    Shading::new(&g, mesh, normals, cam, lights).apply(&mut rgb, 3);
    (g, rgb)
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

/// Per-pixel affine shading terms: colour = albedo·mul + add, over every pixel of an image or
/// over some of them (a view's textured pixels).
#[derive(Clone, Debug, PartialEq)]
pub struct Shading {
    /// Factor on the albedo (ambient + diffuse), 0 where no surface; one per shaded pixel.
    pub mul: Vec<f32>,
    /// Added light (specular), 0 where no surface; one per shaded pixel.
    pub add: Vec<f32>,
    /// The shaded pixels in the order of `mul` and `add`; `None`: every pixel, in order.
    pub pixels: Option<Vec<u32>>,
    /// Pixels in the image.
    pub image_pixels: usize,
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
        Shading { mul, add, pixels: None, image_pixels: n_px }
    }

    /// The same shading at `pixels` only (indices into the image), in their order.
    pub fn restrict(&self, pixels: &[u32]) -> Shading {
        let at = |k: u32| self.pixels.as_ref().map_or(Some(k as usize), |p| p.iter().position(|q| *q == k));
        let keep: Vec<(u32, usize)> = pixels.iter().filter_map(|&p| Some((p, at(p)?))).collect();
        Shading {
            mul: keep.iter().map(|(_, i)| self.mul[*i]).collect(),
            add: keep.iter().map(|(_, i)| self.add[*i]).collect(),
            pixels: Some(keep.iter().map(|(p, _)| *p).collect()),
            image_pixels: self.image_pixels,
        }
    }

    /// The image index of shaded pixel `k`.
    fn pixel(&self, k: usize) -> usize {
        self.pixels.as_ref().map_or(k, |p| p[k] as usize)
    }

    /// In place: `img = img·mul + add` at the shaded pixels, over `c` interleaved channels.
    pub fn apply(&self, img: &mut [f32], c: usize) {
        for k in 0..self.mul.len() {
            let p = self.pixel(k);
            for v in &mut img[p * c..(p + 1) * c] {
                *v = *v * self.mul[k] + self.add[k];
            }
        }
    }

    /// Gradient through the shading, in place: `∂L/∂albedo = mul ⊙ ∂L/∂colour` at the shaded
    /// pixels (the others pass unchanged).
    pub fn adjoint(&self, grad: &mut [f32], c: usize) {
        for k in 0..self.mul.len() {
            let p = self.pixel(k);
            for v in &mut grad[p * c..(p + 1) * c] {
                *v *= self.mul[k];
            }
        }
    }
}

/// Shading as a step on RGB images (the unshaded pixels pass unchanged).
impl Step for Shading {
    type Tape = ();
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.image_pixels * 3
    }

    fn output_len(&self) -> usize {
        self.image_pixels * 3
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
        let mut y = x.to_vec();
        self.apply(&mut y, 3);
        Ok((y, ()))
    }

    fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
        let mut g = gy.to_vec();
        Shading::adjoint(self, &mut g, 3);
        accumulate(gx, g);
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
