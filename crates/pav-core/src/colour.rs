//! Colour science for the print channel: sRGB ↔ XYZ ↔ CIELAB, chromatic adaptation between D65
//! and D50, and the CIEDE2000 colour difference. Values are `f64` triples; sRGB is encoded
//! (gamma) in [0, 1].

/// D65 white (sRGB's), XYZ with Y = 1.
pub const D65: [f64; 3] = [0.950_47, 1.0, 1.088_83];
/// D50 white (ICC's profile connection space), XYZ with Y = 1.
pub const D50: [f64; 3] = [0.964_22, 1.0, 0.825_21];

/// sRGB's transfer function: encoded → linear.
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.040_45 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB's transfer function: linear → encoded.
pub fn linear_to_srgb(v: f64) -> f64 {
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [0.412_456_4, 0.357_576_1, 0.180_437_5],
    [0.212_672_9, 0.715_152_2, 0.072_175_0],
    [0.019_333_9, 0.119_192_0, 0.950_304_1],
];
const XYZ_TO_RGB: [[f64; 3]; 3] = [
    [3.240_454_2, -1.537_138_5, -0.498_531_4],
    [-0.969_266_0, 1.876_010_8, 0.041_556_0],
    [0.055_643_4, -0.204_025_9, 1.057_225_2],
];
/// Bradford adaptation D65 → D50 and back (Lindbloom's matrices).
const D65_TO_D50: [[f64; 3]; 3] = [
    [1.047_811_2, 0.022_886_6, -0.050_127_0],
    [0.029_542_4, 0.990_484_5, -0.017_049_1],
    [-0.009_234_5, 0.015_043_6, 0.752_131_6],
];
const D50_TO_D65: [[f64; 3]; 3] = [
    [0.955_576_6, -0.023_039_3, 0.063_163_6],
    [-0.028_289_5, 1.009_941_6, 0.021_007_7],
    [0.012_298_2, -0.020_483_0, 1.329_909_8],
];

fn mul(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// Encoded sRGB → XYZ (D65).
pub fn srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    mul(&RGB_TO_XYZ, rgb.map(srgb_to_linear))
}

/// XYZ (D65) → encoded sRGB, unclipped.
pub fn xyz_to_srgb(xyz: [f64; 3]) -> [f64; 3] {
    mul(&XYZ_TO_RGB, xyz).map(|v| if v < 0.0 { -linear_to_srgb(-v) } else { linear_to_srgb(v) })
}

/// XYZ under D65 → the same colour's XYZ under D50 (Bradford).
pub fn d65_to_d50(xyz: [f64; 3]) -> [f64; 3] {
    mul(&D65_TO_D50, xyz)
}

/// XYZ under D50 → XYZ under D65 (Bradford).
pub fn d50_to_d65(xyz: [f64; 3]) -> [f64; 3] {
    mul(&D50_TO_D65, xyz)
}

/// XYZ → CIELAB relative to `white`.
pub fn xyz_to_lab(xyz: [f64; 3], white: [f64; 3]) -> [f64; 3] {
    let f = |t: f64| if t > 216.0 / 24389.0 { t.cbrt() } else { (24389.0 / 27.0 * t + 16.0) / 116.0 };
    let [fx, fy, fz] = [f(xyz[0] / white[0]), f(xyz[1] / white[1]), f(xyz[2] / white[2])];
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIELAB relative to `white` → XYZ.
pub fn lab_to_xyz(lab: [f64; 3], white: [f64; 3]) -> [f64; 3] {
    let fy = (lab[0] + 16.0) / 116.0;
    let (fx, fz) = (fy + lab[1] / 500.0, fy - lab[2] / 200.0);
    let finv = |f: f64| if f.powi(3) > 216.0 / 24389.0 { f.powi(3) } else { (116.0 * f - 16.0) * 27.0 / 24389.0 };
    [finv(fx) * white[0], finv(fy) * white[1], finv(fz) * white[2]]
}

/// Encoded sRGB → CIELAB (D65 white, as colour-science's default).
pub fn srgb_to_lab(rgb: [f64; 3]) -> [f64; 3] {
    xyz_to_lab(srgb_to_xyz(rgb), D65)
}

/// CIELAB (D65 white) → encoded sRGB, unclipped.
pub fn lab_to_srgb(lab: [f64; 3]) -> [f64; 3] {
    xyz_to_srgb(lab_to_xyz(lab, D65))
}

/// CIELAB under D50 (ICC, chart reference values) → encoded sRGB, adapted to D65, unclipped.
pub fn lab_d50_to_srgb(lab: [f64; 3]) -> [f64; 3] {
    xyz_to_srgb(d50_to_d65(lab_to_xyz(lab, D50)))
}

/// Encoded sRGB → CIELAB under D50 (adapted from D65).
pub fn srgb_to_lab_d50(rgb: [f64; 3]) -> [f64; 3] {
    xyz_to_lab(d65_to_d50(srgb_to_xyz(rgb)), D50)
}

/// CIEDE2000 colour difference between two CIELAB colours (kL = kC = kH = 1).
pub fn delta_e2000(a: [f64; 3], b: [f64; 3]) -> f64 {
    let [l1, a1, b1] = a;
    let [l2, a2, b2] = b;
    let c_bar = 0.5 * (a1.hypot(b1) + a2.hypot(b2));
    let c7 = c_bar.powi(7);
    let g = 0.5 * (1.0 - (c7 / (c7 + 25f64.powi(7))).sqrt());
    let (a1p, a2p) = ((1.0 + g) * a1, (1.0 + g) * a2);
    let (c1p, c2p) = (a1p.hypot(b1), a2p.hypot(b2));
    let hue = |b: f64, a: f64| {
        if a == 0.0 && b == 0.0 {
            0.0
        } else {
            let h = b.atan2(a).to_degrees();
            if h < 0.0 {
                h + 360.0
            } else {
                h
            }
        }
    };
    let (h1p, h2p) = (hue(b1, a1p), hue(b2, a2p));
    let dl = l2 - l1;
    let dc = c2p - c1p;
    let dh = if c1p * c2p == 0.0 {
        0.0
    } else if (h2p - h1p).abs() <= 180.0 {
        h2p - h1p
    } else if h2p - h1p > 180.0 {
        h2p - h1p - 360.0
    } else {
        h2p - h1p + 360.0
    };
    let dhh = 2.0 * (c1p * c2p).sqrt() * (dh.to_radians() / 2.0).sin();
    let l_bar = 0.5 * (l1 + l2);
    let cp_bar = 0.5 * (c1p + c2p);
    let hp_bar = if c1p * c2p == 0.0 {
        h1p + h2p
    } else if (h1p - h2p).abs() <= 180.0 {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 360.0 {
        0.5 * (h1p + h2p + 360.0)
    } else {
        0.5 * (h1p + h2p - 360.0)
    };
    let t = 1.0 - 0.17 * (hp_bar - 30.0).to_radians().cos()
        + 0.24 * (2.0 * hp_bar).to_radians().cos()
        + 0.32 * (3.0 * hp_bar + 6.0).to_radians().cos()
        - 0.20 * (4.0 * hp_bar - 63.0).to_radians().cos();
    let d_theta = 30.0 * (-((hp_bar - 275.0) / 25.0).powi(2)).exp();
    let cp7 = cp_bar.powi(7);
    let rc = 2.0 * (cp7 / (cp7 + 25f64.powi(7))).sqrt();
    let l50 = (l_bar - 50.0).powi(2);
    let sl = 1.0 + 0.015 * l50 / (20.0 + l50).sqrt();
    let sc = 1.0 + 0.045 * cp_bar;
    let sh = 1.0 + 0.015 * cp_bar * t;
    let rt = -(2.0 * d_theta).to_radians().sin() * rc;
    let (x, y, z) = (dl / sl, dc / sc, dhh / sh);
    (x * x + y * y + z * z + rt * y * z).sqrt()
}

/// CIEDE2000 between two encoded sRGB colours.
pub fn delta_e2000_srgb(a: [f64; 3], b: [f64; 3]) -> f64 {
    delta_e2000(srgb_to_lab(a), srgb_to_lab(b))
}

/// Median, 90th percentile and the share above `over` of a set of differences (NaN for none).
pub fn spread(values: &[f64], over: f64) -> (f64, f64, f64) {
    if values.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.9), v.iter().filter(|x| **x > over).count() as f64 / v.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sharma, Wu and Dalal's CIEDE2000 test data (2005), twelve of its 34 pairs: Lab 1, Lab 2, ΔE00.
    const SHARMA: [([f64; 3], [f64; 3], f64); 12] = [
        ([50.0, 2.6772, -79.7751], [50.0, 0.0, -82.7485], 2.0425),
        ([50.0, 3.1571, -77.2803], [50.0, 0.0, -82.7485], 2.8615),
        ([50.0, 2.8361, -74.0200], [50.0, 0.0, -82.7485], 3.4412),
        ([50.0, -1.3802, -84.2814], [50.0, 0.0, -82.7485], 1.0),
        ([50.0, 0.0, 0.0], [50.0, -1.0, 2.0], 2.3669),
        ([50.0, 2.49, -0.001], [50.0, -2.49, 0.0009], 7.1792),
        ([50.0, 2.5, 0.0], [73.0, 25.0, -18.0], 27.1492),
        ([50.0, 2.5, 0.0], [50.0, 3.2592, 0.3350], 1.0),
        ([60.2574, -34.0099, 36.2677], [60.4626, -34.1751, 39.4387], 1.2644),
        ([63.0109, -31.0961, -5.8663], [62.8187, -29.7946, -4.0864], 1.2630),
        ([22.7233, 20.0904, -46.6940], [23.0331, 14.9730, -42.5619], 2.0373),
        ([90.9257, -0.5406, -0.9208], [88.6381, -0.8985, -0.7239], 1.5381),
    ];

    #[test]
    fn ciede2000_matches_sharma_wu_dalal_and_is_symmetric() {
        for (a, b, want) in SHARMA {
            let got = delta_e2000(a, b);
            assert!((got - want).abs() < 1e-4, "{a:?} {b:?}: {got} vs {want}");
            assert!((delta_e2000(b, a) - want).abs() < 1e-4);
        }
        assert_eq!(delta_e2000([40.0, 10.0, -5.0], [40.0, 10.0, -5.0]), 0.0);
    }

    #[test]
    fn srgb_lab_round_trips_and_hits_known_values() {
        // sRGB white is L 100, a = b = 0 under D65; pure red is Lab(53.24, 80.09, 67.20).
        let w = srgb_to_lab([1.0; 3]);
        assert!((w[0] - 100.0).abs() < 1e-3 && w[1].abs() < 1e-2 && w[2].abs() < 1e-2, "{w:?}");
        let r = srgb_to_lab([1.0, 0.0, 0.0]);
        assert!((r[0] - 53.24).abs() < 0.02 && (r[1] - 80.09).abs() < 0.05 && (r[2] - 67.20).abs() < 0.05, "{r:?}");
        for rgb in [[0.2, 0.5, 0.9], [0.0, 0.01, 0.02], [0.99, 0.3, 0.0]] {
            let back = lab_to_srgb(srgb_to_lab(rgb));
            let d50 = lab_d50_to_srgb(srgb_to_lab_d50(rgb));
            for i in 0..3 {
                assert!((back[i] - rgb[i]).abs() < 1e-6 && (d50[i] - rgb[i]).abs() < 1e-4, "{rgb:?} {back:?} {d50:?}");
            }
        }
        // D50 white adapts to D65 white.
        let w = d50_to_d65(D50);
        assert!((0..3).all(|i| (w[i] - D65[i]).abs() < 2e-3), "{w:?}");
    }
}
