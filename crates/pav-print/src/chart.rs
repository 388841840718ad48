//! pav's printable colour chart: four ArUco markers at the corners of a page and a grid of
//! colour patches between them, each with its intended sRGB colour. The layout is plain data
//! (millimetres on the page) so that a photo of the printed chart can be read back.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The ArUco dictionary of pav's charts (OpenCV's `DICT_4X4_50`).
pub const DICTIONARY: &str = "DICT_4X4_50";
/// The marker IDs of pav's charts at the top-left, top-right, bottom-right and bottom-left
/// corners (not 0–3, which the common ColorChecker sheets use, so the two are told apart).
pub const MARKER_IDS: [i32; 4] = [10, 11, 12, 13];

/// Where everything sits on the page, in millimetres from its top-left corner.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChartLayout {
    /// Page width and height.
    pub page_mm: [f64; 2],
    /// Printer resolution the PNG is written at.
    pub dpi: f64,
    /// ArUco dictionary name.
    pub dictionary: String,
    /// Marker IDs at the top-left, top-right, bottom-right and bottom-left corners.
    pub marker_ids: [i32; 4],
    /// Each marker's top-left corner, in the same order.
    pub marker_at_mm: [[f64; 2]; 4],
    /// Marker side (black border included).
    pub marker_mm: f64,
    /// Patch side.
    pub patch_mm: f64,
}

/// One colour patch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Patch {
    /// Its ID, printed on it.
    pub id: usize,
    /// Top-left corner on the page.
    pub x_mm: f64,
    /// Top-left corner on the page.
    pub y_mm: f64,
    /// Intended colour, 8-bit sRGB.
    pub r: u8,
    /// Intended colour, 8-bit sRGB.
    pub g: u8,
    /// Intended colour, 8-bit sRGB.
    pub b: u8,
    /// Why it is on the chart: "cube" (spans the gamut), "grey", "texture" (a frequent colour of
    /// the given texture) or "fill".
    pub source: String,
}

impl Patch {
    /// The intended colour in [0, 1].
    pub fn rgb(&self) -> [f64; 3] {
        [self.r, self.g, self.b].map(|v| v as f64 / 255.0)
    }
}

/// A chart: layout and patches.
#[derive(Clone, Debug, PartialEq)]
pub struct Chart {
    /// Where things are.
    pub layout: ChartLayout,
    /// The patches, by ID.
    pub patches: Vec<Patch>,
}

/// Why a chart could not be made or read.
#[derive(Debug, thiserror::Error)]
pub enum ChartError {
    /// A file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The layout file is not a chart layout.
    #[error("{path}: not a pav chart layout: {source}")]
    ChartLayout {
        /// The file.
        path: PathBuf,
        /// The TOML error.
        source: toml::de::Error,
    },
    /// The patch table.
    #[error(transparent)]
    Table(#[from] pav_core::table::TableError),
    /// Page, DPI or patch size out of range.
    #[error("{0}")]
    Invalid(String),
    /// OpenCV (markers, text, PNG).
    #[cfg(feature = "video")]
    #[error("OpenCV: {0}")]
    OpenCv(#[from] opencv::Error),
    /// The PDF.
    #[error(transparent)]
    Pdf(#[from] crate::pdf::PdfError),
    /// The PNG encoder.
    #[error("{path}: {source}")]
    Png {
        /// The file.
        path: PathBuf,
        /// Why.
        source: png::EncodingError,
    },
}

/// What to put on a chart.
#[derive(Clone, Debug)]
pub struct ChartSpec {
    /// Page width and height in millimetres (A4: 210 × 297).
    pub page_mm: [f64; 2],
    /// Printer resolution.
    pub dpi: f64,
    /// Patch side in millimetres.
    pub patch_mm: f64,
    /// Levels per channel of the RGB cube that spans the gamut (6: 216 patches).
    pub cube_levels: usize,
    /// Colours of a texture to include (the most frequent first), in [0, 1].
    pub texture_colours: Vec<[f64; 3]>,
    /// Seed of the patch order (shuffled so that uneven light does not follow colour).
    pub seed: u64,
}

impl Default for ChartSpec {
    fn default() -> Self {
        Self {
            page_mm: [210.0, 297.0],
            dpi: 300.0,
            patch_mm: 8.0,
            cube_levels: 6,
            texture_colours: Vec::new(),
            seed: 1,
        }
    }
}

/// Gap between patches, and margin at the page edge, in millimetres.
const GAP_MM: f64 = 2.0;
const MARGIN_MM: f64 = 10.0;
const MARKER_MM: f64 = 20.0;
const GREYS: usize = 16;

/// The most frequent colours of the texels where `mask` is set (colours binned to 5 bits per
/// channel; each bin's mean), most frequent first, at most `k`.
pub fn frequent_colours(rgb: &[f32], mask: Option<&[f32]>, k: usize) -> Vec<[f64; 3]> {
    let mut bins: std::collections::HashMap<u32, (usize, [f64; 3])> = std::collections::HashMap::new();
    for (i, px) in rgb.chunks_exact(3).enumerate() {
        if mask.is_some_and(|m| m[i] <= 0.5) {
            continue;
        }
        let q = |v: f32| ((v.clamp(0.0, 1.0) * 31.0).round() as u32).min(31);
        let key = (q(px[0]) << 10) | (q(px[1]) << 5) | q(px[2]);
        let e = bins.entry(key).or_insert((0, [0.0; 3]));
        e.0 += 1;
        (0..3).for_each(|c| e.1[c] += px[c] as f64);
    }
    let mut v: Vec<(u32, usize, [f64; 3])> =
        bins.into_iter().map(|(k, (n, s))| (k, n, s.map(|x| x / n as f64))).collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    v.into_iter().take(k).map(|(_, _, c)| c).collect()
}

impl Chart {
    /// Lays out a chart: markers in the corners, patches in a grid between them; the cube and
    /// the greys first, then the texture's colours, then colours drawn at random to fill.
    pub fn new(spec: &ChartSpec) -> Result<Chart, ChartError> {
        let [w, h] = spec.page_mm;
        if !(spec.dpi >= 72.0 && spec.dpi <= 2400.0) {
            return Err(ChartError::Invalid(format!("dpi must be in 72..=2400, got {}", spec.dpi)));
        }
        if !(spec.patch_mm >= 3.0 && spec.patch_mm <= 40.0) {
            return Err(ChartError::Invalid(format!("patch size must be in 3..=40 mm, got {}", spec.patch_mm)));
        }
        let pitch = spec.patch_mm + GAP_MM;
        let (x0, y0) = (MARGIN_MM, MARGIN_MM + MARKER_MM + 2.0 * GAP_MM);
        let (aw, ah) = (w - 2.0 * MARGIN_MM, h - 2.0 * y0);
        let cols = ((aw + GAP_MM) / pitch).floor().max(0.0) as usize;
        let rows = ((ah + GAP_MM) / pitch).floor().max(0.0) as usize;
        let slots = rows * cols;
        let levels = spec.cube_levels;
        let cube = levels.pow(3);
        if slots < cube + GREYS {
            return Err(ChartError::Invalid(format!(
                "a {w}×{h} mm page holds {slots} patches of {} mm: fewer than the {cube} of a {levels}-level cube and {GREYS} greys; use a larger page, smaller patches or fewer levels",
                spec.patch_mm
            )));
        }
        let mut colours: Vec<([f64; 3], &str)> = Vec::with_capacity(slots);
        let l = |i: usize| i as f64 / (levels - 1) as f64;
        for r in 0..levels {
            for g in 0..levels {
                for b in 0..levels {
                    colours.push(([l(r), l(g), l(b)], "cube"));
                }
            }
        }
        // Greys strictly between the cube's levels.
        for i in 0..GREYS {
            let v = (i as f64 + 0.5) / GREYS as f64;
            colours.push(([v; 3], "grey"));
        }
        for c in spec.texture_colours.iter().take(slots - colours.len()) {
            colours.push((*c, "texture"));
        }
        let mut rng = pav_core::rng::Rng::new(spec.seed);
        while colours.len() < slots {
            colours.push(([0; 3].map(|_| rng.unit() as f64), "fill"));
        }
        // Shuffle the places, not the IDs: ID order stays the list's.
        let mut places: Vec<usize> = (0..slots).collect();
        for i in (1..slots).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            places.swap(i, j);
        }
        // Centre the grid in its area.
        let (gw, gh) = (cols as f64 * pitch - GAP_MM, rows as f64 * pitch - GAP_MM);
        let (ox, oy) = (x0 + (aw - gw) / 2.0, y0 + (ah - gh) / 2.0);
        let patches = colours
            .iter()
            .zip(&places)
            .enumerate()
            .map(|(id, ((c, source), &p))| {
                let [r, g, b] = c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
                Patch {
                    id,
                    x_mm: ox + (p % cols) as f64 * pitch,
                    y_mm: oy + (p / cols) as f64 * pitch,
                    r,
                    g,
                    b,
                    source: source.to_string(),
                }
            })
            .collect();
        let m = MARGIN_MM;
        let layout = ChartLayout {
            page_mm: spec.page_mm,
            dpi: spec.dpi,
            dictionary: DICTIONARY.into(),
            marker_ids: MARKER_IDS,
            marker_at_mm: [
                [m, m],
                [w - m - MARKER_MM, m],
                [w - m - MARKER_MM, h - m - MARKER_MM],
                [m, h - m - MARKER_MM],
            ],
            marker_mm: MARKER_MM,
            patch_mm: spec.patch_mm,
        };
        Ok(Chart { layout, patches })
    }

    /// The corners of marker `k` (top-left, top-right, bottom-right, bottom-left, as ArUco
    /// reports them) on the page, in millimetres.
    pub fn marker_corners_mm(&self, k: usize) -> [[f64; 2]; 4] {
        let [x, y] = self.layout.marker_at_mm[k];
        let s = self.layout.marker_mm;
        [[x, y], [x + s, y], [x + s, y + s], [x, y + s]]
    }

    /// Writes `chart.toml` (layout) and `chart.csv` (patches) into `dir`.
    pub fn save(&self, dir: &Path) -> Result<(), ChartError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| ChartError::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let toml = toml::to_string(&self.layout).expect("a layout serializes");
        let path = dir.join(LAYOUT_FILE);
        std::fs::write(&path, toml).map_err(io(&path))?;
        pav_core::table::write_csv(&dir.join(PATCHES_FILE), &self.patches)?;
        Ok(())
    }

    /// Reads a chart written by [`Chart::save`] from its folder (or its `chart.toml`).
    pub fn load(path: &Path) -> Result<Chart, ChartError> {
        let dir = if path.is_dir() { path } else { path.parent().unwrap_or(Path::new(".")) };
        let lp = dir.join(LAYOUT_FILE);
        let text = std::fs::read_to_string(&lp).map_err(|source| ChartError::Io { path: lp.clone(), source })?;
        let layout = toml::from_str(&text).map_err(|source| ChartError::ChartLayout { path: lp, source })?;
        let pp = dir.join(PATCHES_FILE);
        let mut rd = csv::Reader::from_path(&pp)
            .map_err(|e| ChartError::Io { path: pp.clone(), source: std::io::Error::other(e) })?;
        let patches = rd
            .deserialize()
            .collect::<Result<Vec<Patch>, _>>()
            .map_err(|e| ChartError::Io { path: pp.clone(), source: std::io::Error::other(e) })?;
        Ok(Chart { layout, patches })
    }
}

/// The layout file in a chart's folder.
pub const LAYOUT_FILE: &str = "chart.toml";
/// The patch table in a chart's folder.
pub const PATCHES_FILE: &str = "chart.csv";
/// The printable image in a chart's folder.
pub const IMAGE_FILE: &str = "chart.png";

/// The chart as a PDF in a chart folder: print this one, from the program that prints the
/// pieces' PDF, with the same settings.
pub const PDF_FILE: &str = "chart.pdf";

#[cfg(feature = "video")]
mod draw {
    use super::*;
    use opencv::core::{Mat, Point, Scalar, CV_8UC3};
    use opencv::prelude::*;
    use opencv::{aruco, imgproc};

    /// The ArUco dictionary by name (the ones pav's charts and common chart sheets use).
    pub fn dictionary(name: &str) -> Result<opencv::core::Ptr<aruco::Dictionary>, ChartError> {
        use aruco::PREDEFINED_DICTIONARY_NAME as D;
        let d = match name {
            "DICT_4X4_50" => D::DICT_4X4_50,
            "DICT_5X5_50" => D::DICT_5X5_50,
            "DICT_6X6_250" => D::DICT_6X6_250,
            "DICT_7X7_50" => D::DICT_7X7_50,
            "DICT_ARUCO_ORIGINAL" => D::DICT_ARUCO_ORIGINAL,
            other => return Err(ChartError::Invalid(format!("unknown ArUco dictionary {other}"))),
        };
        Ok(aruco::get_predefined_dictionary(d)?)
    }

    impl Chart {
        /// The chart as an 8-bit BGR image at its DPI: white page, markers, patches with their
        /// IDs in a corner, and the 10 mm bar.
        pub fn render(&self) -> Result<Mat, ChartError> {
            let l = &self.layout;
            let ppm = l.dpi / 25.4;
            let px = |mm: f64| (mm * ppm).round() as i32;
            let (w, h) = (px(l.page_mm[0]), px(l.page_mm[1]));
            let mut img = Mat::new_rows_cols_with_default(h, w, CV_8UC3, Scalar::all(255.0))?;
            let dict = dictionary(&l.dictionary)?;
            for (k, id) in l.marker_ids.iter().enumerate() {
                let side = px(l.marker_mm);
                let mut m = Mat::default();
                aruco::draw_marker(&dict, *id, side, &mut m, 1)?;
                let mut bgr = Mat::default();
                imgproc::cvt_color_def(&m, &mut bgr, imgproc::COLOR_GRAY2BGR)?;
                let [x, y] = l.marker_at_mm[k];
                let mut roi = Mat::roi_mut(&mut img, opencv::core::Rect::new(px(x), px(y), side, side))?;
                bgr.copy_to(&mut roi)?;
            }
            let side = px(l.patch_mm);
            let scale = l.patch_mm * ppm / 200.0;
            for p in &self.patches {
                let (x, y) = (px(p.x_mm), px(p.y_mm));
                let colour = Scalar::new(p.b as f64, p.g as f64, p.r as f64, 0.0);
                imgproc::rectangle(
                    &mut img,
                    opencv::core::Rect::new(x, y, side, side),
                    colour,
                    imgproc::FILLED,
                    imgproc::LINE_8,
                    0,
                )?;
                let luma = 0.299 * p.r as f64 + 0.587 * p.g as f64 + 0.114 * p.b as f64;
                let ink = if luma > 128.0 { Scalar::all(0.0) } else { Scalar::all(255.0) };
                let thick = (scale * 1.5).round().max(1.0) as i32;
                imgproc::put_text(
                    &mut img,
                    &p.id.to_string(),
                    Point::new(x + side / 20, y + side - side / 20),
                    imgproc::FONT_HERSHEY_PLAIN,
                    scale,
                    ink,
                    thick,
                    imgproc::LINE_AA,
                    false,
                )?;
            }
            // The bar in the bottom margin, between the lower markers.
            let bytes = img.data_bytes_mut()?;
            let (wu, hu) = (w as usize, h as usize);
            // The image is BGR; the bar is black, so channel order does not matter.
            pav_core::image::draw_scale_bar(
                bytes,
                wu,
                hu,
                [px(l.page_mm[0] / 2.0 - 5.0) as usize, px(l.page_mm[1] - MARGIN_MM / 2.0) as usize],
                ppm,
                10.0,
            );
            Ok(img)
        }

        /// Writes the layout, the patch table, the printable PNG (pHYs at the DPI) and the same
        /// page as `chart.pdf` (sRGB-tagged, as `pieces.pdf` is) into `dir`.
        pub fn write(&self, dir: &Path) -> Result<PathBuf, ChartError> {
            self.save(dir)?;
            let img = self.render()?;
            let (w, h) = (img.cols() as usize, img.rows() as usize);
            let rgb: Vec<u8> = img.data_bytes()?.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]]).collect();
            let path = dir.join(IMAGE_FILE);
            pav_core::image::save_png_dpi(&path, w, h, &rgb, self.layout.dpi)
                .map_err(|source| ChartError::Png { path: path.clone(), source })?;
            let pdf = dir.join(PDF_FILE);
            let bytes = crate::pdf::raster_pdf(&rgb, [w, h], self.layout.page_mm)?;
            std::fs::write(&pdf, bytes).map_err(|source| ChartError::Io { path: pdf.clone(), source })?;
            Ok(path)
        }
    }
}

#[cfg(feature = "video")]
pub use draw::dictionary;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_a4_chart_holds_the_cube_the_greys_and_the_texture_colours_without_overlap() {
        let spec = ChartSpec { texture_colours: vec![[0.1, 0.6, 0.2], [0.9, 0.1, 0.1]], ..Default::default() };
        let c = Chart::new(&spec).unwrap();
        let n = c.patches.len();
        assert!(n >= 216 + 16 + 2, "{n}");
        assert_eq!(c.patches.iter().filter(|p| p.source == "cube").count(), 216);
        assert_eq!(c.patches.iter().filter(|p| p.source == "texture").count(), 2);
        let mut places: Vec<(i64, i64)> =
            c.patches.iter().map(|p| ((p.x_mm * 10.0) as i64, (p.y_mm * 10.0) as i64)).collect();
        places.sort();
        places.dedup();
        assert_eq!(places.len(), n, "two patches share a place");
        // Every patch lies on the page between the markers' rows.
        let l = &c.layout;
        for p in &c.patches {
            assert!(p.x_mm >= 10.0 && p.x_mm + l.patch_mm <= l.page_mm[0] - 10.0);
            assert!(p.y_mm >= 10.0 + l.marker_mm && p.y_mm + l.patch_mm <= l.page_mm[1] - 10.0 - l.marker_mm);
        }
        let small = ChartSpec { page_mm: [100.0, 100.0], ..Default::default() };
        assert!(matches!(Chart::new(&small), Err(ChartError::Invalid(_))));
    }

    #[test]
    fn frequent_colours_come_most_frequent_first_within_the_mask() {
        let mut rgb = Vec::new();
        for _ in 0..5 {
            rgb.extend([0.2f32, 0.4, 0.6]);
        }
        for _ in 0..3 {
            rgb.extend([0.9f32, 0.1, 0.1]);
        }
        rgb.extend([0.0f32, 0.0, 1.0]);
        let f = frequent_colours(&rgb, None, 2);
        assert_eq!(f.len(), 2);
        assert!((f[0][0] - 0.2).abs() < 1e-6 && (f[1][0] - 0.9).abs() < 1e-6);
        let mut mask = vec![1.0f32; 9];
        mask[..5].fill(0.0);
        assert!((frequent_colours(&rgb, Some(&mask), 1)[0][0] - 0.9).abs() < 1e-6);
    }
}
