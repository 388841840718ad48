//! The printable sheet: the texture atlas resampled so that, printed at the stated DPI, its
//! texels have the size they have on the scale model (PNG with its DPI in the pHYs chunk, and a
//! 10 mm scale bar in the margin to check the printer did not rescale).

use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::uv::faces_in_mask;
use pav_core::image::resize::{resize, Interpolation};
use pav_core::image::{draw_scale_bar, save_png_dpi, to_u8, Frame, Rgb};
use std::path::Path;

/// Print settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrintSpec {
    /// Model scale denominator (20 for 1:20).
    pub scale: f64,
    /// Printer resolution.
    pub dpi: f64,
}

/// Why the sheet could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SheetError {
    /// The sheet would be unreasonably large.
    #[error("the sheet would be {side_px} px wide ({atlas_mm:.0} mm at {dpi} dpi): lower the DPI")]
    TooLarge {
        /// Its side in pixels.
        side_px: usize,
        /// Its side in millimetres.
        atlas_mm: f64,
        /// The resolution asked for.
        dpi: f64,
    },
    /// The PNG encoder failed.
    #[error("{path}: {source}")]
    Png {
        /// The file.
        path: std::path::PathBuf,
        /// Why.
        source: png::EncodingError,
    },
}

/// What was written.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WrittenSheet {
    /// Atlas side on the real car (m): the UV square spans this much surface per side.
    pub atlas_side_m: f64,
    /// Atlas side on the sheet (mm).
    pub atlas_mm: f64,
    /// Image size in pixels (atlas plus margin).
    pub width_px: u32,
    /// Image height in pixels.
    pub height_px: u32,
    /// Texel spread: ratio of the 90th to the 10th percentile of per-face linear density.
    pub density_spread: f64,
}

fn area3(mesh: &Mesh, f: usize) -> f64 {
    let c = mesh.face_cross(f);
    0.5 * ((c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) as f64).sqrt()
}

fn area2(t: [[f32; 2]; 3]) -> f64 {
    0.5 * (((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1])) as f64).abs()
}

/// Real-world side (m) of the UV square over the faces of `mesh` in `region` (`n × n` texels),
/// for a car `car_length_m` long: sqrt(surface area / UV area), and the per-face density spread.
pub fn atlas_side_m(mesh: &Mesh, region: &[f32], n: usize, car_length_m: f64) -> Option<(f64, f64)> {
    let length = mesh.largest_side() as f64;
    if length <= 0.0 {
        return None;
    }
    let m_per_unit = car_length_m / length;
    let (mut a3, mut a2) = (0.0, 0.0);
    let mut dens = Vec::new();
    for f in faces_in_mask(mesh, region, n, n) {
        let t = mesh.face_uvs[f].map(|i| mesh.uvs[i as usize]);
        let (x, y) = (area3(mesh, f) * m_per_unit * m_per_unit, area2(t));
        if x > 0.0 && y > 0.0 {
            dens.push((x / y).sqrt());
        }
        a3 += x;
        a2 += y;
    }
    if a2 <= 0.0 || dens.is_empty() {
        return None;
    }
    dens.sort_by(f64::total_cmp);
    let q = |f: f64| dens[((dens.len() - 1) as f64 * f) as usize];
    Some(((a3 / a2).sqrt(), q(0.9) / q(0.1)))
}

/// Writes the sheet for the `n × n` RGB texture `tex` to `path`.
pub fn write_sheet(
    path: &Path,
    tex: &[f32],
    n: usize,
    side_m: f64,
    spread: f64,
    spec: PrintSpec,
) -> Result<WrittenSheet, SheetError> {
    let atlas_mm = side_m * 1000.0 / spec.scale;
    let px_per_mm = spec.dpi / 25.4;
    // The sheet's side as `pav print pieces` cuts it, so that its pages are this sheet's pixels.
    let side = pav_print::pieces::Sheet::new(n, atlas_mm, spec.dpi).side_px;
    if side > 20_000 {
        return Err(SheetError::TooLarge { side_px: side, atlas_mm, dpi: spec.dpi });
    }
    let frame = Frame { width: n, height: n, bgr: tex.iter().map(|v| to_u8(*v)).collect() };
    let atlas = resize(&frame, side, side, Interpolation::Bilinear);
    let margin = (15.0 * px_per_mm).round() as usize;
    let (w, h) = (side.max((12.0 * px_per_mm) as usize), side + margin);
    let mut rgb = vec![255u8; w * h * 3];
    for y in 0..side {
        for x in 0..side {
            for c in 0..3 {
                rgb[(y * w + x) * 3 + c] = atlas[(y * side + x) * 3 + c] as u8;
            }
        }
    }
    // The 10 mm bar 5 mm below the atlas, 1 mm from the left edge.
    draw_scale_bar(&mut rgb, w, h, [(1.0 * px_per_mm) as usize, side + (5.0 * px_per_mm) as usize], px_per_mm, 10.0);
    save_png_dpi(path, w, h, &rgb, spec.dpi).map_err(|source| SheetError::Png { path: path.into(), source })?;
    Ok(WrittenSheet { atlas_side_m: side_m, atlas_mm, width_px: w as u32, height_px: h as u32, density_spread: spread })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_square_mapped_to_a_2m_square_prints_at_100mm_for_1_20() {
        // A 2 m × 2 m quad (the "car" is 2 m long) mapped onto the whole UV square.
        let m = Mesh::from_triangles(
            vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 2.0, 0.0], [0.0, 2.0, 0.0]],
            vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let (side, spread) = atlas_side_m(&m, &[1.0; 16], 4, 2.0).unwrap();
        assert!((side - 2.0).abs() < 1e-9 && (spread - 1.0).abs() < 1e-9);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.png");
        let s = write_sheet(&p, &[0.5; 4 * 4 * 3], 4, side, spread, PrintSpec { scale: 20.0, dpi: 254.0 }).unwrap();
        assert!((s.atlas_mm - 100.0).abs() < 1e-9);
        assert_eq!((s.width_px, s.height_px), (1000, 1150));
        let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&p).unwrap()));
        let r = dec.read_info().unwrap();
        assert_eq!(r.info().pixel_dims.unwrap().xppu, 10_000);
        // The scale bar is 10 mm = 100 px of ink at 254 dpi.
        let img = image::open(&p).unwrap().to_rgb8();
        let row = 1000 + 50;
        let dark = (0..1000).filter(|x| img.get_pixel(*x, row).0 == [0, 0, 0]).count();
        assert_eq!(dark, 100);
    }
}

/// The car's paint with the sheet stuck on: `texture` (read bilinearly, as the sheet is printed)
/// on the texels where the `n × n` `region` is on, `base` elsewhere, at the base's resolution.
/// Every image spans the same UV square, so a texel's place is its position in its own image.
pub fn on_the_car(base: &Rgb, texture: &Rgb, region: &[f32], n: usize) -> Rgb {
    let at =
        |i: usize, len: usize, to: usize| if len < 2 { 0.0 } else { i as f32 * (to - 1) as f32 / (len - 1) as f32 };
    let (tw, th) = (texture.width, texture.height);
    let tex = |x: usize, y: usize, c: usize| texture.rgb[(y * tw + x) * 3 + c];
    let mut out = base.clone();
    for y in 0..base.height {
        let (ry, ty) = (at(y, base.height, n).round() as usize, at(y, base.height, th));
        for x in 0..base.width {
            if region[ry * n + at(x, base.width, n).round() as usize] < 0.5 {
                continue;
            }
            let tx = at(x, base.width, tw);
            let (x0, y0) = (tx.floor() as usize, ty.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(tw - 1), (y0 + 1).min(th - 1));
            let (fx, fy) = (tx - x0 as f32, ty - y0 as f32);
            for c in 0..3 {
                let top = tex(x0, y0, c) * (1.0 - fx) + tex(x1, y0, c) * fx;
                let bottom = tex(x0, y1, c) * (1.0 - fx) + tex(x1, y1, c) * fx;
                out.rgb[(y * base.width + x) * 3 + c] = top * (1.0 - fy) + bottom * fy;
            }
        }
    }
    out
}

#[cfg(test)]
mod paint_tests {
    use super::*;

    #[test]
    fn the_sheet_covers_the_region_only_and_reads_the_texture_where_it_lies() {
        // A 5×5 base, a 2×2 region with its right column on, a 3×3 texture whose value is its column.
        let base = Rgb { width: 5, height: 5, rgb: vec![0.25; 75] };
        let region = [0.0, 1.0, 0.0, 1.0];
        let texture = Rgb { width: 3, height: 3, rgb: (0..27).map(|i| ((i / 3) % 3) as f32).collect() };
        let p = on_the_car(&base, &texture, &region, 2);
        let v = |x: usize, y: usize| p.rgb[(y * 5 + x) * 3];
        // Columns 0–1 map to region column 0 (off), columns 3–4 to column 1 (on); column 2
        // (position 0.5) rounds to column 1.
        assert_eq!([v(0, 0), v(1, 4)], [0.25, 0.25]);
        // On, the texture's column at the same position: x = 4 → 2.0, x = 3 → 1.5, x = 2 → 1.0.
        assert_eq!([v(4, 0), v(3, 2), v(2, 4)], [2.0, 1.5, 1.0]);
    }
}
