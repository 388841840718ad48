//! Frame → model input tensor (resize/letterbox, channel order, normalization) and the inverse box map.

use super::config::{Align, ChannelOrder, InputConfig, Resize};
use super::BBox;
use crate::image::resize::resize;
use crate::image::Frame;

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
    use crate::image::resize::Interpolation;

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
}
