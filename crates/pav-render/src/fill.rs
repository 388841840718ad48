//! Push-pull hole filling: unknown samples of an image take the weighted mean of the known
//! samples around them, from the finest pyramid level where any are known. Linear in the image
//! size, with no iteration count to tune, so it fills a car-sized hole in a photo or the unused
//! texels of an atlas alike.

/// Fills the samples of `values` (`w × h`, `c` interleaved channels) whose `weight` is 0 from
/// their known neighbourhood; known samples are left as they are. Nothing changes when no
/// sample is known.
pub fn push_pull(values: &mut [f32], weight: &[f32], w: usize, h: usize, c: usize) {
    assert_eq!(values.len(), w * h * c, "values must hold w × h × c samples");
    assert_eq!(weight.len(), w * h, "one weight per pixel");
    if w == 0 || h == 0 || weight.iter().all(|x| *x <= 0.0) {
        return;
    }
    // Level 0: weighted values. Each coarser level sums 2×2 blocks (push).
    let mut levels: Vec<(usize, usize, Vec<f32>, Vec<f32>)> = Vec::new();
    // Unknown samples may hold anything, NaN included: they never enter a sum.
    let wv: Vec<f32> =
        values.iter().enumerate().map(|(i, v)| if weight[i / c] > 0.0 { v * weight[i / c] } else { 0.0 }).collect();
    levels.push((w, h, wv, weight.iter().map(|x| x.max(0.0)).collect()));
    while levels.last().is_some_and(|l| l.0 > 1 || l.1 > 1) {
        let (lw, lh, lv, lwt) = levels.last().expect("at least one level");
        let (nw, nh) = (lw.div_ceil(2), lh.div_ceil(2));
        let (mut nv, mut nwt) = (vec![0f32; nw * nh * c], vec![0f32; nw * nh]);
        for y in 0..*lh {
            for x in 0..*lw {
                let (i, j) = (y * lw + x, (y / 2) * nw + x / 2);
                nwt[j] += lwt[i];
                for k in 0..c {
                    nv[j * c + k] += lv[i * c + k];
                }
            }
        }
        levels.push((nw, nh, nv, nwt));
    }
    // Pull: from the coarsest level down, a sample with too little weight of its own is blended
    // with its parent's mean; the parent already holds the means of its own neighbourhood.
    // The parent is read bilinearly (a nearest read leaves the coarse levels' blocks visible).
    let mut parent: Vec<f32> = Vec::new();
    for li in (0..levels.len()).rev() {
        let (lw, lh, lv, lwt) = &levels[li];
        let (pw, ph) = (lw.div_ceil(2), lh.div_ceil(2));
        let mut mean = vec![0f32; lw * lh * c];
        let mut up = vec![0f32; c];
        for i in 0..lw * lh {
            let own = lwt[i].min(1.0);
            let (x, y) = (i % lw, i / lw);
            if !parent.is_empty() && own < 1.0 {
                let fx = ((x as f32 + 0.5) / 2.0 - 0.5).clamp(0.0, (pw - 1) as f32);
                let fy = ((y as f32 + 0.5) / 2.0 - 0.5).clamp(0.0, (ph - 1) as f32);
                let (x0, y0) = (fx as usize, fy as usize);
                let (x1, y1) = ((x0 + 1).min(pw - 1), (y0 + 1).min(ph - 1));
                let (ax, ay) = (fx - x0 as f32, fy - y0 as f32);
                for (k, u) in up.iter_mut().enumerate() {
                    let at = |xx: usize, yy: usize| parent[(yy * pw + xx) * c + k];
                    *u = (1.0 - ay) * ((1.0 - ax) * at(x0, y0) + ax * at(x1, y0))
                        + ay * ((1.0 - ax) * at(x0, y1) + ax * at(x1, y1));
                }
            }
            for k in 0..c {
                let m = if lwt[i] > 0.0 { lv[i * c + k] / lwt[i] } else { 0.0 };
                let p = if parent.is_empty() { m } else { up[k] };
                mean[i * c + k] = own * m + (1.0 - own) * p;
            }
        }
        parent = mean;
    }
    for (i, v) in values.iter_mut().enumerate() {
        if weight[i / c] <= 0.0 {
            *v = parent[i];
        }
    }
}

/// Grows a `w × h` mask by `r` pixels (a `(2r+1)²` square), in two separable passes.
pub fn grow(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    let pass = |m: &[bool], along_x: bool| -> Vec<bool> {
        let mut out = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let (c, n) = if along_x { (x, w) } else { (y, h) };
                let (a, b) = (c.saturating_sub(r), (c + r).min(n - 1));
                out[y * w + x] = (a..=b).any(|t| if along_x { m[y * w + t] } else { m[t * w + x] });
            }
        }
        out
    };
    pass(&pass(mask, true), false)
}

/// Shrinks a mask by `r` pixels: the complement of the grown complement.
pub fn shrink(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    let not: Vec<bool> = mask.iter().map(|m| !m).collect();
    grow(&not, w, h, r).into_iter().map(|m| !m).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hole_in_a_linear_ramp_is_filled_between_its_edges() {
        let (w, h) = (37, 23);
        let truth: Vec<f32> = (0..w * h).map(|i| (i % w) as f32 / (w - 1) as f32).collect();
        let mut v = truth.clone();
        let mut wt = vec![1f32; w * h];
        for y in 8..15 {
            for x in 10..20 {
                v[y * w + x] = f32::NAN;
                wt[y * w + x] = 0.0;
            }
        }
        push_pull(&mut v, &wt, w, h, 1);
        for i in 0..w * h {
            assert!(v[i].is_finite(), "pixel {i} left unfilled");
            if wt[i] > 0.0 {
                assert_eq!(v[i], truth[i], "known samples never change");
            } else {
                // The fill comes from the hole's surroundings, not from far across the image.
                assert!((6.0 / 36.0..=23.0 / 36.0).contains(&v[i]), "pixel {i}: {}", v[i]);
            }
        }
        let left = v[11 * w + 10];
        let right = v[11 * w + 19];
        assert!(left < right, "the fill keeps the ramp's direction: {left} vs {right}");
    }

    #[test]
    fn one_known_sample_fills_everything_and_none_changes_nothing() {
        let (w, h) = (5, 4);
        let mut v = vec![0f32; w * h * 3];
        let mut wt = vec![0f32; w * h];
        v[7 * 3..7 * 3 + 3].copy_from_slice(&[0.2, 0.4, 0.6]);
        let untouched = v.clone();
        push_pull(&mut v, &wt, w, h, 3);
        assert_eq!(v, untouched);
        wt[7] = 1.0;
        push_pull(&mut v, &wt, w, h, 3);
        for px in v.chunks(3) {
            assert!((px[0] - 0.2).abs() < 1e-6 && (px[1] - 0.4).abs() < 1e-6 && (px[2] - 0.6).abs() < 1e-6);
        }
    }

    #[test]
    fn grow_and_shrink_move_a_square_edge_by_r() {
        let (w, h) = (20, 20);
        let sq: Vec<bool> = (0..w * h).map(|i| (5..15).contains(&(i % w)) && (5..15).contains(&(i / w))).collect();
        let count = |m: &[bool]| m.iter().filter(|x| **x).count();
        assert_eq!(count(&grow(&sq, w, h, 2)), 14 * 14);
        assert_eq!(count(&shrink(&sq, w, h, 2)), 6 * 6);
        assert!(grow(&sq, w, h, 2)[3 * w + 3] && !grow(&sq, w, h, 2)[2 * w + 2]);
    }
}
