//! UV adjustment by 3D charts: the optimizable patch is cut into charts by its 3D surface, not by
//! the original UV seams, so a door the original map splits into several islands is flattened
//! (LSCM) as one printable piece. The charts are then packed at one common texel density into the
//! texels no other face uses, which lets that density exceed the original map's.

use crate::adjust::lscm_with;
use pav_core::geometry::mesh::Mesh;
use pav_core::geometry::uv::paint_uv;
use std::collections::{HashMap, VecDeque};

/// What a chart adjustment did.
#[derive(Clone, Debug, PartialEq)]
pub struct ChartReport {
    /// Charts the patch was cut into.
    pub charts: usize,
    /// Largest number of original UV islands one chart joins.
    pub max_islands_joined: usize,
    /// Common texel density as an area ratio to the patch's original average density.
    pub density: f64,
    /// Faces whose flattening came out mirrored against the rest of their chart (folds).
    pub flipped: usize,
}

/// Errors of the chart adjustment.
#[derive(Debug, thiserror::Error)]
pub enum UvChartError {
    /// No chart fits the free texels even at a tiny scale.
    #[error("the charts do not fit into the texels the other faces leave free")]
    NoRoom,
    /// A chart's LSCM system was singular.
    #[error("chart {0} could not be flattened (singular LSCM system)")]
    Singular(usize),
}

/// One id per distinct 3D position (OBJ exports often duplicate vertices along seams).
fn weld(mesh: &Mesh) -> Vec<u32> {
    let mut ids: HashMap<[i64; 3], u32> = HashMap::new();
    let scale = mesh.largest_side().max(f32::MIN_POSITIVE) as f64;
    mesh.positions
        .iter()
        .map(|p| {
            let key = p.map(|x| (x as f64 / scale * 1e6).round() as i64);
            let n = ids.len() as u32;
            *ids.entry(key).or_insert(n)
        })
        .collect()
}

fn normal(mesh: &Mesh, f: usize) -> Option<([f64; 3], f64)> {
    let p = mesh.face_positions(f).map(|q| q.map(|x| x as f64));
    let (e1, e2) = ([0, 1, 2].map(|k| p[1][k] - p[0][k]), [0, 1, 2].map(|k| p[2][k] - p[0][k]));
    let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    (len > 1e-14 && len.is_finite()).then(|| (n.map(|x| x / len), len / 2.0))
}

/// Cuts `faces` into charts: region growing from the largest unassigned face across shared 3D
/// edges, taking a face while its (consistently oriented) normal stays within `max_angle_deg` of
/// the seed's. Returns each chart with its faces' orientations (±1 relative to the seed), since
/// game meshes mix windings and LSCM needs one orientation per chart. Degenerate faces are left out.
pub fn charts(mesh: &Mesh, faces: &[usize], max_angle_deg: f64) -> Vec<Vec<(usize, f64)>> {
    let w = weld(mesh);
    let cos_max = max_angle_deg.to_radians().cos();
    let mut by_edge: HashMap<(u32, u32), Vec<(usize, bool)>> = HashMap::new();
    for &f in faces {
        let v = mesh.faces[f].map(|i| w[i as usize]);
        for e in 0..3 {
            let (a, b) = (v[e], v[(e + 1) % 3]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push((f, a < b));
        }
    }
    let info: HashMap<usize, ([f64; 3], f64)> = faces.iter().filter_map(|&f| normal(mesh, f).map(|n| (f, n))).collect();
    let mut order: Vec<usize> = info.keys().copied().collect();
    order.sort_by(|a, b| info[b].1.total_cmp(&info[a].1).then(a.cmp(b)));
    let mut hand: HashMap<usize, f64> = HashMap::new();
    let mut out = Vec::new();
    for seed in order {
        if hand.contains_key(&seed) {
            continue;
        }
        let n0 = info[&seed].0;
        let mut chart = vec![(seed, 1.0)];
        hand.insert(seed, 1.0);
        let mut queue = VecDeque::from([seed]);
        while let Some(f) = queue.pop_front() {
            let v = mesh.faces[f].map(|i| w[i as usize]);
            for e in 0..3 {
                let (a, b) = (v[e], v[(e + 1) % 3]);
                for &(g, fwd) in &by_edge[&(a.min(b), a.max(b))] {
                    if g == f || hand.contains_key(&g) || !info.contains_key(&g) {
                        continue;
                    }
                    // Consistent neighbours run a shared edge in opposite directions.
                    let h = if fwd == (a < b) { -hand[&f] } else { hand[&f] };
                    let n = info[&g].0;
                    if h * (n[0] * n0[0] + n[1] * n0[1] + n[2] * n0[2]) >= cos_max {
                        hand.insert(g, h);
                        chart.push((g, h));
                        queue.push_back(g);
                    }
                }
            }
        }
        out.push(chart);
    }
    out
}

/// A flattened chart at unit density (UV area = 3D area), rotated to its smallest bounding box.
struct Flat {
    uv: HashMap<u32, [f64; 2]>,
    size: [f64; 2],
}

fn signed_area(t: [[f64; 2]; 3]) -> f64 {
    ((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1])) / 2.0
}

fn flatten(mesh: &Mesh, chart: &[(usize, f64)], k: usize, flipped: &mut usize) -> Result<Flat, UvChartError> {
    let faces: Vec<usize> = chart.iter().map(|c| c.0).collect();
    let h: HashMap<usize, f64> = chart.iter().copied().collect();
    let uv = lscm_with(mesh, &faces, &|f| h[&f], Some(1.0)).ok_or(UvChartError::Singular(k))?;
    // Folds: faces whose flattened orientation disagrees with their chart orientation.
    let signs: Vec<f64> = chart.iter().map(|&(f, hf)| signed_area(mesh.face_uvs[f].map(|i| uv[&i])) * hf).collect();
    let pos = signs.iter().filter(|s| **s > 0.0).count();
    *flipped += pos.min(signs.len() - pos);
    let a3: f64 = faces.iter().filter_map(|&f| normal(mesh, f)).map(|n| n.1).sum();
    let auv: f64 = chart.iter().map(|&(f, _)| signed_area(mesh.face_uvs[f].map(|i| uv[&i])).abs()).sum();
    let s = if auv > 0.0 { (a3 / auv).sqrt() } else { 1.0 };
    // Smallest axis-aligned box over rotations in 1° steps.
    let (mut best, mut best_a) = (f64::INFINITY, 0.0);
    for d in 0..90 {
        let a = (d as f64).to_radians();
        let (c, sn) = (a.cos(), a.sin());
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in uv.values() {
            let q = [c * p[0] - sn * p[1], sn * p[0] + c * p[1]];
            for j in 0..2 {
                lo[j] = lo[j].min(q[j]);
                hi[j] = hi[j].max(q[j]);
            }
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if area < best {
            (best, best_a) = (area, a);
        }
    }
    let (c, sn) = (best_a.cos(), best_a.sin());
    let rot: HashMap<u32, [f64; 2]> =
        uv.iter().map(|(i, p)| (*i, [s * (c * p[0] - sn * p[1]), s * (sn * p[0] + c * p[1])])).collect();
    let lo = rot.values().fold([f64::INFINITY; 2], |a, p| [a[0].min(p[0]), a[1].min(p[1])]);
    let uv: HashMap<u32, [f64; 2]> = rot.into_iter().map(|(i, p)| (i, [p[0] - lo[0], p[1] - lo[1]])).collect();
    let size = uv.values().fold([0.0f64; 2], |a, p| [a[0].max(p[0]), a[1].max(p[1])]);
    Ok(Flat { uv, size })
}

/// Summed-area table of a `g × g` occupancy grid.
fn sat(occ: &[bool], g: usize) -> Vec<u32> {
    let mut s = vec![0u32; (g + 1) * (g + 1)];
    for y in 0..g {
        for x in 0..g {
            s[(y + 1) * (g + 1) + x + 1] =
                occ[y * g + x] as u32 + s[y * (g + 1) + x + 1] + s[(y + 1) * (g + 1) + x] - s[y * (g + 1) + x];
        }
    }
    s
}

/// First-fit placement of boxes (cells, largest first) into the free cells; top-left corners.
fn pack(occupied: &[bool], g: usize, boxes: &[[usize; 2]]) -> Option<Vec<[usize; 2]>> {
    let mut occ = occupied.to_vec();
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|a, b| (boxes[*b][1], boxes[*b][0]).cmp(&(boxes[*a][1], boxes[*a][0])));
    let mut at = vec![[0usize; 2]; boxes.len()];
    for k in order {
        let [bw, bh] = boxes[k];
        if bw > g || bh > g {
            return None;
        }
        let s = sat(&occ, g);
        let g1 = g + 1;
        let free =
            |x: usize, y: usize| s[(y + bh) * g1 + x + bw] + s[y * g1 + x] == s[y * g1 + x + bw] + s[(y + bh) * g1 + x];
        let spot = (0..=g - bh).find_map(|y| (0..=g - bw).find(|&x| free(x, y)).map(|x| [x, y]))?;
        for y in spot[1]..spot[1] + bh {
            occ[y * g + spot[0]..y * g + spot[0] + bw].fill(true);
        }
        at[k] = spot;
    }
    Some(at)
}

/// Re-maps the UVs of `faces` by 3D charts (see [`charts`]) packed into the texels of a
/// `grid × grid` atlas that no other face touches, keeping `gutter` free cells around each chart
/// (bilinear lookups read one texel beyond a triangle). The other faces' UVs are not changed.
pub fn adjust_charts(
    mesh: &mut Mesh,
    faces: &[usize],
    max_angle_deg: f64,
    grid: usize,
    gutter: usize,
) -> Result<ChartReport, UvChartError> {
    let original_density = {
        let (mut a3, mut auv) = (0.0, 0.0);
        for &f in faces {
            if let Some((_, a)) = normal(mesh, f) {
                a3 += a;
                auv += signed_area(mesh.face_uvs[f].map(|i| mesh.uvs[i as usize].map(|x| x as f64))).abs();
            }
        }
        auv / a3.max(f64::MIN_POSITIVE)
    };
    let cs = charts(mesh, faces, max_angle_deg);
    let islands = crate::adjust::islands(mesh, faces);
    let island_of: HashMap<usize, usize> =
        islands.iter().enumerate().flat_map(|(k, isl)| isl.iter().map(move |&f| (f, k))).collect();
    let max_islands_joined = cs
        .iter()
        .map(|c| c.iter().map(|(f, _)| island_of[f]).collect::<std::collections::BTreeSet<_>>().len())
        .max()
        .unwrap_or(0);
    // Free cells: every texel a face outside the patch reads, dilated by the gutter.
    let inside: std::collections::HashSet<usize> = faces.iter().copied().collect();
    let others: Vec<(usize, [u8; 3])> =
        (0..mesh.faces.len()).filter(|f| !inside.contains(f)).map(|f| (f, [255u8; 3])).collect();
    let painted = paint_uv(mesh, &others, grid, [0; 3]);
    let mut used: Vec<bool> = painted.chunks(3).map(|p| p[0] == 255).collect();
    for &(f, _) in &others {
        for &t in &mesh.face_uvs[f] {
            let uv = mesh.uvs[t as usize];
            let x = ((uv[0].clamp(0.0, 1.0) * grid as f32) as usize).min(grid - 1);
            let y = (((1.0 - uv[1].clamp(0.0, 1.0)) * grid as f32) as usize).min(grid - 1);
            used[y * grid + x] = true;
        }
    }
    let mut occupied = used.clone();
    for y in 0..grid {
        for x in 0..grid {
            if used[y * grid + x] {
                for yy in y.saturating_sub(gutter)..(y + gutter + 1).min(grid) {
                    for xx in x.saturating_sub(gutter)..(x + gutter + 1).min(grid) {
                        occupied[yy * grid + xx] = true;
                    }
                }
            }
        }
    }
    // Each chart gets its own UV index per 3D vertex, so the original seams inside it close.
    let w = weld(mesh);
    let mut flats = Vec::new();
    let mut flipped = 0;
    for (k, chart) in cs.iter().enumerate() {
        let mut idx: HashMap<u32, u32> = HashMap::new();
        for &(f, _) in chart {
            for c in 0..3 {
                let v = w[mesh.faces[f][c] as usize];
                let n = *idx.entry(v).or_insert_with(|| {
                    mesh.uvs.push([0.0, 0.0]);
                    (mesh.uvs.len() - 1) as u32
                });
                mesh.face_uvs[f][c] = n;
            }
        }
        flats.push(flatten(mesh, chart, k, &mut flipped)?);
    }
    // Largest common scale (atlas units per unit-density length) at which every chart fits.
    let free_cells = occupied.iter().filter(|o| !**o).count() as f64 / (grid * grid) as f64;
    let total: f64 = flats.iter().map(|f| f.size[0] * f.size[1]).sum();
    let boxes = |s: f64| -> Vec<[usize; 2]> {
        flats.iter().map(|f| [0, 1].map(|j| (f.size[j] * s * grid as f64).ceil() as usize + 2 * gutter + 1)).collect()
    };
    let (mut lo, mut hi) = (0.0, (free_cells / total.max(f64::MIN_POSITIVE)).sqrt());
    let mut best = None;
    for _ in 0..24 {
        let mid = (lo + hi) / 2.0;
        match pack(&occupied, grid, &boxes(mid)) {
            Some(at) => {
                best = Some((mid, at));
                lo = mid;
            }
            None => hi = mid,
        }
    }
    let (s, at) = best.ok_or(UvChartError::NoRoom)?;
    for (f, corner) in flats.iter().zip(&at) {
        let (x0, y0) = ((corner[0] + gutter) as f64 / grid as f64, (corner[1] + gutter) as f64 / grid as f64);
        for (i, p) in &f.uv {
            // Grid rows run down from the top of the atlas; v runs up.
            mesh.uvs[*i as usize] = [(x0 + p[0] * s) as f32, (1.0 - y0 - (f.size[1] - p[1]) * s) as f32];
        }
    }
    Ok(ChartReport { charts: cs.len(), max_islands_joined, density: s * s / original_density, flipped })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bent 6×3 strip: a flat half (y = 0) and a half folded up by `bend` degrees about the
    /// line x = 3, with UVs cut into two islands along x = 1.5 and the left island mirrored.
    fn strip(bend: f64) -> Mesh {
        let mut positions = Vec::new();
        let mut uvs = Vec::new();
        for j in 0..4 {
            for i in 0..7 {
                let x = i as f64 * 0.5;
                let (px, py) = if x <= 1.5 {
                    (x, 0.0)
                } else {
                    (1.5 + (x - 1.5) * bend.to_radians().cos(), (x - 1.5) * bend.to_radians().sin())
                };
                positions.push([px as f32, py as f32, j as f32 * 0.5]);
                uvs.push([0.05 + 0.1 * i as f32, 0.05 + 0.1 * j as f32]);
            }
        }
        let mut faces = Vec::new();
        let mut fuv = Vec::new();
        // The left columns (x < 1.5) get their own, mirrored UV copies: a seam at x = 1.5.
        let mut left: HashMap<u32, u32> = HashMap::new();
        for j in 0..3u32 {
            for i in 0..6u32 {
                let a = j * 7 + i;
                for tri in [[a, a + 1, a + 8], [a, a + 8, a + 7]] {
                    faces.push(tri);
                    if i < 3 {
                        fuv.push(tri.map(|v| {
                            *left.entry(v).or_insert_with(|| {
                                let p = uvs[v as usize];
                                uvs.push([0.9 - p[0], p[1] + 0.5]);
                                (uvs.len() - 1) as u32
                            })
                        }));
                    } else {
                        fuv.push(tri);
                    }
                }
            }
        }
        let mut m = Mesh::from_triangles(positions, uvs, faces);
        m.face_uvs = fuv;
        m
    }

    #[test]
    fn a_smooth_surface_cut_by_uv_seams_becomes_one_chart() {
        let m = strip(20.0);
        let all: Vec<usize> = (0..m.faces.len()).collect();
        assert_eq!(crate::adjust::islands(&m, &all).len(), 2);
        let c = charts(&m, &all, 45.0);
        assert_eq!(c.len(), 1, "20° bend under a 45° cone: one chart");
        // A sharp fold splits it, along the fold.
        let c = charts(&strip(80.0), &all, 45.0);
        assert_eq!(c.len(), 2);
    }

    #[test]
    fn charts_are_isometric_packed_without_overlap_and_denser() {
        let mut m = strip(20.0);
        let all: Vec<usize> = (0..m.faces.len()).collect();
        let r = adjust_charts(&mut m, &all, 45.0, 256, 2).unwrap();
        assert_eq!((r.charts, r.max_islands_joined, r.flipped), (1, 2, 0));
        // A developable strip flattens without distortion: every face keeps its 3D shape.
        let d = pav_core::geometry::uv::distortion(&m, &all);
        assert!(d.iter().all(|x| (x.anisotropy - 1.0).abs() < 1e-3 && x.log2_stretch.abs() < 1e-3), "{d:?}");
        // Alone in the atlas, the chart grows well beyond the original density.
        assert!(r.density > 1.5, "{}", r.density);
        // Inside the atlas, and no two faces overlap in UV.
        assert!(m
            .uvs
            .iter()
            .skip(m.positions.len())
            .all(|p| (0.0..=1.0).contains(&p[0]) && (0.0..=1.0).contains(&p[1])));
        let n = 512;
        let mut hits = vec![0u8; n * n];
        for f in &all {
            let img = paint_uv(&m, &[(*f, [255; 3])], n, [0; 3]);
            for (h, p) in hits.iter_mut().zip(img.chunks(3)) {
                *h += (p[0] == 255) as u8;
            }
        }
        assert!(hits.iter().all(|h| *h <= 1));
    }

    #[test]
    fn packing_keeps_clear_of_other_faces() {
        let mut m = strip(20.0);
        // Only the right half is the patch; the left half keeps its (mirrored) island.
        let patch: Vec<usize> = (0..m.faces.len()).filter(|f| f % 12 >= 6).collect();
        let rest: Vec<usize> = (0..m.faces.len()).filter(|f| f % 12 < 6).collect();
        let before: Vec<[u32; 3]> = rest.iter().map(|&f| m.face_uvs[f]).collect();
        adjust_charts(&mut m, &patch, 45.0, 128, 2).unwrap();
        assert_eq!(before, rest.iter().map(|&f| m.face_uvs[f]).collect::<Vec<_>>());
        let paint = |fs: &[usize]| paint_uv(&m, &fs.iter().map(|&f| (f, [255u8; 3])).collect::<Vec<_>>(), 128, [0; 3]);
        let (a, b) = (paint(&patch), paint(&rest));
        assert!(a.chunks(3).zip(b.chunks(3)).all(|(x, y)| !(x[0] == 255 && y[0] == 255)));
    }
}
