//! The dual-render mask (paper: "Combination of Two Renderers"): measure the grey ranges of the
//! textured and plain parts in the dark-light render of the two-valued map T_m, pick c_mid,
//! binarize, and composite `I_o = I_d'·P + I_p·(1−P)`.

/// A closed grey range `[min, max]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GreyRange {
    /// Smallest grey value.
    pub min: f32,
    /// Largest grey value.
    pub max: f32,
}

/// Errors computing the mask.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MaskError {
    /// The ranges overlap, so no threshold separates them (the paper's condition fails).
    #[error("grey ranges intersect: textured [{:.4}, {:.4}] and non-textured [{:.4}, {:.4}]; render T_m in dark-light mode or pick C_t and C_n further apart", .textured.min, .textured.max, .plain.min, .plain.max)]
    Intersect {
        /// Textured range.
        textured: GreyRange,
        /// Non-textured range.
        plain: GreyRange,
    },
    /// One of the classes has no pixel in the render.
    #[error("no {0} pixel is visible in the mask render")]
    Empty(&'static str),
}

/// The paper's c_mid: `(c_t_min + c_n_max)/2` if `c_t_min ≥ c_n_max`, `(c_t_max + c_n_min)/2` if
/// `c_t_max < c_n_min`, and an error when the ranges intersect.
pub fn c_mid(textured: GreyRange, plain: GreyRange) -> Result<f32, MaskError> {
    if textured.min >= plain.max {
        Ok((textured.min + plain.max) / 2.0)
    } else if textured.max < plain.min {
        Ok((textured.max + plain.min) / 2.0)
    } else {
        Err(MaskError::Intersect { textured, plain })
    }
}

/// Grey ranges of the pixels labelled textured and plain (`None` = background, ignored).
pub fn measure(grey: &[f32], label: &[Option<bool>]) -> Result<(GreyRange, GreyRange), MaskError> {
    let mut r = [GreyRange { min: f32::INFINITY, max: f32::NEG_INFINITY }; 2];
    for (g, l) in grey.iter().zip(label) {
        if let Some(t) = l {
            let k = *t as usize;
            r[k].min = r[k].min.min(*g);
            r[k].max = r[k].max.max(*g);
        }
    }
    if r[1].min > r[1].max {
        return Err(MaskError::Empty("textured"));
    }
    if r[0].min > r[0].max {
        return Err(MaskError::Empty("non-textured"));
    }
    Ok((r[1], r[0]))
}

/// P: 1 where the grey value is on the textured side of `c_mid`, else 0 (background → 0).
/// When the textured range lies below the plain one, the comparison flips.
pub fn binarize(grey: &[f32], covered: &[bool], c_mid: f32, textured_is_brighter: bool) -> Vec<f32> {
    grey.iter()
        .zip(covered)
        .map(|(&g, &cov)| if cov && ((g >= c_mid) == textured_is_brighter) { 1.0 } else { 0.0 })
        .collect()
}

/// The grey values of the two-valued map T_m: the textured region and the rest.
pub const C_T: f32 = 0.6;
/// Grey value of the non-textured part of T_m.
pub const C_N: f32 = 0.45;

/// The paper's mask for one view: renders T_m (`C_T` on texels where `region` is 1, `C_N`
/// elsewhere) in dark light, measures both grey ranges on the pixels whose bilinear taps all lie
/// on one side of the region border, and binarizes every covered pixel at c_mid. Dark light is
/// ambient 1 with no directional light, so its render is the gathered albedo unchanged.
/// Returns P over `n_pixels` pixels and c_mid.
pub fn dual_render_mask(
    gather: &super::texture::Gather,
    region: &[f32],
    n_pixels: usize,
) -> Result<(Vec<f32>, f32), MaskError> {
    let t_m: Vec<f32> = region.iter().map(|r| if *r > 0.5 { C_T } else { C_N }).collect();
    let mut grey = vec![0f32; n_pixels];
    gather.apply(&t_m, 1, &mut grey);
    let (mut label, mut covered) = (vec![None; n_pixels], vec![false; n_pixels]);
    for (p, taps) in gather.pixels.iter().zip(&gather.taps) {
        covered[*p as usize] = true;
        let mut sides = taps.iter().filter(|t| t.1 > 0.0).map(|t| region[t.0 as usize] > 0.5);
        let first = sides.next().unwrap_or(false);
        if sides.all(|s| s == first) {
            label[*p as usize] = Some(first);
        }
    }
    let (t, n) = measure(&grey, &label)?;
    let mid = c_mid(t, n)?;
    Ok((binarize(&grey, &covered, mid, t.min >= n.max), mid))
}

/// `I_o = I_d·P + I_p·(1−P)`, per pixel over `c` interleaved channels.
pub fn composite(i_d: &[f32], i_p: &[f32], p: &[f32], c: usize) -> Vec<f32> {
    i_d.iter().zip(i_p).enumerate().map(|(i, (d, q))| d * p[i / c] + q * (1.0 - p[i / c])).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn c_mid_follows_the_paper_and_refuses_overlap() {
        let r = |min, max| GreyRange { min, max };
        assert_eq!(c_mid(r(0.8, 0.9), r(0.2, 0.4)), Ok(0.6));
        assert_eq!(c_mid(r(0.1, 0.3), r(0.5, 0.7)), Ok(0.4));
        // Touching ranges with c_t_min == c_n_max take the first branch.
        assert_eq!(c_mid(r(0.5, 0.9), r(0.2, 0.5)), Ok(0.5));
        let e = c_mid(r(0.3, 0.6), r(0.5, 0.9)).unwrap_err();
        assert!(
            e.to_string().contains("intersect: textured [0.3000, 0.6000] and non-textured [0.5000, 0.9000]"),
            "{e}"
        );
    }

    #[test]
    fn dual_render_mask_splits_at_the_region_border() {
        // A 4×1 texture, textured on the right half, sampled at 5 pixels along u.
        let region = [0.0, 0.0, 1.0, 1.0];
        let us = [0.0, 0.25, 0.55, 0.75, 1.0];
        let g = super::super::texture::Gather::new((0..5).map(|i| (i, [us[i as usize], 0.5])), 4, 1);
        let (p, mid) = dual_render_mask(&g, &region, 6).unwrap();
        assert!((mid - (C_T + C_N) / 2.0).abs() < 1e-6);
        // Pixel 2 straddles the border (grey 0.5475 > c_mid 0.525): unlabelled, binarized textured.
        assert_eq!(p, vec![0.0, 0.0, 1.0, 1.0, 1.0, 0.0]);
        let none = super::super::texture::Gather::new((0..2).map(|i| (i, [0.0, 0.5])), 4, 1);
        assert_eq!(dual_render_mask(&none, &region, 2), Err(MaskError::Empty("textured")));
    }

    #[test]
    fn measure_binarize_composite() {
        let grey = [0.9, 0.2, 0.85, 0.0, 0.3];
        let label = [Some(true), Some(false), Some(true), None, Some(false)];
        let (t, n) = measure(&grey, &label).unwrap();
        assert_eq!((t, n), (GreyRange { min: 0.85, max: 0.9 }, GreyRange { min: 0.2, max: 0.3 }));
        let p = binarize(&grey, &[true, true, true, false, true], c_mid(t, n).unwrap(), true);
        assert_eq!(p, vec![1.0, 0.0, 1.0, 0.0, 0.0]);
        let out = composite(&[1.0; 5], &[0.5; 5], &p, 1);
        assert_eq!(out, vec![1.0, 0.5, 1.0, 0.5, 0.5]);
        assert_eq!(measure(&grey, &[None; 5]), Err(MaskError::Empty("textured")));
    }
}
