//! Images: the 8-bit BGR [`Frame`] that cameras, videos and detectors exchange, the float RGB
//! image that textures, masks and renders use, PNG I/O, and resampling ([`resize`]).

pub mod marks;
pub mod resize;

use std::path::{Path, PathBuf};

/// An 8-bit BGR image, row-major, 3 bytes per pixel (OpenCV's native layout).
#[derive(Clone, Debug)]
pub struct Frame {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `height * width * 3` bytes, B,G,R.
    pub bgr: Vec<u8>,
}

impl Frame {
    /// A frame from BGR levels on the 0–255 scale, each rounded and clamped to a byte.
    pub fn from_levels(width: usize, height: usize, bgr: &[f32]) -> Frame {
        Frame { width, height, bgr: bgr.iter().map(|v| v.round().clamp(0.0, 255.0) as u8).collect() }
    }

    /// Writes the frame as an 8-bit RGB PNG.
    pub fn save_png(&self, path: &Path) -> Result<(), ImageError> {
        save_rgb8(path, self.width, self.height, self.bgr.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect())
    }
}

/// An RGB image with values in [0, 1], row-major from the top-left, 3 floats per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Rgb {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `width × height × 3` values.
    pub rgb: Vec<f32>,
}

/// Errors reading or writing an image file.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be read or decoded.
    #[error("cannot read image {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The decoder's error.
        source: image::ImageError,
    },
    /// The file could not be encoded or written.
    #[error("cannot write image {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The encoder's error.
        source: image::ImageError,
    },
    /// The pixel buffer does not hold `width × height` pixels.
    #[error("image {path}: {len} values do not make a {width}x{height} RGB image")]
    Size {
        /// The file.
        path: PathBuf,
        /// Width asked for.
        width: usize,
        /// Height asked for.
        height: usize,
        /// Values given.
        len: usize,
    },
    /// The file is not a PNG, or could not be rewritten.
    #[error("cannot rewrite PNG {path}: {why}")]
    Rewrite {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

impl Rgb {
    /// Reads a PNG (or any 8-bit image the `image` crate decodes) as RGB in [0, 1].
    pub fn load(path: &Path) -> Result<Rgb, ImageError> {
        let img = image::open(path).map_err(|source| ImageError::Read { path: path.into(), source })?.to_rgb8();
        let (w, h) = img.dimensions();
        Ok(Rgb {
            width: w as usize,
            height: h as usize,
            rgb: img.into_raw().into_iter().map(|v| v as f32 / 255.0).collect(),
        })
    }

    /// The optimizable region as PAV-Camou marks it: 1 where a pixel is pure white (every
    /// channel exactly 1.0, i.e. 255), else 0.
    pub fn white_mask(&self) -> Vec<f32> {
        self.rgb.chunks(3).map(|c| if c.iter().all(|v| *v == 1.0) { 1.0 } else { 0.0 }).collect()
    }

    /// The centre rows of a square of side `width` put back in place, as a rig's landscape
    /// render keeps them; the rows above and below repeat the nearest edge row (`edge`) or are
    /// black. An image that is already square comes back as it is.
    pub fn into_square(self, edge: bool) -> Rgb {
        let (side, h) = (self.width, self.height);
        if h >= side || h == 0 {
            return self;
        }
        let row = 3 * side;
        let y0 = (side - h) / 2;
        let mut rgb = vec![0.0f32; row * side];
        rgb[row * y0..row * (y0 + h)].copy_from_slice(&self.rgb);
        if edge {
            let (first, last) = (self.rgb[..row].to_vec(), self.rgb[row * (h - 1)..].to_vec());
            for y in (0..y0).chain(y0 + h..side) {
                let src = if y < y0 { &first } else { &last };
                rgb[row * y..row * (y + 1)].copy_from_slice(src);
            }
        }
        Rgb { width: side, height: side, rgb }
    }
}

/// PNG chunks that carry text or a time stamp rather than pixels.
const TEXT_CHUNKS: [&[u8; 4]; 4] = [b"tEXt", b"zTXt", b"iTXt", b"tIME"];

/// Rewrites a PNG without its text and time chunks, pixels untouched: Blender writes the date
/// and the render time into every image, so the same view drawn twice would differ in its bytes.
pub fn strip_png_text(path: &Path) -> Result<(), ImageError> {
    let fail = |why: String| ImageError::Rewrite { path: path.into(), why };
    let bytes = std::fs::read(path).map_err(|e| fail(e.to_string()))?;
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    if !bytes.starts_with(SIGNATURE) {
        return Err(fail("no PNG signature".into()));
    }
    let mut out = SIGNATURE.to_vec();
    let mut at = SIGNATURE.len();
    while at < bytes.len() {
        let head = bytes.get(at..at + 8).ok_or_else(|| fail(format!("a chunk cut short at byte {at}")))?;
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
        let end = at + 12 + len;
        let chunk = bytes.get(at..end).ok_or_else(|| fail(format!("a chunk cut short at byte {at}")))?;
        if !TEXT_CHUNKS.iter().any(|t| &head[4..8] == *t) {
            out.extend_from_slice(chunk);
        }
        at = end;
    }
    if out.len() == bytes.len() {
        return Ok(());
    }
    crate::durable::write(path, &out).map_err(|e| fail(e.to_string()))
}

/// Reads an RGBA image as straight (not premultiplied) RGB and alpha, both in [0, 1], as
/// Blender writes PNGs with a transparent film.
pub fn load_rgba(path: &Path) -> Result<(Rgb, Vec<f32>), ImageError> {
    let img = image::open(path).map_err(|source| ImageError::Read { path: path.into(), source })?.to_rgba8();
    let (w, h) = img.dimensions();
    let raw = img.into_raw();
    let rgb = raw.chunks(4).flat_map(|p| [p[0], p[1], p[2]]).map(|v| v as f32 / 255.0).collect();
    let alpha = raw.chunks(4).map(|p| p[3] as f32 / 255.0).collect();
    Ok((Rgb { width: w as usize, height: h as usize, rgb }, alpha))
}

/// `fg` with straight `alpha` laid over `bg` (the same size): `a·fg + (1 − a)·bg` per channel.
pub fn over(fg: &Rgb, alpha: &[f32], bg: &Frame) -> Frame {
    assert!(fg.width == bg.width && fg.height == bg.height && alpha.len() == fg.width * fg.height, "sizes differ");
    let bgr = (0..alpha.len())
        .flat_map(|i| {
            let a = alpha[i];
            [2, 1, 0].map(|c| {
                let v = a * fg.rgb[i * 3 + c] * 255.0 + (1.0 - a) * bg.bgr[i * 3 + (2 - c)] as f32;
                v.round().clamp(0.0, 255.0) as u8
            })
        })
        .collect();
    Frame { width: bg.width, height: bg.height, bgr }
}

/// A value in [0, 1] as an 8-bit channel (clamped, rounded), as every saved image stores it.
pub fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Writes an interleaved 8-bit RGB image as PNG.
pub fn save_rgb8(path: &Path, w: usize, h: usize, rgb: Vec<u8>) -> Result<(), ImageError> {
    let len = rgb.len();
    image::RgbImage::from_raw(w as u32, h as u32, rgb)
        .ok_or_else(|| ImageError::Size { path: path.into(), width: w, height: h, len })?
        .save(path)
        .map_err(|source| ImageError::Write { path: path.into(), source })
}

/// Draws a 10 mm × 1 mm black bar with 1 mm ticks (5 mm ticks twice as tall) into an 8-bit
/// Draws the outline of box `b` (xyxy, frame pixels, clipped to the frame) in colour `bgr`,
/// `thickness` pixels wide, inside the box.
pub fn draw_box(frame: &mut Frame, b: [f32; 4], bgr: [u8; 3], thickness: usize) {
    let (w, h) = (frame.width, frame.height);
    if w == 0 || h == 0 {
        return;
    }
    let clip = |v: f32, hi: usize| (v.round().max(0.0) as usize).min(hi - 1);
    let (x0, y0, x1, y1) = (clip(b[0], w), clip(b[1], h), clip(b[2], w), clip(b[3], h));
    for y in y0..=y1 {
        for x in x0..=x1 {
            let edge = x < x0 + thickness || x + thickness > x1 || y < y0 + thickness || y + thickness > y1;
            if edge {
                frame.bgr[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&bgr);
            }
        }
    }
}

/// Draws a black check bar `len_mm` long into the interleaved 8-bit image `w × h` (any channel
/// order), its left end at `(x, y)`, with a tick every millimetre (taller every 5): printed at
/// 100 %, it measures `len_mm`.
pub fn draw_scale_bar(rgb: &mut [u8], w: usize, h: usize, [x, y]: [usize; 2], px_per_mm: f64, len_mm: f64) {
    let len = (len_mm * px_per_mm).round() as usize;
    let thick = px_per_mm.round().max(1.0) as usize;
    let mut ink = |px: usize, py: usize| {
        if px < w && py < h {
            rgb[(py * w + px) * 3..(py * w + px) * 3 + 3].fill(0);
        }
    };
    for py in y..y + thick {
        for px in x..x + len {
            ink(px, py);
        }
    }
    for k in 0..=len_mm as usize {
        let px = x + (k as f64 * px_per_mm).round() as usize;
        let tick = if k % 5 == 0 { 2 * thick } else { thick };
        for py in y.saturating_sub(tick)..y {
            ink(px.min(x + len - 1), py);
        }
    }
}

/// Writes an interleaved 8-bit RGB image as PNG whose pHYs chunk says `dpi`, so that printing it
/// at 100 % gives its physical size.
pub fn save_png_dpi(path: &Path, w: usize, h: usize, rgb: &[u8], dpi: f64) -> Result<(), png::EncodingError> {
    let file = std::fs::File::create(path)?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w as u32, h as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let ppm = (dpi / 0.0254).round() as u32;
    enc.set_pixel_dims(Some(png::PixelDimensions { xppu: ppm, yppu: ppm, unit: png::Unit::Meter }));
    let mut wr = enc.write_header()?;
    wr.write_image_data(rgb)?;
    wr.finish()
}

/// Writes an interleaved RGB image in [0, 1] as PNG.
pub fn save_rgb(path: &Path, w: usize, h: usize, rgb: &[f32]) -> Result<(), ImageError> {
    save_rgb8(path, w, h, rgb.iter().map(|v| to_u8(*v)).collect())
}

/// The box of the set pixels of a row-major mask `width` pixels wide: `[x0, y0, x1, y1]` on
/// pixel edges (x1, y1 one past the last set pixel), or `None` where no pixel is set.
pub fn set_bounds(width: usize, set: impl IntoIterator<Item = bool>) -> Option<[usize; 4]> {
    let mut b: Option<[usize; 4]> = None;
    for (p, _) in set.into_iter().enumerate().filter(|(_, s)| *s) {
        let (x, y) = (p % width, p / width);
        let r = b.get_or_insert([x, y, x + 1, y + 1]);
        *r = [r[0].min(x), r[1].min(y), r[2].max(x + 1), r[3].max(y + 1)];
    }
    b
}

/// Half the size of an interleaved RGB image by averaging each 2×2 block (odd edges dropped).
pub fn halve(src: &[f32], w: usize, h: usize) -> Vec<f32> {
    let (hw, hh) = (w / 2, h / 2);
    let mut out = vec![0f32; hw * hh * 3];
    for y in 0..hh {
        for x in 0..hw {
            for c in 0..3 {
                let at = |dy: usize, dx: usize| src[((2 * y + dy) * w + 2 * x + dx) * 3 + c];
                out[(y * hw + x) * 3 + c] = (at(0, 0) + at(0, 1) + at(1, 0) + at(1, 1)) / 4.0;
            }
        }
    }
    out
}

/// Lays interleaved RGB tiles of `tw × th` pixels out in rows of `cols`, left to right, on
/// `background`; returns the width, height and pixels of the sheet.
pub fn tile<T: Copy>(tiles: &[Vec<T>], tw: usize, th: usize, cols: usize, background: T) -> (usize, usize, Vec<T>) {
    let cols = cols.clamp(1, tiles.len().max(1));
    let rows = tiles.len().div_ceil(cols);
    let (w, h) = (cols * tw, rows * th);
    let mut out = vec![background; w * h * 3];
    for (k, t) in tiles.iter().enumerate() {
        let (ox, oy) = ((k % cols) * tw, (k / cols) * th);
        for y in 0..th {
            let dst = ((oy + y) * w + ox) * 3;
            out[dst..dst + tw * 3].copy_from_slice(&t[y * tw * 3..(y + 1) * tw * 3]);
        }
    }
    (w, h, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_chunks_leave_a_png_and_its_pixels_stay() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
        save_rgb(&a, 2, 1, &[0.0, 0.5, 1.0, 1.0, 0.25, 0.0]).unwrap();
        // The same image with a date in a text chunk after the header, as Blender writes it.
        let plain = std::fs::read(&a).unwrap();
        let ihdr_end = 8 + 12 + 13;
        let text = b"Date\x002026/11/29 15:51:49";
        let mut chunk = (text.len() as u32).to_be_bytes().to_vec();
        chunk.extend_from_slice(b"tEXt");
        chunk.extend_from_slice(text);
        chunk.extend_from_slice(&[0, 0, 0, 0]); // the CRC is not checked by the stripper
        let stamped = [&plain[..ihdr_end], &chunk[..], &plain[ihdr_end..]].concat();
        std::fs::write(&b, &stamped).unwrap();
        strip_png_text(&b).unwrap();
        assert_eq!(std::fs::read(&b).unwrap(), plain);
        // A file without such chunks is left as it is; a file that is no PNG is refused.
        strip_png_text(&a).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), plain);
        std::fs::write(&b, b"GIF89a").unwrap();
        assert!(strip_png_text(&b).unwrap_err().to_string().contains("no PNG signature"));
    }

    #[test]
    fn tiles_land_in_rows_and_halving_averages_blocks() {
        let a = vec![1u8; 2 * 2 * 3];
        let b = vec![2u8; 2 * 2 * 3];
        let c = vec![3u8; 2 * 2 * 3];
        let (w, h, s) = tile(&[a, b, c], 2, 2, 2, 0);
        assert_eq!((w, h), (4, 4));
        assert_eq!(s[0], 1);
        assert_eq!(s[2 * 3], 2);
        assert_eq!(s[(2 * 4) * 3], 3);
        assert_eq!(s[(2 * 4 + 2) * 3], 0);
        let img: Vec<f32> = (0..4 * 2 * 3).map(|i| (i / 3) as f32).collect();
        assert_eq!(halve(&img, 4, 2), vec![2.5, 2.5, 2.5, 4.5, 4.5, 4.5]);
    }

    #[test]
    fn landscape_rows_go_back_to_the_centre_of_their_square() {
        // Four pixels wide, two rows (values 1 and 2): rows 1 and 2 of a 4 × 4 square.
        let rgb: Vec<f32> = [1.0f32, 2.0].iter().flat_map(|v| std::iter::repeat_n(*v, 12)).collect();
        let img = Rgb { width: 4, height: 2, rgb };
        let row = |im: &Rgb, y: usize| im.rgb[12 * y..12 * (y + 1)].to_vec();
        let black = img.clone().into_square(false);
        assert_eq!((black.width, black.height), (4, 4));
        assert_eq!([row(&black, 0)[0], row(&black, 1)[0], row(&black, 2)[0], row(&black, 3)[0]], [0.0, 1.0, 2.0, 0.0]);
        let edge = img.into_square(true);
        assert_eq!([row(&edge, 0)[0], row(&edge, 1)[0], row(&edge, 2)[0], row(&edge, 3)[0]], [1.0, 1.0, 2.0, 2.0]);
        // A square image is left alone.
        let sq = Rgb { width: 1, height: 1, rgb: vec![0.5; 3] };
        assert_eq!(sq.clone().into_square(true), sq);
    }

    #[test]
    fn a_png_round_trips_and_a_short_buffer_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.png");
        save_rgb(&p, 2, 1, &[0.0, 0.5, 1.0, 1.0, 1.0, 1.0]).unwrap();
        let back = Rgb::load(&p).unwrap();
        assert_eq!(back.rgb, vec![0.0, 128.0 / 255.0, 1.0, 1.0, 1.0, 1.0]);
        assert_eq!(back.white_mask(), vec![0.0, 1.0]);
        let e = save_rgb(&p, 3, 1, &[0.0; 6]).unwrap_err().to_string();
        assert!(e.contains("3x1"), "{e}");
        assert!(matches!(Rgb::load(&dir.path().join("none.png")), Err(ImageError::Read { .. })));
    }
}
