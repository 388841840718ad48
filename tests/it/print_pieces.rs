//! `pav print pieces` on the e-tron at 1:20: numbered pieces on A4 pages at 300 dpi, which,
//! put back where `pieces.csv` says they came from, are the printable sheet's region pixel for
//! pixel; the PDF has A4 pages that Poppler renders as the page PNGs, with bars of 10 and 50 mm;
//! the placement guide highlights each piece where it is on the car; a full-size car goes on a
//! roll within its memory bound; bad input is refused with its fix before anything is written.

use crate::common::{self, pav};
use pav::attack::config::OptimizeConfig;
use pav::attack::export::{atlas_side_m, write_sheet, PrintSpec};
use pav::attack::setup::mesh_and_region;
use pav::image::Rgb;

#[test]
fn pieces_on_a4_put_back_are_the_printable_sheets_region() {
    let shared = common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("pieces");
    let config = "configs/optimize/paper.toml";
    let o = pav()
        .args([
            "print",
            "pieces",
            "--config",
            config,
            "--texture",
            "data:rauca-e2e/RAUCA_E2E.png",
            "--paper",
            "a4",
            "--bleed",
            "1",
            "-o",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let said = common::output_text(&o);
    assert!(o.status.success(), "{said}");
    eprintln!("{said}");
    // The printable sheet of the same texture, as optimize writes it.
    let cfg = OptimizeConfig::load(&common::repo().join(config)).unwrap();
    let tex = Rgb::load(&shared.join("rauca-e2e/RAUCA_E2E.png")).unwrap();
    let n = tex.width;
    let mut at_n = cfg.clone();
    at_n.mesh.texture_size = n;
    let (mesh, region) = mesh_and_region(&at_n).unwrap();
    let (side_m, spread) = atlas_side_m(&mesh, &region, n, cfg.mesh.car_length_m).unwrap();
    let sheet_png = tmp.path().join("texture_print.png");
    write_sheet(&sheet_png, &tex.rgb, n, side_m, spread, PrintSpec { scale: 20.0, dpi: 300.0 }).unwrap();
    let sheet = image::open(&sheet_png).unwrap().to_rgb8();
    let side = (side_m * 1000.0 / 20.0 * 300.0 / 25.4).round() as usize;
    let (labels, _) = pav::print::pieces::parts(&region, n);
    let texel = |px: usize| (((px as f64 + 0.5) * n as f64 / side as f64).floor() as usize).min(n - 1);
    let mut rd = csv::Reader::from_path(out.join("pieces.csv")).unwrap();
    let head = rd.headers().unwrap().clone();
    let col = |r: &csv::StringRecord, k: &str| r[head.iter().position(|h| h == k).unwrap()].to_string();
    let mut pages = std::collections::HashMap::new();
    let mut covered = vec![0u8; side * side];
    // Page pixels on a piece, per page.
    let mut on_piece: std::collections::HashMap<usize, std::collections::HashSet<(usize, usize)>> = Default::default();
    let rows: Vec<csv::StringRecord> = rd.records().map(|r| r.unwrap()).collect();
    assert!(!rows.is_empty());
    for r in &rows {
        let num = |k: &str| col(r, k).parse::<usize>().unwrap();
        let page = pages.entry(num("page")).or_insert_with(|| {
            let p = image::open(out.join(format!("pages/page-{}.png", num("page")))).unwrap().to_rgb8();
            // A4 at 300 dpi.
            assert_eq!(p.dimensions(), (2480, 3508));
            p
        });
        let (part, rotated) = (num("part") as u32, col(r, "rotated") == "true");
        let [x, y, w, h] = ["sheet_x_px", "sheet_y_px", "sheet_w_px", "sheet_h_px"].map(num);
        let (px, py) = (num("page_x_px"), num("page_y_px"));
        let (pw, ph) = if rotated { (h, w) } else { (w, h) };
        for v in 0..ph {
            for u in 0..pw {
                let (sx, sy) = if rotated { (x + v, y + h - 1 - u) } else { (x + u, y + v) };
                if labels[texel(sy) * n + texel(sx)] != part {
                    continue;
                }
                assert_eq!(
                    page.get_pixel((px + u) as u32, (py + v) as u32),
                    sheet.get_pixel(sx as u32, sy as u32),
                    "piece {} at page pixel ({}, {})",
                    col(r, "piece"),
                    px + u,
                    py + v
                );
                covered[sy * side + sx] = covered[sy * side + sx].saturating_add(1);
                on_piece.entry(num("page")).or_default().insert((px + u, py + v));
            }
        }
    }
    // Every region pixel of the sheet is on a piece, or on a part listed to paint by hand; the
    // untiled ones on exactly one.
    let by_hand: Vec<u32> = std::fs::read_to_string(out.join("by_hand.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    let tiled = rows.iter().any(|r| !col(r, "tile").is_empty());
    for sy in 0..side {
        for sx in 0..side {
            let l = labels[texel(sy) * n + texel(sx)];
            if l == 0 || by_hand.contains(&l) {
                continue;
            }
            let c = covered[sy * side + sx];
            assert!(c >= 1 && (tiled || c == 1), "sheet pixel ({sx}, {sy}) of part {l} is on {c} pieces");
        }
    }
    let run = common::run_record(&out.join("run.toml"));
    let pages_used: usize = run["result"]["pages"].as_str().unwrap().parse().unwrap();
    assert_eq!(pages_used, pages.len());
    for (k, page) in &pages {
        bleed_surrounds_each_piece(page, &on_piece[k]);
    }
    pdf_is_the_pages_at_their_size(&out, &pages, &on_piece);
    // The placement guide: the piece it shows largest is highlighted where a flat render of a
    // texture black on that piece's part, white elsewhere, is black.
    let mut guide = csv::Reader::from_path(out.join("placement.csv")).unwrap();
    let (id, side, _) = guide
        .records()
        .map(|r| r.unwrap())
        .map(|r| (r[0].parse::<usize>().unwrap(), r[1].to_string(), r[2].parse::<usize>().unwrap()))
        .max_by_key(|r| r.2)
        .unwrap();
    let part = rows
        .iter()
        .find(|r| col(r, "piece") == id.to_string())
        .map(|r| col(r, "part").parse::<u32>().unwrap())
        .unwrap();
    let black_on_part: Vec<f32> = labels.iter().flat_map(|&l| [if l == part { 0.0 } else { 1.0 }; 3]).collect();
    let tex = Rgb { width: n, height: n, rgb: black_on_part };
    let up = cfg.mesh.up_axis();
    let cam =
        pav::attack::placement::sides(cfg.mesh.front.unwrap(), up).into_iter().find(|s| s.name == side).unwrap().camera;
    let size = 480;
    let flat = pav::render::preview::textured(&mesh, &tex, &cam, size);
    let shown = image::open(out.join(format!("placement/piece-{id}.png"))).unwrap().to_rgb8();
    let band = pav::attack::placement::band(size);
    assert_eq!(shown.dimensions(), (size as u32, (size + band) as u32));
    let (mut both, mut either) = (0, 0);
    for i in 0..size * size {
        let lit = shown.get_pixel((i % size) as u32, (i / size + band) as u32).0 == pav::attack::placement::HIGHLIGHT;
        let dark = flat.rgb[i * 3] < 0.5;
        both += (lit && dark) as usize;
        either += (lit || dark) as usize;
    }
    // The render samples the texture bilinearly, the guide by texel: they part on the edge.
    assert!(both > 2000 && both as f64 >= 0.95 * either as f64, "piece {id} from the {side}: {both} of {either}");
    let info =
        common::output_text(&std::process::Command::new("pdfinfo").arg(out.join("placement.pdf")).output().unwrap());
    assert!(info.contains("Pages:") && info.contains("(A4)"), "{info}");
}

/// With a 1 mm bleed (12 px at 300 dpi) the pixel 6 px outside a piece's edge, where that is
/// not another piece, is printed, not white paper.
fn bleed_surrounds_each_piece(page: &image::RgbImage, on: &std::collections::HashSet<(usize, usize)>) {
    let (mut outside, mut inked) = (0, 0);
    for &(x, y) in on {
        if !on.contains(&(x + 1, y)) && !on.contains(&(x + 6, y)) {
            outside += 1;
            inked += (page.get_pixel(x as u32 + 6, y as u32).0 != [255, 255, 255]) as usize;
        }
    }
    assert!(outside > 0);
    // A piece pixel the sheet has white would carry white outward: allow a few.
    assert!(inked as f64 >= 0.98 * outside as f64, "{inked} of {outside} bleed pixels printed");
}

/// `pieces.pdf`: Poppler reads one A4 page per page PNG; its raster is the PNG's pixels, one
/// for one, away from the cut lines; rendered at 300 dpi, its check bars measure 10 and 50 mm
/// to one pixel.
fn pdf_is_the_pages_at_their_size(
    out: &std::path::Path,
    pages: &std::collections::HashMap<usize, image::RgbImage>,
    on: &std::collections::HashMap<usize, std::collections::HashSet<(usize, usize)>>,
) {
    let pdf = out.join("pieces.pdf");
    let info = std::process::Command::new("pdfinfo")
        .args(["-f", "1", "-l", "99"])
        .arg(&pdf)
        .output()
        .expect("pdfinfo (poppler-utils, installed by scripts/setup.sh)");
    let info = common::output_text(&info);
    let sizes: Vec<(f64, f64)> = info
        .lines()
        .filter(|l| l.starts_with("Page") && l.contains(" size:"))
        .map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            let at = w.iter().position(|t| *t == "size:").unwrap();
            (w[at + 1].parse().unwrap(), w[at + 3].parse().unwrap())
        })
        .collect();
    assert_eq!(sizes.len(), pages.len(), "{info}");
    for (w, h) in sizes {
        assert!((w - 595.276).abs() <= 0.5 && (h - 841.89).abs() <= 0.5, "{w} × {h} pt is no A4 page");
    }
    let tmp = tempfile::tempdir().unwrap();
    let render = |page: usize, args: &[String], name: &str| {
        let o = std::process::Command::new("pdftoppm")
            .args(["-png", "-singlefile", "-f", &page.to_string(), "-l", &page.to_string()])
            .args(args)
            .arg(&pdf)
            .arg(tmp.path().join(name))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", common::output_text(&o));
        image::open(tmp.path().join(format!("{name}.png"))).unwrap().to_rgb8()
    };
    for (&k, png) in pages {
        let (w, h) = png.dimensions();
        // Poppler smooths an image drawn near one to one, and draws it by nearest pixel from
        // four times up: so at four times the PNG's size each PNG pixel is a 4 × 4 block, and
        // its centre is the PNG's pixel. A 500-pixel window where the page's pieces are.
        let inner: Vec<(usize, usize)> = on[&k]
            .iter()
            .copied()
            .filter(|&(x, y)| [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)].iter().all(|q| on[&k].contains(q)))
            .collect();
        let mean = |f: fn(&(usize, usize)) -> usize| inner.iter().map(f).sum::<usize>() / inner.len();
        let side = 500;
        let (x0, y0) = (mean(|p| p.0).saturating_sub(side / 2), mean(|p| p.1).saturating_sub(side / 2));
        let (x0, y0) = (x0.min(w as usize - side), y0.min(h as usize - side));
        let args: Vec<String> = [
            ("-scale-to-x", 4 * w as usize),
            ("-scale-to-y", 4 * h as usize),
            ("-x", 4 * x0),
            ("-y", 4 * y0),
            ("-W", 4 * side),
            ("-H", 4 * side),
        ]
        .iter()
        .flat_map(|(a, v)| [a.to_string(), v.to_string()])
        .collect();
        let zoom = render(k, &args, &format!("zoom-{k}"));
        let window: Vec<&(usize, usize)> =
            inner.iter().filter(|p| (x0..x0 + side).contains(&p.0) && (y0..y0 + side).contains(&p.1)).collect();
        assert!(window.len() > 10_000, "page {k}: {} piece pixels in the window", window.len());
        let same = window
            .iter()
            .filter(|&&&(x, y)| {
                let a = zoom.get_pixel((4 * (x - x0) + 2) as u32, (4 * (y - y0) + 2) as u32).0;
                let b = png.get_pixel(x as u32, y as u32).0;
                (0..3).all(|c| a[c].abs_diff(b[c]) <= 1)
            })
            .count();
        // Cut lines are drawn over the pieces' edge pixels: the few inner pixels they touch.
        assert!(same as f64 >= 0.99 * window.len() as f64, "page {k}: {same} of {} pixels the PNG's", window.len());
        // The bars, rendered at 300 dpi.
        let shown = render(k, &["-r".into(), "300".into()], &format!("page-{k}"));
        let (png_bars, pdf_bars) = (dark_runs_at_bottom(png), dark_runs_at_bottom(&shown));
        for bar_mm in [10.0, 50.0] {
            let px = bar_mm * 300.0 / 25.4;
            for (what, runs) in [("png", &png_bars), ("pdf", &pdf_bars)] {
                assert!(
                    runs.iter().any(|&r| (r as f64 - px).abs() <= 1.0),
                    "{what} page {k}: no {bar_mm} mm bar in {runs:?}"
                );
            }
        }
    }
}

/// The lengths of the horizontal dark runs in the bottom 20 mm of a 300 dpi page.
fn dark_runs_at_bottom(page: &image::RgbImage) -> Vec<usize> {
    let (w, h) = page.dimensions();
    let mut runs = Vec::new();
    for y in h - 236..h {
        let mut run = 0;
        for x in 0..w {
            if page.get_pixel(x, y).0.iter().all(|&c| c < 100) {
                run += 1;
            } else if run > 0 {
                runs.push(run);
                run = 0;
            }
        }
    }
    runs.sort_unstable();
    runs.dedup();
    runs
}

#[test]
fn bad_pieces_input_is_refused_before_anything_is_written() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| {
        let out = tmp.path().join("never");
        let o = pav()
            .args(["print", "pieces", "--config", "configs/optimize/paper.toml", "-o"])
            .arg(&out)
            .args(extra)
            .output()
            .unwrap();
        assert!(!o.status.success());
        assert!(!out.join("pages").exists(), "{extra:?} wrote pages");
        common::output_text(&o)
    };
    let tex = ["--texture", "data:rauca-e2e/RAUCA_E2E.png"];
    assert!(run(&[&tex[..], &["--paper", "b5"]].concat()).contains("use a5, a4, a3, letter"));
    assert!(run(&[&tex[..], &["--paper", "30x30"]].concat()).contains("larger paper or a smaller margin"));
    assert!(run(&[&tex[..], &["--dpi", "0"]].concat()).contains("DPI must be positive"));
    assert!(run(&[&tex[..], &["--scale", "1:0"]].concat()).contains("no model scale"));
    assert!(run(&["--texture", "docs/quickstart_polar.png"]).contains("a UV atlas is square"));
    // A model 160 mm long is no e-tron at any common scale (1:24 would be 204 mm).
    assert!(run(&[&tex[..], &["--model-length", "160"]].concat()).contains("probably another car"));
}

/// The e-tron at full size on a 1370 mm wrap-printer roll: the DPI is capped at four pixels a
/// texel, every page is the roll's width and at most 200 inches long, the metres of roll are
/// reported, and the run stays within its memory bound of 2 GiB.
#[test]
fn a_full_size_car_goes_on_a_roll_within_two_gibibytes() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("roll");
    let o = pav()
        .args(["print", "pieces", "--config", "configs/optimize/paper.toml", "--texture"])
        .args(["data:rauca-e2e/RAUCA_E2E.png", "--scale", "1", "--paper", "roll:1370mm", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let said = common::output_text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("m of the roll:1370mm roll") && said.contains("four pixels a texel"), "{said}");
    let run = common::run_record(&out.join("run.toml"));
    let result = |k: &str| run["result"][k].as_str().unwrap().parse::<f64>().unwrap();
    // 2048 texels over the 6.8 m atlas: 7.7 texels an inch, so 30 dpi.
    assert_eq!(result("dpi"), 30.0);
    assert!(result("peak_memory_mib") < 2048.0, "{}", result("peak_memory_mib"));
    let pages = result("pages") as usize;
    let length = result("paper_length_m");
    assert!(length > 5.0 && pages >= 2, "{length} m on {pages} pages");
    let info = std::process::Command::new("pdfinfo")
        .args(["-f", "1", "-l", "99"])
        .arg(out.join("pieces.pdf"))
        .output()
        .unwrap();
    let sizes: Vec<(f64, f64)> = common::output_text(&info)
        .lines()
        .filter(|l| l.starts_with("Page") && l.contains(" size:"))
        .map(|l| {
            let w: Vec<f64> = l.split_whitespace().filter_map(|t| t.parse().ok()).collect();
            (w[1], w[2])
        })
        .collect();
    assert_eq!(sizes.len(), pages);
    for (w, h) in sizes {
        assert!((w - 1370.0 * 72.0 / 25.4).abs() <= 0.5 && h <= 200.0 * 72.0 + 0.5, "{w} × {h} pt");
    }
}
