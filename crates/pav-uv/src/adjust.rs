//! Automatic UV adjustment of the optimizable patch (what the paper did by hand in MAYA): each
//! UV island is re-flattened by least-squares conformal maps (LSCM), fitted back onto its original
//! island by a similarity transform (so its placement is kept), and all islands are scaled to one
//! common texel density, as large as still fits every island inside its original bounding box.

use pav_core::geometry::linalg::cholesky_solve;
use pav_core::geometry::mesh::Mesh;
use std::collections::{BTreeSet, HashMap};

/// UV islands among `faces`: faces are connected when they share a UV *edge*. Faces touching
/// at a single vertex are separate islands, since a hinge leaves LSCM a free rotation.
pub fn islands(mesh: &Mesh, faces: &[usize]) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..faces.len()).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    let mut by_edge: HashMap<(u32, u32), usize> = HashMap::new();
    for (k, &f) in faces.iter().enumerate() {
        let t = mesh.face_uvs[f];
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            let key = (a.min(b), a.max(b));
            match by_edge.get(&key) {
                Some(&other) => {
                    let (ra, rb) = (find(&mut parent, k), find(&mut parent, other));
                    parent[ra] = rb;
                }
                None => {
                    by_edge.insert(key, k);
                }
            }
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for (k, &f) in faces.iter().enumerate() {
        let r = find(&mut parent, k);
        groups.entry(r).or_default().push(f);
    }
    let mut out: Vec<Vec<usize>> = groups.into_values().collect();
    out.sort();
    out
}

/// Gives `faces` their own copies of UV indices they share with other faces, so moving the
/// patch's UVs never drags the surrounding texture along.
fn detach(mesh: &mut Mesh, faces: &[usize]) {
    let inside: BTreeSet<usize> = faces.iter().copied().collect();
    let outside_uses: BTreeSet<u32> =
        (0..mesh.faces.len()).filter(|f| !inside.contains(f)).flat_map(|f| mesh.face_uvs[f]).collect();
    let mut copy: HashMap<u32, u32> = HashMap::new();
    for &f in faces {
        for c in 0..3 {
            let t = mesh.face_uvs[f][c];
            if outside_uses.contains(&t) {
                let n = *copy.entry(t).or_insert_with(|| {
                    mesh.uvs.push(mesh.uvs[t as usize]);
                    (mesh.uvs.len() - 1) as u32
                });
                mesh.face_uvs[f][c] = n;
            }
        }
    }
}

/// LSCM of one island: new (u, v) per UV index, with the two 3D-farthest vertices pinned at
/// their original UVs. `None` when the system is singular (e.g. a single degenerate face).
pub fn lscm(mesh: &Mesh, island: &[usize]) -> Option<HashMap<u32, [f64; 2]>> {
    // Each triangle keeps the orientation it has in the original UV map: game meshes mix 3D
    // windings, and a conformal map cannot undo a reflection.
    let hand = |f: usize| {
        let t = mesh.face_uvs[f].map(|i| mesh.uvs[i as usize].map(|x| x as f64));
        let s = (t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
        if s < 0.0 {
            -1.0
        } else {
            1.0
        }
    };
    lscm_with(mesh, island, &hand, None)
}

/// LSCM with a given orientation per face (±1: which side of its 3D triangle the flattening is
/// seen from) and, optionally, pins: `None` pins the two 3D-farthest vertices at their current
/// UVs, `Some(d)` pins them at (0, 0) and (d, 0).
pub fn lscm_with(
    mesh: &Mesh,
    island: &[usize],
    hand: &dyn Fn(usize) -> f64,
    pin_span: Option<f64>,
) -> Option<HashMap<u32, [f64; 2]>> {
    let verts: Vec<u32> = island.iter().flat_map(|&f| mesh.face_uvs[f]).collect::<BTreeSet<_>>().into_iter().collect();
    let index: HashMap<u32, usize> = verts.iter().enumerate().map(|(k, &v)| (v, k)).collect();
    // 3D position of each UV index (first corner that uses it).
    let mut pos3 = vec![[0f64; 3]; verts.len()];
    for &f in island {
        for c in 0..3 {
            let p = mesh.positions[mesh.faces[f][c] as usize];
            pos3[index[&mesh.face_uvs[f][c]]] = [p[0] as f64, p[1] as f64, p[2] as f64];
        }
    }
    let (mut pa, mut pb, mut best) = (0, 0, -1.0);
    for i in 0..verts.len() {
        for j in i + 1..verts.len() {
            let d: f64 = (0..3).map(|k| (pos3[i][k] - pos3[j][k]).powi(2)).sum();
            if d > best {
                (pa, pb, best) = (i, j, d);
            }
        }
    }
    if pa == pb {
        return None;
    }
    let n = verts.len();
    // Rows of the real LSCM system over x = [u_0..u_n, v_0..v_n]: two rows per triangle.
    let mut rows: Vec<Vec<(usize, f64)>> = Vec::new();
    for &f in island {
        let p: Vec<[f64; 3]> = (0..3).map(|c| pos3[index[&mesh.face_uvs[f][c]]]).collect();
        let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
        let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
        let l1 = (e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]).sqrt();
        let cr = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
        let dbl = (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
        if l1 == 0.0 || dbl < 1e-14 {
            continue;
        }
        let local = [[0.0, 0.0], [l1, 0.0], [(e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]) / l1, hand(f) * dbl / l1]];
        let s = 1.0 / dbl.sqrt();
        // W_j = (x_{j+2} − x_{j+1}) + i(y_{j+2} − y_{j+1}); conformality: Σ W_j·U_j = 0.
        let (mut re, mut im) = (Vec::new(), Vec::new());
        for j in 0..3 {
            let (a, b) = (local[(j + 2) % 3], local[(j + 1) % 3]);
            let (wr, wi) = ((a[0] - b[0]) * s, (a[1] - b[1]) * s);
            let k = index[&mesh.face_uvs[f][j]];
            // (wr + i wi)(u + i v) = (wr u − wi v) + i(wi u + wr v)
            re.extend([(k, wr), (n + k, -wi)]);
            im.extend([(k, wi), (n + k, wr)]);
        }
        rows.push(re);
        rows.push(im);
    }
    let pinned = [pa, pb, n + pa, n + pb];
    let orig = |k: usize| mesh.uvs[verts[k] as usize];
    let pin_val = match pin_span {
        Some(d) => [0.0, d, 0.0, 0.0],
        None => [orig(pa)[0] as f64, orig(pb)[0] as f64, orig(pa)[1] as f64, orig(pb)[1] as f64],
    };
    let free: Vec<usize> = (0..2 * n).filter(|c| !pinned.contains(c)).collect();
    let col: HashMap<usize, usize> = free.iter().enumerate().map(|(i, &c)| (c, i)).collect();
    let m = free.len();
    let (mut ata, mut atb) = (vec![0.0; m * m], vec![0.0; m]);
    for r in &rows {
        let rhs: f64 =
            -r.iter().filter_map(|(c, w)| pinned.iter().position(|p| p == c).map(|i| w * pin_val[i])).sum::<f64>();
        let fr: Vec<(usize, f64)> = r.iter().filter_map(|(c, w)| col.get(c).map(|&i| (i, *w))).collect();
        for &(i, wi) in &fr {
            atb[i] += wi * rhs;
            for &(j, wj) in &fr {
                ata[i * m + j] += wi * wj;
            }
        }
    }
    let x = cholesky_solve(ata, atb, m)?;
    let mut out = HashMap::new();
    let get = |c: usize| match col.get(&c) {
        Some(&i) => x[i],
        None => pin_val[pinned.iter().position(|p| *p == c).expect("pinned")],
    };
    for (k, v) in verts.iter().enumerate() {
        out.insert(*v, [get(k), get(n + k)]);
    }
    Some(out)
}

/// Least-squares similarity (scale, rotation, translation) taking `from` onto `to`.
fn fit_similarity(from: &[[f64; 2]], to: &[[f64; 2]]) -> impl Fn([f64; 2]) -> [f64; 2] {
    let n = from.len() as f64;
    let mean = |v: &[[f64; 2]]| v.iter().fold([0.0; 2], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    let (mf, mt) = (mean(from), mean(to));
    let (mut a, mut b, mut den) = (0.0, 0.0, 0.0);
    for (p, q) in from.iter().zip(to) {
        let (x, y) = (p[0] - mf[0], p[1] - mf[1]);
        let (u, v) = (q[0] - mt[0], q[1] - mt[1]);
        a += x * u + y * v;
        b += x * v - y * u;
        den += x * x + y * y;
    }
    let (a, b) = if den > 0.0 { (a / den, b / den) } else { (1.0, 0.0) };
    move |p: [f64; 2]| {
        let (x, y) = (p[0] - mf[0], p[1] - mf[1]);
        [mt[0] + a * x - b * y, mt[1] + b * x + a * y]
    }
}

/// Adjusts the UVs of the islands among `faces` in place and returns the common density kept,
/// as an area ratio to the islands' original average (< 1 when an island had to shrink to stay
/// inside its original bounding box). UV indices shared with other faces or other islands get
/// copies first, so nothing outside an island moves with it.
pub fn adjust(mesh: &mut Mesh, faces: &[usize]) -> f64 {
    detach(mesh, faces);
    let isl = islands(mesh, faces);
    // Islands touching at a single (hinge) vertex share its UV index; each must move its own copy.
    let mut owner: HashMap<u32, usize> = HashMap::new();
    for (k, island) in isl.iter().enumerate() {
        let mut copy: HashMap<u32, u32> = HashMap::new();
        for &f in island {
            for c in 0..3 {
                let t = mesh.face_uvs[f][c];
                match owner.get(&t) {
                    Some(&o) if o != k => {
                        let n = *copy.entry(t).or_insert_with(|| {
                            mesh.uvs.push(mesh.uvs[t as usize]);
                            (mesh.uvs.len() - 1) as u32
                        });
                        mesh.face_uvs[f][c] = n;
                        owner.insert(n, k);
                    }
                    Some(_) => {}
                    None => {
                        owner.insert(t, k);
                    }
                }
            }
        }
    }
    let area3 = |m: &Mesh, f: usize| {
        let c = m.face_cross(f);
        (pav_core::geometry::vec3::dot(c, c).sqrt() / 2.0) as f64
    };
    let area_uv = |uv: &HashMap<u32, [f64; 2]>, m: &Mesh, f: usize| {
        let t = m.face_uvs[f].map(|i| uv[&i]);
        ((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1])).abs() / 2.0
    };
    // Re-flatten and fit each island; remember its original bounding box and areas.
    let mut fitted = Vec::new();
    let (mut a3_all, mut auv_all) = (0.0, 0.0);
    for island in &isl {
        let Some(flat) = lscm(mesh, island) else { continue };
        let keys: Vec<u32> = flat.keys().copied().collect();
        let orig: Vec<[f64; 2]> = keys.iter().map(|k| mesh.uvs[*k as usize].map(|x| x as f64)).collect();
        let new: Vec<[f64; 2]> = keys.iter().map(|k| flat[k]).collect();
        let t = fit_similarity(&new, &orig);
        let placed: HashMap<u32, [f64; 2]> = keys.iter().zip(&new).map(|(k, p)| (*k, t(*p))).collect();
        let lo = orig.iter().fold([f64::INFINITY; 2], |a, p| [a[0].min(p[0]), a[1].min(p[1])]);
        let hi = orig.iter().fold([f64::NEG_INFINITY; 2], |a, p| [a[0].max(p[0]), a[1].max(p[1])]);
        let a3: f64 = island.iter().map(|&f| area3(mesh, f)).sum();
        let auv_orig: f64 = island
            .iter()
            .map(|&f| {
                let t = mesh.face_uvs[f].map(|i| mesh.uvs[i as usize].map(|x| x as f64));
                ((t[1][0] - t[0][0]) * (t[2][1] - t[0][1]) - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1])).abs() / 2.0
            })
            .sum();
        let auv_new: f64 = island.iter().map(|&f| area_uv(&placed, mesh, f)).sum();
        a3_all += a3;
        auv_all += auv_orig;
        fitted.push((placed, lo, hi, a3, auv_new));
    }
    // Common density: the original average, reduced until every island fits its original box.
    let target = auv_all / a3_all; // UV area per unit 3D area
    let mut k = 1.0f64;
    for (placed, lo, hi, a3, auv) in &fitted {
        let s = (target * a3 / auv).sqrt(); // linear scale giving the target density
        let c = placed.values().fold([0.0; 2], |a, p| [a[0] + p[0], a[1] + p[1]]).map(|x| x / placed.len() as f64);
        for p in placed.values() {
            for d in 0..2 {
                let off = (p[d] - c[d]) * s;
                if off > 0.0 && c[d] + off > hi[d] {
                    k = k.min((hi[d] - c[d]) / off);
                }
                if off < 0.0 && c[d] + off < lo[d] {
                    k = k.min((lo[d] - c[d]) / off);
                }
            }
        }
    }
    for (placed, _, _, a3, auv) in &fitted {
        let s = (target * a3 / auv).sqrt() * k;
        let c = placed.values().fold([0.0; 2], |a, p| [a[0] + p[0], a[1] + p[1]]).map(|x| x / placed.len() as f64);
        for (i, p) in placed {
            mesh.uvs[*i as usize] = [(c[0] + (p[0] - c[0]) * s) as f32, (c[1] + (p[1] - c[1]) * s) as f32];
        }
    }
    k * k
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat 4×3 grid in the XZ plane with UVs = a scaled, rotated copy of its coordinates.
    fn grid(mirror: bool) -> Mesh {
        let mut positions = Vec::new();
        let mut uvs = Vec::new();
        for j in 0..3 {
            for i in 0..4 {
                let (x, z) = (i as f32 * 0.3, j as f32 * 0.2);
                positions.push([x, 0.0, z]);
                let (u, v) = (0.1 + 0.5 * (0.8 * x - 0.6 * z), 0.2 + 0.5 * (0.6 * x + 0.8 * z));
                uvs.push(if mirror { [1.0 - u, v] } else { [u, v] });
            }
        }
        let mut faces = Vec::new();
        for j in 0..2u32 {
            for i in 0..3u32 {
                let a = j * 4 + i;
                faces.push([a, a + 1, a + 5]);
                faces.push([a, a + 5, a + 4]);
            }
        }
        Mesh::from_triangles(positions, uvs, faces)
    }

    #[test]
    fn lscm_reproduces_an_already_conformal_map() {
        for mirror in [false, true] {
            let m = grid(mirror);
            let all: Vec<usize> = (0..m.faces.len()).collect();
            let out = lscm(&m, &all).unwrap();
            for (i, uv) in &out {
                let o = m.uvs[*i as usize];
                assert!(
                    (uv[0] - o[0] as f64).abs() < 1e-5 && (uv[1] - o[1] as f64).abs() < 1e-5,
                    "mirror {mirror}: {i}: {uv:?} vs {o:?}"
                );
            }
        }
    }
}
