//! `pav print pieces` on the e-tron at 1:20: numbered pieces on A4 pages at 300 dpi, which,
//! put back where `pieces.csv` says they came from, are the printable sheet's region pixel for
//! pixel; bad input is refused with its fix before anything is written.

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
