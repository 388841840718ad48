//! The texture as pieces a person can cut out and stick on: the textured region's connected
//! parts in the atlas (8-connected: texels that touch at a corner are one piece, as the paper
//! would hold together), each at its size on the model, packed onto pages of the user's paper
//! with its cut line and its number, and two check bars per page.
//!
//! Every page pixel of a piece is the pixel of the whole printable sheet at the same DPI
//! ([`pav_core::image::resize::resize_window`] of the same resize), so the pieces put back at
//! their atlas positions are the sheet's region, pixel for pixel.

use crate::panels::Orientation;
use crate::paper::Paper;
use pav_core::image::marks::{draw_arrow, draw_line, draw_text, text_width};
use pav_core::image::resize::resize_window;
use pav_core::image::Frame;
use std::fmt::Write as _;

/// Why the pieces could not be laid out.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PiecesError {
    /// A setting out of its range.
    #[error("{0}")]
    Invalid(String),
    /// The region has no texel.
    #[error("the textured region is empty: nothing to print")]
    Empty,
}

/// How the pieces are laid out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spec {
    /// The paper.
    pub paper: Paper,
    /// Unprinted border on every side, mm (what the printer cannot reach).
    pub margin_mm: f64,
    /// Space between two pieces, mm (room for the scissors).
    pub gap_mm: f64,
    /// A part narrower than this, mm, is listed to paint by hand instead of printed.
    pub min_mm: f64,
    /// How far two tiles of a part too large for the page overlap, mm.
    pub overlap_mm: f64,
    /// How far a piece's own texels are printed past its cut line, mm, so that a cut a little
    /// off the line shows no white paper.
    pub bleed_mm: f64,
    /// Printer resolution.
    pub dpi: f64,
}

impl Spec {
    /// Pixels per millimetre at the spec's DPI.
    pub fn px_per_mm(&self) -> f64 {
        self.dpi / 25.4
    }

    /// The bleed in pixels at the DPI.
    pub fn bleed_px(&self) -> usize {
        (self.bleed_mm * self.px_per_mm()).round() as usize
    }

    /// The printable area of a page, mm: the paper less its margins and the band of bars.
    fn usable_mm(&self) -> [f64; 2] {
        [self.paper.width_mm - 2.0 * self.margin_mm, self.paper.height_mm - 2.0 * self.margin_mm - BAND_MM]
    }

    /// What one piece's own pixels may span on a page: the printable area less its label
    /// below it and its bleed all round.
    fn free_px(&self) -> [usize; 2] {
        let (px, bleed, usable) = (self.px_per_mm(), 2 * self.bleed_px(), self.usable_mm());
        [
            ((usable[0] * px) as usize).saturating_sub(bleed),
            (((usable[1] - LABEL_MM - self.gap_mm) * px) as usize).saturating_sub(bleed),
        ]
    }

    /// A piece `w × h` pixels fits on one page, upright or turned.
    pub fn fits(&self, w: usize, h: usize) -> bool {
        let [fw, fh] = self.free_px();
        (w <= fw && h <= fh) || (h <= fw && w <= fh)
    }
}

impl Default for Spec {
    fn default() -> Self {
        Spec { paper: Paper::A4, margin_mm: 5.0, gap_mm: 2.0, min_mm: 3.0, overlap_mm: 5.0, bleed_mm: 0.0, dpi: 300.0 }
    }
}

/// One connected part of the region in the atlas.
#[derive(Clone, Debug, PartialEq)]
pub struct RegionPart {
    /// Its number in the label image (from 1).
    pub label: u32,
    /// Its texels.
    pub texels: usize,
    /// Its bounding box in texels: x0, y0, x1, y1 (ends excluded).
    pub bbox: [usize; 4],
    /// The UV chart it is, when a part too large for a page was split along its charts.
    pub chart: Option<u32>,
}

/// The up to eight pixels that touch pixel `i` of a `w × h` image, at a side or a corner.
fn neighbours(i: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((i % w) as i64, (i / w) as i64);
    [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)]
        .into_iter()
        .map(move |(dx, dy)| (x + dx, y + dy))
        .filter(move |&(nx, ny)| nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64)
        .map(move |(nx, ny)| ny as usize * w + nx as usize)
}

/// The 8-connected parts of the `n × n` region (on where ≥ 0.5), largest first, and the label
/// of every texel (0: off the region).
pub fn parts(region: &[f32], n: usize) -> (Vec<u32>, Vec<RegionPart>) {
    let mut labels = vec![0u32; n * n];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for start in 0..n * n {
        if region[start] < 0.5 || labels[start] != 0 {
            continue;
        }
        let label = out.len() as u32 + 1;
        let (mut texels, mut bbox) = (0, [n, n, 0, 0]);
        labels[start] = label;
        stack.push(start);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % n, i / n);
            texels += 1;
            bbox = [bbox[0].min(x), bbox[1].min(y), bbox[2].max(x + 1), bbox[3].max(y + 1)];
            for j in neighbours(i, n, n) {
                if region[j] >= 0.5 && labels[j] == 0 {
                    labels[j] = label;
                    stack.push(j);
                }
            }
        }
        out.push(RegionPart { label, texels, bbox, chart: None });
    }
    out.sort_by(|a, b| b.texels.cmp(&a.texels).then(a.label.cmp(&b.label)));
    (labels, out)
}

/// Splits every part too large for one page of `spec` along the UV charts it joins
/// (`charts`: each texel's chart, 0 where no face lies; such texels go with the nearest chart of
/// their part), relabelling `labels`: so that a door and a fender that touch in the atlas
/// print as two pieces rather than as tiles cut across both. Parts that fit stay whole.
pub fn split_by_chart(
    labels: &mut [u32],
    parts: Vec<RegionPart>,
    charts: &[u32],
    sheet: Sheet,
    spec: Spec,
) -> Vec<RegionPart> {
    let n = sheet.n;
    let mut next = parts.iter().map(|p| p.label).max().unwrap_or(0) + 1;
    let mut out = Vec::new();
    for p in parts {
        let [x0, y0, x1, y1] = p.bbox;
        let (w, h) = (sheet.pixels(x0, x1), sheet.pixels(y0, y1));
        if spec.fits(w.1 - w.0, h.1 - h.0) {
            out.push(p);
            continue;
        }
        // Each texel's chart, spread breadth-first within the part to the texels without one.
        let mut chart: Vec<(usize, u32)> = Vec::new();
        let mut seen = std::collections::HashMap::new();
        for y in y0..y1 {
            for x in x0..x1 {
                let i = y * n + x;
                if labels[i] == p.label && charts[i] != 0 {
                    seen.insert(i, charts[i]);
                    chart.push((i, charts[i]));
                }
            }
        }
        let mut ring: Vec<usize> = chart.iter().map(|c| c.0).collect();
        while !ring.is_empty() {
            let mut grown = Vec::new();
            for &i in &ring {
                for j in neighbours(i, n, n) {
                    if labels[j] == p.label && !seen.contains_key(&j) {
                        seen.insert(j, seen[&i]);
                        grown.push(j);
                    }
                }
            }
            ring = grown;
        }
        let mut ids: Vec<u32> = seen.values().copied().collect();
        ids.sort_unstable();
        ids.dedup();
        if ids.len() < 2 {
            out.push(p);
            continue;
        }
        for c in ids {
            let label = next;
            next += 1;
            let (mut texels, mut bbox) = (0, [n, n, 0, 0]);
            for (&i, _) in seen.iter().filter(|(_, &k)| k == c) {
                let (x, y) = (i % n, i / n);
                labels[i] = label;
                texels += 1;
                bbox = [bbox[0].min(x), bbox[1].min(y), bbox[2].max(x + 1), bbox[3].max(y + 1)];
            }
            out.push(RegionPart { label, texels, bbox, chart: Some(c) });
        }
    }
    out.sort_by(|a, b| b.texels.cmp(&a.texels).then(a.label.cmp(&b.label)));
    out
}

/// The printed atlas: `n` texels across, `side_px` pixels across at the spec's DPI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sheet {
    /// Texels across the atlas.
    pub n: usize,
    /// The atlas's side on paper, mm.
    pub atlas_mm: f64,
    /// The atlas's side in pixels at the DPI (as the printable sheet has it).
    pub side_px: usize,
}

impl Sheet {
    /// The atlas of `n` texels printed `atlas_mm` wide at `dpi`.
    pub fn new(n: usize, atlas_mm: f64, dpi: f64) -> Sheet {
        Sheet { n, atlas_mm, side_px: (atlas_mm * dpi / 25.4).round().max(1.0) as usize }
    }

    /// The texel a sheet pixel shows (the nearest texel whose span holds its centre).
    fn texel(&self, px: usize) -> usize {
        ((px as f64 + 0.5) * self.n as f64 / self.side_px as f64).floor().min((self.n - 1) as f64) as usize
    }

    /// The sheet pixels that show texels `t0..t1`.
    fn pixels(&self, t0: usize, t1: usize) -> (usize, usize) {
        let at = |t: usize| ((t as f64 * self.side_px as f64 / self.n as f64) - 0.5).ceil().max(0.0) as usize;
        (at(t0), at(t1).min(self.side_px))
    }
}

/// One piece on a page.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    /// Its number, printed beside it (from 1).
    pub id: usize,
    /// The label of the part it is (or is a tile of).
    pub part: u32,
    /// Its window of the sheet, pixels: x, y, width, height.
    pub window: [usize; 4],
    /// Its tile (column, row) when the part was too large for one page.
    pub tile: Option<(usize, usize)>,
    /// The page it is on (from 1).
    pub page: usize,
    /// Its top-left corner on the page, pixels.
    pub at: [usize; 2],
    /// Turned a quarter clockwise to fit.
    pub rotated: bool,
    /// Printed mirror-imaged, because its UV island is mirrored on the car.
    pub mirrored: bool,
    /// The UV chart it is, where its part was split along its charts.
    pub chart: Option<u32>,
}

impl Piece {
    /// Its size on the page, pixels (width, height), as placed.
    pub fn placed(&self) -> [usize; 2] {
        if self.rotated {
            [self.window[3], self.window[2]]
        } else {
            [self.window[2], self.window[3]]
        }
    }

    /// The sheet pixel under page pixel `(u, v)` of the piece (from its top-left corner):
    /// mirrored first, then turned.
    fn sheet_pixel(&self, u: usize, v: usize) -> (usize, usize) {
        let u = if self.mirrored { self.placed()[0] - 1 - u } else { u };
        let [x, y, _, h] = self.window;
        if self.rotated {
            // A quarter turn clockwise: the window's left column becomes the top row.
            (x + v, y + h - 1 - u)
        } else {
            (x + u, y + v)
        }
    }

    /// Where sheet pixel `(sx, sy)` of the piece's window is on the piece (from its top-left):
    /// [`Piece::sheet_pixel`] undone.
    pub fn page_pixel(&self, sx: usize, sy: usize) -> [usize; 2] {
        let [x, y, _, h] = self.window;
        let [u, v] = if self.rotated { [y + h - 1 - sy, sx - x] } else { [sx - x, sy - y] };
        if self.mirrored {
            [self.placed()[0] - 1 - u, v]
        } else {
            [u, v]
        }
    }

    /// A direction across the sheet (x right, y down) as it runs across the piece on its page.
    pub fn on_page(&self, d: [f64; 2]) -> [f64; 2] {
        let [dx, dy] = if self.rotated { [-d[1], d[0]] } else { d };
        if self.mirrored {
            [-dx, dy]
        } else {
            [dx, dy]
        }
    }
}

/// A part too small to cut: painted by hand in its mean colour.
#[derive(Clone, Debug, PartialEq)]
pub struct ByHand {
    /// The label of the part.
    pub part: u32,
    /// Its mean sRGB colour.
    pub rgb: [u8; 3],
    /// Its size on the model, mm.
    pub size_mm: [f64; 2],
    /// Where it is in the atlas, as a share of its side (x, y of its centre).
    pub at: [f64; 2],
}

/// The pieces on their pages.
#[derive(Clone, Debug, PartialEq)]
pub struct PageLayout {
    /// The spec it was made with.
    pub spec: Spec,
    /// The sheet it cuts.
    pub sheet: Sheet,
    /// Every piece.
    pub pieces: Vec<Piece>,
    /// The parts to paint by hand.
    pub by_hand: Vec<ByHand>,
    /// Pages.
    pub pages: usize,
    /// Each page's size, mm: the paper's, or on a roll its width by the length its pieces take.
    pub page_mm: Vec<[f64; 2]>,
    /// How each part lies on the car, by label − 1 (empty: not known).
    pub orient: Vec<Orientation>,
}

/// A number or bar on a page, in page pixels.
#[derive(Clone, Debug, PartialEq)]
pub enum Mark {
    /// A number `height` pixels tall, its top-left at `at`.
    Text {
        /// Top-left corner.
        at: [usize; 2],
        /// Height in pixels.
        height: f64,
        /// What it says.
        text: String,
    },
    /// A check bar `len_mm` long, its left end's top at `at`.
    Bar {
        /// Left end, top.
        at: [usize; 2],
        /// Length, mm.
        len_mm: f64,
    },
    /// An alignment cross centred on `at`, its arms `arm` pixels long.
    Cross {
        /// Centre.
        at: [usize; 2],
        /// Arm length in pixels.
        arm: f64,
    },
    /// An arrow `len` pixels long centred on `at`, pointing `dir` (x right, y down), with its
    /// letter (`F` the car's front, `U` its up) right of it.
    Arrow {
        /// Centre.
        at: [usize; 2],
        /// Unit direction.
        dir: [f64; 2],
        /// Length in pixels.
        len: f64,
        /// Its letter.
        letter: char,
    },
}

/// A piece before packing: its part, its window of the sheet (x, y, w, h) and its tile.
type Boxed = (u32, [usize; 4], Option<(usize, usize)>);

/// Height of a piece's number below it, and of the page's band of bars, in mm.
const LABEL_MM: f64 = 4.0;
/// Width of a piece's label: its number (two digits) and two arrows with their letters, mm.
const LABEL_W_MM: f64 = 17.0;
const BAND_MM: f64 = 9.0;

/// Lays the parts of `labels` out as pieces on pages.
pub fn layout(
    labels: &[u32],
    parts: &[RegionPart],
    texture: &Frame,
    sheet: Sheet,
    spec: Spec,
    orient: Vec<Orientation>,
) -> Result<PageLayout, PiecesError> {
    let px = spec.px_per_mm();
    let bad = |m: String| Err(PiecesError::Invalid(m));
    if !(spec.dpi.is_finite() && spec.dpi > 0.0) {
        return bad(format!("the DPI must be positive, not {}", spec.dpi));
    }
    for (name, v) in [
        ("margin", spec.margin_mm),
        ("gap", spec.gap_mm),
        ("overlap", spec.overlap_mm),
        ("bleed", spec.bleed_mm),
        ("smallest piece", spec.min_mm),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("the {name} is a length in mm ≥ 0, not {v}"));
        }
    }
    let usable_mm = spec.usable_mm();
    // A tile must hold more than its overlaps and its number.
    let least = 2.0 * spec.overlap_mm + 2.0 * spec.bleed_mm + LABEL_MM + spec.gap_mm + 5.0;
    if usable_mm[0] < least || usable_mm[1] < least {
        return bad(format!(
            "the printable area of {:.0} × {:.0} mm (paper less {} mm margins and the bars) holds no piece: a tile needs {least:.0} mm; use larger paper or a smaller margin",
            usable_mm[0], usable_mm[1], spec.margin_mm
        ));
    }
    if parts.is_empty() {
        return Err(PiecesError::Empty);
    }
    let mm_per_texel = sheet.atlas_mm / sheet.n as f64;
    let mut by_hand = Vec::new();
    let mut boxes = Vec::new();
    let bleed = 2 * spec.bleed_px();
    let [free_w, free_h] = spec.free_px();
    for p in parts {
        let [x0, y0, x1, y1] = p.bbox;
        let size_mm = [(x1 - x0) as f64 * mm_per_texel, (y1 - y0) as f64 * mm_per_texel];
        if size_mm[0].min(size_mm[1]) < spec.min_mm {
            by_hand.push(ByHand {
                part: p.label,
                rgb: mean_colour(labels, p, texture, sheet.n),
                size_mm,
                at: [(x0 + x1) as f64 / 2.0 / sheet.n as f64, (y0 + y1) as f64 / 2.0 / sheet.n as f64],
            });
            continue;
        }
        let (sx0, sx1) = sheet.pixels(x0, x1);
        let (sy0, sy1) = sheet.pixels(y0, y1);
        let (w, h) = (sx1 - sx0, sy1 - sy0);
        if spec.fits(w, h) {
            boxes.push((p.label, [sx0, sy0, w, h], None));
            continue;
        }
        // Too large for a page either way: tiles that overlap, each fitting upright.
        let overlap = (spec.overlap_mm * px).round() as usize;
        let (tw, th) = (free_w.min(w), free_h.min(h));
        let steps = |len: usize, tile: usize| if len <= tile { 1 } else { (len - overlap).div_ceil(tile - overlap) };
        let (cols, rows) = (steps(w, tw), steps(h, th));
        for r in 0..rows {
            for c in 0..cols {
                let tx = sx0 + (c * (tw - overlap)).min(w - tw);
                let ty = sy0 + (r * (th - overlap)).min(h - th);
                boxes.push((p.label, [tx, ty, tw, th], Some((c + 1, r + 1))));
            }
        }
    }
    let (mut pieces, pages) = pack(&boxes, free_w + bleed, (usable_mm[1] * px) as usize, spec);
    for p in &mut pieces {
        p.mirrored = orient.get(p.part as usize - 1).is_some_and(|o| o.mirrored);
        p.chart = parts.iter().find(|q| q.label == p.part).and_then(|q| q.chart);
    }
    let page_mm = (1..=pages)
        .map(|page| {
            if !spec.paper.roll {
                return spec.paper.mm();
            }
            // A roll is cut below its lowest label, with the margin and the band of bars.
            let b = spec.bleed_px() as f64;
            let on = pieces.iter().filter(|p| p.page == page);
            let low = on.map(|p| p.at[1] as f64 + p.placed()[1] as f64 + b).fold(0.0, f64::max);
            [spec.paper.width_mm, ((low / px + LABEL_MM + spec.gap_mm + spec.margin_mm + BAND_MM) * 10.0).ceil() / 10.0]
        })
        .collect();
    Ok(PageLayout { spec, sheet, pieces, by_hand, pages, page_mm, orient })
}

/// Shelf packing, tallest first: each piece turned so that it is wider than tall when that
/// fits, put on the first shelf of the first page with room, else on a new shelf or page.
fn pack(boxes: &[Boxed], free_w: usize, free_h: usize, spec: Spec) -> (Vec<Piece>, usize) {
    let px = spec.px_per_mm();
    let label = ((LABEL_MM + spec.gap_mm) * px).round() as usize;
    let gap = (spec.gap_mm * px).round() as usize;
    let bleed = spec.bleed_px();
    // A piece's label under it is as wide as this at least.
    let label_w = (LABEL_W_MM * px).round() as usize;
    let mut order: Vec<(usize, bool)> =
        boxes.iter().enumerate().map(|(i, (_, [_, _, w, h], _))| (i, h > w && *h + 2 * bleed <= free_w)).collect();
    let placed_h = |i: usize, rot: bool| if rot { boxes[i].1[2] } else { boxes[i].1[3] };
    order.sort_by(|a, b| placed_h(b.0, b.1).cmp(&placed_h(a.0, a.1)).then(a.0.cmp(&b.0)));
    // Per page: shelves (y, height, x filled).
    let mut pages: Vec<Vec<(usize, usize, usize)>> = Vec::new();
    let margin = (spec.margin_mm * px).round() as usize;
    let mut pieces = Vec::new();
    for (i, rot) in order {
        let (part, window, tile) = boxes[i];
        let (w, h) = if rot { (window[3], window[2]) } else { (window[2], window[3]) };
        // The footprint: the piece and its bleed all round, and its label under it.
        let (w, h) = ((w + 2 * bleed).max(label_w), h + 2 * bleed);
        let spot = pages.iter().enumerate().find_map(|(pg, shelves)| {
            shelves.iter().position(|s| s.2 + w <= free_w && h + label <= s.1).map(|k| (pg, Some(k)))
        });
        let (pg, k) = match spot {
            Some((pg, Some(k))) => (pg, k),
            _ => {
                // A new shelf below the last on the first page with room, else a new page.
                let room = pages.iter().position(|s| s.last().map_or(0, |l| l.0 + l.1) + h + label <= free_h);
                let pg = room.unwrap_or_else(|| {
                    pages.push(Vec::new());
                    pages.len() - 1
                });
                let y = pages[pg].last().map_or(0, |l| l.0 + l.1);
                pages[pg].push((y, h + label, 0));
                (pg, pages[pg].len() - 1)
            }
        };
        let shelf = &mut pages[pg][k];
        pieces.push(Piece {
            id: 0,
            part,
            window,
            tile,
            page: pg + 1,
            at: [margin + shelf.2 + bleed, margin + shelf.0 + bleed],
            rotated: rot,
            mirrored: false,
            chart: None,
        });
        shelf.2 += w + gap;
    }
    pieces.sort_by_key(|p| (p.page, p.at[1], p.at[0]));
    for (k, p) in pieces.iter_mut().enumerate() {
        p.id = k + 1;
    }
    (pieces, pages.len())
}

/// The mean sRGB colour of a part's texels.
fn mean_colour(labels: &[u32], p: &RegionPart, texture: &Frame, n: usize) -> [u8; 3] {
    let mut sum = [0u64; 3];
    for y in p.bbox[1]..p.bbox[3] {
        for x in p.bbox[0]..p.bbox[2] {
            if labels[y * n + x] == p.label {
                for (c, total) in sum.iter_mut().enumerate() {
                    *total += texture.bgr[(y * n + x) * 3 + c] as u64;
                }
            }
        }
    }
    sum.map(|s| (s as f64 / p.texels.max(1) as f64).round() as u8)
}

impl PageLayout {
    /// Page `page`'s size (from 1) in pixels at the DPI.
    pub fn page_px(&self, page: usize) -> [usize; 2] {
        self.page_mm[page - 1].map(|mm| (mm * self.spec.px_per_mm()).round() as usize)
    }

    /// The length of paper the pages take, mm (what a roll needs).
    pub fn length_mm(&self) -> f64 {
        self.page_mm.iter().map(|p| p[1]).sum()
    }

    /// Which of `piece`'s page pixels, row by row as placed, show its part (the sheet pixel's
    /// texel is in it): what is printed, cut around and counted.
    fn mask(&self, piece: &Piece, labels: &[u32]) -> Vec<bool> {
        let [w, h] = piece.placed();
        let mut on = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                let (sx, sy) = piece.sheet_pixel(u, v);
                on.push(labels[self.sheet.texel(sy) * self.sheet.n + self.sheet.texel(sx)] == piece.part);
            }
        }
        on
    }

    /// Page `page` (from 1) as 8-bit RGB on white: every piece's pixels as the sheet has them,
    /// and around each its bleed (its own edge pixels carried outward). What the PDF embeds.
    pub fn raster(&self, page: usize, labels: &[u32], texture: &Frame) -> Vec<u8> {
        let [pw, ph] = self.page_px(page);
        let mut rgb = vec![255u8; pw * ph * 3];
        let b = self.spec.bleed_px();
        for piece in self.pieces.iter().filter(|p| p.page == page) {
            let [w, h] = piece.placed();
            let win = resize_window(texture, self.sheet.side_px, self.sheet.side_px, piece.window);
            let mask = self.mask(piece, labels);
            // The footprint (piece and bleed), each pixel the colour of its nearest piece pixel
            // within the bleed: a breadth-first spread from the piece, one ring a step.
            let (fw, fh) = (w + 2 * b, h + 2 * b);
            let mut colour: Vec<Option<[u8; 3]>> = vec![None; fw * fh];
            let mut ring = Vec::new();
            for v in 0..h {
                for u in 0..w {
                    if mask[v * w + u] {
                        let (sx, sy) = piece.sheet_pixel(u, v);
                        let s = ((sy - piece.window[1]) * piece.window[2] + (sx - piece.window[0])) * 3;
                        let i = (v + b) * fw + u + b;
                        colour[i] = Some([win[s] as u8, win[s + 1] as u8, win[s + 2] as u8]);
                        ring.push(i);
                    }
                }
            }
            for _ in 0..b {
                let mut next = Vec::new();
                for &i in &ring {
                    for j in neighbours(i, fw, fh) {
                        if colour[j].is_none() {
                            colour[j] = colour[i];
                            next.push(j);
                        }
                    }
                }
                ring = next;
            }
            for (i, c) in colour.iter().enumerate() {
                if let Some(c) = c {
                    let (pu, pv) = (piece.at[0] + i % fw - b, piece.at[1] + i / fw - b);
                    rgb[(pv * pw + pu) * 3..][..3].copy_from_slice(c);
                }
            }
        }
        rgb
    }

    /// The numbers and bars of page `page`, placed in page pixels: what the PNG draws as
    /// pixels and the PDF as text and vectors.
    pub fn marks(&self, page: usize, labels: &[u32]) -> Vec<Mark> {
        let px = self.spec.px_per_mm();
        let b = self.spec.bleed_px();
        let mut marks = self.alignment(page, labels);
        for piece in self.pieces.iter().filter(|p| p.page == page) {
            let h = piece.placed()[1];
            let (x, y) = (piece.at[0].saturating_sub(b), piece.at[1] + h + b + (0.8 * px) as usize);
            let text = piece.id.to_string();
            let mut x_end = x + (text_width(&text, 2.5 * px)).ceil() as usize;
            marks.push(Mark::Text { at: [x, y], height: 2.5 * px, text });
            let o = self.orient.get(piece.part as usize - 1);
            for (dir, letter) in [(o.and_then(|o| o.front), 'F'), (o.and_then(|o| o.up), 'U')] {
                if let Some(d) = dir {
                    let centre = [x_end + (3.0 * px) as usize, y + (1.25 * px) as usize];
                    marks.push(Mark::Arrow { at: centre, dir: piece.on_page(d), len: 2.6 * px, letter });
                    x_end += (6.5 * px) as usize;
                }
            }
        }
        // The band along the bottom: the page number, then the 10 mm and 50 mm bars.
        let margin = (self.spec.margin_mm * px).round() as usize;
        let band_y = self.page_px(page)[1] - margin - (BAND_MM * px) as usize;
        marks.push(Mark::Text { at: [margin, band_y + (2.0 * px) as usize], height: 3.0 * px, text: page.to_string() });
        for (k, len_mm) in [10.0, 50.0].into_iter().enumerate() {
            let x = margin + ((15.0 + k as f64 * 20.0) * px) as usize;
            marks.push(Mark::Bar { at: [x, band_y + (5.0 * px) as usize], len_mm });
        }
        marks
    }

    /// The alignment crosses on page `page`'s tiles: where two tiles of a part overlap, three
    /// points on the middle line of the overlap (on the part), marked on both tiles, so that
    /// laid over each other the crosses meet.
    fn alignment(&self, page: usize, labels: &[u32]) -> Vec<Mark> {
        let arm = 1.5 * self.spec.px_per_mm();
        let mut marks = Vec::new();
        for piece in self.pieces.iter().filter(|p| p.page == page && p.tile.is_some()) {
            for other in self.pieces.iter().filter(|o| o.part == piece.part && o.id != piece.id && o.tile.is_some()) {
                let ([ax, ay, aw, ah], [bx, by, bw, bh]) = (piece.window, other.window);
                let (x0, x1, y0, y1) = (ax.max(bx), (ax + aw).min(bx + bw), ay.max(by), (ay + ah).min(by + bh));
                if x0 >= x1 || y0 >= y1 {
                    continue;
                }
                // The overlap runs along the longer of its sides; the marks sit on its middle.
                let along_x = x1 - x0 > y1 - y0;
                let len = if along_x { x1 - x0 } else { y1 - y0 };
                for k in 1..=3 {
                    let t = len * k / 4;
                    let (sx, sy) = if along_x { (x0 + t, (y0 + y1) / 2) } else { ((x0 + x1) / 2, y0 + t) };
                    if labels[self.sheet.texel(sy) * self.sheet.n + self.sheet.texel(sx)] != piece.part {
                        continue;
                    }
                    let [u, v] = piece.page_pixel(sx, sy);
                    marks.push(Mark::Cross { at: [piece.at[0] + u, piece.at[1] + v], arm });
                }
            }
        }
        marks
    }

    /// The cut line of `piece`: the edges between its pixels and the rest, merged into runs,
    /// in page pixels (x0, y0, x1, y1 on pixel corners).
    pub fn cut_line(&self, piece: &Piece, labels: &[u32]) -> Vec<[usize; 4]> {
        let [w, h] = piece.placed();
        let mask = self.mask(piece, labels);
        let on = |u: i64, v: i64| {
            u >= 0 && v >= 0 && (u as usize) < w && (v as usize) < h && mask[v as usize * w + u as usize]
        };
        let [x, y] = piece.at;
        let mut out = Vec::new();
        // Horizontal edges lie on row lines 0..=h, vertical ones on column lines 0..=w.
        for line in 0..=h as i64 {
            let mut run: Option<usize> = None;
            for u in 0..=w {
                let edge = u < w && on(u as i64, line - 1) != on(u as i64, line);
                match (edge, run) {
                    (true, None) => run = Some(u),
                    (false, Some(s)) => {
                        out.push([x + s, y + line as usize, x + u, y + line as usize]);
                        run = None;
                    }
                    _ => {}
                }
            }
        }
        for line in 0..=w as i64 {
            let mut run: Option<usize> = None;
            for v in 0..=h {
                let edge = v < h && on(line - 1, v as i64) != on(line, v as i64);
                match (edge, run) {
                    (true, None) => run = Some(v),
                    (false, Some(s)) => {
                        out.push([x + line as usize, y + s, x + line as usize, y + v]);
                        run = None;
                    }
                    _ => {}
                }
            }
        }
        out
    }

    /// Page `page` (from 1) as 8-bit RGB, the PNG: the raster, a grey cut line just outside
    /// each piece, and the marks.
    pub fn render(&self, page: usize, labels: &[u32], texture: &Frame) -> Vec<u8> {
        let [pw, ph] = self.page_px(page);
        let mut rgb = self.raster(page, labels, texture);
        for piece in self.pieces.iter().filter(|p| p.page == page) {
            let [w, h] = piece.placed();
            let mask = self.mask(piece, labels);
            let inside = |u: i64, v: i64| {
                u >= 0 && v >= 0 && (u as usize) < w && (v as usize) < h && mask[v as usize * w + u as usize]
            };
            // The cut line: the pixels around the piece that are not on it.
            for v in -1..=h as i64 {
                for u in -1..=w as i64 {
                    if inside(u, v) {
                        continue;
                    }
                    let near = (-1..=1).any(|dv| (-1..=1).any(|du| inside(u + du, v + dv)));
                    let (pu, pv) = (piece.at[0] as i64 + u, piece.at[1] as i64 + v);
                    if near && pu >= 0 && pv >= 0 && (pu as usize) < pw && (pv as usize) < ph {
                        rgb[(pv as usize * pw + pu as usize) * 3..][..3].fill(96);
                    }
                }
            }
        }
        let px = self.spec.px_per_mm();
        for mark in self.marks(page, labels) {
            match mark {
                Mark::Text { at, height, text } => draw_text(&mut rgb, pw, at, &text, height),
                Mark::Bar { at, len_mm } => pav_core::image::draw_scale_bar(&mut rgb, pw, ph, at, px, len_mm),
                Mark::Cross { at, arm } => {
                    for d in [[1.0, 0.0], [0.0, 1.0]] {
                        draw_line(&mut rgb, pw, at, d, 2.0 * arm);
                    }
                }
                Mark::Arrow { at, dir, len, letter } => {
                    draw_arrow(&mut rgb, pw, at, dir, len);
                    let x = at[0] + (len / 2.0 + 0.5 * px) as usize;
                    draw_text(&mut rgb, pw, [x, at[1] - (px as usize)], &letter.to_string(), 2.0 * px);
                }
            }
        }
        rgb
    }

    /// `pieces.csv`: a row per piece: its page, its place and size on the page in mm (and in
    /// pixels at the DPI), whether it is turned, its part and tile, and the window of the
    /// printable sheet it is, in pixels, so that it can be put back exactly.
    pub fn csv(&self) -> String {
        let mm = |p: usize| p as f64 / self.spec.px_per_mm();
        let mut s = String::from(
            "piece,page,x_mm,y_mm,width_mm,height_mm,rotated,mirrored,part,chart,panel,front_deg,up_deg,tile,page_x_px,page_y_px,sheet_x_px,sheet_y_px,sheet_w_px,sheet_h_px\n",
        );
        for p in &self.pieces {
            let [w, h] = p.placed();
            let tile = p.tile.map_or(String::new(), |(c, r)| format!("{c}x{r}"));
            let [sx, sy, sw, sh] = p.window;
            let o = self.orient.get(p.part as usize - 1);
            let panel = o.and_then(|o| o.panel).map_or(String::new(), |p| p.to_string());
            let chart = p.chart.map_or(String::new(), |c| c.to_string());
            // Counter-clockwise from the page's right, as a person reads an arrow on paper.
            let deg = |d: Option<[f64; 2]>| {
                d.map_or(String::new(), |d| {
                    let d = p.on_page(d);
                    format!("{:.0}", (-d[1]).atan2(d[0]).to_degrees().rem_euclid(360.0))
                })
            };
            let _ = writeln!(
                s,
                "{},{},{:.1},{:.1},{:.1},{:.1},{},{},{},{chart},{panel},{},{},{tile},{},{},{sx},{sy},{sw},{sh}",
                p.id,
                p.page,
                mm(p.at[0]),
                mm(p.at[1]),
                mm(w),
                mm(h),
                p.rotated,
                p.mirrored,
                p.part,
                deg(o.and_then(|o| o.front)),
                deg(o.and_then(|o| o.up)),
                p.at[0],
                p.at[1]
            );
        }
        s
    }

    /// `by_hand.csv`: the parts too small to cut, each with its size on the model, its mean
    /// colour and where its centre is in the atlas (shares of its side).
    pub fn by_hand_csv(&self) -> String {
        let mut s = String::from("part,width_mm,height_mm,colour,atlas_x,atlas_y\n");
        for b in &self.by_hand {
            let [r, g, bl] = b.rgb;
            let _ = writeln!(
                s,
                "{},{:.1},{:.1},#{r:02x}{g:02x}{bl:02x},{:.4},{:.4}",
                b.part, b.size_mm[0], b.size_mm[1], b.at[0], b.at[1]
            );
        }
        s
    }

    /// The share of the pages' printable area the pieces cover.
    pub fn paper_used(&self, labels: &[u32]) -> f64 {
        let on: usize = self.pieces.iter().map(|p| self.mask(p, labels).iter().filter(|&&m| m).count()).sum();
        let px = self.spec.px_per_mm();
        let margin = 2.0 * self.spec.margin_mm;
        let area: f64 = self.page_mm.iter().map(|[w, h]| (w - margin) * (h - margin)).sum();
        on as f64 / (area * px * px).max(f64::MIN_POSITIVE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16-texel atlas with three parts: a 6×5 block, a diagonal pair (one part by its
    /// corner) and a column one texel wide, 8 long.
    fn atlas() -> (Vec<f32>, Frame) {
        let n = 16;
        let mut region = vec![0.0; n * n];
        for y in 2..7 {
            for x in 1..7 {
                region[y * n + x] = 1.0;
            }
        }
        region[10 * n + 10] = 1.0;
        region[11 * n + 11] = 1.0;
        for y in 3..11 {
            region[y * n + 14] = 1.0;
        }
        let bgr = (0..n * n * 3).map(|i| ((i * 37) % 251) as u8).collect();
        (region, Frame { width: n, height: n, bgr })
    }

    #[test]
    fn parts_are_eight_connected_and_largest_first() {
        let (region, _) = atlas();
        let (labels, p) = parts(&region, 16);
        assert_eq!(p.iter().map(|p| p.texels).collect::<Vec<_>>(), [30, 8, 2]);
        assert_eq!(p[0].bbox, [1, 2, 7, 7]);
        assert_eq!(p[2].bbox, [10, 10, 12, 12], "touching at a corner is one part");
        assert_eq!(labels.iter().filter(|&&l| l != 0).count(), 40);
    }

    #[test]
    fn pieces_put_back_are_the_sheet_and_never_overlap_or_leave_the_printable_area() {
        let (region, tex) = atlas();
        let (labels, p) = parts(&region, 16);
        // 16 texels on 160 mm: 10 mm a texel; the column is 10 mm wide, so printed, and every
        // part fits the page whole.
        let sheet = Sheet::new(16, 160.0, 25.4);
        let spec = Spec { paper: Paper::sheet(100.0, 120.0), dpi: 25.4, ..Spec::default() };
        let l = layout(&labels, &p, &tex, sheet, spec, Vec::new()).unwrap();
        assert!(l.by_hand.is_empty() && l.pieces.iter().all(|p| p.tile.is_none()), "{:?}", l.pieces);
        let whole = pav_core::image::resize::resize(&tex, 160, 160, pav_core::image::resize::Interpolation::Bilinear);
        let pages: Vec<Vec<u8>> = (1..=l.pages).map(|pg| l.render(pg, &labels, &tex)).collect();
        let [pw, _] = l.page_px(1);
        let mut covered = vec![0u32; 160 * 160];
        for piece in &l.pieces {
            let [w, h] = piece.placed();
            let mask = l.mask(piece, &labels);
            assert!(piece.at[0] >= 5 && piece.at[0] + w <= 95 && piece.at[1] >= 5, "{piece:?}");
            for v in 0..h {
                for u in 0..w {
                    if !mask[v * w + u] {
                        continue;
                    }
                    let (sx, sy) = piece.sheet_pixel(u, v);
                    covered[sy * 160 + sx] += 1;
                    let page = &pages[piece.page - 1];
                    let at = ((piece.at[1] + v) * pw + piece.at[0] + u) * 3;
                    assert_eq!(
                        &page[at..at + 3],
                        whole[(sy * 160 + sx) * 3..][..3].iter().map(|&x| x as u8).collect::<Vec<_>>().as_slice()
                    );
                }
            }
        }
        // Every sheet pixel of the region is on exactly one piece.
        for (i, c) in covered.iter().enumerate() {
            let on = labels[sheet.texel(i / 160) * 16 + sheet.texel(i % 160)] != 0;
            assert_eq!(*c, on as u32, "sheet pixel {i}");
        }
        // No two pieces overlap on a page.
        for a in &l.pieces {
            for b in l.pieces.iter().filter(|b| b.id > a.id && b.page == a.page) {
                let ([aw, ah], [bw, bh]) = (a.placed(), b.placed());
                let apart = a.at[0] + aw <= b.at[0]
                    || b.at[0] + bw <= a.at[0]
                    || a.at[1] + ah <= b.at[1]
                    || b.at[1] + bh <= a.at[1];
                assert!(apart, "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn slivers_go_to_paint_by_hand_and_a_part_larger_than_the_page_is_tiled() {
        let (region, tex) = atlas();
        let (labels, p) = parts(&region, 16);
        // 2 mm a texel: the one-texel column is a 2 mm sliver, the pair 4 mm.
        let l =
            layout(&labels, &p, &tex, Sheet::new(16, 32.0, 254.0), Spec { dpi: 254.0, ..Spec::default() }, Vec::new())
                .unwrap();
        assert_eq!(l.by_hand.len(), 1);
        assert_eq!(l.by_hand[0].size_mm, [2.0, 16.0]);
        assert!(l.by_hand_csv().lines().nth(1).unwrap().contains(",2.0,16.0,#"), "{}", l.by_hand_csv());
        // The 6×5 block at 100 mm a texel (600 × 500 mm) needs tiles on A4.
        let big = layout(
            &labels,
            &p[..1],
            &tex,
            Sheet::new(16, 1600.0, 25.4),
            Spec { dpi: 25.4, ..Spec::default() },
            Vec::new(),
        )
        .unwrap();
        assert!(big.pieces.len() >= 6 && big.pieces.iter().all(|t| t.tile.is_some()), "{:?}", big.pieces);
        // Every alignment cross is on a pixel its tile shares with a neighbour, and that
        // neighbour marks the same sheet pixel.
        let crosses = |piece: &Piece| -> Vec<(usize, usize)> {
            big.alignment(piece.page, &labels)
                .into_iter()
                .filter_map(|m| match m {
                    Mark::Cross { at, .. } => Some(at),
                    _ => None,
                })
                .filter(|at| {
                    let [w, h] = piece.placed();
                    (piece.at[0]..piece.at[0] + w).contains(&at[0]) && (piece.at[1]..piece.at[1] + h).contains(&at[1])
                })
                .map(|at| piece.sheet_pixel(at[0] - piece.at[0], at[1] - piece.at[1]))
                .collect()
        };
        let marked: Vec<Vec<(usize, usize)>> = big.pieces.iter().map(crosses).collect();
        assert!(marked.iter().all(|m| !m.is_empty()), "{marked:?}");
        for (k, m) in marked.iter().enumerate() {
            for s in m {
                assert!(
                    marked.iter().enumerate().any(|(j, o)| j != k && o.contains(s)),
                    "tile {k}'s cross at {s:?} is alone"
                );
            }
        }
    }

    #[test]
    fn a_mirrored_piece_prints_mirror_imaged_and_a_roll_is_cut_to_its_pieces() {
        let (region, tex) = atlas();
        let (labels, p) = parts(&region, 16);
        let sheet = Sheet::new(16, 160.0, 25.4);
        let spec = Spec { paper: Paper::sheet(100.0, 120.0), dpi: 25.4, ..Spec::default() };
        let mirrored = Orientation { panel: None, front: Some([1.0, 0.0]), up: None, mirrored: true };
        let plain = Orientation { mirrored: false, ..mirrored };
        let orient: Vec<Orientation> = p.iter().map(|q| if q.label == p[0].label { mirrored } else { plain }).collect();
        let l = layout(&labels, &p, &tex, sheet, spec, orient).unwrap();
        let big = l.pieces.iter().find(|q| q.part == p[0].label).unwrap();
        assert!(big.mirrored && !big.rotated, "{big:?}");
        // Its page row is the sheet's row read right to left, and its front points left.
        let [w, _] = big.placed();
        let page = l.render(big.page, &labels, &tex);
        let whole = pav_core::image::resize::resize(&tex, 160, 160, pav_core::image::resize::Interpolation::Bilinear);
        let (sx, sy) = (big.window[0], big.window[1] + 5);
        for u in 0..w {
            let at = ((big.at[1] + 5) * l.page_px(1)[0] + big.at[0] + u) * 3;
            let s = (sy * 160 + sx + w - 1 - u) * 3;
            assert_eq!(page[at..at + 3], whole[s..s + 3].iter().map(|&v| v as u8).collect::<Vec<_>>()[..]);
        }
        assert_eq!(big.on_page([1.0, 0.0]), [-1.0, 0.0]);
        // A roll 100 mm wide takes the length its pieces need, not a fixed page.
        let roll = Spec { paper: "roll:100mm".parse().unwrap(), ..spec };
        let r = layout(&labels, &p, &tex, sheet, roll, Vec::new()).unwrap();
        let low = r.pieces.iter().map(|q| q.at[1] + q.placed()[1]).max().unwrap() as f64;
        assert_eq!(r.pages, 1);
        assert!(r.page_mm[0][1] > low && r.page_mm[0][1] < low + 30.0, "{:?} below {low} mm", r.page_mm);
    }

    #[test]
    fn a_part_too_large_for_the_page_is_split_along_its_charts_before_it_is_tiled() {
        let (region, tex) = atlas();
        let (mut labels, p) = parts(&region, 16);
        // The 6 × 5 block is two charts, its left 3 columns and its right 3, and one texel of
        // it lies under no face. At 10 mm a texel on a 60 × 80 mm page the 60 mm block fits
        // no page, its 30 mm halves do.
        let mut charts = vec![0u32; 256];
        for y in 2..7 {
            for x in 1..7 {
                charts[y * 16 + x] = if x < 4 { 7 } else { 9 };
            }
        }
        charts[2 * 16 + 6] = 0;
        let sheet = Sheet::new(16, 160.0, 25.4);
        let spec = Spec { paper: Paper::sheet(60.0, 80.0), dpi: 25.4, min_mm: 0.0, ..Spec::default() };
        let split = split_by_chart(&mut labels, p.clone(), &charts, sheet, spec);
        let halves: Vec<&RegionPart> = split.iter().filter(|q| q.chart.is_some()).collect();
        assert_eq!(halves.len(), 2, "{split:?}");
        assert_eq!(halves.iter().map(|q| q.texels).sum::<usize>(), 30, "the texel under no face went with a chart");
        assert_eq!(labels.iter().filter(|&&l| l != 0).count(), 40);
        let l = layout(&labels, &split, &tex, sheet, spec, Vec::new()).unwrap();
        // The halves print whole; the column, one chart 80 mm long, is still tiled.
        let whole: Vec<&Piece> = l.pieces.iter().filter(|q| q.chart.is_some()).collect();
        assert!(whole.len() == 2 && whole.iter().all(|q| q.tile.is_none()), "{:?}", l.pieces);
    }

    #[test]
    fn bad_settings_are_refused_with_their_fix() {
        let (region, tex) = atlas();
        let (labels, p) = parts(&region, 16);
        let sheet = Sheet::new(16, 160.0, 300.0);
        let tiny = Spec { paper: Paper::sheet(30.0, 30.0), ..Spec::default() };
        assert!(
            matches!(layout(&labels, &p, &tex, sheet, tiny, Vec::new()), Err(PiecesError::Invalid(m)) if m.contains("larger paper"))
        );
        let zero = Spec { dpi: 0.0, ..Spec::default() };
        assert!(
            matches!(layout(&labels, &p, &tex, sheet, zero, Vec::new()), Err(PiecesError::Invalid(m)) if m.contains("DPI"))
        );
        assert_eq!(layout(&labels, &[], &tex, sheet, Spec::default(), Vec::new()), Err(PiecesError::Empty));
    }
}
