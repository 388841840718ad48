//! Rig configs: the shipped rigs put the model where a pinhole camera of their lens and sensor
//! would see it, shots no camera could take are refused, and each camera effect is off unless
//! the rig lists it.

use crate::common;
use crate::common::{pav, pav_rig};

use pav::render::raster::{GBuffer, EMPTY};
use pav::scene::camera_effects::{apply_noise, circle_of_confusion_px, codec_kbps, cut};
use pav::scene::rig::{CameraEffect, RigConfig};
use pav::scene::turntable::CarScene;

fn rig(name: &str) -> RigConfig {
    common::shared_data();
    RigConfig::load(&common::repo().join("configs/rig").join(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// Rows and columns of a square G-buffer the model covers: (first row, last row, first column,
/// last column).
fn covered_box(g: &GBuffer) -> (usize, usize, usize, usize) {
    let hit: Vec<(usize, usize)> =
        (0..g.size * g.size).filter(|&i| g.face[i] != EMPTY).map(|i| (i / g.size, i % g.size)).collect();
    assert!(!hit.is_empty(), "the model is out of sight");
    let rows = hit.iter().map(|h| h.0);
    let cols = hit.iter().map(|h| h.1);
    (rows.clone().min().unwrap(), rows.max().unwrap(), cols.clone().min().unwrap(), cols.max().unwrap())
}

/// The model's extent across a `width`-pixel frame by the pinhole formula alone: its vertices
/// in metres about its centre, a camera `d_m` away level with the centre on the +Z side
/// (table angle 0), x·f/(d − z) with f from the lens and the sensor.
fn pinhole_extent_px(mesh: &pav::geometry::mesh::Mesh, r: &RigConfig, d_m: f64, width: usize) -> f64 {
    let (lo, hi) = mesh.bounds();
    let length_units = f64::from((hi[0] - lo[0]).max(hi[2] - lo[2]));
    let per_m = length_units / (r.model.car_length_m / r.model.scale);
    let cy = f64::from(lo[1] + hi[1]) / 2.0;
    let f_px = r.camera.focal_mm.unwrap() / r.camera.sensor_mm.unwrap()[0] * width as f64;
    let cols: Vec<f64> = mesh
        .positions
        .iter()
        .map(|p| {
            let (x, _y, z) = (f64::from(p[0]) / per_m, (f64::from(p[1]) - cy) / per_m, f64::from(p[2]) / per_m);
            f_px * x / (d_m - z)
        })
        .collect();
    cols.iter().cloned().fold(f64::MIN, f64::max) - cols.iter().cloned().fold(f64::MAX, f64::min)
}

#[test]
fn the_model_spans_the_pixels_a_pinhole_camera_predicts() {
    let r = rig("phone-etron.toml");
    let (_, mesh) = r.views_config().unwrap();
    let shot = r.shot(&mesh);
    assert_eq!(shot.size, (640, 360));
    // Level with the model's centre (elevation 0), at the rig's distance and at twice it.
    for d in [0.5, 1.0] {
        let mut at = r.clone();
        at.placement.distance_m = d;
        let shot = at.shot(&mesh);
        let g = GBuffer::render(&mesh, &RigConfig::camera(&shot, 0, 0.0), 640);
        let (_, _, a, b) = covered_box(&g);
        let measured = (b - a + 1) as f64;
        let predicted = pinhole_extent_px(&mesh, &r, d, 640);
        eprintln!("at {d} m: {measured} px, predicted {predicted:.1}");
        assert!((measured / predicted - 1.0).abs() < 0.02, "at {d} m: {measured} px against {predicted:.1}");
        // The camera looks at the model's centre.
        assert!((((a + b) as f64 / 2.0) - 319.5).abs() < 3.0, "centred at {}", (a + b) / 2);
    }
    // A 1:20 model filmed from 0.5 m fills about f·L/D of the frame: 235 px of 640 for the
    // paper's phone, with the perspective of its near corners on top.
    let plain = 4.8 / 6.4 * 640.0 * (4.9 / 20.0) / 0.5;
    let near = pinhole_extent_px(&mesh, &r, 0.5, 640);
    assert!(near > plain && near < 1.1 * plain, "{near} against {plain}");
    let _ = shot;
}

#[test]
fn a_camera_height_is_metres_above_the_table_top() {
    let r = rig("webcam.toml");
    let (cfg, mesh) = r.views_config().unwrap();
    let shot = r.shot(&mesh);
    let cam = RigConfig::camera(&shot, 0, 30.0);
    let u = shot.units_per_m;
    let height = (cam.eye[1] - shot.ground_y) / u;
    let horizontal = (cam.eye[0] * cam.eye[0] + cam.eye[2] * cam.eye[2]).sqrt() / u;
    assert!((height - 0.1).abs() < 1e-4 && (horizontal - 0.4).abs() < 1e-4, "{height} m up, {horizontal} m away");
    // The views the turntable renders are these cameras, a turn of render.frames angles.
    let views = cfg.views();
    assert_eq!(views.len(), r.render.frames);
    let v = &views[3];
    let c = RigConfig::camera(&shot, 0, v.pose[2]);
    assert!(v.camera.eye.iter().zip(c.eye).all(|(a, b)| (a - b).abs() < 1e-5));
    assert_eq!(cfg.render.size, 640);
    // 1:20 of a 4.9 m car is 24.5 cm long.
    let (lo, hi) = mesh.bounds();
    let length = (hi[0] - lo[0]).max(hi[2] - lo[2]) / u;
    assert!((length - 0.245).abs() < 1e-5, "{length}");
}

#[test]
fn every_shipped_rig_keeps_the_whole_model_in_its_frame() {
    common::shared_data();
    let mut n = 0;
    for e in std::fs::read_dir(common::repo().join("configs/rig")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let r = rig(&name);
        r.check().unwrap_or_else(|e| panic!("{name}: {e}"));
        let (cfg, mesh) = r.views_config().unwrap_or_else(|e| panic!("{name}: {e}"));
        let shot = r.shot(&mesh);
        assert_eq!(cfg.views().len(), r.render.frames * shot.poses.len(), "{name}");
        // The square render is cut to the frame: the model must lie inside that band at every
        // camera height and table angle, or the training and test views would crop the car.
        let side = 160;
        let (w, h) = shot.size;
        // The frame's first and last row (column) in the square render, cut about its centre.
        let cut = |n: usize| ((side - side * n / w.max(h)) / 2, (side + side * n / w.max(h)) / 2 - 1);
        let ((top, bottom), (left, right)) = (cut(h), cut(w));
        for k in 0..shot.poses.len() {
            for a in (0..360).step_by(30) {
                let g = GBuffer::render(&mesh, &RigConfig::camera(&shot, k, a as f32), side);
                let (r0, r1, c0, c1) = covered_box(&g);
                let inside = r0 > top && r1 < bottom && c0 > left && c1 < right;
                assert!(inside, "{name}: camera {k} at {a}°: rows {r0}–{r1}, columns {c0}–{c1}, frame rows {top}–{bottom}, columns {left}–{right}");
            }
        }
        n += 1;
    }
    assert!(n >= 8, "{n} rigs");
}

/// One change to a rig config.
type Change = Box<dyn Fn(&mut RigConfig)>;

#[test]
fn shots_no_camera_could_take_are_refused() {
    let good = rig("phone-etron.toml");
    assert!(good.check().is_ok());
    let cases: Vec<(&str, Change, &str)> = vec![
        ("zero distance", Box::new(|r| r.placement.distance_m = 0.0), "distance_m"),
        ("negative distance", Box::new(|r| r.placement.distance_m = -0.5), "distance_m"),
        ("focus behind the camera", Box::new(|r| r.camera.focus_m = Some(-0.2)), "in front of the camera"),
        ("focus inside the lens", Box::new(|r| r.camera.focus_m = Some(0.004)), "focal length"),
        ("exposure over a frame", Box::new(|r| r.camera.exposure_s = 0.05), "does not fit"),
        ("zero fps", Box::new(|r| r.camera.fps = 0.0), "camera.fps"),
        ("table reaching the camera", Box::new(|r| r.table.radius_m = 0.6), "reaches the camera"),
        ("no lens", Box::new(|r| r.camera.focal_mm = None), "focal_mm with sensor_mm"),
        ("lens and field of view", Box::new(|r| r.camera.fov_deg = Some(60.0)), "focal_mm with sensor_mm"),
        ("heights and elevations", Box::new(|r| r.placement.heights_m = vec![0.1]), "heights_m or elevations_deg"),
        (
            "camera under the table",
            Box::new(|r| {
                r.placement.elevations_deg.clear();
                r.placement.heights_m = vec![-0.1];
            }),
            "below the table top",
        ),
        ("zero scale", Box::new(|r| r.model.scale = 0.0), "model.scale"),
        ("colour out of range", Box::new(|r| r.room.backdrop = [1.5, 0.0, 0.0]), "sRGB"),
        ("effect twice", Box::new(|r| r.effects = vec![CameraEffect::Noise, CameraEffect::Noise]), "twice"),
        (
            "defocus without a lens",
            Box::new(|r| {
                (r.camera.focal_mm, r.camera.sensor_mm, r.camera.fov_deg) = (None, None, Some(60.0));
                r.effects = vec![CameraEffect::Defocus];
            }),
            "defocus needs the lens",
        ),
    ];
    for (what, change, says) in cases {
        let mut r = good.clone();
        change(&mut r);
        let e = r.check().expect_err(what);
        assert!(e.contains(says), "{what}: {e}");
    }
    // Unknown keys are refused when read, naming the file.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rig.toml");
    let text = std::fs::read_to_string(common::repo().join("configs/rig/phone-paper.toml")).unwrap();
    std::fs::write(&path, text.replace("f_number", "aperture")).unwrap();
    let e = RigConfig::load(&path).unwrap_err().to_string();
    assert!(e.contains("rig.toml") && e.contains("aperture"), "{e}");
}

#[test]
fn the_circle_of_confusion_is_the_thin_lens_one() {
    let r = rig("phone-etron.toml");
    // In focus: a point. At 1 m with the lens at 0.5 m: f²/(N(s−f))·|z−s|/z on the sensor.
    assert_eq!(circle_of_confusion_px(&r, 0.5, 0.5, 640), 0.0);
    let mm = 4.8 * 4.8 / (1.8 * (500.0 - 4.8)) * 0.5;
    let px = circle_of_confusion_px(&r, 0.5, 1.0, 640);
    assert!((px - mm / 6.4 * 640.0).abs() < 1e-9, "{px}");
    // Nearer than the focus blurs more than as far behind it.
    assert!(circle_of_confusion_px(&r, 0.5, 0.4, 640) > circle_of_confusion_px(&r, 0.5, 0.6, 640));
}

#[test]
fn each_camera_effect_is_off_unless_listed() {
    let mut r = rig("webcam.toml");
    r.effects.clear();
    r.render.width = Some(320);
    let plain = CarScene::from_rig(&r, None, 0).unwrap();
    let (w, h) = (320, 180);
    let angle = 60.0;
    let bare = {
        let rgb = pav::image::halve(&plain.render(angle, 640), 640, 640);
        cut(&rgb, 320, (w, h))
    };
    let none = plain.frame(angle, w, h);
    assert_eq!(none.bgr, bare.bgr, "no effect listed, yet the frame changed");
    let mut untouched = none.clone();
    apply_noise(&r, &mut untouched, 7);
    assert_eq!(untouched.bgr, none.bgr);
    assert_eq!(codec_kbps(&r), None);
    // The model's pixels, and the backdrop's well away from them.
    let shot = {
        let (_, mesh) = r.views_config().unwrap();
        (r.shot(&mesh), mesh)
    };
    let g = GBuffer::render(&shot.1, &RigConfig::camera(&shot.0, 0, angle), 320);
    let y0 = (320 - h) / 2;
    let on_model = |x: usize, y: usize| {
        let (lo_x, hi_x, lo_y, hi_y) =
            (x.saturating_sub(4), (x + 4).min(319), (y + y0).saturating_sub(4), (y + y0 + 4).min(319));
        (lo_y..=hi_y).any(|yy| (lo_x..=hi_x).any(|xx| g.face[yy * 320 + xx] != EMPTY))
    };
    for effect in [CameraEffect::Defocus, CameraEffect::MotionBlur, CameraEffect::Noise, CameraEffect::Codec] {
        let mut one = r.clone();
        one.effects = vec![effect];
        if effect == CameraEffect::Codec {
            // The codec is the video writer's: the capture's bits per pixel at the simulated size.
            let kbps = codec_kbps(&one).unwrap();
            assert!((kbps - 4000.0 * (320.0 * 180.0) / (1280.0 * 720.0)).abs() < 1e-9, "{kbps}");
            assert_eq!(CarScene::from_rig(&one, None, 0).unwrap().frame(angle, w, h).bgr, none.bgr);
            continue;
        }
        let f = CarScene::from_rig(&one, None, 0).unwrap().frame(angle, w, h);
        let changed: Vec<(usize, usize)> = (0..w * h)
            .filter(|&i| f.bgr[3 * i..3 * i + 3] != none.bgr[3 * i..3 * i + 3])
            .map(|i| (i % w, i / w))
            .collect();
        eprintln!("{effect:?}: {} pixels changed", changed.len());
        assert!(changed.len() > 100, "{effect:?} changed only {} pixels", changed.len());
        if effect == CameraEffect::MotionBlur {
            // Only the turning model blurs; the room stands still.
            assert!(changed.iter().all(|&(x, y)| on_model(x, y)), "motion blur moved the room");
        }
        if effect == CameraEffect::Noise {
            let d: Vec<f64> = (0..w * h * 3).map(|i| f64::from(f.bgr[i]) - f64::from(none.bgr[i])).collect();
            let mean = d.iter().sum::<f64>() / d.len() as f64;
            assert!(mean.abs() < 0.5, "noise shifted the levels by {mean}");
        }
    }
}

#[test]
fn the_rasterizer_films_the_rigs_frames_at_the_views_angles() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let path = common::small_rig(tmp.path(), "webcam.toml", 256, 4);
    let out = tmp.path().join("tt");
    let o =
        pav().args(["views", "turntable", "--rasterizer", "--rig"]).arg(&path).arg("-o").arg(&out).output().unwrap();
    let said = common::output_text(&o);
    assert!(o.status.success(), "{said}");
    let r = RigConfig::load(&path).unwrap();
    let (cfg, _) = r.views_config().unwrap();
    let videos: Vec<_> = std::fs::read_dir(out.join("videos"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "mp4"))
        .collect();
    assert_eq!(videos.len(), 1, "{said}");
    // The file is named as Blender's would be, and holds the views' angles, a turn in 28 s.
    let v = &cfg.views()[0];
    let stem = format!("interior_d{:.2}_e{:.0}", v.pose[0], v.pose[1]);
    assert_eq!(videos[0].file_stem().unwrap().to_string_lossy(), stem);
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&videos[0])).unwrap();
    let want: Vec<f64> = cfg.views().iter().map(|v| f64::from(v.pose[2])).collect();
    assert_eq!(rows.iter().map(|s| s.angle_deg).collect::<Vec<_>>(), want);
    assert_eq!(rows[3].timestamp_s, 21.0);
    // Each frame is the scene's frame at its angle, through the rig's codec (4:2:0 at a low
    // bitrate smooths the sensor noise away: about 5 levels per byte), and not the frame a
    // quarter turn on (about 14).
    let scene = CarScene::from_rig(&r, None, 0).unwrap();
    let mut reader = pav::video::VideoReader::open(&videos[0]).unwrap();
    let diff = common::mean_abs_diff;
    while let Some((i, f)) = reader.read().unwrap() {
        assert_eq!((f.width, f.height), (256, 144));
        let a = rows[i].angle_deg as f32;
        let (at, off) =
            (diff(&f.bgr, &scene.frame(a, 256, 144).bgr), diff(&f.bgr, &scene.frame(a + 90.0, 256, 144).bgr));
        eprintln!("frame {i}: mean |Δ| {at:.2} at its angle, {off:.2} a quarter turn on");
        assert!(at < 0.5 * off, "frame {i}: {at} against {off}");
    }
    let run = std::fs::read_to_string(out.join("run.toml")).unwrap();
    assert!(run.contains("webcam.toml") && run.contains("rasterizer"), "{run}");
}

#[test]
fn a_capture_names_its_rig_and_its_simulated_camera_films_the_rigs_model() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let path = common::small_rig(tmp.path(), "webcam.toml", 256, 22);
    let video = tmp.path().join("cap.mp4");
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--time-scale", "8", "--camera", "sim", "--rig"])
        .arg(&path)
        .args(["--width", "256", "--height", "144", "--fps", "10", "-o"])
        .arg(&video)
        .output()
        .unwrap();
    let said = common::output_text(&o);
    assert!(o.status.success(), "{said}");
    let run = std::fs::read_to_string(video.with_extension("run.toml")).unwrap();
    assert!(run.contains("webcam.toml") && run.contains("placement"), "{run}");
    // The frames are the rig's model at the sidecar's angles.
    let r = RigConfig::load(&path).unwrap();
    let scene = CarScene::from_rig(&r, None, 0).unwrap();
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap();
    let mut reader = pav::video::VideoReader::open(&video).unwrap();
    let diff = common::mean_abs_diff;
    // Each frame is closer to the model drawn at its sidecar angle than at 5° either side (the
    // capture claims 0.5°). The camera's noise is drawn afresh at every angle, so every
    // comparison carries the same noise floor and only the model's pose can tell them apart.
    let mut frames = Vec::new();
    while let Some((i, f)) = reader.read().unwrap() {
        let a = rows[i].angle_deg as f32;
        let at = diff(&f.bgr, &scene.frame(a, 256, 144).bgr);
        let near = [a - 5.0, a + 5.0].map(|b| diff(&f.bgr, &scene.frame(b, 256, 144).bgr));
        frames.push((a, at, near[0].min(near[1])));
    }
    eprintln!("(angle, mean |Δ| per byte at it, at 5° off): {frames:.2?}");
    // In simulated time every frame of the 3.5 s turn at 10 fps is filmed, however busy the
    // machine.
    assert!(frames.len() >= 35 && frames.len() == rows.len(), "{} frames, {} rows", frames.len(), rows.len());
    assert!(frames.iter().all(|f| f.1 < f.2), "{frames:?}");
    // --texture without a model to paint is refused.
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--camera", "gst-test", "--rig"])
        .arg(&path)
        .arg("--texture")
        .arg(&path)
        .arg("-o")
        .arg(tmp.path().join("x.mp4"))
        .output()
        .unwrap();
    assert!(!o.status.success() && common::output_text(&o).contains("--texture paints"), "{}", common::output_text(&o));
}

#[test]
fn compare_finds_how_far_a_capture_s_zero_is_from_the_simulation_s() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let path = common::small_rig(tmp.path(), "phone-etron.toml", 320, 36);
    let sim = tmp.path().join("sim");
    let o =
        pav().args(["views", "turntable", "--rasterizer", "--rig"]).arg(&path).arg("-o").arg(&sim).output().unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    // The "real" capture: the live simulated camera at the table's own angles (other frames
    // than the simulation's), from the rig's first camera position, its sidecar then written as
    // a table that homed 40° before the simulation's zero.
    let real = tmp.path().join("real.mp4");
    let o = pav_rig()
        .args(["capture", "--port", "sim", "--time-scale", "4", "--camera", "sim", "--rig"])
        .arg(&path)
        .args(["--width", "320", "--height", "180", "--fps", "10", "-o"])
        .arg(&real)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let side = pav::sidecar::sidecar_path(&real);
    let mut rows = pav::sidecar::read(&side).unwrap();
    for r in &mut rows {
        r.angle_deg = (r.angle_deg - 40.0).rem_euclid(360.0);
    }
    let mut w = pav::sidecar::Writer::create(&side).unwrap();
    for r in &rows {
        w.push(*r).unwrap();
    }
    drop(w);
    let level = std::fs::read_dir(sim.join("videos"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.to_string_lossy().ends_with("_e0.mp4"))
        .unwrap();
    let eval = tmp.path().join("eval");
    let o = pav_rig()
        .arg("evaluate")
        .args([&real, &level])
        .args(["--label", "real", "--label", "sim", "--no-plots", "-d"])
        .arg(common::repo().join("configs/detectors"))
        .arg("-o")
        .arg(&eval)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let out = tmp.path().join("cmp");
    let o = pav_rig()
        .arg("compare")
        .arg(&eval)
        .args(["--real", "real", "--sim", "sim", "--sectors", "36", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    let said = common::output_text(&o);
    assert!(o.status.success(), "{said}");
    let run = std::fs::read_to_string(out.join("run.toml")).unwrap();
    let offset: f64 = run
        .lines()
        .find_map(|l| l.strip_prefix("offset_deg = "))
        .map(|v| v.trim_matches('"').parse().unwrap())
        .unwrap_or_else(|| panic!("{run}"));
    eprintln!("{said}");
    let err = (offset - 40.0 + 180.0).rem_euclid(360.0) - 180.0;
    // Within a sector (10°) of the truth.
    assert!(err.abs() <= 10.0, "found {offset}°, put in 40°");
    assert!(std::fs::read_to_string(out.join("compare.csv")).unwrap().lines().count() == 1 + 4 * 36);
    // A label that was not scored is named with the ones that were.
    let o =
        pav_rig().arg("compare").arg(&eval).args(["--real", "nope", "--sim", "sim", "-o"]).arg(&out).output().unwrap();
    assert!(
        !o.status.success() && common::output_text(&o).contains("labels here: real, sim"),
        "{}",
        common::output_text(&o)
    );
}

/// `pav-rig paired`: the original paint and RAUCA-E2E's texture filmed by the rasterizer on the
/// same shots of the phone rig, scored, then paired frame by frame; the difference is the mean
/// of the per-frame differences in frames.csv, and a label filmed on other shots is refused.
#[test]
fn paired_compares_two_paints_frame_by_frame() {
    let shared = common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let path = common::small_rig(tmp.path(), "phone-etron.toml", 320, 12);
    let film = |name: &str, texture: Option<&std::path::Path>| {
        let out = tmp.path().join(name);
        let mut c = pav();
        c.args(["views", "turntable", "--rasterizer", "--rig"]).arg(&path).arg("-o").arg(&out);
        if let Some(t) = texture {
            c.arg("--texture").arg(t);
        }
        let o = c.output().unwrap();
        assert!(o.status.success(), "{}", common::output_text(&o));
        let mut v: Vec<_> = std::fs::read_dir(out.join("videos"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "mp4"))
            .collect();
        v.sort();
        v
    };
    let (original, rauca) = (film("original", None), film("rauca", Some(&shared.join("rauca-e2e/RAUCA_E2E.png"))));
    assert_eq!(original.len(), rauca.len());
    let eval = tmp.path().join("eval");
    let mut c = pav_rig();
    c.arg("evaluate").args(&original).args(&rauca);
    for l in original.iter().map(|_| "original").chain(rauca.iter().map(|_| "rauca")) {
        c.args(["--label", l]);
    }
    let o = c
        .args(["--no-plots", "-d"])
        .arg(common::repo().join("configs/detectors/yolov3-tiny.toml"))
        .arg("-o")
        .arg(&eval)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let out = tmp.path().join("paired");
    let o = pav_rig().arg("paired").arg(&eval).args(["--against", "original", "-o"]).arg(&out).output().unwrap();
    let said = common::output_text(&o);
    assert!(o.status.success(), "{said}");
    eprintln!("{said}");
    // Recomputed from frames.csv: each RAUCA-E2E frame against the original's frame of the same
    // shot (the videos' names are the shots') and index.
    let frames = pav::eval::compare::read_frames(&eval.join("frames.csv")).unwrap();
    let name = |f: &str| std::path::Path::new(f).file_name().unwrap().to_string_lossy().into_owned();
    let score = |label: &str, file: &str, frame: usize| {
        frames
            .iter()
            .find(|r| r.video == label && name(&r.file) == file && r.frame == frame)
            .map(|r| r.max_score as f64)
    };
    let d: Vec<f64> = frames
        .iter()
        .filter(|r| r.video == "rauca")
        .map(|r| r.max_score as f64 - score("original", &name(&r.file), r.frame).unwrap())
        .collect();
    assert_eq!(d.len(), 12 * original.len());
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let csv = std::fs::read_to_string(out.join("paired.csv")).unwrap();
    let row: Vec<&str> = csv.lines().nth(1).unwrap().split(',').collect();
    // label,against,detector,frames,detected,detected_against,score,score_against,diff,lo,hi
    assert_eq!(&row[..4], ["rauca", "original", "yolov3-tiny", &d.len().to_string()], "{csv}");
    let diff: f64 = row[8].parse().unwrap();
    assert!((diff - mean).abs() < 1e-6, "{diff} against {mean}");
    assert!(row[9].parse::<f64>().unwrap() <= diff && diff <= row[10].parse::<f64>().unwrap(), "{csv}");
    // Two shots against one: refused, named.
    let one = tmp.path().join("eval1");
    let o = pav_rig()
        .arg("evaluate")
        .args([&original[0], &rauca[0], &rauca[1]])
        .args(["--label", "original", "--label", "rauca", "--label", "rauca", "--no-plots", "-d"])
        .arg(common::repo().join("configs/detectors/yolov3-tiny.toml"))
        .arg("-o")
        .arg(&one)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", common::output_text(&o));
    let o = pav_rig().arg("paired").arg(&one).args(["--against", "original", "-o"]).arg(&out).output().unwrap();
    let said = common::output_text(&o);
    assert!(!o.status.success() && said.contains("`rauca` has 2 videos and `original` 1"), "{said}");
}
