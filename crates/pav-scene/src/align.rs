//! Do pav's rasterizer and Blender put the same surface point on the same pixel?
//!
//! Blender renders the interpolated UV itself as a raw 16-bit colour (R = u, G = v, alpha =
//! coverage, every sample at its pixel's centre); pav rasterizes the same mesh from the same
//! camera. Where both cover a pixel, the UV difference is turned into pixels through the local
//! UV-per-pixel Jacobian of pav's render, so the error reads as "how far Blender's surface point
//! lies from pav's, in pixels". The silhouettes are compared as the mean edge offset: pixels
//! where exactly one renderer sees the car, per pixel of pav's silhouette outline.

use pav_core::geometry::mesh::Mesh;
use pav_render::raster::{GBuffer, EMPTY};
use std::path::Path;

/// How well two renders of one view agree.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Alignment {
    /// Pixels compared (covered by both, with a UV Jacobian).
    pub pixels: usize,
    /// Median, 95th and 99th percentile of the surface-point distance, pixels.
    pub uv_px: [f64; 3],
    /// Pixels where exactly one renderer covers the car, per outline pixel of pav's silhouette.
    pub edge_offset_px: f64,
    /// Intersection over union of the two silhouettes.
    pub iou: f64,
}

impl Alignment {
    /// The acceptance rule: 95 % of pixels within one pixel, and the silhouettes within one pixel.
    pub fn within_one_pixel(&self) -> bool {
        self.pixels > 0 && self.uv_px[1] < 1.0 && self.edge_offset_px < 1.0
    }
}

/// A Blender UV render: per pixel (u, v, alpha) from a 16-bit RGBA PNG.
pub fn read_uv_png(path: &Path) -> Result<(usize, Vec<[f64; 3]>), image::ImageError> {
    let img = image::open(path)?.to_rgba16();
    let (w, h) = img.dimensions();
    if w != h {
        return Err(image::ImageError::Parameter(image::error::ParameterError::from_kind(
            image::error::ParameterErrorKind::DimensionMismatch,
        )));
    }
    let px = img.pixels().map(|p| [p[0] as f64 / 65535.0, p[1] as f64 / 65535.0, p[3] as f64 / 65535.0]).collect();
    Ok((w as usize, px))
}

/// A texel-coded texture, `w × h`, 16-bit: R = column / (w − 1), G = row from the top / (h − 1).
pub fn texel_code(w: usize, h: usize) -> image::ImageBuffer<image::Rgb<u16>, Vec<u16>> {
    let c = |i: usize, n: usize| (i as f64 / (n - 1).max(1) as f64 * 65535.0).round() as u16;
    image::ImageBuffer::from_fn(w as u32, h as u32, |x, y| image::Rgb([c(x as usize, w), c(y as usize, h), 0]))
}

/// Where both cover a pixel: the fraction whose texel (decoded from a [`texel_code`] render)
/// is the one pav's lookup reads (the nearest under its align-corners convention), and the
/// largest texel distance.
pub fn compare_texels(pav: &[Option<[f64; 2]>], blender: &[[f64; 3]], w: usize, h: usize) -> (f64, usize, usize) {
    let (mut same, mut n, mut worst) = (0usize, 0usize, 0usize);
    for (p, b) in pav.iter().zip(blender) {
        let (Some([u, v]), true) = (p, b[2] > 0.5) else { continue };
        let pc = (u.clamp(0.0, 1.0) * (w - 1) as f64).round() as i64;
        let pr = ((1.0 - v.clamp(0.0, 1.0)) * (h - 1) as f64).round() as i64;
        let bc = (b[0] * (w - 1) as f64).round() as i64;
        let br = (b[1] * (h - 1) as f64).round() as i64;
        let d = (pc - bc).unsigned_abs().max((pr - br).unsigned_abs()) as usize;
        n += 1;
        same += usize::from(d == 0);
        worst = worst.max(d);
    }
    (same as f64 / n.max(1) as f64, worst, n)
}

/// pav's interpolated UV per pixel (`None` where no face covers it).
pub fn pav_uv(g: &GBuffer, mesh: &Mesh) -> Vec<Option<[f64; 2]>> {
    let mut out = vec![None; g.size * g.size];
    for (i, uv) in g.uv_samples(mesh) {
        out[i as usize] = Some([uv[0] as f64, uv[1] as f64]);
    }
    out
}

/// Compares pav's UV field `pav` (from [`pav_uv`], faces from `g`) with Blender's `blender`.
pub fn compare(g: &GBuffer, pav: &[Option<[f64; 2]>], blender: &[[f64; 3]]) -> Alignment {
    let n = g.size;
    let covered_b = |i: usize| blender[i][2] > 0.5;
    let mut errs = Vec::new();
    for y in 1..n.saturating_sub(1) {
        for x in 1..n - 1 {
            let i = y * n + x;
            let (Some(uv), true) = (pav[i], covered_b(i)) else { continue };
            // The Jacobian from neighbours on the same face (UV is affine per face up to
            // perspective, and seams between faces would poison a difference).
            let f = g.face[i];
            let same = |j: usize| (g.face[j] == f).then(|| pav[j]).flatten();
            // UV per pixel along one axis: central where both neighbours lie on the face, else
            // one-sided.
            let derivative = |step: usize| match (same(i + step), same(i - step)) {
                (Some(a), Some(b)) => Some([(a[0] - b[0]) / 2.0, (a[1] - b[1]) / 2.0]),
                (Some(a), None) => Some([a[0] - uv[0], a[1] - uv[1]]),
                (None, Some(b)) => Some([uv[0] - b[0], uv[1] - b[1]]),
                (None, None) => None,
            };
            let (Some(dx), Some(dy)) = (derivative(1), derivative(n)) else { continue };
            let det = dx[0] * dy[1] - dy[0] * dx[1];
            if det.abs() < 1e-14 {
                continue;
            }
            let d = [blender[i][0] - uv[0], blender[i][1] - uv[1]];
            // Solve [dx dy]·p = d for the pixel offset p.
            let px = (d[0] * dy[1] - dy[0] * d[1]) / det;
            let py = (dx[0] * d[1] - d[0] * dx[1]) / det;
            errs.push((px * px + py * py).sqrt());
        }
    }
    errs.sort_by(f64::total_cmp);
    let q = |p: f64| if errs.is_empty() { f64::INFINITY } else { errs[((errs.len() - 1) as f64 * p).round() as usize] };
    let pav_mask: Vec<bool> = g.face.iter().map(|f| *f != EMPTY).collect();
    let blender_mask: Vec<bool> = (0..n * n).map(covered_b).collect();
    let (iou, edge_offset_px) = silhouettes(&pav_mask, &blender_mask, n);
    Alignment { pixels: errs.len(), uv_px: [q(0.5), q(0.95), q(0.99)], edge_offset_px, iou }
}

/// Two `n × n` silhouettes compared: their intersection over union, and the pixels where
/// exactly one covers per outline pixel of `a` (a pixel of `a` at the border or beside one `a`
/// leaves uncovered), i.e. the mean edge offset in pixels.
pub fn silhouettes(a: &[bool], b: &[bool], n: usize) -> (f64, f64) {
    let (mut both, mut either, mut outline) = (0usize, 0usize, 0usize);
    for y in 0..n {
        for x in 0..n {
            let i = y * n + x;
            let (p, q) = (a[i], b[i]);
            both += usize::from(p && q);
            either += usize::from(p || q);
            if p {
                let edge =
                    x == 0 || y == 0 || x == n - 1 || y == n - 1 || !a[i - 1] || !a[i + 1] || !a[i - n] || !a[i + n];
                outline += usize::from(edge);
            }
        }
    }
    (both as f64 / either.max(1) as f64, (either - both) as f64 / outline.max(1) as f64)
}
