//! Frame → model input tensor (resize/letterbox, channel order, normalization) and the inverse box map.

use super::config::{Align, ChannelOrder, InputConfig, Interpolation, Resize};
use super::{BBox, Frame};

/// Maps boxes from model-input pixels back to frame pixels: `frame = (input - pad) / scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InputMap {
    /// Horizontal scale from frame to input.
    pub scale_x: f32,
    /// Vertical scale from frame to input.
    pub scale_y: f32,
    /// Left padding in input pixels.
    pub pad_x: f32,
    /// Top padding in input pixels.
    pub pad_y: f32,
    /// Frame width, to clip boxes.
    pub frame_w: f32,
    /// Frame height, to clip boxes.
    pub frame_h: f32,
}

impl InputMap {
    /// Converts an input-pixel box to a frame-pixel box, clipped to the frame.
    pub fn to_frame(&self, b: BBox) -> BBox {
        let fx = |x: f32| ((x - self.pad_x) / self.scale_x).clamp(0.0, self.frame_w);
        let fy = |y: f32| ((y - self.pad_y) / self.scale_y).clamp(0.0, self.frame_h);
        [fx(b[0]), fy(b[1]), fx(b[2]), fy(b[3])]
    }
}

/// Source taps of one output sample: first source index and normalized weights.
struct Taps {
    start: usize,
    weights: Vec<f64>,
}

/// Per-axis resampling table from `src` to `dst` samples.
fn axis_taps(src: usize, dst: usize, filter: Interpolation) -> Vec<Taps> {
    let scale = src as f64 / dst as f64;
    match filter {
        Interpolation::Bilinear => (0..dst)
            .map(|d| {
                // OpenCV: half-pixel centres, coordinates clamped to the edge.
                let f = ((d as f64 + 0.5) * scale - 0.5).max(0.0);
                let i0 = (f.floor() as usize).min(src - 1);
                let a = f - i0 as f64;
                if i0 + 1 < src {
                    Taps { start: i0, weights: vec![1.0 - a, a] }
                } else {
                    Taps { start: i0, weights: vec![1.0] }
                }
            })
            .collect(),
        Interpolation::Antialias => {
            // PIL: triangle filter of support `max(scale, 1)`, window truncated at the edges and renormalized.
            let fscale = scale.max(1.0);
            let support = fscale;
            (0..dst)
                .map(|d| {
                    let centre = (d as f64 + 0.5) * scale;
                    let lo = ((centre - support + 0.5) as i64).max(0) as usize;
                    let hi = ((centre + support + 0.5) as i64).min(src as i64) as usize;
                    let w: Vec<f64> =
                        (lo..hi).map(|x| (1.0 - ((x as f64 - centre + 0.5) / fscale).abs()).max(0.0)).collect();
                    let total: f64 = w.iter().sum();
                    Taps { start: lo, weights: w.iter().map(|v| v / total).collect() }
                })
                .collect()
        }
    }
}

/// Resizes an interleaved 3-channel u8 image to `nw × nh`, returning values on the 0–255 scale.
pub fn resize(frame: &Frame, nw: usize, nh: usize, filter: Interpolation) -> Vec<f32> {
    match filter {
        Interpolation::Bilinear => resize_float(frame, nw, nh),
        Interpolation::Antialias => resize_pil(frame, nw, nh),
    }
}

/// Separable bilinear in f32 with one final rounding (OpenCV's result to within 1 LSB).
fn resize_float(frame: &Frame, nw: usize, nh: usize) -> Vec<f32> {
    let (w, h) = (frame.width, frame.height);
    let xs = axis_taps(w, nw, Interpolation::Bilinear);
    let ys = axis_taps(h, nh, Interpolation::Bilinear);
    let mut mid = vec![0f32; h * nw * 3];
    for y in 0..h {
        let row = &frame.bgr[y * w * 3..(y + 1) * w * 3];
        for (dx, t) in xs.iter().enumerate() {
            for (k, &wt) in t.weights.iter().enumerate() {
                let p = &row[(t.start + k) * 3..(t.start + k) * 3 + 3];
                for c in 0..3 {
                    mid[(y * nw + dx) * 3 + c] += p[c] as f32 * wt as f32;
                }
            }
        }
    }
    let mut out = vec![0f32; nh * nw * 3];
    for (dy, t) in ys.iter().enumerate() {
        for (k, &wt) in t.weights.iter().enumerate() {
            let src = &mid[(t.start + k) * nw * 3..(t.start + k + 1) * nw * 3];
            for (o, s) in out[dy * nw * 3..(dy + 1) * nw * 3].iter_mut().zip(src) {
                *o += s * wt as f32;
            }
        }
    }
    out.iter_mut().for_each(|v| *v = v.round().clamp(0.0, 255.0));
    out
}

/// PIL's 8-bit resampler: 22-bit fixed-point weights, horizontal pass rounded to 8 bits, then vertical.
fn resize_pil(frame: &Frame, nw: usize, nh: usize) -> Vec<f32> {
    const BITS: u32 = 22;
    let fixed = |taps: Vec<Taps>| -> Vec<(usize, Vec<i64>)> {
        taps.into_iter()
            .map(|t| (t.start, t.weights.iter().map(|&w| (w * (1u64 << BITS) as f64 + 0.5).floor() as i64).collect()))
            .collect()
    };
    let (w, h) = (frame.width, frame.height);
    let xs = fixed(axis_taps(w, nw, Interpolation::Antialias));
    let ys = fixed(axis_taps(h, nh, Interpolation::Antialias));
    let round = |acc: i64| ((acc + (1 << (BITS - 1))) >> BITS).clamp(0, 255) as u8;
    let mut mid = vec![0u8; h * nw * 3];
    for y in 0..h {
        let row = &frame.bgr[y * w * 3..(y + 1) * w * 3];
        for (dx, (start, ks)) in xs.iter().enumerate() {
            for c in 0..3 {
                let acc: i64 = ks.iter().enumerate().map(|(k, &wt)| row[(start + k) * 3 + c] as i64 * wt).sum();
                mid[(y * nw + dx) * 3 + c] = round(acc);
            }
        }
    }
    let mut out = vec![0f32; nh * nw * 3];
    for (dy, (start, ks)) in ys.iter().enumerate() {
        for i in 0..nw * 3 {
            let acc: i64 = ks.iter().enumerate().map(|(k, &wt)| mid[(start + k) * nw * 3 + i] as i64 * wt).sum();
            out[dy * nw * 3 + i] = round(acc) as f32;
        }
    }
    out
}

/// The resampling of `src` samples to `dst` as a dense row-major `dst × src` matrix, so a
/// differentiable pipeline can resize with two matrix products (`A_h · X · A_wᵀ`).
pub fn interpolation_matrix(src: usize, dst: usize, filter: Interpolation) -> Vec<f32> {
    let mut m = vec![0f32; dst * src];
    for (d, t) in axis_taps(src, dst, filter).into_iter().enumerate() {
        for (k, w) in t.weights.iter().enumerate() {
            m[d * src + t.start + k] += *w as f32;
        }
    }
    m
}

/// Builds the NCHW float input (batch 1) for `frame` and the map back to frame pixels.
pub fn prepare(frame: &Frame, cfg: &InputConfig) -> (Vec<f32>, InputMap) {
    let (w, h) = (frame.width, frame.height);
    let (iw, ih) = (cfg.width, cfg.height);
    let (nw, nh, px, py) = match cfg.resize {
        Resize::Stretch => (iw, ih, 0, 0),
        Resize::Letterbox => {
            let r = (iw as f32 / w as f32).min(ih as f32 / h as f32);
            let nw = ((w as f32 * r).round() as usize).clamp(1, iw);
            let nh = ((h as f32 * r).round() as usize).clamp(1, ih);
            match cfg.align {
                Align::TopLeft => (nw, nh, 0, 0),
                Align::Center => (nw, nh, (iw - nw) / 2, (ih - nh) / 2),
            }
        }
    };
    // Model channel c reads BGR channel src_ch[c].
    let src_ch = match cfg.channels {
        ChannelOrder::Bgr => [0, 1, 2],
        ChannelOrder::Rgb => [2, 1, 0],
    };
    let norm = |c: usize, v: f32| (v * cfg.scale - cfg.mean[c]) / cfg.std[c];
    let plane = iw * ih;
    let mut out = vec![0f32; 3 * plane];
    for c in 0..3 {
        out[c * plane..(c + 1) * plane].fill(norm(c, cfg.pad_value as f32));
    }
    let resized = if (nw, nh) == (w, h) {
        frame.bgr.iter().map(|&v| v as f32).collect()
    } else {
        resize(frame, nw, nh, cfg.interpolation)
    };
    for y in 0..nh {
        for x in 0..nw {
            let p = &resized[(y * nw + x) * 3..(y * nw + x) * 3 + 3];
            let at = (y + py) * iw + x + px;
            for (c, &sc) in src_ch.iter().enumerate() {
                out[c * plane + at] = norm(c, p[sc]);
            }
        }
    }
    let map = InputMap {
        scale_x: nw as f32 / w as f32,
        scale_y: nh as f32 / h as f32,
        pad_x: px as f32,
        pad_y: py as f32,
        frame_w: w as f32,
        frame_h: h as f32,
    };
    (out, map)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(resize: Resize, align: Align, channels: ChannelOrder) -> InputConfig {
        InputConfig {
            name: None,
            width: 8,
            height: 8,
            channels,
            scale: 1.0,
            mean: [0.0; 3],
            std: [1.0; 3],
            resize,
            interpolation: Interpolation::Bilinear,
            pad_value: 114,
            align,
        }
    }

    fn solid(w: usize, h: usize, bgr: [u8; 3]) -> Frame {
        Frame { width: w, height: h, bgr: (0..w * h).flat_map(|_| bgr).collect() }
    }

    #[test]
    fn letterbox_centre_pads_and_maps_boxes_back() {
        let f = solid(16, 8, [10, 20, 30]);
        let (t, m) = prepare(&f, &cfg(Resize::Letterbox, Align::Center, ChannelOrder::Rgb));
        // 16x8 -> 8x4 centred vertically: rows 0,1 and 6,7 are padding.
        assert_eq!(t[0], 114.0);
        assert_eq!(t[2 * 8], 30.0); // R plane, row 2 = image
        assert_eq!(t[64 + 2 * 8], 20.0); // G
        assert_eq!(t[128 + 7 * 8], 114.0);
        assert_eq!(m.to_frame([0.0, 2.0, 8.0, 6.0]), [0.0, 0.0, 16.0, 8.0]);
    }

    #[test]
    fn top_left_letterbox_and_stretch() {
        let f = solid(8, 16, [1, 2, 3]);
        let (t, m) = prepare(&f, &cfg(Resize::Letterbox, Align::TopLeft, ChannelOrder::Bgr));
        assert_eq!(t[0], 1.0);
        assert_eq!(t[7], 114.0); // column 4..8 padded
        assert_eq!((m.pad_x, m.scale_x), (0.0, 0.5));
        let (_, m) = prepare(&f, &cfg(Resize::Stretch, Align::Center, ChannelOrder::Bgr));
        assert_eq!(m.to_frame([4.0, 4.0, 8.0, 8.0]), [4.0, 8.0, 8.0, 16.0]);
    }

    #[test]
    fn bilinear_matches_opencv_half_pixel_convention() {
        // A 2-pixel ramp upsampled to 4: OpenCV gives 0, 64, 191, 255 for [0, 255].
        let f = Frame { width: 2, height: 1, bgr: vec![0, 0, 0, 255, 255, 255] };
        let mut c = cfg(Resize::Stretch, Align::Center, ChannelOrder::Bgr);
        c.width = 4;
        c.height = 1;
        let (t, _) = prepare(&f, &c);
        assert_eq!(&t[..4], &[0.0, 64.0, 191.0, 255.0]);
    }

    #[test]
    fn antialias_reproduces_pil_bilinear_downscale() {
        // 23x9 image (rows 4.. inverted) resized to 5x3; expected values from PIL 11 Image.resize(BILINEAR).
        let row: Vec<u8> = (0..23u32).map(|x| ((x * x * 7 + 13) % 256) as u8).collect();
        let bgr: Vec<u8> =
            (0..9).flat_map(|y| row.iter().flat_map(move |&v| [if y >= 4 { 255 - v } else { v }; 3])).collect();
        let f = Frame { width: 23, height: 9, bgr };
        let mut c = cfg(Resize::Stretch, Align::Center, ChannelOrder::Bgr);
        (c.width, c.height, c.interpolation) = (5, 3, Interpolation::Antialias);
        let (t, _) = prepare(&f, &c);
        let pil =
            [60.0, 113.0, 153.0, 133.0, 168.0, 150.0, 132.0, 119.0, 126.0, 114.0, 195.0, 142.0, 102.0, 122.0, 87.0];
        let worst = t[..15].iter().zip(pil).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert_eq!(worst, 0.0, "got {:?}", &t[..15]);
        // Weights sum to one, so a flat image stays flat.
        let (flat, _) = prepare(&solid(37, 11, [200, 200, 200]), &c);
        assert!(flat[..15].iter().all(|&v| v == 200.0));
    }

    #[test]
    fn interpolation_matrices_reproduce_the_resize() {
        let (w, h, nw, nh) = (13, 7, 5, 4);
        let bgr: Vec<u8> = (0..w * h * 3).map(|i| ((i * 37) % 256) as u8).collect();
        let f = Frame { width: w, height: h, bgr };
        let direct = resize(&f, nw, nh, Interpolation::Bilinear);
        let (ax, ay) = (
            interpolation_matrix(w, nw, Interpolation::Bilinear),
            interpolation_matrix(h, nh, Interpolation::Bilinear),
        );
        for r in 0..nw {
            assert!((ax[r * w..(r + 1) * w].iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        for y in 0..nh {
            for x in 0..nw {
                for c in 0..3 {
                    let mut v = 0.0;
                    for sy in 0..h {
                        for sx in 0..w {
                            v += ay[y * h + sy] * ax[x * w + sx] * f.bgr[(sy * w + sx) * 3 + c] as f32;
                        }
                    }
                    assert!((v.round() - direct[(y * nw + x) * 3 + c]).abs() <= 1.0, "({x},{y},{c})");
                }
            }
        }
    }
}
