//! The texture as a sum of resolutions: `levels` RGB grids of side n, n/2, n/4, …, each
//! upsampled bilinearly to n and added. Adam moves every parameter by about `lr` per step
//! whatever its gradient's size, so a coarse cell moves a whole patch of texels at once: the
//! optimization is biased towards large structures, which survive a changed texel-to-pixel map
//! (another view, the print, the camera) better than per-texel speckle.
//!
//! With one level the parameters are the texels. With more, the composed texture is kept inside
//! the clamp range and equal to the start outside the optimized region by [`Pyramid::project`],
//! which moves the finest level only.
use pav_core::rng::Rng;
use pav_core::step::{accumulate, Step};

/// The layout of the levels in one parameter vector (finest first, each RGB interleaved).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pyramid {
    /// Side of the finest level (the texture).
    pub size: usize,
    /// Each level's side.
    pub sides: Vec<usize>,
    /// Each level's first value in the parameter vector.
    offsets: Vec<usize>,
}

/// Why a pyramid cannot be built.
#[derive(Debug, thiserror::Error)]
#[error("a {levels}-level pyramid on a {size}² texture: {why}")]
pub struct PyramidError {
    /// Levels asked for.
    pub levels: usize,
    /// Texture side.
    pub size: usize,
    /// What is wrong.
    pub why: &'static str,
}

/// Source coordinate and weights of output index `o` for a bilinear upsampling by `f`
/// (half-pixel centres, edges clamped, as `align_corners = false`).
fn taps(o: usize, f: usize, src: usize) -> (usize, usize, f32) {
    let x = (o as f32 + 0.5) / f as f32 - 0.5;
    let x = x.max(0.0);
    let i0 = (x.floor() as usize).min(src - 1);
    let i1 = (i0 + 1).min(src - 1);
    (i0, i1, x - i0 as f32)
}

/// Bilinear upsampling of an RGB grid of side `s` by `f`, added into `out` (side s·f).
fn upsample_add(src: &[f32], s: usize, f: usize, out: &mut [f32]) {
    let n = s * f;
    for y in 0..n {
        let (y0, y1, wy) = taps(y, f, s);
        for x in 0..n {
            let (x0, x1, wx) = taps(x, f, s);
            for c in 0..3 {
                let at = |yy: usize, xx: usize| src[(yy * s + xx) * 3 + c];
                let top = at(y0, x0) * (1.0 - wx) + at(y0, x1) * wx;
                let bot = at(y1, x0) * (1.0 - wx) + at(y1, x1) * wx;
                out[(y * n + x) * 3 + c] += top * (1.0 - wy) + bot * wy;
            }
        }
    }
}

/// The adjoint of [`upsample_add`]: the gradient of a side-s·f grid pulled back to side s.
fn upsample_adjoint(g: &[f32], s: usize, f: usize, out: &mut [f32]) {
    let n = s * f;
    for y in 0..n {
        let (y0, y1, wy) = taps(y, f, s);
        for x in 0..n {
            let (x0, x1, wx) = taps(x, f, s);
            for c in 0..3 {
                let v = g[(y * n + x) * 3 + c];
                out[(y0 * s + x0) * 3 + c] += v * (1.0 - wy) * (1.0 - wx);
                out[(y0 * s + x1) * 3 + c] += v * (1.0 - wy) * wx;
                out[(y1 * s + x0) * 3 + c] += v * wy * (1.0 - wx);
                out[(y1 * s + x1) * 3 + c] += v * wy * wx;
            }
        }
    }
}

impl Pyramid {
    /// `levels` resolutions of a `size`² texture; `size` must halve evenly `levels − 1` times.
    pub fn new(size: usize, levels: usize) -> Result<Pyramid, PyramidError> {
        let err = |why| PyramidError { levels, size, why };
        if levels == 0 {
            return Err(err("needs at least one level"));
        }
        if levels > 1 && (size % (1 << (levels - 1)) != 0 || size >> (levels - 1) < 2) {
            return Err(err("the side must halve evenly to a coarsest level of 2 or more"));
        }
        let sides: Vec<usize> = (0..levels).map(|l| size >> l).collect();
        let mut offsets = Vec::with_capacity(levels);
        let mut at = 0;
        for s in &sides {
            offsets.push(at);
            at += s * s * 3;
        }
        Ok(Pyramid { size, sides, offsets })
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.offsets.last().unwrap() + self.sides.last().map_or(0, |s| s * s * 3)
    }

    /// Whether there are no parameters (never, for a built pyramid).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn level<'a>(&self, p: &'a [f32], l: usize) -> &'a [f32] {
        let s = self.sides[l];
        &p[self.offsets[l]..self.offsets[l] + s * s * 3]
    }

    /// Parameters whose composition is `texture`: all of it in the finest level.
    pub fn from_texture(&self, texture: &[f32]) -> Vec<f32> {
        let mut p = vec![0.0; self.len()];
        p[..texture.len()].copy_from_slice(texture);
        p
    }

    /// The texture: the sum of every level upsampled to the finest.
    pub fn compose(&self, p: &[f32]) -> Vec<f32> {
        let mut t = self.level(p, 0).to_vec();
        for l in 1..self.sides.len() {
            upsample_add(self.level(p, l), self.sides[l], 1 << l, &mut t);
        }
        t
    }

    /// ∂L/∂parameters from ∂L/∂texture.
    pub fn pullback(&self, g: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0; self.len()];
        out[..g.len()].copy_from_slice(g);
        for l in 1..self.sides.len() {
            let (o, s) = (self.offsets[l], self.sides[l]);
            upsample_adjoint(g, s, 1 << l, &mut out[o..o + s * s * 3]);
        }
        out
    }

    /// The parameters that move some texel of `texels` (indices into the texture's values).
    pub fn active(&self, texels: &[u32]) -> Vec<u32> {
        let mut mask = vec![0.0f32; self.size * self.size * 3];
        texels.iter().for_each(|&i| mask[i as usize] = 1.0);
        let reach = self.pullback(&mask);
        (0..reach.len() as u32).filter(|&i| reach[i as usize] > 0.0).collect()
    }

    /// Moves the finest level so that the composed texture lies in `[lo, hi]` on `texels` and
    /// equals `start` everywhere else (the coarse levels also reach texels outside the region).
    pub fn project(&self, p: &mut [f32], texels: &[u32], start: &[f32], (lo, hi): (f32, f32)) {
        let t = self.compose(p);
        let n = t.len();
        let mut target = start.to_vec();
        for &i in texels {
            target[i as usize] = t[i as usize].clamp(lo, hi);
        }
        for i in 0..n {
            p[i] += target[i] - t[i];
        }
    }
}

/// The composition as a step from the parameters to the texture.
impl Step for Pyramid {
    type Tape = ();
    type Error = std::convert::Infallible;

    fn input_len(&self) -> usize {
        self.len()
    }

    fn output_len(&self) -> usize {
        self.size * self.size * 3
    }

    fn forward(&self, x: &[f32], _: &mut Rng) -> Result<(Vec<f32>, ()), Self::Error> {
        Ok((self.compose(x), ()))
    }

    fn adjoint(&self, _: &(), gy: &[f32], gx: &mut [f32]) {
        accumulate(gx, self.pullback(gy));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pav_core::rng::Rng;

    fn noise(n: usize, seed: u64) -> Vec<f32> {
        let mut r = Rng::new(seed);
        (0..n).map(|_| r.uniform(-0.5, 0.5)).collect()
    }

    #[test]
    fn pullback_is_the_exact_adjoint_of_compose() {
        // ⟨compose(p), g⟩ = ⟨p, pullback(g)⟩ for random p and g: the gradient is exact.
        let py = Pyramid::new(32, 4).unwrap();
        let (p, g) = (noise(py.len(), 1), noise(32 * 32 * 3, 2));
        let lhs: f64 = py.compose(&p).iter().zip(&g).map(|(a, b)| (a * b) as f64).sum();
        let rhs: f64 = p.iter().zip(py.pullback(&g)).map(|(a, b)| (a * b) as f64).sum();
        assert!((lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0), "{lhs} vs {rhs}");
    }

    #[test]
    fn a_constant_coarse_level_shifts_every_texel_and_one_level_is_the_texture() {
        let py = Pyramid::new(16, 3).unwrap();
        let mut p = vec![0.0; py.len()];
        let o = py.offsets[2];
        p[o..].iter_mut().for_each(|v| *v = 0.25);
        assert!(py.compose(&p).iter().all(|&v| (v - 0.25).abs() < 1e-6));
        let one = Pyramid::new(16, 1).unwrap();
        let t = noise(16 * 16 * 3, 3);
        assert_eq!(one.compose(&one.from_texture(&t)), t);
        assert_eq!(one.pullback(&t), t);
        assert!(Pyramid::new(20, 4).is_err() && Pyramid::new(16, 0).is_err() && Pyramid::new(8, 3).is_ok());
    }

    #[test]
    fn projection_clamps_the_region_and_restores_the_rest() {
        let py = Pyramid::new(16, 3).unwrap();
        let start = vec![0.5; 16 * 16 * 3];
        let region: Vec<u32> = (0..16 * 8 * 3).collect(); // the top half
        let mut p = py.from_texture(&start);
        // A coarse push far out of range, as Adam's steps can make.
        let o = py.offsets[2];
        p[o..].iter_mut().for_each(|v| *v = 2.0);
        py.project(&mut p, &region, &start, (0.0, 1.0));
        let t = py.compose(&p);
        assert!(t[..16 * 8 * 3].iter().all(|&v| (v - 1.0).abs() < 1e-5), "region clamped");
        assert!(t[16 * 8 * 3..].iter().all(|&v| (v - 0.5).abs() < 1e-5), "outside restored");
        // Every coarse cell reaches the region except none: the active set covers the region.
        let act = py.active(&region);
        assert!(region.iter().all(|i| act.contains(i)));
        assert!(!act.contains(&(16 * 16 * 3 - 1)), "a finest texel outside the region is not active");
        assert!(act.contains(&(o as u32)), "the coarsest cell over the region is");
    }
}
