//! `pav render` and `pav uv check|adjust` as a user runs them: images and CSVs on real data,
//! clear errors on bad meshes.

use crate::common;
use crate::common::pav;

use std::process::Command;

#[test]
fn render_and_uv_commands_write_their_files() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let png = tmp.path().join("r.png");
    let o = pav().args(["render", "--size", "200", "-o"]).arg(&png).output().unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (200, 200));
    // The car is drawn: not every pixel is the white background.
    assert!(img.pixels().filter(|p| p.0 != [255, 255, 255]).count() > 2000);
    assert!(tmp.path().join("r_mask.png").exists());

    let o = pav().args(["uv", "adjust", "-o"]).arg(tmp.path().join("adj")).output().unwrap();
    let out = common::output_text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("adjusted 281 faces: mean |log2 stretch| 0.474 -> 0.002"), "{out}");
    // The new mask marks every patch face again, thin strips included.
    assert!(out.contains("281 patch faces: area-weighted mean |log2 stretch| 0.002"), "{out}");
    for f in [
        "adjusted.obj",
        "adjusted_mask.png",
        "before/uv_heat_mesh.png",
        "after/uv_heat_uv.png",
        "after/uv_distortion.csv",
    ] {
        assert!(tmp.path().join("adj").join(f).exists(), "{f}");
    }
}

#[test]
fn bad_meshes_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let o = pav().args(["render", "--mesh", "no/such.obj"]).output().unwrap();
    assert!(!o.status.success());
    assert!(common::output_text(&o).contains("cannot read no/such.obj"), "{}", common::output_text(&o));
    let obj = tmp.path().join("nouv.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let o = pav().args(["uv", "check", "--mesh"]).arg(&obj).output().unwrap();
    assert!(!o.status.success());
    assert!(
        common::output_text(&o).contains("nouv.obj:4: face corner `1` has no UV index; the mesh needs UVs"),
        "{}",
        common::output_text(&o)
    );
    let obj = tmp.path().join("badidx.obj");
    std::fs::write(&obj, "v 0 0 0\nvt 0 0\nf 1/1 2/1 3/1\n").unwrap();
    let o = pav().args(["render", "--mesh"]).arg(&obj).output().unwrap();
    assert!(
        common::output_text(&o).contains("vertex index `2/1` is out of range (1 positions)"),
        "{}",
        common::output_text(&o)
    );
    let obj = tmp.path().join("nan.obj");
    std::fs::write(&obj, "v 0 nan 0\n").unwrap();
    let o = pav().args(["render", "--mesh"]).arg(&obj).output().unwrap();
    assert!(common::output_text(&o).contains("nan.obj:1: non-finite value NaN"), "{}", common::output_text(&o));
}

/// `pav eval-digital` of `half-turns.toml`'s photos scored by YOLOv3-tiny; the caller adds the rest.
#[cfg(feature = "optimize")]
fn eval_digital_yolov3_tiny() -> Command {
    let mut c = pav();
    c.args(["eval-digital", "--config", "configs/studies/half-turns.toml", "-d", "configs/detectors/yolov3-tiny.toml"]);
    c
}

/// `pav eval-digital` with a peer's texture at its own size (RAUCA-E2E's 2048² atlas on a 256²
/// config): resampled, scored, and both random baselines beside it.
#[cfg(feature = "optimize")]
#[test]
fn eval_digital_resamples_a_texture_of_another_size() {
    let shared = common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    // A texture whose run recorded a YOLOX-only config: starred for that config, not this one's.
    let yolox_run = tmp.path().join("yolox_run");
    std::fs::create_dir_all(&yolox_run).unwrap();
    std::fs::copy(shared.join("rauca-e2e/RAUCA_E2E.png"), yolox_run.join("texture.png")).unwrap();
    let record = format!(
        "cwd = {:?}\n[config]\npath = \"configs/studies/half-turns-yolox.toml\"\n",
        common::repo().display().to_string()
    );
    std::fs::write(yolox_run.join("run.toml"), record).unwrap();
    let out_dir = tmp.path().join("out");
    let o = eval_digital_yolov3_tiny()
        .args(["-t", "data:rauca-e2e/RAUCA_E2E.png", "-t"])
        .arg(yolox_run.join("texture.png"))
        .args(["--random-seeds", "2", "-o"])
        .arg(&out_dir)
        .output()
        .unwrap();
    let out = common::output_text(&o);
    assert!(o.status.success(), "{out}");

    // The run's record names the texture by manifest entry and hash, and the models it ran.
    let run = common::run_record(&out_dir.join("run.toml"));
    let texture = common::record_input(&run, "rauca-e2e/RAUCA_E2E.png");
    assert_eq!(texture["data"].as_str(), Some("rauca-e2e/RAUCA_E2E.png"), "{run}");
    let entry = pav::data::manifest::Manifest::builtin().get("rauca-e2e/RAUCA_E2E.png").unwrap();
    assert_eq!(texture["sha256"].as_str(), Some(entry.sha256.as_str()));
    assert!(shared.join("rauca-e2e/RAUCA_E2E.png").is_file());
    common::record_input(&run, "yolov3-tiny.onnx");
    assert!(run["config"]["path"].as_str().unwrap().ends_with("half-turns.toml"), "{run}");
    assert!(run["tools"]["onnxruntime"].as_str().unwrap().contains("libonnxruntime.so.1.31"), "{run}");
    let csv = std::fs::read_to_string(out_dir.join("digital.csv")).unwrap();
    let column = |texture: &str, name: &str| -> f64 {
        let line = csv
            .lines()
            .find(|l| l.contains(&format!(",{texture},all,")))
            .unwrap_or_else(|| panic!("no {texture} row: {csv}"));
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        let i = header.iter().position(|h| *h == name).unwrap();
        line.split(',').nth(i).unwrap().parse().unwrap()
    };
    let p50 = |texture: &str| column(texture, "p50");
    let (original, random32, rauca) = (p50("original"), p50("random32"), p50("rauca-e2e"));
    eprintln!("YOLOv3-tiny P@0.5 over 11 views: original {original:.3}, random32 {random32:.3}, RAUCA-E2E {rauca:.3}");
    // Measured: 0.855 for the original paint; RAUCA-E2E's texture hides the car far better.
    assert!(original > 0.8 && rauca < 0.5 * original, "{csv}");
    // ASR over the views whose original paint is detected: 0 for the original itself; RAUCA-E2E's
    // texture hides the car on every one of them (measured 1.000).
    assert_eq!(column("original", "asr_detected"), 0.0);
    let white = |texture: &str| {
        let line = csv.lines().find(|l| l.contains(&format!(",{texture},all,"))).unwrap();
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        line.split(',').nth(header.iter().position(|h| *h == "white_box").unwrap()).unwrap().to_string()
    };
    assert_eq!((white("rauca-e2e").as_str(), white("yolox_run").as_str()), ("true", "false"), "{csv}");
    let (asr, asr_detected) = (column("rauca-e2e", "asr"), column("rauca-e2e", "asr_detected"));
    eprintln!("RAUCA-E2E ASR {asr:.3}, over detected originals {asr_detected:.3}");
    assert!(asr_detected >= 0.9, "{csv}");
    // Every view's score per texture and seed, and RAUCA-E2E paired against each other texture
    // on the 5 held-out views: recomputed here from the per-view rows.
    let views = std::fs::read_to_string(out_dir.join("digital_views.csv")).unwrap();
    let rows: Vec<Vec<&str>> = views.lines().skip(1).map(|l| l.split(',').collect()).collect();
    // fold,role,view,texture,seed,detector,score
    let held = |tex: &str, seed: &str| -> Vec<(String, f64)> {
        rows.iter()
            .filter(|r| r[1] == "held-out" && r[3] == tex && r[4] == seed)
            .map(|r| (r[2].to_string(), r[6].parse().unwrap()))
            .collect()
    };
    let (mine, orig, r1, r2) =
        (held("rauca-e2e", "0"), held("original", "0"), held("random32", "1"), held("random32", "2"));
    assert_eq!([mine.len(), orig.len(), r1.len(), r2.len()], [5; 4], "{views}");
    let paired = std::fs::read_to_string(out_dir.join("digital_paired.csv")).unwrap();
    let mean_vs = |against: &str| -> f64 {
        let line = paired.lines().find(|l| l.starts_with(&format!("rauca-e2e,yolov3-tiny,true,{against},"))).unwrap();
        assert!(line.ends_with(",5"), "{line}");
        line.split(',').nth(4).unwrap().parse().unwrap()
    };
    let d_orig: f64 = mine.iter().zip(&orig).map(|(m, o)| m.1 - o.1).sum::<f64>() / 5.0;
    let d_rand: f64 = mine.iter().zip(r1.iter().zip(&r2)).map(|(m, (a, b))| m.1 - (a.1 + b.1) / 2.0).sum::<f64>() / 5.0;
    eprintln!("RAUCA-E2E − original {d_orig:.3}, − random32 (2 seeds) {d_rand:.3}");
    assert!((mean_vs("original") - d_orig).abs() < 1e-5 && (mean_vs("random32") - d_rand).abs() < 1e-5, "{paired}");
    assert!(d_orig < -0.3, "RAUCA-E2E hides the car on held-out views: {d_orig}");
    assert!(common::output_text(&o).contains("rauca-e2e against each other texture"), "{}", common::output_text(&o));
}

/// `eval-digital -t DIR` on the folder of a `pav optimize --seeds` run: its seeds pool into one
/// row, and it is paired with each other texture per (seed, view); a folder without seeds is a
/// clear error.
#[cfg(feature = "optimize")]
#[test]
fn eval_digital_pools_a_seeded_runs_folder() {
    let shared = common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("pooled");
    for (seed, png) in [(0, "rauca-e2e/RAUCA_E2E.png"), (1, "pav-camou/image.png")] {
        std::fs::create_dir_all(run.join(format!("seed{seed}"))).unwrap();
        std::fs::copy(shared.join(png), run.join(format!("seed{seed}/texture.png"))).unwrap();
    }
    std::fs::create_dir_all(run.join("not-a-seed")).unwrap();
    let out_dir = tmp.path().join("out");
    let o = eval_digital_yolov3_tiny()
        .args(["-t", "data:rauca-e2e/RAUCA_E2E.png", "-t"])
        .arg(&run)
        .arg("-o")
        .arg(&out_dir)
        .output()
        .unwrap();
    let out = common::output_text(&o);
    assert!(o.status.success(), "{out}");
    assert!(out.contains("pooled against each other texture, held-out views: mean difference of the best car score [95 % paired-bootstrap interval over (seed, view) pairs of its 2 seeds"), "{out}");
    let views = std::fs::read_to_string(out_dir.join("digital_views.csv")).unwrap();
    let rows: Vec<Vec<&str>> = views.lines().skip(1).map(|l| l.split(',').collect()).collect();
    // fold,role,view,texture,seed,detector,score
    let held = |tex: &str, seed: &str| -> Vec<f64> {
        rows.iter()
            .filter(|r| r[1] == "held-out" && r[3] == tex && r[4] == seed)
            .map(|r| r[6].parse().unwrap())
            .collect()
    };
    // Seed 0 is RAUCA-E2E's texture: the same scores as the file given on its own.
    assert_eq!(held("pooled", "0"), held("rauca-e2e", "0"), "{views}");
    let (s0, s1, orig) = (held("pooled", "0"), held("pooled", "1"), held("original", "0"));
    assert_eq!([s0.len(), s1.len(), orig.len()], [5; 3], "{views}");
    assert_ne!(s0, s1, "two different textures score alike: {views}");
    // One row of 2 × 11 images, and pairs over the 2 × 5 (seed, held-out view) pairs.
    let csv = std::fs::read_to_string(out_dir.join("digital.csv")).unwrap();
    let all = csv.lines().find(|l| l.contains(",pooled,all,")).unwrap_or_else(|| panic!("{csv}"));
    assert_eq!(all.split(',').nth(4), Some("22"), "{csv}");
    let paired = std::fs::read_to_string(out_dir.join("digital_paired.csv")).unwrap();
    let line = paired.lines().find(|l| l.starts_with("pooled,yolov3-tiny,true,original,")).unwrap();
    assert!(line.ends_with(",10"), "{line}");
    let d: f64 = s0.iter().chain(&s1).zip(orig.iter().chain(&orig)).map(|(m, o)| m - o).sum::<f64>() / 10.0;
    let mean: f64 = line.split(',').nth(4).unwrap().parse().unwrap();
    assert!((mean - d).abs() < 1e-5, "{line}: recomputed {d}");

    let empty = tmp.path().join("empty");
    std::fs::create_dir_all(empty.join("seed0")).unwrap();
    let o = eval_digital_yolov3_tiny().arg("-t").arg(&empty).arg("-o").arg(tmp.path().join("o2")).output().unwrap();
    let msg = common::output_text(&o);
    assert!(!o.status.success() && msg.contains("a folder without seed<N>/texture.png in it"), "{msg}");
}

/// Ctrl-C during `pav optimize` saves the state and exits non-zero, so a following command in
/// `pav optimize && …` does not go on with a partial texture (resuming is tested in attack_optimize).
#[cfg(all(feature = "optimize", unix))]
#[test]
fn an_interrupted_optimize_saves_and_exits_non_zero() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("run");
    let child = pav()
        .args(["optimize", "--config", "configs/optimize/paper.toml", "--epochs", "60", "-o"])
        .arg(&out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // The first epoch's checkpoint shows the run (and its Ctrl-C handler) is going.
    let t = std::time::Instant::now();
    while !out.join("loss.csv").exists() {
        assert!(t.elapsed().as_secs() < 300, "no checkpoint after 5 minutes");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let o = child.wait_with_output().unwrap();
    let msg = common::output_text(&o);
    assert!(!o.status.success() && msg.contains("stopped: state saved"), "{msg}");
    let done = pav::attack::checkpoint::Checkpoint::load(&out.join("checkpoint.bin")).unwrap().steps_done;
    assert!((6..360).contains(&done), "{done} steps saved");
    let run = common::run_record(&out.join("run.toml"));
    assert_eq!(run["settings"]["seed"].as_str(), Some("0"), "{run}");
    assert_eq!(
        common::record_input(&run, "pytorch3d_Etron.obj")["data"].as_str(),
        Some("rauca-e2e/pytorch3d_Etron.obj")
    );
}

#[test]
fn paint_puts_a_texture_on_the_region_and_keeps_the_car_paint_elsewhere() {
    let data = common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("painted.png");
    let o = pav()
        .args(["paint", "--config", "configs/studies/half-turns-ensemble-pbr.toml"])
        .args(["--texture", "data:rauca-e2e/RAUCA_E2E.png", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    // The config's region: mask.png's white on the sides' middle and the top, at 256² texels.
    assert!(common::output_text(&o).contains("over 14421 of 65536 region texels"), "{}", common::output_text(&o));
    let (p, base, tex) = (
        image::open(&out).unwrap().to_rgb8(),
        image::open(data.join("rauca-e2e/img_optim.png")).unwrap().to_rgb8(),
        image::open(data.join("rauca-e2e/RAUCA_E2E.png")).unwrap().to_rgb8(),
    );
    assert_eq!(p.dimensions(), base.dimensions());
    let (mut kept, mut from_tex, mut other) = (0usize, 0usize, 0usize);
    for (x, y, px) in p.enumerate_pixels() {
        if px == base.get_pixel(x, y) {
            kept += 1;
        } else if px.0.iter().zip(tex.get_pixel(x, y).0).all(|(a, b)| a.abs_diff(b) <= 1) {
            from_tex += 1; // Same-size texture: the bilinear read lands on the texel itself.
        } else {
            other += 1;
        }
    }
    let n = (p.width() * p.height()) as usize;
    eprintln!("kept {kept}, from the texture {from_tex}, other {other} of {n}");
    // 14421/65536 of the atlas is region; every painted texel comes from the texture.
    assert_eq!(other, 0);
    assert!(from_tex > n / 6 && from_tex < n / 4, "{from_tex} of {n}");
    let o = pav()
        .args(["paint", "--config", "configs/studies/half-turns-ensemble-pbr.toml", "--texture", "nope.png", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!o.status.success() && common::output_text(&o).contains("nope.png"), "{}", common::output_text(&o));
    // The random baseline as a paint: blocks of one colour, 1/64 of the atlas side, the same
    // for the same seed and not for another.
    let random = |seed: &str, name: &str| {
        let path = tmp.path().join(name);
        let o = pav()
            .args(["paint", "--config", "configs/studies/half-turns-ensemble-pbr.toml", "--random", seed, "-o"])
            .arg(&path)
            .output()
            .unwrap();
        assert!(o.status.success() && common::output_text(&o).contains("random blocks"), "{}", common::output_text(&o));
        image::open(&path).unwrap().to_rgb8()
    };
    let (r0, again, r1) = (random("0", "r0.png"), random("0", "r0b.png"), random("1", "r1.png"));
    assert_eq!(r0, again);
    let differ = r0.pixels().zip(r1.pixels()).filter(|(a, b)| a != b).count();
    assert!(differ > n / 8, "seeds 0 and 1 differ in {differ} of {n} pixels");
    let kept = r0.enumerate_pixels().filter(|(x, y, px)| *px == base.get_pixel(*x, *y)).count();
    assert!(kept > n / 2, "the car's paint outside the region: {kept} of {n}");
}

/// `--defence` on the experiments: `eval-digital` and `crossval` score each detector behind each
/// defence beside the undefended one (never starred as a white box: the texture was not made
/// through the defence), and record the defences in run.toml.
#[cfg(feature = "optimize")]
#[test]
fn eval_digital_and_crossval_score_defended_detectors() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let rows = |csv: &str, detector: &str| -> Vec<String> {
        csv.lines().filter(|l| l.split(',').next() == Some(detector)).map(str::to_string).collect()
    };
    let o = eval_digital_yolov3_tiny()
        .args(["--defence", "bits:b=1", "--random-seeds", "1", "-o"])
        .arg(tmp.path().join("digital"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let csv = std::fs::read_to_string(tmp.path().join("digital/digital.csv")).unwrap();
    let (plain, defended) = (rows(&csv, "yolov3-tiny"), rows(&csv, "yolov3-tiny+bits1"));
    assert_eq!(plain.len(), defended.len(), "{csv}");
    assert!(plain.iter().all(|l| l.contains(",true,")) && defended.iter().all(|l| l.contains(",false,")), "{csv}");
    // One bit per channel: the original paint is found far less often (the defence's clean cost).
    let p50 = |lines: &[String]| -> f64 {
        let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
        let line = lines.iter().find(|l| l.contains(",original,all,")).unwrap();
        line.split(',').nth(header.iter().position(|h| *h == "p50").unwrap()).unwrap().parse().unwrap()
    };
    assert!(p50(&defended) < p50(&plain) - 0.3, "{csv}");
    let run = common::run_record(&tmp.path().join("digital/run.toml"));
    assert_eq!(run["settings"]["defences"].as_str(), Some("bits1"), "{run}");

    // Cross-validation of a two-photo, one-epoch config: each fold's texture and baselines are
    // scored by the plain and the defended detector.
    let cfg = tmp.path().join("tiny.toml");
    let base = common::repo().join("configs/studies/half.toml");
    std::fs::write(
        &cfg,
        format!(
            "extends = {:?}\n[views]\ntrain = [\"data:fca/carla_dataset/test/data12501.npz\"]\ntest = [\"data:fca/carla_dataset/test/data12502.npz\"]\n[optimizer]\nepochs = 1\n",
            base.display().to_string()
        ),
    )
    .unwrap();
    let o = pav()
        .args(["crossval", "--config"])
        .arg(&cfg)
        .args(["--random-seeds", "1", "-d", "configs/detectors/yolov3-tiny.toml", "--defence", "median:k=5", "-o"])
        .arg(tmp.path().join("cv"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let csv = std::fs::read_to_string(tmp.path().join("cv/crossval.csv")).unwrap();
    let defended = rows(&csv, "yolov3-tiny+median5");
    assert_eq!(defended.len(), rows(&csv, "yolov3-tiny").len(), "{csv}");
    assert!(defended.iter().any(|l| l.contains(",optimized,held-out,2,")), "both photos held out once:\n{csv}");
    let run = common::run_record(&tmp.path().join("cv/run.toml"));
    assert_eq!(run["settings"]["defences"].as_str(), Some("median5"), "{run}");
    let o = pav().args(["crossval", "--config"]).arg(&cfg).args(["--defence", "jpeg:q=0"]).output().unwrap();
    assert!(!o.status.success() && common::output_text(&o).contains("q = 0 must be a quality from 1 to 100"));
}

/// `eval-digital --squeeze` (feature squeezing as an attack detector): every view's gap is the
/// largest change of its best car score under bit depth 4 and a 3×3 median, as
/// `digital_views.csv` records the scores, and the thresholds flag at most 5 % of the legitimate
/// views (the photo and the random textures).
#[cfg(feature = "optimize")]
#[test]
fn eval_digital_squeeze_flags_views_whose_score_moves_under_squeezing() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let rauca = common::shared_data().join("rauca-e2e/RAUCA_E2E.png");
    let o = eval_digital_yolov3_tiny()
        .args(["--squeeze", "--random-seeds", "2", "-t"])
        .arg(&rauca)
        .arg("-o")
        .arg(tmp.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let table = |name: &str| -> Vec<std::collections::HashMap<String, String>> {
        let text = std::fs::read_to_string(tmp.path().join(name)).unwrap();
        let header: Vec<String> = text.lines().next().unwrap().split(',').map(String::from).collect();
        text.lines().skip(1).map(|l| header.iter().cloned().zip(l.split(',').map(String::from)).collect()).collect()
    };
    let views = table("digital_views.csv");
    let score = |v: &std::collections::HashMap<String, String>, det: &str| -> f32 {
        let r = views
            .iter()
            .find(|r| {
                r["view"] == v["view"] && r["texture"] == v["texture"] && r["seed"] == v["seed"] && r["detector"] == det
            })
            .unwrap_or_else(|| panic!("no {det} row for {v:?}"));
        r["score"].parse().unwrap()
    };
    let squeeze = table("digital_squeeze.csv");
    let (mut legit, mut flagged) = (0, 0);
    for v in &squeeze {
        assert_eq!(v["detector"], "yolov3-tiny");
        let s = score(v, "yolov3-tiny");
        let want = (s - score(v, "yolov3-tiny+bits4")).abs().max((s - score(v, "yolov3-tiny+median3")).abs());
        assert!((v["gap"].parse::<f32>().unwrap() - want).abs() < 1e-6, "{v:?}: {want}");
        if ["original", "random", "random32"].contains(&v["texture"].as_str()) {
            legit += 1;
            flagged += usize::from(v["flagged"] == "true");
        }
    }
    assert!(squeeze.iter().any(|v| v["texture"] == "rauca-e2e"), "the given texture is scored too");
    assert!(legit >= 40 && flagged * 20 <= legit, "{flagged} of {legit} legitimate views flagged");
    let md = std::fs::read_to_string(tmp.path().join("digital.md")).unwrap();
    assert!(md.contains("Feature squeezing as an attack detector") && md.contains("| yolov3-tiny |"), "{md}");
}
