//! One training or test view: a PBR photo, the camera that matches it, and everything the
//! texture-to-image map needs, computed once (the geometry and poses are fixed).
//!
//! The composite `I_o = I_d'·P + I_p·(1−P)` with a binary P takes the transformed render at the
//! P = 1 pixels and the photo elsewhere, so only those pixels are rendered, shaded and transformed.

use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use pav_core::image::resize::{resize, Interpolation};
use pav_core::image::Frame;
use pav_core::rng::Rng;
use pav_core::step::{Chain, Step};
use pav_render::mask::{dual_render_mask, MaskError};
use pav_render::raster::GBuffer;
use pav_render::shade::{Lights, Shading};
use pav_render::texture::Gather;
use pav_scene::eot::{self, Eot};
use pav_scene::zoom::{self, Zoom};
use pav_scene::Scene;

/// A view ready for rendering.
#[derive(Clone, Debug)]
pub struct TrainView {
    /// Name (the photo's file stem).
    pub name: String,
    /// Image side in pixels.
    pub size: usize,
    /// The photo resized to `size`, RGB in [0, 1], interleaved.
    pub photo: Vec<f32>,
    /// Pixels where P = 1, in the order of `gather`.
    pub active: Vec<u32>,
    /// Share of the image the car covers.
    pub coverage: f32,
    /// The mask threshold found for this view.
    pub c_mid: f32,
    /// The car's box in the view (its rendered silhouette's, xyxy pixels), if it is in view.
    pub car_box: Option<[f32; 4]>,
    /// Texture lookup at the active pixels.
    gather: Gather,
    /// The shading at the active pixels, when the scene is lit.
    shade: Option<Shading>,
}

impl TrainView {
    /// Rasterizes `mesh` from `cam` at `size`, computes P from the texel `region` of a
    /// `tex_w × tex_h` texture, and shades with `lights` (`None`: unlit albedo).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        name: &str,
        mesh: &Mesh,
        normals: &[[f32; 3]],
        cam: &Camera,
        photo: &Frame,
        size: usize,
        region: &[f32],
        (tex_w, tex_h): (usize, usize),
        lights: Option<&Lights>,
    ) -> Result<TrainView, MaskError> {
        let g = GBuffer::render(mesh, cam, size);
        let full = Gather::new(g.uv_samples(mesh), tex_w, tex_h);
        let (p, c_mid) = dual_render_mask(&full, region, size * size)?;
        let keep: Vec<bool> = full.pixels.iter().map(|px| p[*px as usize] == 1.0).collect();
        let pick = |v: &[u32]| v.iter().zip(&keep).filter(|(_, k)| **k).map(|(x, _)| *x).collect::<Vec<u32>>();
        let active = pick(&full.pixels);
        let taps = full.taps.iter().zip(&keep).filter(|(_, k)| **k).map(|(t, _)| *t).collect();
        let gather = Gather { tex_size: full.tex_size, pixels: active.clone(), taps };
        let shade = lights.map(|l| Shading::new(&g, mesh, normals, cam, l).restrict(&active));
        let bgr = resize(photo, size, size, Interpolation::Antialias);
        let photo = bgr.chunks(3).flat_map(|c| [c[2] / 255.0, c[1] / 255.0, c[0] / 255.0]).collect();
        Ok(TrainView {
            name: name.into(),
            size,
            photo,
            active,
            coverage: g.coverage(),
            c_mid,
            car_box: g.bounds(),
            gather,
            shade,
        })
    }

    /// The composite under a scene without random effects (the lit texture at P = 1, the photo
    /// elsewhere, clamped to [0, 1]): what scores and previews show.
    pub fn composite(&self, tex: &[f32], scene: &Scene) -> Vec<f32> {
        let mut img = self.render_plain(tex);
        eot::apply(scene, &mut img, 3, &self.active, &mut Rng::new(0));
        img
    }

    /// The composite before EoT (lit texture at P = 1, photo elsewhere), not yet clamped.
    pub fn render_plain(&self, tex: &[f32]) -> Vec<f32> {
        let mut img = self.photo.clone();
        self.gather.apply(tex, 3, &mut img);
        if let Some(s) = &self.shade {
            s.apply(&mut img, 3);
        }
        img
    }

    /// What the detectors see for a texture, as a chain of steps: the render and composite,
    /// then the scene's EoT at the textured pixels, then its zoom when it lists one.
    pub fn chain<'a>(&'a self, scene: &'a Scene) -> Chain<'a> {
        let mut c = Chain::new()
            .then("render", Composite { view: self })
            .then("eot", Eot { scene, active: &self.active, pixels: self.size * self.size });
        if zoom::range(scene).is_some() {
            c.push("zoom", Zoom { scene, size: self.size });
        }
        c
    }

    /// The texels this view reads (a bilinear tap with non-zero weight), each once, ascending.
    pub fn texels_read(&self) -> Vec<u32> {
        let mut t: Vec<u32> = self.gather.taps.iter().flatten().filter(|(_, w)| *w > 0.0).map(|(i, _)| *i).collect();
        t.sort_unstable();
        t.dedup();
        t
    }

    /// Bytes the view holds on the heap: the photo, the textured pixels, their texture lookup and
    /// shading.
    pub fn heap_bytes(&self) -> usize {
        let shade =
            self.shade.as_ref().map_or(0, |s| (s.mul.len() + s.add.len() + s.pixels.as_ref().map_or(0, Vec::len)) * 4);
        self.name.len()
            + self.photo.len() * 4
            + self.active.len() * 4
            + self.gather.pixels.len() * 4
            + self.gather.taps.len() * std::mem::size_of::<[(u32, f32); 4]>()
            + shade
    }

    /// Share of the image that shows the texture (P = 1).
    pub fn textured_share(&self) -> f32 {
        self.active.len() as f32 / (self.size * self.size) as f32
    }
}

/// A view's render and composite, as a step from the texture to the composite before the
/// scene's effects: linear in the texture, read at the textured pixels only.
pub struct Composite<'a> {
    /// The view.
    pub view: &'a TrainView,
}

impl Step for Composite<'_> {
    type Tape = ();
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        let (w, h) = self.view.gather.tex_size;
        w * h * 3
    }

    fn output_len(&self) -> usize {
        self.view.size * self.view.size * 3
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
        Ok((self.view.render_plain(x), ()))
    }

    fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
        // The photo does not depend on the texture: only the textured pixels carry a gradient.
        let mut g = vec![0f32; gy.len()];
        for p in &self.view.active {
            let i = *p as usize * 3;
            g[i..i + 3].copy_from_slice(&gy[i..i + 3]);
        }
        if let Some(s) = &self.view.shade {
            s.adjoint(&mut g, 3);
        }
        self.view.gather.adjoint(&g, 3, gx);
    }

    fn map_box(&self, _: &(), _: Option<[f32; 4]>) -> Option<[f32; 4]> {
        self.view.car_box
    }
}
