//! UV distortion: how much each face's texture is stretched or compressed when the flat UV map
//! is wrapped onto the 3D surface (the paper's "2D Coordinate Adjustments", where MAYA colours
//! stretch purple and compression red).
//!
//! Per face, `J` maps the triangle's own 2D frame to UV. Its singular values σ₁ ≥ σ₂ give the
//! anisotropy σ₁/σ₂ (1 = shapes kept), and the area ratio det J, divided by the average ratio of
//! the faces considered, gives the relative stretch (1 = the patch's average texel density).

use super::mesh::Mesh;

/// Distortion of one face.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FaceDistortion {
    /// Face index.
    pub face: usize,
    /// 3D area.
    pub area_3d: f64,
    /// UV area (unit square = 1).
    pub area_uv: f64,
    /// log₂ of (3D area share / UV area share): > 0 the texture is stretched over more surface
    /// than average, < 0 compressed; 0 = average density.
    pub log2_stretch: f64,
    /// σ₁/σ₂ of the 3D→UV map (≥ 1; 1 = conformal). Infinite for a face collapsed in UV.
    pub anisotropy: f64,
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
    [(a[0] - b[0]) as f64, (a[1] - b[1]) as f64, (a[2] - b[2]) as f64]
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// Distortion of `faces` (the patch being evaluated), relative to their own average density.
/// Degenerate faces (zero 3D area) are skipped.
pub fn distortion(mesh: &Mesh, faces: &[usize]) -> Vec<FaceDistortion> {
    let mut raw = Vec::with_capacity(faces.len());
    for &f in faces {
        let v = mesh.face_positions(f);
        let t = mesh.face_uvs[f].map(|i| mesh.uvs[i as usize]);
        let (e1, e2) = (sub(v[1], v[0]), sub(v[2], v[0]));
        let l1 = norm(e1);
        let c = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        let area_3d = norm(c) / 2.0;
        if area_3d.is_nan() || area_3d <= 1e-15 || l1 == 0.0 {
            continue;
        }
        // Triangle in its own frame: p1 = (l1, 0), p2 = (x2, y2).
        let x2 = (e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]) / l1;
        let y2 = 2.0 * area_3d / l1;
        let (du1, dv1) = ((t[1][0] - t[0][0]) as f64, (t[1][1] - t[0][1]) as f64);
        let (du2, dv2) = ((t[2][0] - t[0][0]) as f64, (t[2][1] - t[0][1]) as f64);
        // J = [du1 du2; dv1 dv2] · [l1 x2; 0 y2]⁻¹
        let (a, b) = (du1 / l1, (du2 - du1 * x2 / l1) / y2);
        let (cc, d) = (dv1 / l1, (dv2 - dv1 * x2 / l1) / y2);
        let area_uv = (du1 * dv2 - du2 * dv1).abs() / 2.0;
        // Singular values of [a b; c d].
        let (s1sq, s2sq) = {
            let (p, q) = (a * a + b * b + cc * cc + d * d, (a * d - b * cc).powi(2));
            let r = (p * p / 4.0 - q).max(0.0).sqrt();
            (p / 2.0 + r, (p / 2.0 - r).max(0.0))
        };
        let anisotropy = if s2sq > 0.0 { (s1sq / s2sq).sqrt() } else { f64::INFINITY };
        raw.push((f, area_3d, area_uv, anisotropy));
    }
    let (sum3, sumuv) = raw.iter().fold((0.0, 0.0), |a, r| (a.0 + r.1, a.1 + r.2));
    raw.into_iter()
        .map(|(face, area_3d, area_uv, anisotropy)| {
            let share = (area_3d / sum3) / (area_uv / sumuv).max(1e-300);
            FaceDistortion { face, area_3d, area_uv, log2_stretch: share.log2().clamp(-20.0, 20.0), anisotropy }
        })
        .collect()
}

/// MAYA-like colour: grey at no distortion, purple for stretch, red for compression,
/// saturating at a factor of 2 (|log₂| = 1).
pub fn heat_colour(log2_stretch: f64) -> [u8; 3] {
    let t = log2_stretch.clamp(-1.0, 1.0).abs() as f32;
    let grey = [150.0f32, 150.0, 150.0];
    let target = if log2_stretch >= 0.0 { [150.0, 40.0, 220.0] } else { [230.0, 30.0, 30.0] };
    std::array::from_fn(|k| (grey[k] + t * (target[k] - grey[k])).round() as u8)
}

/// Summary numbers over a patch: area-weighted mean |log₂ stretch| and the 95th percentile of
/// anisotropy.
pub fn summary(d: &[FaceDistortion]) -> (f64, f64) {
    let total: f64 = d.iter().map(|x| x.area_3d).sum();
    let mean_abs = d.iter().map(|x| x.area_3d * x.log2_stretch.abs()).sum::<f64>() / total.max(1e-300);
    let mut an: Vec<f64> = d.iter().map(|x| x.anisotropy).collect();
    an.sort_by(f64::total_cmp);
    let p95 = an.get(((an.len().max(1) - 1) as f64 * 0.95) as usize).copied().unwrap_or(f64::NAN);
    (mean_abs, p95)
}

/// Index of the texel nearest `uv` in a `w × h` map (row 0 at the top), clamped to the map.
fn texel(uv: [f32; 2], w: usize, h: usize) -> usize {
    let x = (uv[0].clamp(0.0, 1.0) * (w - 1) as f32).round() as usize;
    let y = ((1.0 - uv[1].clamp(0.0, 1.0)) * (h - 1) as f32).round() as usize;
    y * w + x
}

/// Faces whose UV centroid falls on a texel where `mask` (one value per texel, `w × h`,
/// row 0 at the top) is 1: the optimizable patch, as PAV-Camou marks it in half.png.
pub fn faces_in_mask(mesh: &Mesh, mask: &[f32], w: usize, h: usize) -> Vec<usize> {
    (0..mesh.faces.len())
        .filter(|&f| {
            let c = mesh.face_uvs[f].iter().fold([0f32; 2], |a, &t| {
                let uv = mesh.uvs[t as usize];
                [a[0] + uv[0] / 3.0, a[1] + uv[1] / 3.0]
            });
            mask[texel(c, w, h)] == 1.0
        })
        .collect()
}

/// Texels of a `size × size` map (row 0 at the top) that `faces` cover: their UV triangles plus
/// the texels under their centroids and corners, so a face thinner than a texel still owns the
/// texels it samples (and [`faces_in_mask`] finds it again).
pub fn faces_mask(mesh: &Mesh, faces: &[usize], size: usize) -> Vec<bool> {
    let painted = paint_uv(mesh, &faces.iter().map(|&f| (f, [255u8; 3])).collect::<Vec<_>>(), size, [0; 3]);
    let mut out: Vec<bool> = painted.chunks(3).map(|p| p[0] == 255).collect();
    for &f in faces {
        let t = mesh.face_uvs[f].map(|i| mesh.uvs[i as usize]);
        for uv in t {
            out[texel(uv, size, size)] = true;
        }
        out[texel([(t[0][0] + t[1][0] + t[2][0]) / 3.0, (t[0][1] + t[1][1] + t[2][1]) / 3.0], size, size)] = true;
    }
    out
}

/// Paints each face's UV triangle in `colour(face)` on a `size × size` RGB image (v up).
pub fn paint_uv(mesh: &Mesh, faces: &[(usize, [u8; 3])], size: usize, background: [u8; 3]) -> Vec<u8> {
    let mut img: Vec<u8> = (0..size * size).flat_map(|_| background).collect();
    let s = size as f32;
    for &(f, col) in faces {
        let t = mesh.face_uvs[f].map(|i| {
            let uv = mesh.uvs[i as usize];
            [uv[0] * s, (1.0 - uv[1]) * s]
        });
        let area = (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[1][1] - t[0][1]) * (t[2][0] - t[0][0]);
        if area.abs() < 1e-9 || !area.is_finite() {
            continue;
        }
        let (x0, x1) = (
            t.iter().map(|p| p[0]).fold(f32::INFINITY, f32::min).max(0.0) as usize,
            (t.iter().map(|p| p[0]).fold(0.0, f32::max).ceil() as usize).min(size),
        );
        let (y0, y1) = (
            t.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min).max(0.0) as usize,
            (t.iter().map(|p| p[1]).fold(0.0, f32::max).ceil() as usize).min(size),
        );
        for y in y0..y1 {
            for x in x0..x1 {
                let p = [x as f32 + 0.5, y as f32 + 0.5];
                let e =
                    |a: [f32; 2], b: [f32; 2]| ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) / area;
                if e(t[0], t[1]) >= 0.0 && e(t[1], t[2]) >= 0.0 && e(t[2], t[0]) >= 0.0 {
                    img[(y * size + x) * 3..(y * size + x) * 3 + 3].copy_from_slice(&col);
                }
            }
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(pos: [[f32; 3]; 3], uv: [[f32; 2]; 3]) -> Mesh {
        Mesh::from_triangles(pos.to_vec(), uv.to_vec(), vec![[0, 1, 2]])
    }

    #[test]
    fn isometric_scaled_and_sheared_maps() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        // Any uniform scale is conformal.
        let d = distortion(&tri(p, [[0.0, 0.0], [0.5, 0.0], [0.0, 0.5]]), &[0]);
        assert!((d[0].anisotropy - 1.0).abs() < 1e-9);
        // Stretch u by 3: σ₁/σ₂ = 3.
        let d = distortion(&tri(p, [[0.0, 0.0], [0.3, 0.0], [0.0, 0.1]]), &[0]);
        assert!((d[0].anisotropy - 3.0).abs() < 1e-6, "{}", d[0].anisotropy);
        // A face collapsed in UV is infinitely anisotropic, not NaN.
        let d = distortion(&tri(p, [[0.1, 0.1], [0.1, 0.1], [0.2, 0.2]]), &[0]);
        assert!(d[0].anisotropy.is_infinite() && d[0].log2_stretch.is_finite());
        // A degenerate 3D face is skipped.
        assert!(distortion(&tri([[0.0; 3]; 3], [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]), &[0]).is_empty());
        assert_eq!(heat_colour(0.0), [150, 150, 150]);
        assert_eq!(heat_colour(5.0), [150, 40, 220]);
        assert_eq!(heat_colour(-1.0), [230, 30, 30]);
    }
}
