//! The pieces as a PDF at physical size: one page per sheet of paper, the pieces' pixels as one
//! sRGB raster at the layout's DPI (its ICC profile embedded, so that a colour-managed driver
//! prints the colours the texture was optimized in, never a soft proof), and the cut lines,
//! numbers and check bars as vectors, sharp at any printer resolution.
//!
//! Written with `pdf-writer` (typst's step-by-step writer): it only serializes, so the layout
//! stays the one description of every page, and it pulls in no font or image stack.

use crate::pieces::{Mark, PageLayout};
use pav_core::image::Frame;
use pdf_writer::{Content, Filter, Finish, Name, Pdf, Rect, Ref, Str};

/// Points per millimetre (a point is 1/72 inch).
const PT_PER_MM: f64 = 72.0 / 25.4;

/// Why the PDF could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PdfError {
    /// LittleCMS could not serialize the sRGB profile.
    #[error("the sRGB profile: {0}")]
    Profile(String),
}

/// Writes LittleCMS's sRGB profile as object `id`, the colour space every printed raster is
/// tagged with.
fn srgb_profile(pdf: &mut Pdf, id: Ref) -> Result<(), PdfError> {
    let icc = lcms2::Profile::new_srgb().icc().map_err(|e| PdfError::Profile(e.to_string()))?;
    let packed = miniz_oxide::deflate::compress_to_vec_zlib(&icc, LEVEL);
    let mut profile = pdf.icc_profile(id, &packed);
    profile.filter(Filter::FlateDecode);
    profile.n(3).range([0.0, 1.0, 0.0, 1.0, 0.0, 1.0]);
    profile.finish();
    Ok(())
}

/// Writes `rgb` (`w × h`, 8-bit sRGB) as image object `id` in the colour space of the profile
/// `icc`: one colour path for the chart and the pieces, so that pieces print as the chart the
/// calibration measured did.
fn srgb_image(pdf: &mut Pdf, id: Ref, icc: Ref, rgb: &[u8], [w, h]: [usize; 2]) {
    let data = miniz_oxide::deflate::compress_to_vec_zlib(rgb, LEVEL);
    let mut image = pdf.image_xobject(id, &data);
    image.filter(Filter::FlateDecode);
    image.width(w as i32).height(h as i32).bits_per_component(8);
    image.color_space().icc_based(icc);
    image.finish();
}

/// Deflate's level for every stream.
const LEVEL: u8 = miniz_oxide::deflate::CompressionLevel::DefaultLevel as u8;

/// One page of `page_mm` that is the raster `rgb` (`w × h`, 8-bit sRGB): what `chart.pdf`
/// holds.
pub fn raster_pdf(rgb: &[u8], size: [usize; 2], page_mm: [f64; 2]) -> Result<Vec<u8>, PdfError> {
    let mut pdf = Pdf::new();
    let (catalog, tree, icc, page, content, image) =
        (Ref::new(1), Ref::new(2), Ref::new(3), Ref::new(4), Ref::new(5), Ref::new(6));
    pdf.catalog(catalog).pages(tree);
    pdf.pages(tree).kids([page]).count(1);
    srgb_profile(&mut pdf, icc)?;
    let (w, h) = ((page_mm[0] * PT_PER_MM) as f32, (page_mm[1] * PT_PER_MM) as f32);
    let mut p = pdf.page(page);
    p.media_box(Rect::new(0.0, 0.0, w, h));
    p.parent(tree);
    p.contents(content);
    p.resources().x_objects().pair(Name(b"Im"), image);
    p.finish();
    srgb_image(&mut pdf, image, icc, rgb, size);
    let mut c = Content::new();
    c.save_state().transform([w, 0.0, 0.0, h, 0.0, 0.0]);
    c.x_object(Name(b"Im")).restore_state();
    pdf.stream(content, &c.finish());
    Ok(pdf.finish())
}

/// The layout's pages as one PDF: what `pieces.pdf` holds.
pub fn pieces_pdf(layout: &PageLayout, labels: &[u32], texture: &Frame) -> Result<Vec<u8>, PdfError> {
    let mut pdf = Pdf::new();
    let (catalog, tree, icc_id, font, bold) = (Ref::new(1), Ref::new(2), Ref::new(3), Ref::new(4), Ref::new(5));
    // Three objects a page: the page, its content and its raster.
    let page_ref = |k: usize, o: i32| Ref::new(6 + 3 * k as i32 + o);
    pdf.catalog(catalog).pages(tree);
    pdf.pages(tree).kids((0..layout.pages).map(|k| page_ref(k, 0))).count(layout.pages as i32);
    srgb_profile(&mut pdf, icc_id)?;
    // Two of the fourteen fonts every reader has: nothing to embed.
    pdf.type1_font(font).base_font(Name(b"Helvetica"));
    pdf.type1_font(bold).base_font(Name(b"Helvetica-Bold"));
    let pt = |px: f64| (px / layout.spec.dpi * 72.0) as f32;
    for k in 0..layout.pages {
        let page = k + 1;
        let [mm_w, mm_h] = layout.page_mm[k];
        let (page_w, page_h) = ((mm_w * PT_PER_MM) as f32, (mm_h * PT_PER_MM) as f32);
        // Page pixels (x right, y down) to PDF points (y up from the bottom).
        let at = |x: f64, y: f64| (pt(x), page_h - pt(y));
        let mut p = pdf.page(page_ref(k, 0));
        p.media_box(Rect::new(0.0, 0.0, page_w, page_h));
        p.parent(tree);
        p.contents(page_ref(k, 1));
        let mut res = p.resources();
        res.x_objects().pair(Name(b"Im"), page_ref(k, 2));
        res.fonts().pair(Name(b"F"), font).pair(Name(b"B"), bold);
        res.finish();
        p.finish();

        srgb_image(&mut pdf, page_ref(k, 2), icc_id, &layout.raster(page, labels, texture), layout.page_px(page));

        let mut c = Content::new();
        // The raster spans the page: its pixels are the page's rounded to whole ones (under
        // 0.1 mm off on any paper), and a renderer at the PNG's resolution maps them one to one
        // instead of resampling every pixel by a fraction.
        c.save_state().transform([page_w, 0.0, 0.0, page_h, 0.0, 0.0]);
        c.x_object(Name(b"Im")).restore_state();
        // Cut lines: a hairline of 0.25 pt in mid grey, on the pieces' own edges.
        c.set_line_width(0.25).set_stroke_gray(0.4);
        for piece in layout.pieces.iter().filter(|p| p.page == page) {
            for [ax, ay, bx, by] in layout.cut_line(piece, labels) {
                let ((x, y), (u, v)) = (at(ax as f64, ay as f64), at(bx as f64, by as f64));
                c.move_to(x, y).line_to(u, v);
            }
        }
        c.stroke();
        c.set_fill_gray(0.0);
        let px_per_mm = layout.spec.px_per_mm();
        for mark in layout.marks(page, labels) {
            match mark {
                Mark::Text { at: [x, y], height, text } => {
                    // The top of the text where the PNG's digits start: cap height ≈ 0.72 em.
                    let size = pt(height) / 0.72;
                    let (tx, ty) = at(x as f64, y as f64 + height);
                    c.begin_text().set_font(Name(b"B"), size).next_line(tx, ty);
                    c.show(Str(text.as_bytes())).end_text();
                }
                Mark::Bar { at: [x, y], len_mm } => {
                    // The bar as the PNG draws it: 1 mm thick, a tick each mm, longer every 5.
                    let thick = px_per_mm.round().max(1.0);
                    let len = (len_mm * px_per_mm).round();
                    let (bx, by) = at(x as f64, y as f64 + thick);
                    c.rect(bx, by, pt(len), pt(thick));
                    for m in 0..=len_mm as usize {
                        let tick = if m % 5 == 0 { 2.0 * thick } else { thick };
                        let tx = (x as f64 + (m as f64 * px_per_mm).round()).min(x as f64 + len - 1.0);
                        let (tx, ty) = at(tx, y as f64);
                        c.rect(tx, ty, pt(1.0).max(0.24), pt(tick));
                    }
                    c.fill_nonzero();
                    let (lx, ly) = at(x as f64, y as f64 + thick + 3.0 * px_per_mm);
                    c.begin_text().set_font(Name(b"F"), 6.0).next_line(lx, ly);
                    c.show(Str(format!("{len_mm} mm").as_bytes())).end_text();
                }
                Mark::Cross { at: [x, y], arm } => {
                    let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                    let ((l, m), (r, n)) = (at(cx - arm, cy), at(cx + arm, cy));
                    let ((t, u), (b, v)) = (at(cx, cy - arm), at(cx, cy + arm));
                    c.set_line_width(0.3).set_stroke_gray(0.0);
                    c.move_to(l, m).line_to(r, n).move_to(t, u).line_to(b, v).stroke();
                }
                Mark::Arrow { at: [x, y], dir, len, letter } => {
                    let (cx, cy) = (x as f64, y as f64);
                    let tip = at(cx + dir[0] * len / 2.0, cy + dir[1] * len / 2.0);
                    let tail = at(cx - dir[0] * len / 2.0, cy - dir[1] * len / 2.0);
                    let back = |a: f64| {
                        let (co, si) = (a.cos(), a.sin());
                        let d = [dir[0] * co - dir[1] * si, dir[0] * si + dir[1] * co];
                        at(cx + dir[0] * len / 2.0 - d[0] * len * 0.4, cy + dir[1] * len / 2.0 - d[1] * len * 0.4)
                    };
                    c.set_line_width(pt(len / 12.0)).set_stroke_gray(0.0);
                    c.move_to(tail.0, tail.1).line_to(tip.0, tip.1).stroke();
                    let (l, r) = (back(0.5), back(-0.5));
                    c.move_to(l.0, l.1).line_to(tip.0, tip.1).line_to(r.0, r.1).close_path().fill_nonzero();
                    let (lx, ly) = at(cx + len / 2.0 + 0.5 * px_per_mm, cy + px_per_mm);
                    c.begin_text().set_font(Name(b"B"), 7.0).next_line(lx, ly);
                    c.show(Str(letter.to_string().as_bytes())).end_text();
                }
            }
        }
        pdf.stream(page_ref(k, 1), &c.finish());
    }
    Ok(pdf.finish())
}

/// An image with a caption, for a PDF of figures.
pub struct Figure {
    /// Interleaved 8-bit RGB.
    pub rgb: Vec<u8>,
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// What it shows.
    pub caption: String,
}

/// `figures` on pages of `paper`, `columns` across, each as wide as a column allows with its
/// caption under it: the placement guide's PDF.
pub fn figures_pdf(figures: &[Figure], paper: crate::paper::Paper, columns: usize) -> Vec<u8> {
    let (margin, gap, caption) = (12.0 * PT_PER_MM, 6.0 * PT_PER_MM, 12.0);
    let [w_mm, h_mm] = if paper.roll { crate::paper::Paper::A4.mm() } else { paper.mm() };
    let (page_w, page_h) = ((w_mm * PT_PER_MM) as f32, (h_mm * PT_PER_MM) as f32);
    let columns = columns.max(1);
    let col_w = (page_w as f64 - 2.0 * margin - (columns - 1) as f64 * gap) / columns as f64;
    // Rows a page holds: the tallest figure's height at column width, and its caption.
    let tallest = figures.iter().map(|f| f.height as f64 / f.width.max(1) as f64).fold(1.0, f64::max) * col_w;
    let rows = (((page_h as f64 - 2.0 * margin + gap) / (tallest + caption + gap)).floor() as usize).max(1);
    let per_page = rows * columns;
    let pages = figures.len().div_ceil(per_page).max(1);
    let mut pdf = Pdf::new();
    let (catalog, tree, font) = (Ref::new(1), Ref::new(2), Ref::new(3));
    let mut next = 4;
    let mut alloc = || {
        next += 1;
        Ref::new(next - 1)
    };
    let page_refs: Vec<(Ref, Ref)> = (0..pages).map(|_| (alloc(), alloc())).collect();
    let image_refs: Vec<Ref> = figures.iter().map(|_| alloc()).collect();
    pdf.catalog(catalog).pages(tree);
    pdf.pages(tree).kids(page_refs.iter().map(|r| r.0)).count(pages as i32);
    pdf.type1_font(font).base_font(Name(b"Helvetica"));
    for (k, &(page_id, content_id)) in page_refs.iter().enumerate() {
        let on = k * per_page..((k + 1) * per_page).min(figures.len());
        let mut p = pdf.page(page_id);
        p.media_box(Rect::new(0.0, 0.0, page_w, page_h));
        p.parent(tree);
        p.contents(content_id);
        let mut res = p.resources();
        let mut xo = res.x_objects();
        let names: Vec<String> = on.clone().map(|i| format!("Im{i}")).collect();
        for (i, name) in on.clone().zip(&names) {
            xo.pair(Name(name.as_bytes()), image_refs[i]);
        }
        xo.finish();
        res.fonts().pair(Name(b"F"), font);
        res.finish();
        p.finish();
        let mut c = Content::new();
        for (slot, i) in on.clone().enumerate() {
            let f = &figures[i];
            let (row, col) = (slot / columns, slot % columns);
            let h = col_w * f.height as f64 / f.width.max(1) as f64;
            let x = margin + col as f64 * (col_w + gap);
            let top = page_h as f64 - margin - row as f64 * (tallest + caption + gap);
            c.save_state().transform([col_w as f32, 0.0, 0.0, h as f32, x as f32, (top - h) as f32]);
            c.x_object(Name(names[slot].as_bytes())).restore_state();
            c.begin_text().set_font(Name(b"F"), 8.0).next_line(x as f32, (top - h - 9.0) as f32);
            // Helvetica's standard encoding has no ×: an x reads the same.
            c.show(Str(f.caption.replace('×', "x").as_bytes())).end_text();
        }
        pdf.stream(content_id, &c.finish());
    }
    for (f, &id) in figures.iter().zip(&image_refs) {
        let data = miniz_oxide::deflate::compress_to_vec_zlib(&f.rgb, LEVEL);
        let mut image = pdf.image_xobject(id, &data);
        image.filter(Filter::FlateDecode);
        image.width(f.width as i32).height(f.height as i32).bits_per_component(8);
        image.color_space().device_rgb();
        image.finish();
    }
    pdf.finish()
}
