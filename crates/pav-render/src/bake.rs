//! Novel views of the photographed car: its appearance is baked from the photos into a UV atlas
//! (every pixel the mesh covers, splatted through the texture gather's adjoint and weighted by
//! how squarely the face looks at the camera), and a photo is re-rendered with the car turned in
//! place: the car's pixels are filled from the surrounding background (push-pull), then the
//! baked car is drawn at the new pose. The lighting baked into the photos turns with the car, and
//! the car's ground shadow stays where it was: these are synthetic views for training, never for
//! scoring.

use super::fill::{grow, push_pull, shrink};
use super::raster::{GBuffer, EMPTY};
use super::texture::Gather;
use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::vec3::{dot, normalize};
use pav_core::image::Frame;

/// Side of the baked appearance atlas (a photographed car spans a few hundred pixels).
pub const BAKE_SIZE: usize = 512;

/// Errors baking or re-rendering.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// The renderer's images are square.
    #[error("the photo is {0}×{1}; only square photos can be matched by the renderer")]
    NotSquare(usize, usize),
    /// No photo shows any face.
    #[error("the mesh covers no interior pixel of any photo: nothing to bake")]
    Empty,
}

/// One photo and the camera that matches it.
pub struct PosedPhoto<'a> {
    /// Camera in mesh coordinates.
    pub cam: Camera,
    /// The photo.
    pub photo: &'a Frame,
}

/// The car's appearance: a `size × size` atlas in the photos' BGR order, 0–255.
#[derive(Clone, Debug)]
pub struct Appearance {
    /// Atlas side.
    pub size: usize,
    /// Interleaved BGR texels.
    pub bgr: Vec<f32>,
    /// Share of the texels the photos saw (the rest is filled from their neighbours).
    pub seen: f32,
}

fn square(photo: &Frame) -> Result<usize, BakeError> {
    if photo.width != photo.height {
        return Err(BakeError::NotSquare(photo.width, photo.height));
    }
    Ok(photo.width)
}

/// Pixels of an `n × n` render of `mesh` from `cam` that the car covers.
pub fn car_mask(mesh: &Mesh, cam: &Camera, n: usize) -> Vec<bool> {
    GBuffer::render(mesh, cam, n).face.iter().map(|f| *f != EMPTY).collect()
}

/// Bakes the appearance from `shots` into a `size × size` atlas. Pixels within `margin`
/// of the silhouette are skipped: the fitted cameras are off by a few pixels there, and those
/// pixels would paint the background onto the car.
pub fn bake(mesh: &Mesh, shots: &[PosedPhoto], size: usize, margin: usize) -> Result<Appearance, BakeError> {
    let face_normals: Vec<[f32; 3]> = (0..mesh.faces.len()).map(|f| normalize(mesh.face_cross(f))).collect();
    let (mut num, mut den) = (vec![0f32; size * size * 3], vec![0f32; size * size]);
    for shot in shots {
        let n = square(shot.photo)?;
        let g = GBuffer::render(mesh, &shot.cam, n);
        let covered: Vec<bool> = g.face.iter().map(|f| *f != EMPTY).collect();
        let inner = shrink(&covered, n, n, margin);
        let (mut wbgr, mut wpx) = (vec![0f32; n * n * 3], vec![0f32; n * n]);
        for (i, &f) in g.face.iter().enumerate() {
            if !inner[i] {
                continue;
            }
            let c = mesh.face_centroid(f as usize);
            let to_eye = normalize([shot.cam.eye[0] - c[0], shot.cam.eye[1] - c[1], shot.cam.eye[2] - c[2]]);
            // |cos|: the game meshes mix windings. Grazing views smear a texel over many pixels.
            let w = dot(face_normals[f as usize], to_eye).abs().powi(4);
            wpx[i] = w;
            for k in 0..3 {
                wbgr[i * 3 + k] = w * shot.photo.bgr[i * 3 + k] as f32;
            }
        }
        let samples = g.uv_samples(mesh).filter(|(p, _)| inner[*p as usize]);
        let gather = Gather::new(samples, size, size);
        gather.adjoint(&wbgr, 3, &mut num);
        gather.adjoint(&wpx, 1, &mut den);
    }
    let seen = den.iter().filter(|d| **d > 0.0).count();
    if seen == 0 {
        return Err(BakeError::Empty);
    }
    let mut bgr: Vec<f32> =
        num.iter().enumerate().map(|(i, v)| if den[i / 3] > 0.0 { v / den[i / 3] } else { 0.0 }).collect();
    push_pull(&mut bgr, &den, size, size, 3);
    Ok(Appearance { size, bgr, seen: seen as f32 / (size * size) as f32 })
}

/// A photo with its car painted out: the background every turned view of it is drawn on.
pub struct Plate {
    n: usize,
    bgr: Vec<f32>,
}

impl Plate {
    /// `photo` (taken from `from`) with the car's pixels, grown by `grow_px`, filled from the
    /// surrounding background.
    pub fn new(mesh: &Mesh, photo: &Frame, from: &Camera, grow_px: usize) -> Result<Plate, BakeError> {
        let n = square(photo)?;
        let hole = grow(&car_mask(mesh, from, n), n, n, grow_px);
        let known: Vec<f32> = hole.iter().map(|h| if *h { 0.0 } else { 1.0 }).collect();
        let mut bgr: Vec<f32> = photo.bgr.iter().map(|v| *v as f32).collect();
        push_pull(&mut bgr, &known, n, n, 3);
        Ok(Plate { n, bgr })
    }

    /// The plate itself.
    pub fn frame(&self) -> Frame {
        Frame::from_levels(self.n, self.n, &self.bgr)
    }

    /// The plate with the baked car drawn as `to` sees it.
    pub fn with_car(&self, mesh: &Mesh, app: &Appearance, to: &Camera) -> Frame {
        let n = self.n;
        let mut img = self.bgr.clone();
        let g = GBuffer::render(mesh, to, n);
        Gather::new(g.uv_samples(mesh), app.size, app.size).apply(&app.bgr, 3, &mut img);
        Frame::from_levels(n, n, &img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        let p = vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]];
        let uv = p.iter().map(|q: &[f32; 3]| [(q[0] + 1.0) / 2.0, (q[1] + 1.0) / 2.0]).collect();
        Mesh::from_triangles(p, uv, vec![[0, 1, 2], [0, 2, 3]])
    }

    /// A photo of the quad painted with a smooth 16² texture on a flat green background.
    fn photo(m: &Mesh, cam: &Camera, n: usize) -> Frame {
        let tex: Vec<f32> =
            (0..16 * 16).flat_map(|i| [(i % 16) as f32 * 15.0, (i / 16) as f32 * 15.0, 128.0]).collect();
        let mut img: Vec<f32> = (0..n * n).flat_map(|_| [10.0, 200.0, 30.0]).collect();
        Gather::new(GBuffer::render(m, cam, n).uv_samples(m), 16, 16).apply(&tex, 3, &mut img);
        Frame { width: n, height: n, bgr: img.iter().map(|v| v.round() as u8).collect() }
    }

    #[test]
    fn a_baked_car_re_rendered_at_its_own_pose_gives_the_photo_back() {
        let (m, n) = (quad(), 64);
        let cam = Camera::look_at([0.3, 0.2, 3.0], [0.0; 3], [0.0, 1.0, 0.0], 60.0);
        let ph = photo(&m, &cam, n);
        let app = bake(&m, &[PosedPhoto { cam, photo: &ph }], 32, 2).unwrap();
        assert!(app.seen > 0.5, "a frontal view sees most of the atlas: {}", app.seen);
        let out = Plate::new(&m, &ph, &cam, 3).unwrap().with_car(&m, &app, &cam);
        let inner = shrink(&car_mask(&m, &cam, n), n, n, 3);
        let hole = grow(&car_mask(&m, &cam, n), n, n, 3);
        let mut worst = 0i32;
        for i in 0..n * n {
            let d = (0..3).map(|k| (out.bgr[i * 3 + k] as i32 - ph.bgr[i * 3 + k] as i32).abs()).max().unwrap();
            if !hole[i] {
                assert_eq!(d, 0, "pixel {i} outside the car changed");
            } else if inner[i] {
                worst = worst.max(d);
            } else if !car_mask(&m, &cam, n)[i] {
                // The filled background around the car is the flat background.
                assert_eq!(&out.bgr[i * 3..i * 3 + 3], &[10, 200, 30], "pixel {i}");
            }
        }
        // Bilinear splat then bilinear gather blurs by about a texel: 15 levels per texel here.
        assert!(worst <= 12, "baked interior off by {worst} levels");
    }

    #[test]
    fn bad_input_is_refused_with_its_reason() {
        let m = quad();
        let cam = Camera::look_at([0.0, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0], 60.0);
        let wide = Frame { width: 8, height: 4, bgr: vec![0; 8 * 4 * 3] };
        assert!(matches!(bake(&m, &[PosedPhoto { cam, photo: &wide }], 16, 1), Err(BakeError::NotSquare(8, 4))));
        let away = Camera::look_at([0.0, 0.0, 3.0], [0.0, 0.0, 6.0], [0.0, 1.0, 0.0], 60.0);
        let ph = photo(&m, &cam, 32);
        assert!(matches!(bake(&m, &[PosedPhoto { cam: away, photo: &ph }], 16, 1), Err(BakeError::Empty)));
    }
}
