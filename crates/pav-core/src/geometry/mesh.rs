//! Triangle meshes from Wavefront OBJ (positions, UVs, normals, materials), validated, and the
//! PAV-Camou normalization (centre on the vertex mean, divide by the largest absolute coordinate).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Errors reading a mesh.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// A line is malformed or refers to something that does not exist.
    #[error("{path}:{line}: {msg}")]
    Parse {
        /// File.
        path: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// The mesh as a whole cannot be used.
    #[error("{path}: {msg}")]
    Invalid {
        /// File.
        path: String,
        /// What is wrong.
        msg: String,
    },
}

/// A material group: its name and, if the MTL gives one, its diffuse texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// `usemtl` name.
    pub name: String,
    /// `map_Kd` path, resolved against the MTL's directory.
    pub map_kd: Option<PathBuf>,
}

/// A triangle mesh with per-corner UV and normal indices.
#[derive(Clone, Debug)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Texture coordinates (u, v), v up as in OBJ.
    pub uvs: Vec<[f32; 2]>,
    /// Vertex normals (may be empty).
    pub normals: Vec<[f32; 3]>,
    /// Triangles: position indices.
    pub faces: Vec<[u32; 3]>,
    /// Triangles: UV indices.
    pub face_uvs: Vec<[u32; 3]>,
    /// Triangles: normal indices (empty when the file has none).
    pub face_normals: Vec<[u32; 3]>,
    /// Material index per triangle.
    pub face_material: Vec<u32>,
    /// Materials in order of first use.
    pub materials: Vec<Material>,
}

fn parse_index(tok: &str, len: usize) -> Option<u32> {
    let i: i64 = tok.parse().ok()?;
    // OBJ indices are 1-based; negative ones count back from the end.
    let z = if i > 0 {
        i - 1
    } else if i < 0 {
        len as i64 + i
    } else {
        return None;
    };
    (0..len as i64).contains(&z).then_some(z as u32)
}

fn read_mtl(path: &Path) -> HashMap<String, Option<PathBuf>> {
    let mut out = HashMap::new();
    let Ok(text) = std::fs::read_to_string(path) else {
        return out;
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut cur: Option<String> = None;
    for line in text.lines() {
        let line = line.trim();
        if let Some(n) = line.strip_prefix("newmtl ") {
            cur = Some(n.trim().to_string());
            out.insert(n.trim().to_string(), None);
        } else if let (Some(m), Some(t)) = (cur.as_ref(), line.strip_prefix("map_Kd ")) {
            out.insert(m.clone(), Some(dir.join(t.trim())));
        }
    }
    out
}

impl Mesh {
    /// Reads an OBJ file (and its MTL, when present); polygons are fan-triangulated.
    pub fn load_obj(path: &Path) -> Result<Mesh, MeshError> {
        let text = std::fs::read_to_string(path).map_err(|source| MeshError::Io { path: path.into(), source })?;
        let p = path.display().to_string();
        let perr = |line: usize, msg: String| MeshError::Parse { path: p.clone(), line, msg };
        let mut m = Mesh {
            positions: Vec::new(),
            uvs: Vec::new(),
            normals: Vec::new(),
            faces: Vec::new(),
            face_uvs: Vec::new(),
            face_normals: Vec::new(),
            face_material: Vec::new(),
            materials: Vec::new(),
        };
        let mut mtl: HashMap<String, Option<PathBuf>> = HashMap::new();
        let mut current = 0u32;
        let mut any_normals = true;
        let floats = |it: std::str::SplitWhitespace<'_>, n: usize, line: usize| -> Result<Vec<f32>, MeshError> {
            let v: Vec<f32> = it
                .take(n)
                .map(|t| t.parse::<f32>())
                .collect::<Result<_, _>>()
                .map_err(|e| perr(line, format!("bad number: {e}")))?;
            if v.len() < n {
                return Err(perr(line, format!("expected {n} numbers")));
            }
            if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
                return Err(perr(line, format!("non-finite value {bad}")));
            }
            Ok(v)
        };
        for (i, raw) in text.lines().enumerate() {
            let ln = i + 1;
            let line = raw.split('#').next().unwrap_or("").trim();
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let v = floats(it, 3, ln)?;
                    m.positions.push([v[0], v[1], v[2]]);
                }
                Some("vt") => {
                    let v = floats(it, 2, ln)?;
                    m.uvs.push([v[0], v[1]]);
                }
                Some("vn") => {
                    let v = floats(it, 3, ln)?;
                    m.normals.push([v[0], v[1], v[2]]);
                }
                Some("mtllib") => {
                    let name = line["mtllib".len()..].trim();
                    mtl.extend(read_mtl(&path.parent().unwrap_or(Path::new(".")).join(name)));
                }
                Some("usemtl") => {
                    let name = line["usemtl".len()..].trim().to_string();
                    current = match m.materials.iter().position(|x| x.name == name) {
                        Some(k) => k as u32,
                        None => {
                            m.materials.push(Material { map_kd: mtl.get(&name).cloned().flatten(), name });
                            (m.materials.len() - 1) as u32
                        }
                    };
                }
                Some("f") => {
                    let mut corner = Vec::new();
                    for tok in it {
                        let mut parts = tok.split('/');
                        let v = parts.next().and_then(|t| parse_index(t, m.positions.len()));
                        let t = parts.next().filter(|s| !s.is_empty());
                        let n = parts.next().filter(|s| !s.is_empty());
                        let v = v.ok_or_else(|| {
                            perr(ln, format!("vertex index `{tok}` is out of range ({} positions)", m.positions.len()))
                        })?;
                        let t = t
                            .ok_or_else(|| perr(ln, format!("face corner `{tok}` has no UV index; the mesh needs UVs")))
                            .and_then(|t| {
                                parse_index(t, m.uvs.len()).ok_or_else(|| {
                                    perr(ln, format!("UV index in `{tok}` is out of range ({} UVs)", m.uvs.len()))
                                })
                            })?;
                        let n = match n {
                            Some(n) => Some(
                                parse_index(n, m.normals.len())
                                    .ok_or_else(|| perr(ln, format!("normal index in `{tok}` is out of range")))?,
                            ),
                            None => None,
                        };
                        corner.push((v, t, n));
                    }
                    if corner.len() < 3 {
                        return Err(perr(ln, format!("a face needs 3 corners, found {}", corner.len())));
                    }
                    any_normals &= corner.iter().all(|c| c.2.is_some());
                    for k in 1..corner.len() - 1 {
                        let (a, b, c) = (corner[0], corner[k], corner[k + 1]);
                        m.faces.push([a.0, b.0, c.0]);
                        m.face_uvs.push([a.1, b.1, c.1]);
                        m.face_normals.push([a.2.unwrap_or(0), b.2.unwrap_or(0), c.2.unwrap_or(0)]);
                        m.face_material.push(current);
                    }
                }
                _ => {}
            }
        }
        if !any_normals {
            m.face_normals.clear();
        }
        if m.faces.is_empty() {
            return Err(MeshError::Invalid { path: p, msg: "no faces".into() });
        }
        if m.materials.is_empty() {
            m.materials.push(Material { name: "default".into(), map_kd: None });
        }
        Ok(m)
    }

    /// A single-material mesh whose UV indices equal its position indices (one UV per vertex).
    pub fn from_triangles(positions: Vec<[f32; 3]>, uvs: Vec<[f32; 2]>, faces: Vec<[u32; 3]>) -> Mesh {
        let nf = faces.len();
        Mesh {
            positions,
            uvs,
            normals: Vec::new(),
            face_uvs: faces.clone(),
            faces,
            face_normals: Vec::new(),
            face_material: vec![0; nf],
            materials: vec![Material { name: "default".into(), map_kd: None }],
        }
    }

    /// Writes the mesh as OBJ (positions as stored, UVs, normals, one `usemtl` group per material
    /// run), with `mtllib` pointing at `mtl` when given.
    pub fn write_obj(&self, path: &Path, mtl: Option<&str>) -> std::io::Result<()> {
        use std::io::Write;
        let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(w, "# written by pav")?;
        if let Some(m) = mtl {
            writeln!(w, "mtllib {m}")?;
        }
        for p in &self.positions {
            writeln!(w, "v {} {} {}", p[0], p[1], p[2])?;
        }
        for t in &self.uvs {
            writeln!(w, "vt {} {}", t[0], t[1])?;
        }
        for n in &self.normals {
            writeln!(w, "vn {} {} {}", n[0], n[1], n[2])?;
        }
        let mut current = u32::MAX;
        for f in 0..self.faces.len() {
            if self.face_material[f] != current {
                current = self.face_material[f];
                writeln!(w, "usemtl {}", self.materials[current as usize].name)?;
            }
            let (v, t) = (self.faces[f], self.face_uvs[f]);
            if self.face_normals.is_empty() {
                writeln!(w, "f {}/{} {}/{} {}/{}", v[0] + 1, t[0] + 1, v[1] + 1, t[1] + 1, v[2] + 1, t[2] + 1)?;
            } else {
                let n = self.face_normals[f];
                writeln!(
                    w,
                    "f {}/{}/{} {}/{}/{} {}/{}/{}",
                    v[0] + 1,
                    t[0] + 1,
                    n[0] + 1,
                    v[1] + 1,
                    t[1] + 1,
                    n[1] + 1,
                    v[2] + 1,
                    t[2] + 1,
                    n[2] + 1
                )?;
            }
        }
        w.flush()
    }

    /// Axis-aligned bounding box (min, max) of the positions (±∞ for an empty mesh).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Corner positions of face `f`.
    pub fn face_positions(&self, f: usize) -> [[f32; 3]; 3] {
        self.faces[f].map(|i| self.positions[i as usize])
    }

    /// Edge cross product of face `f`, (p1 − p0) × (p2 − p0): along the winding's normal, its
    /// length twice the face's area (zero for a degenerate face).
    pub fn face_cross(&self, f: usize) -> [f32; 3] {
        let p = self.face_positions(f);
        let e = |a: [f32; 3], b: [f32; 3]| [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        super::vec3::cross(e(p[0], p[1]), e(p[0], p[2]))
    }

    /// Centroid of face `f`.
    pub fn face_centroid(&self, f: usize) -> [f32; 3] {
        let p = self.face_positions(f);
        [0, 1, 2].map(|k| (p[0][k] + p[1][k] + p[2][k]) / 3.0)
    }

    /// Longest side of the bounding box (0 for an empty mesh).
    pub fn largest_side(&self) -> f32 {
        let (lo, hi) = self.bounds();
        (0..3).map(|k| hi[k] - lo[k]).fold(0f32, f32::max)
    }

    /// neural_renderer's `load_obj` normalization (used by FCA and DAS): the bounding box is
    /// centred and its longest side scaled to 2.
    pub fn normalize_bbox(&mut self) {
        let (lo, hi) = self.bounds();
        let side = self.largest_side();
        let s = if side > 0.0 { 2.0 / side } else { 1.0 };
        for p in &mut self.positions {
            for k in 0..3 {
                p[k] = (p[k] - (lo[k] + hi[k]) / 2.0) * s;
            }
        }
    }

    /// Centres on the vertex mean and divides by the largest absolute coordinate (PAV-Camou's
    /// normalization); returns (centre, scale) so it can be undone.
    pub fn normalize(&mut self) -> ([f32; 3], f32) {
        let n = self.positions.len().max(1) as f64;
        let mut c = [0f64; 3];
        for p in &self.positions {
            for k in 0..3 {
                c[k] += p[k] as f64 / n;
            }
        }
        let centre = [c[0] as f32, c[1] as f32, c[2] as f32];
        let mut s = 0f32;
        for p in &mut self.positions {
            for k in 0..3 {
                p[k] -= centre[k];
                s = s.max(p[k].abs());
            }
        }
        let scale = if s > 0.0 { s } else { 1.0 };
        for p in &mut self.positions {
            for v in p.iter_mut() {
                *v /= scale;
            }
        }
        (centre, scale)
    }
}
