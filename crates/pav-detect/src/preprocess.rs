//! Frame → model input tensor (resize/letterbox, channel order, normalization) and the inverse box map.

use super::config::{Align, ChannelOrder, InputConfig, Resize};
use super::defence::{apply_chain, DefenceError};
use super::BBox;
use pav_core::image::resize::{resize, resize_pil_u8, Interpolation};
use pav_core::image::Frame;

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
    /// The map of a `w × h` frame that is already the model's input (no resize, no padding).
    pub fn identity(w: usize, h: usize) -> InputMap {
        InputMap { scale_x: 1.0, scale_y: 1.0, pad_x: 0.0, pad_y: 0.0, frame_w: w as f32, frame_h: h as f32 }
    }

    /// Converts an input-pixel box to a frame-pixel box, clipped to the frame.
    pub fn to_frame(&self, b: BBox) -> BBox {
        let fx = |x: f32| ((x - self.pad_x) / self.scale_x).clamp(0.0, self.frame_w);
        let fy = |y: f32| ((y - self.pad_y) / self.scale_y).clamp(0.0, self.frame_h);
        [fx(b[0]), fy(b[1]), fx(b[2]), fy(b[3])]
    }

    /// [`InputMap::to_frame`] and each corner's derivative through it (0 where it was clamped).
    pub fn to_frame_with_grad(&self, b: BBox) -> (BBox, [f32; 4]) {
        let d = |k: usize| {
            let (pad, scale, top) = if k % 2 == 0 {
                (self.pad_x, self.scale_x, self.frame_w)
            } else {
                (self.pad_y, self.scale_y, self.frame_h)
            };
            if (0.0..=top).contains(&((b[k] - pad) / scale)) {
                1.0 / scale
            } else {
                0.0
            }
        };
        (self.to_frame(b), [d(0), d(1), d(2), d(3)])
    }
}

/// Builds the NCHW float input (batch 1) for `frame` and the map back to frame pixels.
///
/// One pass: the frame is resized to 8 bits (OpenCV's `INTER_LINEAR`, as the models' upstream
/// code resizes, or PIL's antialiased bilinear), then each sample goes through a 256-entry table
/// of its channel's normalization straight into its plane. With defences, the 8-bit input
/// (padding included) is built first and goes through them before the tables.
pub fn prepare(frame: &Frame, cfg: &InputConfig) -> Result<(Vec<f32>, InputMap), DefenceError> {
    if cfg.defence.is_empty() {
        return Ok(prepare_with(frame, cfg, true));
    }
    let (mut canvas, map) = model_image(frame, cfg);
    apply_chain(&cfg.defence, &mut canvas)?;
    Ok((prepare_with(&canvas, cfg, true).0, map))
}

/// The 8-bit BGR image the model's input is made from (`cfg`'s size, resized and padded, before
/// channel order and normalization), and the map back to frame pixels.
pub fn model_image(frame: &Frame, cfg: &InputConfig) -> (Frame, InputMap) {
    let g = geometry(frame, cfg);
    let (iw, ih) = (cfg.width, cfg.height);
    let mut canvas = Frame { width: iw, height: ih, bgr: vec![cfg.pad_value; iw * ih * 3] };
    let pixels = g.pixels(frame, cfg, true);
    for (y, row) in pixels.chunks_exact(g.nw * 3).take(g.nh).enumerate() {
        let at = ((y + g.py) * iw + g.px) * 3;
        canvas.bgr[at..at + g.nw * 3].copy_from_slice(row);
    }
    (canvas, g.map(frame))
}

/// Where a frame lands in the input: resized to `nw × nh` at `(px, py)`.
struct Geometry {
    nw: usize,
    nh: usize,
    px: usize,
    py: usize,
}

impl Geometry {
    /// The frame's pixels at `nw × nh` (the frame itself when it already has that size).
    fn pixels<'a>(&self, frame: &'a Frame, cfg: &InputConfig, opencv: bool) -> std::borrow::Cow<'a, [u8]> {
        if (self.nw, self.nh) == (frame.width, frame.height) {
            std::borrow::Cow::Borrowed(&frame.bgr)
        } else {
            std::borrow::Cow::Owned(resize_u8(frame, self.nw, self.nh, cfg.interpolation, opencv))
        }
    }

    fn map(&self, frame: &Frame) -> InputMap {
        let (w, h) = (frame.width as f32, frame.height as f32);
        InputMap {
            scale_x: self.nw as f32 / w,
            scale_y: self.nh as f32 / h,
            pad_x: self.px as f32,
            pad_y: self.py as f32,
            frame_w: w,
            frame_h: h,
        }
    }
}

fn geometry(frame: &Frame, cfg: &InputConfig) -> Geometry {
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
    Geometry { nw, nh, px, py }
}

/// [`prepare`] with pav's own float bilinear (OpenCV's result to within one level) instead of
/// OpenCV's: what `prepare` did before it called OpenCV, kept to measure what the switch moved.
pub fn prepare_exact(frame: &Frame, cfg: &InputConfig) -> (Vec<f32>, InputMap) {
    prepare_with(frame, cfg, false)
}

fn prepare_with(frame: &Frame, cfg: &InputConfig, opencv: bool) -> (Vec<f32>, InputMap) {
    let (iw, ih) = (cfg.width, cfg.height);
    let g = geometry(frame, cfg);
    let (nw, nh, px, py) = (g.nw, g.nh, g.px, g.py);
    // Model channel c reads BGR channel src_ch[c].
    let src_ch = match cfg.channels {
        ChannelOrder::Bgr => [0, 1, 2],
        ChannelOrder::Rgb => [2, 1, 0],
    };
    let norm = |c: usize, v: f32| (v * cfg.scale - cfg.mean[c]) / cfg.std[c];
    let lut: [[f32; 256]; 3] = std::array::from_fn(|c| std::array::from_fn(|v| norm(c, v as f32)));
    let plane = iw * ih;
    let mut out = vec![0f32; 3 * plane];
    if (nw, nh) != (iw, ih) {
        for c in 0..3 {
            out[c * plane..(c + 1) * plane].fill(norm(c, cfg.pad_value as f32));
        }
    }
    let pixels = g.pixels(frame, cfg, opencv);
    let (p0, rest) = out.split_at_mut(plane);
    let (p1, p2) = rest.split_at_mut(plane);
    for (y, row) in pixels.chunks_exact(nw * 3).take(nh).enumerate() {
        let at = (y + py) * iw + px;
        let (o0, o1, o2) = (&mut p0[at..at + nw], &mut p1[at..at + nw], &mut p2[at..at + nw]);
        for (x, p) in row.chunks_exact(3).enumerate() {
            o0[x] = lut[0][p[src_ch[0]] as usize];
            o1[x] = lut[1][p[src_ch[1]] as usize];
            o2[x] = lut[2][p[src_ch[2]] as usize];
        }
    }
    (out, g.map(frame))
}

/// `frame` resized to `nw × nh`, 8-bit BGR; bilinear by OpenCV when `opencv` and the `video`
/// feature allow.
fn resize_u8(frame: &Frame, nw: usize, nh: usize, filter: Interpolation, opencv: bool) -> Vec<u8> {
    match filter {
        Interpolation::Antialias => resize_pil_u8(frame, nw, nh),
        Interpolation::Bilinear | Interpolation::Area => {
            #[cfg(feature = "video")]
            if opencv {
                if let Ok(v) = resize_opencv(frame, nw, nh, filter) {
                    return v;
                }
            }
            #[cfg(not(feature = "video"))]
            let _ = opencv;
            // Within one level of OpenCV's fixed-point result.
            resize(frame, nw, nh, filter).into_iter().map(|v| v as u8).collect()
        }
    }
}

/// OpenCV's `resize` with `INTER_LINEAR` (or `INTER_AREA`): fixed point and vectorized, what the models' reference
/// code calls.
#[cfg(feature = "video")]
fn resize_opencv(frame: &Frame, nw: usize, nh: usize, filter: Interpolation) -> opencv::Result<Vec<u8>> {
    use opencv::core::{Mat, Size};
    use opencv::prelude::*;
    let flat = Mat::from_slice(&frame.bgr)?;
    let src = flat.reshape(3, frame.height as i32)?;
    let mut dst = Mat::default();
    let flag = if filter == Interpolation::Area { opencv::imgproc::INTER_AREA } else { opencv::imgproc::INTER_LINEAR };
    opencv::imgproc::resize(&src, &mut dst, Size::new(nw as i32, nh as i32), 0.0, 0.0, flag)?;
    Ok(dst.data_bytes()?.to_vec())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(feature = "video")]
    #[test]
    fn area_resampling_matches_opencv_inter_area_within_one_level() {
        let mut rng = pav_core::rng::Rng::new(3);
        // Smooth content with noise, as photos are.
        let (w, h) = (640, 480);
        let bgr: Vec<u8> = (0..w * h * 3)
            .map(|i| {
                let (x, y) = ((i / 3) % w, (i / 3) / w);
                let v = 128.0 + 60.0 * ((x as f32) * 0.05).sin() * ((y as f32) * 0.03).cos() + rng.uniform(-20.0, 20.0);
                v.clamp(0.0, 255.0) as u8
            })
            .collect();
        let f = Frame { width: w, height: h, bgr };
        for (nw, nh) in [(416, 312), (320, 240), (211, 97)] {
            let cv = resize_opencv(&f, nw, nh, Interpolation::Area).unwrap();
            let ours = resize(&f, nw, nh, Interpolation::Area);
            let worst = cv.iter().zip(&ours).map(|(a, b)| (*a as f32 - b).abs()).fold(0f32, f32::max);
            assert!(worst <= 1.0, "{nw}×{nh}: {worst}");
        }
    }

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
            extra: Vec::new(),
            defence: Vec::new(),
        }
    }

    fn solid(w: usize, h: usize, bgr: [u8; 3]) -> Frame {
        Frame { width: w, height: h, bgr: (0..w * h).flat_map(|_| bgr).collect() }
    }

    #[test]
    fn letterbox_centre_pads_and_maps_boxes_back() {
        let f = solid(16, 8, [10, 20, 30]);
        let (t, m) = prepare(&f, &cfg(Resize::Letterbox, Align::Center, ChannelOrder::Rgb)).unwrap();
        // 16x8 -> 8x4 centred vertically: rows 0,1 and 6,7 are padding.
        assert_eq!(t[0], 114.0);
        assert_eq!(t[2 * 8], 30.0); // R plane, row 2 = image
        assert_eq!(t[64 + 2 * 8], 20.0); // G
        assert_eq!(t[128 + 7 * 8], 114.0);
        assert_eq!(m.to_frame([0.0, 2.0, 8.0, 6.0]), [0.0, 0.0, 16.0, 8.0]);
    }

    /// OpenCV's fixed-point bilinear and pav's float one agree to within one 8-bit level on a
    /// textured frame, at a downscale and an upscale.
    #[test]
    fn opencv_and_exact_bilinear_agree_within_one_level() {
        let (w, h) = (97, 61);
        let f =
            Frame { width: w, height: h, bgr: (0..w * h * 3).map(|i| ((i * 37 + i / 7 * 11) % 256) as u8).collect() };
        for size in [40, 150] {
            let mut c = cfg(Resize::Letterbox, Align::Center, ChannelOrder::Rgb);
            (c.width, c.height) = (size, size);
            let (a, ma) = prepare(&f, &c).unwrap();
            let (b, mb) = prepare_exact(&f, &c);
            assert_eq!(ma, mb);
            let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
            assert!(worst <= 1.0, "size {size}: {worst}");
            assert!(a.iter().zip(&b).filter(|(x, y)| x != y).count() < a.len() / 2);
        }
    }

    /// The defended path builds the padded 8-bit input first: with a defence that changes nothing
    /// (8 bits kept) it gives the plain path's tensor exactly; with a real one, the padding is
    /// defended too and the map is unchanged.
    #[test]
    fn defences_see_the_padded_input_and_an_identity_changes_nothing() {
        let (w, h) = (37, 23);
        let f =
            Frame { width: w, height: h, bgr: (0..w * h * 3).map(|i| ((i * 53 + i / 9 * 7) % 256) as u8).collect() };
        for (resize, align) in
            [(Resize::Letterbox, Align::Center), (Resize::Letterbox, Align::TopLeft), (Resize::Stretch, Align::Center)]
        {
            let mut c = cfg(resize, align, ChannelOrder::Rgb);
            (c.width, c.height) = (20, 16);
            let plain = prepare(&f, &c).unwrap();
            c.defence = vec![crate::defence::Defence::Bits(crate::defence::Bits { b: 8 })];
            assert_eq!(prepare(&f, &c).unwrap(), plain);
            c.defence = vec![crate::defence::Defence::Bits(crate::defence::Bits { b: 1 })];
            let (t, m) = prepare(&f, &c).unwrap();
            assert_eq!(m, plain.1);
            assert!(t.iter().all(|&v| v == 0.0 || v == 255.0));
        }
    }

    #[test]
    fn top_left_letterbox_and_stretch() {
        let f = solid(8, 16, [1, 2, 3]);
        let (t, m) = prepare(&f, &cfg(Resize::Letterbox, Align::TopLeft, ChannelOrder::Bgr)).unwrap();
        assert_eq!(t[0], 1.0);
        assert_eq!(t[7], 114.0); // column 4..8 padded
        assert_eq!((m.pad_x, m.scale_x), (0.0, 0.5));
        let (_, m) = prepare(&f, &cfg(Resize::Stretch, Align::Center, ChannelOrder::Bgr)).unwrap();
        assert_eq!(m.to_frame([4.0, 4.0, 8.0, 8.0]), [4.0, 8.0, 8.0, 16.0]);
    }
}
