//! `pav print pieces`: a config's textured region and a texture laid out as numbered pieces on
//! pages of the user's paper, at the model's scale: a PDF at physical size, page PNGs at the DPI
//! and `pieces.csv`.

use crate::config::OptimizeConfig;
use crate::export::atlas_side_m;
use crate::placement::{figures, sides, SideView};
use crate::setup::{mesh_and_region, SetupError};
use pav_core::geometry::parts::Axis;
use pav_core::image::{save_png_dpi, to_u8, Frame, Rgb};
use pav_print::pieces::{layout, parts, split_by_chart, PageLayout, PiecesError, Sheet, Spec};
use std::path::{Path, PathBuf};

/// Why the pieces could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PrintPiecesError {
    /// The config, its mesh or its region.
    #[error(transparent)]
    Setup(#[from] SetupError),
    /// The layout.
    #[error(transparent)]
    Pieces(#[from] PiecesError),
    /// The texture.
    #[error("{0}")]
    Texture(String),
    /// The PDF.
    #[error(transparent)]
    Pdf(#[from] pav_print::pdf::PdfError),
    /// A file could not be written.
    #[error("{path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// What was written.
#[derive(Clone, Debug)]
pub struct PiecesReport {
    /// The layout.
    pub layout: PageLayout,
    /// The share of the pages' printable area the pieces cover.
    pub paper_used: f64,
    /// The length of paper the pages take, m (what a roll needs).
    pub length_m: f64,
    /// The page files, in order.
    pub pages: Vec<PathBuf>,
    /// `pieces.csv`.
    pub csv: PathBuf,
    /// `pieces.pdf`.
    pub pdf: PathBuf,
    /// `placement.pdf`.
    pub guide: PathBuf,
    /// The config names the mesh's front (else the guide takes its longest axis for it).
    pub front_known: bool,
}

/// Lays `texture` out over `cfg`'s region at model scale 1:`scale` with `spec`, into `out`:
/// `pieces.pdf`, `pages/page-N.png` (with their DPI), `pieces.csv`, `by_hand.csv`, a one-row
/// `summary.csv` and the placement guide (`placement.pdf`, `placement/`, `placement.csv`).
pub fn write_pieces(
    cfg: &OptimizeConfig,
    texture: &Path,
    scale: f64,
    spec: Spec,
    out: &Path,
) -> Result<PiecesReport, PrintPiecesError> {
    let tex = Rgb::load(texture).map_err(|e| PrintPiecesError::Texture(format!("{}: {e}", texture.display())))?;
    if tex.width != tex.height {
        return Err(PrintPiecesError::Texture(format!(
            "{} is {}×{}: a UV atlas is square",
            texture.display(),
            tex.width,
            tex.height
        )));
    }
    let n = tex.width;
    let mut at_size = cfg.clone();
    at_size.mesh.texture_size = n;
    let (mesh, region) = mesh_and_region(&at_size)?;
    let (side_m, _) = atlas_side_m(&mesh, &region, n, cfg.mesh.car_length_m).ok_or(PiecesError::Empty)?;
    let atlas_mm = side_m * 1000.0 / scale;
    // Past four pixels a texel, resampling adds nothing a printer's own interpolation would
    // not; the cap keeps a full-size layout (a texel of about 7 mm) small.
    let carried = 4.0 * n as f64 / (atlas_mm / 25.4);
    let spec = Spec { dpi: if spec.dpi > carried { carried.floor().max(1.0) } else { spec.dpi }, ..spec };
    let sheet = Sheet::new(n, atlas_mm, spec.dpi);
    // The same 8-bit atlas the printable sheet resamples.
    let frame = Frame { width: n, height: n, bgr: tex.rgb.iter().map(|v| to_u8(*v)).collect() };
    let (mut labels, found) = parts(&region, n);
    let charts = pav_print::panels::uv_charts(&mesh, n);
    let found = split_by_chart(&mut labels, found, &charts, sheet, spec);
    let count = found.iter().map(|p| p.label as usize).max().unwrap_or(0);
    let orient = pav_print::panels::orient(&mesh, &labels, n, count, cfg.mesh.front, cfg.mesh.up_axis());
    let l = layout(&labels, &found, &frame, sheet, spec, orient)?;
    let dir = out.join("pages");
    std::fs::create_dir_all(&dir).map_err(|source| PrintPiecesError::Write { path: dir.clone(), source })?;
    let mut pages = Vec::new();
    for page in 1..=l.pages {
        let path = dir.join(format!("page-{page}.png"));
        let [w, h] = l.page_px(page);
        save_png_dpi(&path, w, h, &l.render(page, &labels, &frame), spec.dpi)
            .map_err(|e| PrintPiecesError::Write { path: path.clone(), source: std::io::Error::other(e) })?;
        pages.push(path);
    }
    let pdf = out.join("pieces.pdf");
    let bytes = pav_print::pdf::pieces_pdf(&l, &labels, &frame)?;
    std::fs::write(&pdf, bytes).map_err(|source| PrintPiecesError::Write { path: pdf.clone(), source })?;
    let csv = out.join("pieces.csv");
    for (path, text) in [(csv.clone(), l.csv()), (out.join("by_hand.csv"), l.by_hand_csv())] {
        std::fs::write(&path, text).map_err(|source| PrintPiecesError::Write { path: path.clone(), source })?;
    }
    let paper_used = l.paper_used(&labels);
    let length_m = l.length_mm() / 1000.0;
    let summary = out.join("summary.csv");
    let row = format!(
        "paper,scale,dpi,bleed_mm,atlas_mm,pages,pieces,by_hand,paper_used,paper_length_m\n{},{scale},{},{},{:.1},{},{},{},{paper_used:.4},{length_m:.3}\n",
        spec.paper,
        spec.dpi,
        spec.bleed_mm,
        l.sheet.atlas_mm,
        l.pages,
        l.pieces.len(),
        l.by_hand.len()
    );
    std::fs::write(&summary, row).map_err(|source| PrintPiecesError::Write { path: summary.clone(), source })?;
    let front = cfg.mesh.front.unwrap_or_else(|| length_axis(&mesh, cfg.mesh.up_axis()));
    let guide = write_guide(&mesh, &labels, &frame, &l, front, cfg.mesh.up_axis(), spec.paper, out)?;
    Ok(PiecesReport { layout: l, paper_used, length_m, pages, csv, pdf, guide, front_known: cfg.mesh.front.is_some() })
}

/// The mesh's longest axis across `up`, pointing +: the guide's front where the config names
/// none (its sides are then named as if it were).
fn length_axis(mesh: &pav_core::geometry::mesh::Mesh, up: Axis) -> Axis {
    let (lo, hi) = mesh.bounds();
    let index =
        (0..3).filter(|&k| k != up.index).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
    Axis { index, positive: true }
}

/// Side of each view of the placement guide, pixels.
const GUIDE_PX: usize = 480;

/// The placement guide into `out`: `placement/overview-SIDE.png` per side,
/// `placement/piece-N.png` per piece, `placement.csv` (the side each piece is shown from and
/// how many pixels of it show) and `placement.pdf` on `paper` (A4 for a roll).
#[allow(clippy::too_many_arguments)]
fn write_guide(
    mesh: &pav_core::geometry::mesh::Mesh,
    labels: &[u32],
    texture: &Frame,
    l: &PageLayout,
    front: Axis,
    up: Axis,
    paper: pav_print::paper::Paper,
    out: &Path,
) -> Result<PathBuf, PrintPiecesError> {
    let sides = sides(front, up);
    let parts = l.orient.len().max(labels.iter().copied().max().unwrap_or(0) as usize);
    let shots: Vec<SideView> =
        sides.iter().map(|s| SideView::take(mesh, &s.camera, GUIDE_PX, labels, texture, parts)).collect();
    let (figs, chosen) = figures(l, &sides, &shots, front, up);
    let dir = out.join("placement");
    std::fs::create_dir_all(&dir).map_err(|source| PrintPiecesError::Write { path: dir.clone(), source })?;
    let names = sides
        .iter()
        .map(|s| format!("overview-{}.png", s.name))
        .chain(chosen.iter().map(|c| format!("piece-{}.png", c.0)));
    for (fig, name) in figs.iter().zip(names) {
        let path = dir.join(name);
        save_png_dpi(&path, fig.width, fig.height, &fig.rgb, 96.0)
            .map_err(|e| PrintPiecesError::Write { path: path.clone(), source: std::io::Error::other(e) })?;
    }
    let mut csv = String::from("piece,side,pixels\n");
    for (id, side, px) in &chosen {
        csv.push_str(&format!("{id},{side},{px}\n"));
    }
    let path = out.join("placement.csv");
    std::fs::write(&path, csv).map_err(|source| PrintPiecesError::Write { path: path.clone(), source })?;
    let pdf = out.join("placement.pdf");
    std::fs::write(&pdf, pav_print::pdf::figures_pdf(&figs, paper, 2))
        .map_err(|source| PrintPiecesError::Write { path: pdf.clone(), source })?;
    Ok(pdf)
}
