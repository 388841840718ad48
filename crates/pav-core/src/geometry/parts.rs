//! Car parts picked by geometry (which way a face looks, where it sits along the car), so a
//! partial camouflage region like PAV-Camou's half.png (doors, hood, roof, trunk) can be stated
//! for any UV-mapped car instead of painted by hand.

use super::mesh::Mesh;
use std::fmt;

/// Which way the selected faces look.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Facing {
    /// Normal along the up axis, face above mid-height: hood, roof, trunk lid.
    Top,
    /// Normal across the car: doors, fenders, sills.
    Side,
    /// Normal along the car: front and rear faces.
    End,
}

/// One part: a facing, optionally limited to a stretch of the car's length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Part {
    /// Which way the faces look.
    pub facing: Facing,
    /// Fractions of the length, 0 at the low end of the length axis, 1 at the high end.
    pub span: [f32; 2],
}

/// A part string that does not parse.
#[derive(Debug, thiserror::Error)]
#[error("part {0:?}: expected top|side|end, optionally with a length span like side:0.2-0.8 (fractions, low < high)")]
pub struct PartError(pub String);

impl std::str::FromStr for Part {
    type Err = PartError;
    fn from_str(s: &str) -> Result<Part, PartError> {
        let bad = || PartError(s.to_string());
        let (name, span) = match s.split_once(':') {
            Some((n, sp)) => {
                let (a, b) = sp.split_once('-').ok_or_else(bad)?;
                let (a, b): (f32, f32) = (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
                if !(0.0..=1.0).contains(&a) || !(0.0..=1.0).contains(&b) || a >= b {
                    return Err(bad());
                }
                (n, [a, b])
            }
            None => (s, [0.0, 1.0]),
        };
        let facing = match name.trim() {
            "top" => Facing::Top,
            "side" => Facing::Side,
            "end" => Facing::End,
            _ => return Err(bad()),
        };
        Ok(Part { facing, span })
    }
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = match self.facing {
            Facing::Top => "top",
            Facing::Side => "side",
            Facing::End => "end",
        };
        write!(f, "{n}:{}-{}", self.span[0], self.span[1])
    }
}

/// A signed mesh axis, written `+x`, `-z`, …: which way the car's front or up points in the
/// mesh's coordinates (a mesh file says neither).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize, schemars::JsonSchema)]
#[serde(try_from = "String", into = "String")]
pub struct Axis {
    /// 0, 1 or 2 for x, y, z.
    pub index: usize,
    /// Points along +index (else −index).
    pub positive: bool,
}

impl Axis {
    /// The unit vector.
    pub fn vector(self) -> [f32; 3] {
        let mut v = [0.0; 3];
        v[self.index] = if self.positive { 1.0 } else { -1.0 };
        v
    }
}

impl From<Axis> for String {
    fn from(a: Axis) -> String {
        a.to_string()
    }
}

impl TryFrom<String> for Axis {
    type Error = String;
    fn try_from(s: String) -> Result<Axis, String> {
        s.parse()
    }
}

impl std::str::FromStr for Axis {
    type Err = String;
    fn from_str(s: &str) -> Result<Axis, String> {
        let t = s.trim().to_ascii_lowercase();
        let (positive, name) = match t.as_bytes().first() {
            Some(b'+') => (true, &t[1..]),
            Some(b'-') => (false, &t[1..]),
            _ => (true, t.as_str()),
        };
        let index = ["x", "y", "z"]
            .iter()
            .position(|a| *a == name)
            .ok_or_else(|| format!("`{s}` is no mesh axis: write +x, -x, +y, -y, +z or -z"))?;
        Ok(Axis { index, positive })
    }
}

impl fmt::Display for Axis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}{}", if self.positive { '+' } else { '-' }, ["x", "y", "z"][self.index])
    }
}

/// The panel of the car a surface lies on, from which way it looks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Panel {
    /// Looks up: hood, roof, trunk lid.
    Top,
    /// Looks down: the floor.
    Bottom,
    /// Looks to the driver's left.
    LeftSide,
    /// Looks to the driver's right.
    RightSide,
    /// Looks forward.
    FrontEnd,
    /// Looks back.
    RearEnd,
}

impl Panel {
    /// The panel an outward normal `n` looks at, for a car whose front and up are `front`
    /// and `up` (left is up × front, as for a driver facing front).
    pub fn facing(n: [f32; 3], front: Axis, up: Axis) -> Panel {
        let (f, u) = (front.vector(), up.vector());
        let l = super::vec3::cross(u, f);
        let dot = |a: [f32; 3]| a[0] * n[0] + a[1] * n[1] + a[2] * n[2];
        let (df, du, dl) = (dot(f), dot(u), dot(l));
        if du.abs() >= df.abs() && du.abs() >= dl.abs() {
            if du >= 0.0 {
                Panel::Top
            } else {
                Panel::Bottom
            }
        } else if dl.abs() >= df.abs() {
            if dl >= 0.0 {
                Panel::LeftSide
            } else {
                Panel::RightSide
            }
        } else if df >= 0.0 {
            Panel::FrontEnd
        } else {
            Panel::RearEnd
        }
    }
}

impl fmt::Display for Panel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Panel::Top => "top",
            Panel::Bottom => "bottom",
            Panel::LeftSide => "left side",
            Panel::RightSide => "right side",
            Panel::FrontEnd => "front end",
            Panel::RearEnd => "rear end",
        })
    }
}

/// Faces belonging to any of `parts`. `up` is the mesh's up axis (0, 1 or 2); the length axis is
/// the longer of the other two. A face "looks" along an axis when |cos| between its geometric
/// normal and that axis is at least `min_cos`; face winding is not trusted, hence |cos| and the
/// mid-height test for `top`.
pub fn select_faces(mesh: &Mesh, up: usize, parts: &[Part], min_cos: f32) -> Vec<usize> {
    let (lo, hi) = mesh.bounds();
    let others: Vec<usize> = (0..3).filter(|&k| k != up).collect();
    let (len_ax, lat_ax) = if hi[others[0]] - lo[others[0]] >= hi[others[1]] - lo[others[1]] {
        (others[0], others[1])
    } else {
        (others[1], others[0])
    };
    let mid_h = (lo[up] + hi[up]) / 2.0;
    let length = (hi[len_ax] - lo[len_ax]).max(f32::MIN_POSITIVE);
    (0..mesh.faces.len())
        .filter(|&f| {
            let n = mesh.face_cross(f);
            let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if !(norm > 0.0 && norm.is_finite()) {
                return false;
            }
            let c = mesh.face_centroid(f);
            let t = (c[len_ax] - lo[len_ax]) / length;
            parts.iter().any(|part| {
                let axis = match part.facing {
                    Facing::Top => up,
                    Facing::Side => lat_ax,
                    Facing::End => len_ax,
                };
                (n[axis] / norm).abs() >= min_cos
                    && (part.facing != Facing::Top || c[up] > mid_h)
                    && t >= part.span[0]
                    && t <= part.span[1]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_parse_and_name_the_panels_a_normal_looks_at() {
        let (front, up): (Axis, Axis) = ("+x".parse().unwrap(), "z".parse().unwrap());
        assert_eq!((front.to_string(), up.to_string()), ("+x".into(), "+z".into()));
        assert!("w".parse::<Axis>().unwrap_err().contains("+x, -x"));
        // Facing +x with +z up, the driver's left is +y.
        assert_eq!(Panel::facing([0.0, 1.0, 0.1], front, up), Panel::LeftSide);
        assert_eq!(Panel::facing([0.0, -1.0, 0.1], front, up), Panel::RightSide);
        assert_eq!(Panel::facing([0.9, 0.1, 0.3], front, up), Panel::FrontEnd);
        assert_eq!(Panel::facing([-0.9, 0.1, 0.3], front, up), Panel::RearEnd);
        assert_eq!(Panel::facing([0.3, 0.1, 0.9], front, up), Panel::Top);
        // The Impala's frame: front −z, up +y: its left is +y × −z = −x.
        let (front, up): (Axis, Axis) = ("-z".parse().unwrap(), "+y".parse().unwrap());
        assert_eq!(Panel::facing([-1.0, 0.0, 0.0], front, up), Panel::LeftSide);
    }

    /// A 4 × 1 × 2 box (length x, width y, height z) with 12 outward triangles.
    fn box_mesh() -> Mesh {
        let mut pos = Vec::new();
        for i in 0..8 {
            pos.push([
                if i & 1 == 0 { 0.0 } else { 4.0 },
                if i & 2 == 0 { 0.0 } else { 1.0 },
                if i & 4 == 0 { 0.0 } else { 2.0 },
            ]);
        }
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let faces: Vec<[u32; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        let uvs = vec![[0.5, 0.5]; 8];
        Mesh::from_triangles(pos, uvs, faces)
    }

    #[test]
    fn parts_parse_and_reject() {
        let p: Part = "side:0.2-0.8".parse().unwrap();
        assert_eq!(p, Part { facing: Facing::Side, span: [0.2, 0.8] });
        assert_eq!("top".parse::<Part>().unwrap().span, [0.0, 1.0]);
        for bad in ["roof", "side:0.8-0.2", "side:0.2", "side:-1-0.5", "top:a-b"] {
            assert!(bad.parse::<Part>().is_err(), "{bad}");
        }
    }

    #[test]
    fn box_faces_fall_into_the_right_parts() {
        let m = box_mesh();
        // z up: the top is quad 1 (z = 2), the sides quads 2 and 3 (y = 0, 1), the ends 4 and 5.
        assert_eq!(select_faces(&m, 2, &["top".parse().unwrap()], 0.7), vec![2, 3]);
        assert_eq!(select_faces(&m, 2, &["side".parse().unwrap()], 0.7), vec![4, 5, 6, 7]);
        assert_eq!(select_faces(&m, 2, &["end".parse().unwrap()], 0.7), vec![8, 9, 10, 11]);
        // The bottom is never "top", whichever way it is wound.
        let mut flipped = box_mesh();
        flipped.faces[0].swap(1, 2);
        assert!(!select_faces(&flipped, 2, &["top".parse().unwrap()], 0.7).contains(&0));
        // A span keeps only faces whose centroid lies in that stretch of the length.
        let m2 = box_mesh();
        assert!(select_faces(&m2, 2, &["end:0.0-0.4".parse().unwrap()], 0.7) == vec![8, 9]);
    }
}
