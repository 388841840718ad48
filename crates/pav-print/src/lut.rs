//! A 3D lookup table over the RGB cube with trilinear interpolation, its Jacobian-vector
//! product and its exact adjoint (vector-Jacobian product): the print channel's differentiable
//! primitive. The table is fixed; only its input is differentiated.

/// A table of `channels` values at `n³` nodes spanning [0, 1]³.
#[derive(Clone, Debug, PartialEq)]
pub struct Lut3 {
    /// Nodes per axis (≥ 2).
    pub n: usize,
    /// Values per node.
    pub channels: usize,
    /// Node values, red slowest: `((r·n + g)·n + b)·channels + k`.
    pub values: Vec<f32>,
}

/// Where a point falls: the cell's lower node per axis and the fraction within it.
struct Cell {
    base: [usize; 3],
    frac: [f32; 3],
    /// Whether the input lies inside [0, 1] on that axis (outside, the table is flat).
    inside: [bool; 3],
}

fn cell(n: usize, rgb: &[f32]) -> Cell {
    let s = (n - 1) as f32;
    let mut c = Cell { base: [0; 3], frac: [0.0; 3], inside: [false; 3] };
    for (d, &x) in rgb.iter().take(3).enumerate() {
        c.inside[d] = (0.0..=1.0).contains(&x);
        let t = x.clamp(0.0, 1.0) * s;
        let i = (t.floor() as usize).min(n - 2);
        c.base[d] = i;
        c.frac[d] = t - i as f32;
    }
    c
}

/// The eight corner weights of a cell and their node indices.
fn corners(n: usize, c: &Cell) -> [(f32, usize); 8] {
    std::array::from_fn(|k| {
        let (dr, dg, db) = (k >> 2, (k >> 1) & 1, k & 1);
        let w = |d: usize, bit: usize| if bit == 1 { c.frac[d] } else { 1.0 - c.frac[d] };
        let node = ((c.base[0] + dr) * n + c.base[1] + dg) * n + c.base[2] + db;
        (w(0, dr) * w(1, dg) * w(2, db), node)
    })
}

impl Lut3 {
    /// Samples `f` at the nodes.
    pub fn sample(n: usize, channels: usize, mut f: impl FnMut([f64; 3]) -> Vec<f64>) -> Self {
        assert!(n >= 2, "a LUT needs at least 2 nodes per axis");
        let mut values = Vec::with_capacity(n * n * n * channels);
        let at = |i: usize| i as f64 / (n - 1) as f64;
        for r in 0..n {
            for g in 0..n {
                for b in 0..n {
                    let v = f([at(r), at(g), at(b)]);
                    assert_eq!(v.len(), channels);
                    values.extend(v.iter().map(|x| *x as f32));
                }
            }
        }
        Self { n, channels, values }
    }

    fn cell(&self, rgb: &[f32]) -> Cell {
        cell(self.n, rgb)
    }

    fn node(&self, r: usize, g: usize, b: usize) -> usize {
        ((r * self.n + g) * self.n + b) * self.channels
    }

    /// The eight corner weights and value offsets of a cell.
    fn corners(&self, c: &Cell) -> [(f32, usize); 8] {
        corners(self.n, c).map(|(w, node)| (w, node * self.channels))
    }

    /// The trilinear weights of one point in a table of `n` nodes per axis, and the indices of
    /// their nodes (red slowest), whatever the table holds at them.
    pub fn node_weights(n: usize, rgb: &[f32]) -> [(f32, usize); 8] {
        corners(n, &cell(n, rgb))
    }

    /// The table at one point (inputs outside [0, 1] are clamped), into `out` (`channels` long).
    pub fn eval(&self, rgb: &[f32], out: &mut [f32]) {
        let c = self.cell(rgb);
        out.fill(0.0);
        for (w, at) in self.corners(&c) {
            for (o, v) in out.iter_mut().zip(&self.values[at..at + self.channels]) {
                *o += w * v;
            }
        }
    }

    /// ∂out_k/∂in_d at one point: `jac[d·channels + k]`.
    fn jacobian(&self, rgb: &[f32], jac: &mut [f32]) {
        let c = self.cell(rgb);
        let s = (self.n - 1) as f32;
        jac.fill(0.0);
        for k in 0..8usize {
            let bits = [k >> 2, (k >> 1) & 1, k & 1];
            let at = self.node(c.base[0] + bits[0], c.base[1] + bits[1], c.base[2] + bits[2]);
            let w = |d: usize| if bits[d] == 1 { c.frac[d] } else { 1.0 - c.frac[d] };
            let dw = |d: usize| if bits[d] == 1 { s } else { -s };
            for d in 0..3 {
                if !c.inside[d] {
                    continue;
                }
                let (e, f) = ((d + 1) % 3, (d + 2) % 3);
                let coef = dw(d) * w(e) * w(f);
                for (j, v) in jac[d * self.channels..(d + 1) * self.channels].iter_mut().zip(&self.values[at..]) {
                    *j += coef * v;
                }
            }
        }
    }

    /// The table applied to every RGB triple of `rgb` (interleaved).
    pub fn apply(&self, rgb: &[f32]) -> Vec<f32> {
        let mut out = vec![0f32; rgb.len() / 3 * self.channels];
        for (px, o) in rgb.chunks_exact(3).zip(out.chunks_exact_mut(self.channels)) {
            self.eval(px, o);
        }
        out
    }

    /// Tangent: the change of [`Self::apply`] at `rgb` along `tangent` (both interleaved RGB).
    pub fn jvp(&self, rgb: &[f32], tangent: &[f32]) -> Vec<f32> {
        let mut out = vec![0f32; rgb.len() / 3 * self.channels];
        let mut jac = vec![0f32; 3 * self.channels];
        for ((px, t), o) in rgb.chunks_exact(3).zip(tangent.chunks_exact(3)).zip(out.chunks_exact_mut(self.channels)) {
            self.jacobian(px, &mut jac);
            for (d, td) in t.iter().enumerate() {
                for (ok, j) in o.iter_mut().zip(&jac[d * self.channels..]) {
                    *ok += td * j;
                }
            }
        }
        out
    }

    /// Adjoint: adds `Jᵀ·grad_out` at `rgb` into `grad_in`, for the triples listed in `texels`
    /// (texel indices; all when `None`).
    pub fn vjp(&self, rgb: &[f32], grad_out: &[f32], grad_in: &mut [f32], texels: Option<&[u32]>) {
        let mut jac = vec![0f32; 3 * self.channels];
        let mut one = |i: usize| {
            let g = &grad_out[i * self.channels..(i + 1) * self.channels];
            if g.iter().all(|v| *v == 0.0) {
                return;
            }
            self.jacobian(&rgb[3 * i..3 * i + 3], &mut jac);
            for d in 0..3 {
                grad_in[3 * i + d] +=
                    jac[d * self.channels..(d + 1) * self.channels].iter().zip(g).map(|(j, g)| j * g).sum::<f32>();
            }
        };
        match texels {
            Some(t) => t.iter().for_each(|&i| one(i as usize)),
            None => (0..rgb.len() / 3).for_each(one),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::rng::Rng;

    fn smooth_map(p: [f64; 3]) -> Vec<f64> {
        let [r, g, b] = p;
        vec![(r * 2.0 + g).sin() * 0.5 + 0.5, r * g + b * b, (1.0 - b).powi(3) + 0.1 * r, r + g + b]
    }

    fn points(rng: &mut Rng, n: usize) -> Vec<f32> {
        (0..3 * n).map(|_| rng.uniform(0.02, 0.98)).collect()
    }

    #[test]
    fn nodes_are_reproduced_and_an_affine_map_exactly() {
        let affine = |p: [f64; 3]| vec![0.2 + 0.5 * p[0] - 0.3 * p[2], p[1] * 0.8 + 0.1 * p[0]];
        let lut = Lut3::sample(5, 2, affine);
        let mut rng = Rng::new(3);
        let pts = points(&mut rng, 500);
        let out = lut.apply(&pts);
        for (p, o) in pts.chunks_exact(3).zip(out.chunks_exact(2)) {
            let want = affine([p[0] as f64, p[1] as f64, p[2] as f64]);
            assert!((o[0] as f64 - want[0]).abs() < 1e-5 && (o[1] as f64 - want[1]).abs() < 1e-5);
        }
        let node = [0.25f32, 0.75, 1.0];
        let mut o = [0f32; 2];
        lut.eval(&node, &mut o);
        let want = affine([0.25, 0.75, 1.0]);
        assert!((o[0] as f64 - want[0]).abs() < 1e-6 && (o[1] as f64 - want[1]).abs() < 1e-6);
    }

    #[test]
    fn adjoint_passes_the_dot_product_test() {
        let lut = Lut3::sample(9, 4, smooth_map);
        let mut rng = Rng::new(11);
        let n = 400;
        let x = points(&mut rng, n);
        let v: Vec<f32> = (0..3 * n).map(|_| rng.uniform(-0.5, 0.5)).collect();
        let w: Vec<f32> = (0..4 * n).map(|_| rng.uniform(-0.5, 0.5)).collect();
        let jv = lut.jvp(&x, &v);
        let mut jtw = vec![0f32; 3 * n];
        lut.vjp(&x, &w, &mut jtw, None);
        let lhs: f64 = jv.iter().zip(&w).map(|(a, b)| *a as f64 * *b as f64).sum();
        let rhs: f64 = v.iter().zip(&jtw).map(|(a, b)| *a as f64 * *b as f64).sum();
        assert!((lhs - rhs).abs() <= 1e-5 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
        // Restricted to some texels, the adjoint touches those alone.
        let mut some = vec![0f32; 3 * n];
        lut.vjp(&x, &w, &mut some, Some(&[3, 7]));
        assert!(some.iter().enumerate().all(|(i, g)| [3, 7].contains(&(i / 3)) || *g == 0.0));
        assert_eq!(&some[9..12], &jtw[9..12]);
    }

    #[test]
    fn tangent_matches_central_finite_differences_inside_cells() {
        let lut = Lut3::sample(9, 4, smooth_map);
        let mut rng = Rng::new(5);
        let h = 1e-3f32;
        let mut checked = 0;
        for _ in 0..300 {
            let x = points(&mut rng, 1);
            // Skip points within h of a cell wall, where the piecewise-linear map has a kink.
            if x.iter().any(|v| {
                let t = v * 8.0;
                (t - t.round()).abs() < 2.0 * h * 8.0
            }) {
                continue;
            }
            for d in 0..3 {
                let mut e = [0f32; 3];
                e[d] = 1.0;
                let jv = lut.jvp(&x, &e);
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[d] += h;
                xm[d] -= h;
                let (fp, fm) = (lut.apply(&xp), lut.apply(&xm));
                for k in 0..4 {
                    let fd = (fp[k] - fm[k]) / (2.0 * h);
                    assert!((fd - jv[k]).abs() < 2e-2 * jv[k].abs().max(1.0), "d{d} k{k}: fd {fd} vs {}", jv[k]);
                }
            }
            checked += 1;
        }
        assert!(checked > 100, "only {checked} points away from cell walls");
    }

    #[test]
    fn outside_the_cube_the_table_is_clamped_and_flat() {
        let lut = Lut3::sample(5, 4, smooth_map);
        let x = [1.2f32, -0.1, 0.5];
        let (a, b) = (lut.apply(&x), lut.apply(&[1.0, 0.0, 0.5]));
        assert_eq!(a, b);
        let mut g = vec![0f32; 3];
        lut.vjp(&x, &[1.0; 4], &mut g, None);
        assert_eq!((g[0], g[1]), (0.0, 0.0));
        assert!(g[2] != 0.0);
    }
}
