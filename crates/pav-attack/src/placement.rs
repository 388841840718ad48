//! The placement guide: where each printed piece goes on the car. The car is drawn by pav's
//! rasterizer from nine sides (left, right, front, rear, top and the four corners), each pixel
//! showing the atlas texel under it; for every piece, the side that shows most of it, with the
//! piece in solid magenta and the rest of the car in its texture washed out, its number and the
//! car's front and up as arrows; and per side an overview with every piece in its own colour.

use pav_core::geometry::camera::Camera;
use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::parts::Axis;
use pav_core::geometry::vec3::cross;
use pav_core::image::marks::{draw_arrow, draw_text, text_width};
use pav_core::image::Frame;
use pav_print::pdf::Figure;
use pav_print::pieces::PageLayout;
use pav_render::raster::{GBuffer, EMPTY};

/// The colour a highlighted piece is drawn in.
pub const HIGHLIGHT: [u8; 3] = [255, 0, 255];

/// Height of the band above each view that says which piece and which way, as a share of the
/// view's side.
const BAND: f64 = 0.1;

/// One side the car is drawn from.
#[derive(Clone, Debug)]
pub struct Side {
    /// Its name: `left`, `front-right`, `top`, …
    pub name: &'static str,
    /// The camera.
    pub camera: Camera,
}

/// The nine sides of a car of `mesh` (normalized: centred, at most unit half-extent along
/// its longest side) whose front and up are `front` and `up`: each camera is 3.6 units away,
/// 20° above the horizon (the top from straight above, its image's top to the front), with a
/// 40° field of view.
pub fn sides(front: Axis, up: Axis) -> Vec<Side> {
    let (f, u) = (front.vector(), up.vector());
    let l = cross(u, f);
    let unit = |v: [f32; 3]| {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|x| x / n)
    };
    let (dist, rise) = (3.6, 20f32.to_radians().tan());
    let around = [
        ("left", l),
        ("front-left", unit([f[0] + l[0], f[1] + l[1], f[2] + l[2]])),
        ("front", f),
        ("front-right", unit([f[0] - l[0], f[1] - l[1], f[2] - l[2]])),
        ("right", l.map(|x| -x)),
        ("rear-right", unit([-f[0] - l[0], -f[1] - l[1], -f[2] - l[2]])),
        ("rear", f.map(|x| -x)),
        ("rear-left", unit([l[0] - f[0], l[1] - f[1], l[2] - f[2]])),
    ];
    let mut out: Vec<Side> = around
        .into_iter()
        .map(|(name, d)| {
            let eye = unit([d[0] + u[0] * rise, d[1] + u[1] * rise, d[2] + u[2] * rise]).map(|x| x * dist);
            Side { name, camera: Camera::look_at(eye, [0.0; 3], u, 40.0) }
        })
        .collect();
    out.push(Side { name: "top", camera: Camera::look_at(u.map(|x| x * dist), [0.0; 3], f, 40.0) });
    out
}

/// The car from one side: which part of the atlas and which colour every pixel shows.
pub struct SideView {
    /// Image side, pixels.
    pub size: usize,
    /// The part label under each pixel (0: off the region or off the car).
    pub part: Vec<u32>,
    /// The texture's colour under each pixel, white off the car.
    pub rgb: Vec<u8>,
    /// Where on the car each part is seen, the mean of its pixels' surface points.
    centre: Vec<([f64; 3], usize)>,
}

impl SideView {
    /// `mesh` from `cam` at `size²`, looking each pixel's texel up in the `n × n` atlas.
    pub fn take(mesh: &Mesh, cam: &Camera, size: usize, labels: &[u32], texture: &Frame, parts: usize) -> SideView {
        let n = texture.width;
        let g = GBuffer::render(mesh, cam, size);
        let mut part = vec![0u32; size * size];
        let mut rgb = vec![255u8; size * size * 3];
        let mut centre = vec![([0.0; 3], 0usize); parts];
        for (i, &f) in g.face.iter().enumerate() {
            if f == EMPTY {
                continue;
            }
            let (b, t, corners) = (g.bary[i], mesh.face_uvs[f as usize], mesh.face_positions(f as usize));
            let mut uv = [0f32; 2];
            let mut p = [0f64; 3];
            for k in 0..3 {
                let c = mesh.uvs[t[k] as usize];
                uv = [uv[0] + b[k] * c[0], uv[1] + b[k] * c[1]];
                for (a, q) in p.iter_mut().zip(corners[k]) {
                    *a += (b[k] * q) as f64;
                }
            }
            // The texel whose span holds the UV, as the printed sheet shows it (v runs up).
            let x = ((uv[0].rem_euclid(1.0) * n as f32) as usize).min(n - 1);
            let y = (((1.0 - uv[1].rem_euclid(1.0)) * n as f32) as usize).min(n - 1);
            let label = labels[y * n + x];
            part[i] = label;
            rgb[i * 3..i * 3 + 3].copy_from_slice(&texture.bgr[(y * n + x) * 3..(y * n + x) * 3 + 3]);
            if label != 0 && label as usize <= parts {
                let c = &mut centre[label as usize - 1];
                c.0 = [c.0[0] + p[0], c.0[1] + p[1], c.0[2] + p[2]];
                c.1 += 1;
            }
        }
        SideView { size, part, rgb, centre }
    }

    /// How many pixels show part `label`.
    pub fn pixels(&self, label: u32) -> usize {
        self.centre.get(label as usize - 1).map_or(0, |c| c.1)
    }

    /// The part's mean surface point and where it is in the image.
    fn seen_at(&self, label: u32, cam: &Camera) -> Option<([f32; 3], [f32; 2])> {
        let (sum, k) = *self.centre.get(label as usize - 1)?;
        (k > 0).then(|| {
            let p = sum.map(|v| (v / k as f64) as f32);
            (p, cam.to_pixel(cam.to_view(p), self.size))
        })
    }
}

/// Which way `axis` runs in the image at surface point `p`, a unit direction (none when it
/// points at or away from the camera).
fn on_screen(cam: &Camera, size: usize, p: [f32; 3], axis: [f32; 3]) -> Option<[f64; 2]> {
    let a = cam.to_pixel(cam.to_view(p), size);
    let q = [p[0] + 0.05 * axis[0], p[1] + 0.05 * axis[1], p[2] + 0.05 * axis[2]];
    let b = cam.to_pixel(cam.to_view(q), size);
    let d = [(b[0] - a[0]) as f64, (b[1] - a[1]) as f64];
    let len = d[0].hypot(d[1]);
    (len > 0.02 * size as f64 * 0.05).then(|| [d[0] / len, d[1] / len])
}

/// The band's height above a view of side `size`.
pub fn band(size: usize) -> usize {
    (size as f64 * BAND).round() as usize
}

/// A band of `height` white rows above `rgb` (`size` wide), with `text` and arrows for the
/// car's front and up drawn in it.
fn banded(rgb: &[u8], size: usize, text: &str, arrows: &[([f64; 2], char)]) -> Vec<u8> {
    let b = band(size);
    let mut out = vec![255u8; size * b * 3];
    out.extend_from_slice(rgb);
    let tall = b as f64 * 0.6;
    draw_text(&mut out, size, [b / 4, b / 5], text, tall);
    let mut x = b / 4 + text_width(text, tall) as usize + b / 2;
    for &(d, letter) in arrows {
        draw_arrow(&mut out, size, [x + b / 3, b / 2], d, b as f64 * 0.6);
        draw_text(&mut out, size, [x + b * 3 / 4, b / 4], &letter.to_string(), tall * 0.8);
        x += b * 3 / 2;
    }
    out
}

/// The guide's figures: one overview per side (every piece in its own colour, its number on
/// it), then one per piece from the side that shows most of it. `shots` are `sides`' shots;
/// `front` and `up` as [`sides`] took them. Also returns, per piece, the side it is shown from.
pub fn figures(
    layout: &PageLayout,
    sides: &[Side],
    shots: &[SideView],
    front: Axis,
    up: Axis,
) -> (Vec<Figure>, Vec<(usize, &'static str, usize)>) {
    let mut figs = Vec::new();
    let size = shots[0].size;
    // The smallest number among each part's pieces, which the overviews print on it.
    let first_id = |label: u32| layout.pieces.iter().filter(|p| p.part == label).map(|p| p.id).min();
    for (side, shot) in sides.iter().zip(shots) {
        let mut rgb = shot.rgb.clone();
        for (i, &l) in shot.part.iter().enumerate() {
            if l != 0 && first_id(l).is_some() {
                rgb[i * 3..i * 3 + 3].copy_from_slice(&palette(l));
            } else if l == 0 && shot.rgb[i * 3..i * 3 + 3] != [255, 255, 255] {
                // The car off the region, in light grey.
                rgb[i * 3..i * 3 + 3].fill(215);
            }
        }
        for label in 1..=layout.orient.len().max(shot.centre.len()) as u32 {
            let (Some(id), Some((_, at))) = (first_id(label), shot.seen_at(label, &side.camera)) else { continue };
            if shot.pixels(label) < size * size / 2000 {
                continue;
            }
            let text = id.to_string();
            let tall = size as f64 / 40.0;
            let x = (at[0] as f64 - text_width(&text, tall) / 2.0).max(0.0) as usize;
            let y = (at[1] as f64 - tall / 2.0).max(0.0) as usize;
            draw_text(&mut rgb, size, [x, y.min(size - tall as usize - 1)], &text, tall);
        }
        figs.push(Figure {
            rgb: banded(&rgb, size, "", &[]),
            width: size,
            height: size + band(size),
            caption: format!("Every piece, seen from the {}", side.name),
        });
    }
    let mut chosen = Vec::new();
    for piece in &layout.pieces {
        let Some((k, shot)) = shots
            .iter()
            .enumerate()
            .max_by_key(|(_, s)| s.pixels(piece.part))
            .filter(|(_, s)| s.pixels(piece.part) > 0)
        else {
            continue;
        };
        let cam = &sides[k].camera;
        let mut rgb = shot.rgb.clone();
        for (i, &l) in shot.part.iter().enumerate() {
            if l == piece.part {
                rgb[i * 3..i * 3 + 3].copy_from_slice(&HIGHLIGHT);
            } else {
                // Washed out: halfway to white.
                for v in &mut rgb[i * 3..i * 3 + 3] {
                    *v = 128 + *v / 2;
                }
            }
        }
        let mut arrows = Vec::new();
        if let Some((p, _)) = shot.seen_at(piece.part, cam) {
            for (axis, letter) in [(front, 'F'), (up, 'U')] {
                if let Some(d) = on_screen(cam, size, p, axis.vector()) {
                    arrows.push((d, letter));
                }
            }
        }
        let panel = layout.orient.get(piece.part as usize - 1).and_then(|o| o.panel);
        let tile = piece.tile.map_or(String::new(), |(c, r)| format!(", tile {c}×{r} of its part"));
        figs.push(Figure {
            rgb: banded(&rgb, size, &piece.id.to_string(), &arrows),
            width: size,
            height: size + band(size),
            caption: format!(
                "Piece {} (page {}){tile}: {}, seen from the {}",
                piece.id,
                piece.page,
                panel.map_or("its part".to_string(), |p| p.to_string()),
                sides[k].name
            ),
        });
        chosen.push((piece.id, sides[k].name, shot.pixels(piece.part)));
    }
    (figs, chosen)
}

/// A colour per part label, far from the highlight and from each other's neighbours.
fn palette(label: u32) -> [u8; 3] {
    // Hues around the circle by the golden angle, kept clear of magenta.
    let h = (label as f64 * 137.508).rem_euclid(360.0);
    let h = if (280.0..330.0).contains(&h) { h - 60.0 } else { h };
    let (s, v) = (0.55, 0.92);
    let c = v * s;
    let x = c * (1.0 - ((h / 60.0).rem_euclid(2.0) - 1.0).abs());
    let (r, g, b) = match (h / 60.0) as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    [r, g, b].map(|t| ((t + v - c) * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sides_look_at_the_car_from_where_they_say() {
        let (front, up): (Axis, Axis) = ("+x".parse().unwrap(), "+z".parse().unwrap());
        let s = sides(front, up);
        assert_eq!(s.len(), 9);
        let eye = |name: &str| s.iter().find(|v| v.name == name).unwrap().camera.eye;
        // Facing +x with +z up, left is +y.
        assert!(eye("left")[1] > 3.0 && eye("front")[0] > 3.0 && eye("rear")[0] < -3.0 && eye("top")[2] > 3.5);
        assert!(eye("front-right")[0] > 2.0 && eye("front-right")[1] < -2.0);
        // The car's front is on the left of the image seen from its left side (the camera's
        // pixel x runs right): a point ahead of the centre lands left of the image's middle.
        let cam = &s[0].camera;
        assert!(cam.to_pixel(cam.to_view([0.5, 0.0, 0.0]), 100)[0] < 50.0);
        assert!(palette(1) != palette(2) && (1..60).all(|l| palette(l) != HIGHLIGHT));
    }
}
