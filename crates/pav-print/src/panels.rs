//! Where each part of the atlas lies on the car: the panel it covers (left side, front end, …),
//! which way the car's front and up run across it, and whether its UV island is mirrored, read
//! from the mesh faces whose UV centroids fall in it.
//!
//! A mesh's winding is not trusted (nor is it in [`pav_core::geometry::parts`]): a face's outward
//! side is the one facing away from the mesh's centre, which holds for the convex-ish shell of
//! a car body, and every answer is a vote of the part's faces weighted by their area.

use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::parts::{Axis, Panel};
use pav_core::geometry::vec3::cross;

/// How one part of the atlas lies on the car.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Orientation {
    /// The panel it covers, when the mesh's front is known.
    pub panel: Option<Panel>,
    /// The car's front across the part, a unit direction in atlas pixels (x right, y down);
    /// none when the front is unknown or runs mostly through the surface, not along it.
    pub front: Option<[f64; 2]>,
    /// The car's up across the part, likewise (none on a roof, which up leaves).
    pub up: Option<[f64; 2]>,
    /// The UV island is mirrored: seen from outside, the atlas shows it mirror-imaged, so it
    /// prints mirrored to lie right.
    pub mirrored: bool,
}

/// Sums of one part's faces.
#[derive(Clone, Copy, Default)]
struct Votes {
    normal: [f64; 3],
    front: [f64; 2],
    up: [f64; 2],
    front_along: f64,
    up_along: f64,
    handed: f64,
    area: f64,
}

/// The orientation of every part of `labels` (an `n × n` atlas labelled 1..=`parts`), indexed
/// by label − 1, for a mesh whose up is `up` and front, when known, `front`.
pub fn orient(mesh: &Mesh, labels: &[u32], n: usize, parts: usize, front: Option<Axis>, up: Axis) -> Vec<Orientation> {
    let (lo, hi) = mesh.bounds();
    let centre = [0, 1, 2].map(|k| (lo[k] + hi[k]) as f64 / 2.0);
    let mut votes = vec![Votes::default(); parts];
    let f64s = |a: [f32; 3]| a.map(|x| x as f64);
    for f in 0..mesh.faces.len() {
        let p = mesh.face_positions(f).map(f64s);
        let uv = mesh.face_uvs[f].map(|i| mesh.uvs[i as usize]).map(|t| [t[0] as f64, t[1] as f64]);
        let (cu, cv) = ((uv[0][0] + uv[1][0] + uv[2][0]) / 3.0, (uv[0][1] + uv[1][1] + uv[2][1]) / 3.0);
        if !(0.0..1.0).contains(&cu) || !(0.0..1.0).contains(&cv) {
            continue;
        }
        // Atlas rows run down, v runs up.
        let (x, y) = ((cu * n as f64) as usize, (((1.0 - cv) * n as f64) as usize).min(n - 1));
        let label = labels[y * n + x];
        if label == 0 || label as usize > parts {
            continue;
        }
        let e1 = [0, 1, 2].map(|k| p[1][k] - p[0][k]);
        let e2 = [0, 1, 2].map(|k| p[2][k] - p[0][k]);
        let c = cross(e1.map(|v| v as f32), e2.map(|v| v as f32)).map(|v| v as f64);
        let twice_area = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        let (d1, d2) = ([uv[1][0] - uv[0][0], uv[1][1] - uv[0][1]], [uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]]);
        let det = d1[0] * d2[1] - d2[0] * d1[1];
        if !(twice_area > 0.0 && det.abs() > 1e-14) {
            continue;
        }
        let mid = [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0 - centre[k]);
        let out = if c[0] * mid[0] + c[1] * mid[1] + c[2] * mid[2] >= 0.0 { 1.0 } else { -1.0 };
        let normal = c.map(|v| v * out / twice_area);
        let area = twice_area / 2.0;
        // The gradient over the UV triangle of s(p) = a · p, turned into atlas pixels, and how
        // much of `a` lies along the surface (1: in it, 0: along the normal).
        let across = |a: [f32; 3]| {
            let a = f64s(a);
            let dot = |b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            let (s1, s2) = (dot(e1), dot(e2));
            let g = [(s1 * d2[1] - s2 * d1[1]) / det, (d1[0] * s2 - d2[0] * s1) / det];
            let len = (g[0] * g[0] + g[1] * g[1]).sqrt().max(f64::MIN_POSITIVE);
            let along = (1.0 - dot(normal).powi(2)).max(0.0).sqrt();
            ([g[0] / len * area, -g[1] / len * area], along * area)
        };
        let v = &mut votes[label as usize - 1];
        for (sum, n) in v.normal.iter_mut().zip(normal) {
            *sum += n * area;
        }
        if let Some(front) = front {
            let (g, along) = across(front.vector());
            v.front = [v.front[0] + g[0], v.front[1] + g[1]];
            v.front_along += along;
        }
        let (g, along) = across(up.vector());
        v.up = [v.up[0] + g[0], v.up[1] + g[1]];
        v.up_along += along;
        v.handed += area * det.signum() * out;
        v.area += area;
    }
    votes
        .iter()
        .map(|v| {
            // An arrow only where the axis runs mostly along the surface (over 30° off its
            // normal on average) and its faces agree on a way.
            let arrow = |g: [f64; 2], along: f64| {
                let len = (g[0] * g[0] + g[1] * g[1]).sqrt();
                (v.area > 0.0 && along >= 0.5 * v.area && len >= 0.5 * v.area).then(|| [g[0] / len, g[1] / len])
            };
            let n = v.normal.map(|x| x as f32);
            Orientation {
                panel: front.filter(|_| v.area > 0.0).map(|f| Panel::facing(n, f, up)),
                front: front.and_then(|_| arrow(v.front, v.front_along)),
                up: arrow(v.up, v.up_along),
                mirrored: v.handed < 0.0,
            }
        })
        .collect()
}

/// The UV chart of every texel of an `n × n` atlas (numbered from 1; 0 where no face lies): the
/// faces joined by shared UV corners, painted into the atlas.
pub fn uv_charts(mesh: &Mesh, n: usize) -> Vec<u32> {
    let mut parent: Vec<usize> = (0..mesh.uvs.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for t in &mesh.face_uvs {
        let a = root(&mut parent, t[0] as usize);
        for &c in &t[1..] {
            let b = root(&mut parent, c as usize);
            parent[b] = a;
        }
    }
    // Charts numbered in order of first face, as 24-bit colours for the painter.
    let mut number = std::collections::HashMap::new();
    let faces: Vec<(usize, [u8; 3])> = (0..mesh.face_uvs.len())
        .map(|f| {
            let r = root(&mut parent, mesh.face_uvs[f][0] as usize);
            let next = number.len() as u32 + 1;
            let id = *number.entry(r).or_insert(next);
            (f, [(id >> 16) as u8, (id >> 8) as u8, id as u8])
        })
        .collect();
    pav_core::geometry::uv::paint_uv(mesh, &faces, n, [0; 3])
        .chunks(3)
        .map(|c| (c[0] as u32) << 16 | (c[1] as u32) << 8 | c[2] as u32)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4 × 2 × 2 box centred on the origin (length x, width y, height z) whose +y face is
    /// UV-mapped with front +x to the atlas's right and up to its top onto the atlas's left
    /// half, and whose −y face the same way onto its right half. Standing by a car's left side
    /// its front is on your left: so the +y (left) face's mapping is the mirrored one.
    fn box_mesh() -> Mesh {
        let (mut pos, mut uvs, mut faces) = (Vec::new(), Vec::new(), Vec::new());
        for (y, u0) in [(1.0, 0.0), (-1.0, 0.5)] {
            let b = pos.len() as u32;
            pos.extend([[-2.0, y, -1.0], [2.0, y, -1.0], [2.0, y, 1.0], [-2.0, y, 1.0]]);
            uvs.extend([[u0 + 0.05, 0.3], [u0 + 0.45, 0.3], [u0 + 0.45, 0.7], [u0 + 0.05, 0.7]]);
            faces.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        }
        Mesh::from_triangles(pos, uvs, faces)
    }

    #[test]
    fn the_two_faces_of_the_box_are_two_charts_where_their_uvs_lie() {
        let c = uv_charts(&box_mesh(), 20);
        // Row 10 (v = 0.475): the +y face's chart over u 0.05–0.45, the −y face's over 0.55–0.95.
        let row: Vec<u32> = c[10 * 20..11 * 20].to_vec();
        assert_eq!(row[0], 0);
        assert!(row[2..8].iter().all(|&k| k == 1) && row[12..18].iter().all(|&k| k == 2), "{row:?}");
    }

    #[test]
    fn each_side_of_a_box_is_named_pointed_and_mirrored_where_its_uvs_are() {
        let m = box_mesh();
        let n = 20;
        let mut labels = vec![0u32; n * n];
        for y in 6..14 {
            for x in 1..9 {
                labels[y * n + x] = 1;
                labels[y * n + x + 10] = 2;
            }
        }
        let (front, up) = ("+x".parse().unwrap(), "+z".parse().unwrap());
        let o = orient(&m, &labels, n, 2, Some(front), up);
        assert_eq!(o[0].panel, Some(Panel::LeftSide));
        assert_eq!(o[1].panel, Some(Panel::RightSide));
        let close = |a: Option<[f64; 2]>, b: [f64; 2]| {
            a.is_some_and(|a| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9)
        };
        // Front runs to the atlas's right on both; up runs to its top (rows run down).
        assert!(close(o[0].front, [1.0, 0.0]) && close(o[0].up, [0.0, -1.0]), "{:?}", o[0]);
        assert!(close(o[1].front, [1.0, 0.0]) && close(o[1].up, [0.0, -1.0]), "{:?}", o[1]);
        assert!(o[0].mirrored && !o[1].mirrored, "{o:?}");
        // Without a front: no panel and no front arrow, up still known.
        let o = orient(&m, &labels, n, 2, None, up);
        assert!(o[0].panel.is_none() && o[0].front.is_none() && o[0].up.is_some());
    }
}
