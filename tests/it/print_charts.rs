//! The print channel on real data, as a user runs it: the ColorChecker photos are read and fitted
//! (camera alone; by their marker sheet, or by OpenCV's mcc without one or when the markers do not
//! frame the checker), photos of other charts are refused with what they show, a chart is written
//! (as a PNG and as a PDF whose patches Poppler shows in their colours) and read back, texture
//! proofs match LittleCMS, and bad profiles and configs are clear errors.

use crate::common;
use crate::common::pav;

fn run(args: &[&str]) -> (bool, String) {
    let o = pav().args(args).output().unwrap();
    (o.status.success(), common::output_text(&o))
}

/// The kept model's held-out median ΔE2000 from `pav print calibrate`'s output.
fn kept_median(text: &str) -> f64 {
    let kept = text.lines().find_map(|l| l.strip_prefix("kept ")).expect("a kept line");
    let model = kept.split_whitespace().next().unwrap();
    let line = text.lines().find(|l| l.trim_start().starts_with(model) && l.contains("held-out")).unwrap();
    line.split("median ").nth(1).unwrap().split(',').next().unwrap().trim().parse().unwrap()
}

#[test]
fn colorchecker_photos_give_a_camera_fit_and_other_charts_are_named() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    for (photo, bound) in [("jtvd_color_checker_1.jpg", 3.5), ("jtvd_color_checker_mini_5.jpg", 4.0)] {
        let out = tmp.path().join(format!("{photo}.toml"));
        let (ok, text) = run(&[
            "print",
            "calibrate",
            "--colorchecker",
            &format!("data:charts/colorchecker/{photo}"),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{text}");
        let m = kept_median(&text);
        eprintln!("{photo}: {text}");
        assert!(m > 0.5 && m < bound, "{photo}: held-out median {m}");
        assert!(text.contains("from 24 patches"), "{text}");
        let cal = std::fs::read_to_string(&out).unwrap();
        assert!(cal.contains("measures = \"camera\""), "{cal}");
        assert_eq!(std::fs::read_to_string(out.with_extension("csv")).unwrap().lines().count(), 25);
        assert!(image::open(out.with_extension("png")).is_ok());
    }
    // A hand-held checker in mixed light without a marker sheet: OpenCV's mcc finds it.
    let out = tmp.path().join("handheld.toml");
    let (ok, text) = run(&[
        "print",
        "calibrate",
        "--colorchecker",
        "data:charts/colorchecker/pedrodiamel_img-colorchecker.jpg",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    eprintln!("hand-held: {text}");
    let m = kept_median(&text);
    assert!(m > 0.5 && m < 3.5, "hand-held: held-out median {m}");
    assert!(text.contains("found by OpenCV's mcc (the marker sheet: no ArUco marker found"), "{text}");
    // A photo with neither a sheet nor a checker.
    let (ok, text) = run(&["print", "calibrate", "--colorchecker", "data:charts/aruco/cv_gboriginal.png"]);
    assert!(!ok && text.contains("no ColorChecker found, neither by its marker sheet ("), "{text}");
    assert!(text.contains("nor by OpenCV's marker-less detector, mcc (it finds no ColorChecker Classic)"), "{text}");
    // Photos of other charts given as pav's.
    let chart = tmp.path().join("chart");
    let (ok, text) = run(&["print", "chart", "--dpi", "100", "-o", chart.to_str().unwrap()]);
    assert!(ok, "{text}");
    let c = chart.to_str().unwrap();
    let (ok, text) = run(&["print", "calibrate", "--chart", c, "data:charts/colorchecker/jtvd_color_checker_1.jpg"]);
    assert!(!ok && text.contains("markers [0, 1, 2, 3] belong to another chart"), "{text}");
    for board in ["cv_choriginal.jpg", "cv_singlemarkersoriginal.jpg"] {
        let (ok, text) = run(&["print", "calibrate", "--chart", c, &format!("data:charts/aruco/{board}")]);
        assert!(!ok && text.contains("of DICT_6X6_250, none of DICT_4X4_50"), "{board}: {text}");
    }
    let (ok, text) = run(&["print", "calibrate", "data:charts/aruco/cv_gboriginal.png"]);
    assert!(!ok && text.contains("--chart DIR"), "{text}");
}

/// `img` with the placement sheet's four markers (DICT_4X4_50, IDs 0–3) at the corners of the
/// square of side `span` whose top-left corner is (x, y), each on a white quiet zone.
fn with_sheet_markers(img: &mut opencv::core::Mat, x: i32, y: i32, span: i32) {
    use opencv::core::{Mat, Rect, Scalar};
    use opencv::prelude::*;
    use opencv::{aruco, imgproc};
    let dict = aruco::get_predefined_dictionary(aruco::PREDEFINED_DICTIONARY_NAME::DICT_4X4_50).unwrap();
    let (side, zone) = (60, 12);
    for (id, (dx, dy)) in [(0, (0, 0)), (1, (1, 0)), (2, (1, 1)), (3, (0, 1))] {
        let (mx, my) = (x + dx * (span - side), y + dy * (span - side));
        let quiet = Rect::new(mx - zone, my - zone, side + 2 * zone, side + 2 * zone);
        imgproc::rectangle(img, quiet, Scalar::all(255.0), -1, imgproc::LINE_8, 0).unwrap();
        let (mut m, mut bgr) = (Mat::default(), Mat::default());
        aruco::draw_marker(&dict, id, side, &mut m, 1).unwrap();
        imgproc::cvt_color_def(&m, &mut bgr, imgproc::COLOR_GRAY2BGR).unwrap();
        let mut roi = Mat::roi_mut(img, Rect::new(mx, my, side, side)).unwrap();
        bgr.copy_to(&mut roi).unwrap();
    }
}

#[test]
fn a_colorchecker_whose_markers_do_not_frame_it_is_found_without_them() {
    use opencv::core::{Mat, Scalar, Vector, CV_8UC3};
    use opencv::imgcodecs;
    let shared = common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    // The hand-held checker with a marker sheet beside it, on the cloth to its lower right.
    let src = shared.join("charts/colorchecker/pedrodiamel_img-colorchecker.jpg");
    let mut img = imgcodecs::imread(src.to_str().unwrap(), imgcodecs::IMREAD_COLOR).unwrap();
    with_sheet_markers(&mut img, 680, 480, 260);
    let photo = tmp.path().join("beside.png");
    imgcodecs::imwrite(photo.to_str().unwrap(), &img, &Vector::new()).unwrap();
    let out = tmp.path().join("beside.toml");
    let (ok, text) =
        run(&["print", "calibrate", "--colorchecker", photo.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(
        text.contains("found by OpenCV's mcc (the marker sheet: no ColorChecker grid between the markers"),
        "{text}"
    );
    let m = kept_median(&text);
    assert!(m > 0.5 && m < 3.5, "held-out median {m}");
    let cal = std::fs::read_to_string(&out).unwrap();
    assert!(cal.contains("found by OpenCV's mcc"), "the calibration file records the path: {cal}");
    // The same markers with no checker anywhere: refused, with both reasons.
    let mut blank = Mat::new_rows_cols_with_default(600, 800, CV_8UC3, Scalar::all(128.0)).unwrap();
    with_sheet_markers(&mut blank, 200, 150, 300);
    let photo = tmp.path().join("markers-only.png");
    imgcodecs::imwrite(photo.to_str().unwrap(), &blank, &Vector::new()).unwrap();
    let (ok, text) = run(&["print", "calibrate", "--colorchecker", photo.to_str().unwrap()]);
    assert!(!ok, "{text}");
    assert!(text.contains("neither by its marker sheet (no ColorChecker grid between the markers"), "{text}");
    assert!(text.contains("nor by OpenCV's marker-less detector, mcc (it finds no ColorChecker Classic)"), "{text}");
}

#[test]
fn a_chart_carries_the_texture_colours_and_its_pixels_its_intended_colours() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("chart");
    let (ok, text) = run(&[
        "print",
        "chart",
        "--texture",
        "data:rauca-e2e/RAUCA_E2E.png",
        "--config",
        "configs/optimize/quick.toml",
        "-o",
        dir.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    assert!(text.contains("216 spanning the cube, 16 greys, 205 from the texture"), "{text}");
    let img = image::open(dir.join("chart.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (2480, 3508), "A4 at 300 dpi");
    let mut rd = csv::Reader::from_path(dir.join("chart.csv")).unwrap();
    let ppm = 300.0 / 25.4;
    let mut checked = 0;
    for rec in rd.records() {
        let r = rec.unwrap();
        let f = |i: usize| r[i].parse::<f64>().unwrap();
        // The patch's centre pixel is its intended colour (the ID sits in a corner).
        let (x, y) = (((f(1) + 4.0) * ppm) as u32, ((f(2) + 4.0) * ppm) as u32);
        let px = img.get_pixel(x, y).0;
        assert_eq!(px, [f(3) as u8, f(4) as u8, f(5) as u8], "patch {}", &r[0]);
        checked += 1;
    }
    assert_eq!(checked, 437);
    // chart.pdf, rendered by Poppler at the PNG's size through its sRGB profile, has every
    // patch in its intended colour (to a level: the profile's round trip).
    let o = std::process::Command::new("pdftoppm")
        .args(["-scale-to-x", "2480", "-scale-to-y", "3508", "-png", "-singlefile"])
        .arg(dir.join("chart.pdf"))
        .arg(tmp.path().join("shown"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let shown = image::open(tmp.path().join("shown.png")).unwrap().to_rgb8();
    let mut rd = csv::Reader::from_path(dir.join("chart.csv")).unwrap();
    for rec in rd.records() {
        let r = rec.unwrap();
        let f = |i: usize| r[i].parse::<f64>().unwrap();
        let (x, y) = (((f(1) + 4.0) * ppm) as u32, ((f(2) + 4.0) * ppm) as u32);
        let px = shown.get_pixel(x, y).0;
        let want = [f(3), f(4), f(5)];
        assert!((0..3).all(|c| (px[c] as f64 - want[c]).abs() <= 1.0), "patch {}: {px:?} for {want:?}", &r[0]);
    }
    let (ok, text) = run(&["print", "chart", "--paper", "roll:610mm", "-o", dir.to_str().unwrap()]);
    assert!(!ok && text.contains("not a roll"), "{text}");
    let (ok, text) = run(&["print", "chart", "--paper", "100x100", "-o", dir.to_str().unwrap()]);
    assert!(!ok && text.contains("fewer than the 216"), "{text}");
}

#[test]
fn a_proof_moves_the_texture_as_littlecms_does_and_bad_profiles_are_refused() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("proof.png");
    let args =
        ["print", "proof", "--config", "configs/optimize/quick.toml", "--texture", "data:rauca-e2e/RAUCA_E2E.png"];
    let (ok, text) = run(&[&args[..], &["-o", out.to_str().unwrap()]].concat());
    assert!(ok, "{text}");
    // Pillow's ImageCms (the same LittleCMS) through the same profile and intent gives a
    // median of 10.2 and 76 % above 5 over this texture's region.
    assert!(text.contains("median 10.2") && text.contains("76 % move by more than 5"), "{text}");
    let (ok, text) =
        run(&[&args[..], &["-o", out.to_str().unwrap(), "--profile", "/usr/share/color/icc/ghostscript/srgb.icc"]]
            .concat());
    assert!(!ok && text.contains("is a display profile, not a printer's output profile"), "{text}");
    let (ok, text) = run(&[&args[..], &["-o", out.to_str().unwrap(), "--profile", "no-such.icc"]].concat());
    assert!(!ok && text.contains("no-such.icc") && text.contains("libgs-common"), "{text}");
    let (ok, text) = run(&[&args[..], &["-o", out.to_str().unwrap(), "--intent", "vivid"]].concat());
    assert!(!ok && text.contains("unknown rendering intent"), "{text}");
    // A [print] table with a bad value or key.
    for (table, says) in
        [("gamut_weight = -1.0", "print.gamut_weight must be ≥ 0"), ("lut = 33", "unknown field `lut`")]
    {
        let cfg = tmp.path().join("c.toml");
        let base = common::repo().join("configs/studies/print-base.toml");
        std::fs::write(&cfg, format!("extends = \"{}\"\n[print]\n{table}\n", base.display())).unwrap();
        let (ok, text) = run(&[
            "print",
            "proof",
            "--config",
            cfg.to_str().unwrap(),
            "--texture",
            "data:rauca-e2e/RAUCA_E2E.png",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(!ok && text.contains(says), "{table}: {text}");
    }
}
