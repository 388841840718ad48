//! The print channel on real data, as a user runs it: the ColorChecker photos are read and fitted
//! (camera alone; by their marker sheet, or by OpenCV's mcc without one), photos of other charts are refused with what they show, a chart is written
//! and read back, texture proofs match LittleCMS, and bad profiles and configs are clear errors.

use crate::common;

use std::process::Command;

fn pav() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_pav"));
    c.current_dir(common::repo()).env("RUST_BACKTRACE", "0");
    c
}

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
    // A photo with neither a sheet nor a checker.
    let (ok, text) = run(&["print", "calibrate", "--colorchecker", "data:charts/aruco/cv_gboriginal.png"]);
    assert!(!ok && text.contains("finds no ColorChecker Classic either"), "{text}");
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
        "configs/optimize/recommended.toml",
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
    let (ok, text) = run(&["print", "chart", "--page", "100x100", "-o", dir.to_str().unwrap()]);
    assert!(!ok && text.contains("fewer than the 216"), "{text}");
}

#[test]
fn a_proof_moves_the_texture_as_littlecms_does_and_bad_profiles_are_refused() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("proof.png");
    let args = [
        "print",
        "proof",
        "--config",
        "configs/optimize/recommended.toml",
        "--texture",
        "data:rauca-e2e/RAUCA_E2E.png",
    ];
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
