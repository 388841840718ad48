//! Blender Cycles views: pav's rasterizer and Blender agree on pose and texture mapping to the
//! pixel (the composite lays one over the other), and a flipped or mirrored mapping fails the
//! same check. Needs Debian's `blender` (scripts/setup.sh installs it).

use crate::common;
use crate::common::pav;

use pav::dataset::fca::CarlaSample;
use pav::geometry::camera::{spherical, Camera};
use pav::geometry::mesh::Mesh;
use pav::render::raster::GBuffer;
use pav::scene::align::{compare, compare_texels, pav_uv, read_uv_png, silhouettes, texel_code};
use pav::scene::blender::{Blender, Job, JobView, Mode};
use pav::scene::views::{render_views, ViewsConfig};

fn impala() -> Mesh {
    let mut m = Mesh::load_obj(&common::shared_data().join("pav-camou/xfl_yxz.obj")).unwrap();
    m.normalize();
    m
}

/// Blender, the normalized Impala, a temporary folder and the mesh written there in pav's frame.
fn impala_job_files() -> (Blender, Mesh, tempfile::TempDir, std::path::PathBuf) {
    let blender = Blender::find().expect("blender (scripts/setup.sh installs it)");
    let mesh = impala();
    let tmp = tempfile::tempdir().unwrap();
    let obj = tmp.path().join("mesh.obj");
    mesh.write_obj(&obj, None).unwrap();
    (blender, mesh, tmp, obj)
}

#[test]
fn blender_and_pav_agree_to_the_pixel() {
    let (blender, mesh, tmp, obj) = impala_job_files();
    let size = 256;
    let cams: Vec<Camera> = [(2.2, 20.0, 45.0), (1.6, 5.0, 200.0), (3.0, 45.0, 300.0)]
        .iter()
        .map(|&(d, e, a)| Camera::look_at(spherical(d, e, a), [0.0; 3], [0.0, 1.0, 0.0], 60.0))
        .collect();
    let mut job = Job::new(Mode::Uv, obj, size, 1, mesh.bounds().0[1]);
    job.views = cams
        .iter()
        .enumerate()
        .map(|(i, c)| JobView::new(&format!("v{i}"), c, tmp.path().join(format!("v{i}.png"))))
        .collect();
    let mut done = Vec::new();
    blender.run(&job, tmp.path(), |name, _| done.push(name.to_string())).unwrap();
    assert_eq!(done, ["v0", "v1", "v2"]);
    for (i, cam) in cams.iter().enumerate() {
        let (n, b) = read_uv_png(&tmp.path().join(format!("v{i}.png"))).unwrap();
        assert_eq!(n, size);
        let g = GBuffer::render(&mesh, cam, size);
        let uv = pav_uv(&g, &mesh);
        let a = compare(&g, &uv, &b);
        eprintln!("view {i}: {a:?}");
        assert!(a.pixels > 2000, "{a:?}");
        assert!(a.within_one_pixel(), "view {i}: {a:?}");
        assert!(a.iou > 0.97, "view {i}: {a:?}");
        // A texture flipped in v, or an image mirrored left to right, must fail the same check.
        let flipped: Vec<_> = uv.iter().map(|o| o.map(|[u, v]| [u, 1.0 - v])).collect();
        let f = compare(&g, &flipped, &b);
        assert!(!f.within_one_pixel(), "a v-flipped UV passed: {f:?}");
        let mirrored: Vec<[f64; 3]> = (0..size * size).map(|k| b[(k / size) * size + size - 1 - k % size]).collect();
        let m = compare(&g, &uv, &mirrored);
        assert!(!m.within_one_pixel(), "a mirrored image passed: {m:?}");
    }
}

#[test]
fn a_texture_lands_on_the_same_texels_in_both_renderers() {
    let (blender, mesh, tmp, obj) = impala_job_files();
    // A coarse code: texels several pixels wide, so a half-texel convention slip shows.
    let (w, h) = (96, 64);
    let tex = tmp.path().join("code.png");
    texel_code(w, h).save(&tex).unwrap();
    let size = 256;
    let cam = Camera::look_at(spherical(2.0, 25.0, 60.0), [0.0; 3], [0.0, 1.0, 0.0], 60.0);
    let mut job = Job::new(Mode::Emission, obj, size, 1, mesh.bounds().0[1]);
    job.texture = Some(tex);
    job.tex_size = [w, h];
    job.interpolation = "Closest".into();
    job.raw = true;
    job.views = vec![JobView::new("code", &cam, tmp.path().join("code_render.png"))];
    blender.run(&job, tmp.path(), |_, _| {}).unwrap();
    let (_, b) = read_uv_png(&tmp.path().join("code_render.png")).unwrap();
    let g = GBuffer::render(&mesh, &cam, size);
    let uv = pav_uv(&g, &mesh);
    let (same, worst, n) = compare_texels(&uv, &b, w, h);
    eprintln!("texel code: {n} pixels, {:.2} % on the same texel, worst {worst} texels", 100.0 * same);
    assert!(n > 5000, "{n}");
    assert!(same > 0.97 && worst <= 1, "{same} same, worst {worst}");
    let flipped: Vec<_> = uv.iter().map(|o| o.map(|[u, v]| [u, 1.0 - v])).collect();
    let (fs, _, _) = compare_texels(&flipped, &b, w, h);
    assert!(fs < 0.5, "a v-flipped texture matched {fs}");
}

fn run_ok(c: &mut std::process::Command) -> String {
    let o = c.output().unwrap();
    let text = format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "{text}");
    text
}

fn manifest_names(path: &std::path::Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap(), pav::scene::views::MANIFEST_HEADER);
    lines.map(|l| l.split(',').next().unwrap().to_string()).collect()
}

#[test]
fn the_ci_config_renders_resumes_and_shards() {
    common::shared_data();
    let cfg = common::repo().join("configs/views/ci.toml");
    let tmp = tempfile::tempdir().unwrap();
    let full = tmp.path().join("full");
    // Killed part way (pav and its Blender child): what was finished stays, a rerun resumes.
    let mut child = {
        use std::os::unix::process::CommandExt;
        pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&full).process_group(0).spawn().unwrap()
    };
    let manifest = full.join("manifest.csv");
    let t0 = std::time::Instant::now();
    while std::fs::read_to_string(&manifest).map_or(0, |t| t.lines().count()) < 3 {
        assert!(t0.elapsed() < std::time::Duration::from_secs(120), "no view within 2 min");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let killed = std::process::Command::new("kill").args(["-s", "KILL", "--", &format!("-{}", child.id())]).status();
    assert!(killed.unwrap().success());
    let _ = child.wait();
    let before = manifest_names(&manifest).len();
    assert!((2..6).contains(&before), "{before} views before the kill");
    // Until it is rerun, the folder is marked unfinished and no consumer takes it for the set.
    assert!(full.join(pav::scene::views::UNFINISHED).exists());
    let e = pav::scene::views::read_view_set(&full).unwrap_err().to_string();
    assert!(e.contains("has not finished"), "{e}");
    let out = run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&full));
    assert!(out.contains(&format!("6 views: {} rendered now, {before} from an earlier run", 6 - before)), "{out}");
    let names = manifest_names(&manifest);
    assert_eq!(names.len(), 6, "{names:?}");
    assert_eq!(names.iter().collect::<std::collections::HashSet<_>>().len(), 6, "{names:?}");
    assert!(!full.join(pav::scene::views::UNFINISHED).exists());
    assert_eq!(pav::scene::views::read_view_set(&full).unwrap().1.len(), 6);
    assert!(full.join("contact.png").exists());
    let run = common::run_record(&full.join("run.toml"));
    assert!(run["tools"]["blender"].as_str().unwrap().starts_with("Blender 3."), "{run}");
    assert_eq!(common::record_input(&run, "xfl_yxz.obj")["data"].as_str(), Some("pav-camou/xfl_yxz.obj"), "{run}");
    // Every view shows the car where pav's mask says, brighter or darker than its surroundings.
    for n in &names {
        let img = pav::image::Rgb::load(&full.join(format!("views/{n}.png"))).unwrap();
        let mask = pav::image::Rgb::load(&full.join(format!("views/{n}_mask.png"))).unwrap();
        assert_eq!((img.width, mask.width), (64, 64));
        let on: Vec<usize> = (0..64 * 64).filter(|&i| mask.rgb[3 * i] > 0.5).collect();
        assert!(on.len() > 200 && on.len() < 3000, "{n}: car covers {} px", on.len());
    }
    // A rerun renders nothing; a deleted image is rendered again.
    let out = run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&full));
    assert!(out.contains("6 views: 0 rendered now, 6 from an earlier run"), "{out}");
    let drawn = full.join(format!("views/{}.png", names[4]));
    let bytes = std::fs::read(&drawn).unwrap();
    std::fs::remove_file(&drawn).unwrap();
    let out = run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&full));
    assert!(out.contains("6 views: 1 rendered now, 5 from an earlier run"), "{out}");
    // Drawn again, the view is the same file, byte for byte: no date or render time inside.
    assert!(std::fs::read(&drawn).unwrap() == bytes, "{} differs when drawn again", drawn.display());
    // Two shards and a merge make the same set of views.
    let sharded = tmp.path().join("sharded");
    for k in ["1/2", "2/2"] {
        let out = run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&sharded).args(["--shard", k]));
        assert!(out.contains("3 views: 3 rendered now"), "{out}");
    }
    let out = run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&sharded).arg("--merge"));
    assert!(out.contains("6 views from 2 shards"), "{out}");
    let mut a = manifest_names(&sharded.join("manifest.csv"));
    let mut b = names.clone();
    a.sort();
    b.sort();
    assert_eq!(a, b);
}

#[test]
fn bad_input_gets_a_clear_error() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let ci = std::fs::read_to_string(common::repo().join("configs/views/ci.toml")).unwrap();
    let write = |name: &str, text: &str| {
        let p = tmp.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let fails = |cfg: &std::path::Path, env: Option<(&str, &str)>, needle: &str| {
        let mut c = pav();
        c.args(["views", "render"]).arg(cfg).arg("-o").arg(tmp.path().join("out"));
        if let Some((k, v)) = env {
            c.env(k, v);
        }
        let o = c.output().unwrap();
        let text = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(!o.status.success(), "{needle}: {text}");
        assert!(text.contains(needle), "expected `{needle}` in: {text}");
    };
    let good = write("good.toml", &ci);
    fails(&good, Some(("PAV_BLENDER", "/nonexistent/blender")), "blender not found");
    fails(&write("env.toml", &ci.replace("\"sunset\"", "\"nowhere\"")), None, "environment `nowhere`");
    fails(&write("twice.toml", &ci.replace("\"sunset\"", "\"city\"")), None, "view city_d2.20_e15_a000.0 comes twice");
    fails(&write("up.toml", &ci.replace("up = \"+y\"", "up = \"sideways\"")), None, "mesh.up `sideways`");
    fails(&write("effect.toml", &ci.replace("[\"shadows\"]", "[\"shadows\", \"lens-flare\"]")), None, "lens-flare");
    let obj = write("flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let no_uv = ci.replace("data:pav-camou/xfl_yxz.obj", &obj.display().to_string());
    fails(&write("nouv.toml", &no_uv), None, "the mesh needs UVs");
}

/// Three Cycles views of the e-tron as `paper.toml` loads it (bounding-box normalization; the
/// file is +Z up), into `dir`.
fn render_etron(dir: &std::path::Path) {
    let obj = common::shared_data().join("rauca-e2e/pytorch3d_Etron.obj");
    let cfg_path = dir.with_extension("toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[mesh]\nobj = {:?}\nnormalize = \"bbox\"\nup = \"+z\"\n[render]\nsize = 96\nsamples = 2\n\
             [[environments]]\nname = \"city\"\n[[poses]]\ndistances = [2.6]\nelevations = [20]\nazimuths = [30, 150, 270]\n",
            obj.display().to_string()
        ),
    )
    .unwrap();
    let cfg = ViewsConfig::load(&cfg_path).unwrap();
    let s = render_views(&cfg, dir, None, Some(&Blender::find().unwrap()), &pav::progress::Silent).unwrap();
    assert_eq!(s.rendered, 3);
}

#[cfg(feature = "optimize")]
#[test]
fn the_optimizer_trains_on_rendered_views() {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::optimize::{optimize_texture, Finish, RunOptions};
    use pav::attack::setup::Setup;
    use pav::attack::whitebox::Ensemble;
    use pav::geometry::camera::CameraConvention;
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("etron");
    render_etron(&dir);
    let path = common::repo().join("configs/optimize/paper.toml");
    let mut cfg = OptimizeConfig::load(&path).unwrap();
    cfg.views.train = cfg.views.train[1..2].to_vec();
    cfg.views.test.clear();
    cfg.views.pbr = vec![dir.clone()];
    let s = Setup::load(&cfg, None).unwrap();
    assert_eq!(s.pbr.len(), 3, "every rendered pose shows the region");
    assert_eq!(s.training_views().len(), 4);
    assert!(s.pbr.iter().all(|v| v.name().starts_with("pbr:city_")));
    let wb = Ensemble::load(&cfg, cfg.views.size).unwrap();
    let out = tmp.path().join("run");
    let ro = RunOptions {
        out: out.clone(),
        resume: false,
        checkpoint_every: 1000,
        max_skips: 0,
        epochs: Some(1),
        snapshot_every: 0,
    };
    let o =
        optimize_texture(&path, &cfg, &s, &wb, &ro, &pav::progress::Silent, &std::sync::atomic::AtomicBool::new(false))
            .unwrap();
    assert!(matches!(o.finish, Finish::Done));
    assert_eq!(o.log.len(), 4, "one step per training view, rendered ones included");
    // Streamed (`views.stream`): only the rendered views' files are held, each view is rebuilt
    // when stepped on, and the run is the same bit for bit.
    let mut streamed = cfg.clone();
    streamed.views.stream = true;
    let ss = Setup::load(&streamed, None).unwrap();
    assert!(ss.pbr.iter().all(|v| matches!(v, pav::attack::setup::PbrView::Stored(_))));
    assert_eq!(ss.region_views_shares(), s.region_views_shares());
    let (held, kept) = (s.training_bytes(), ss.training_bytes());
    eprintln!("training views hold {held} bytes, streamed {kept}");
    assert!(kept < held / 2, "{kept} of {held}");
    let ro2 = RunOptions { out: tmp.path().join("run-streamed"), ..ro.clone() };
    let o2 = optimize_texture(
        &path,
        &streamed,
        &ss,
        &wb,
        &ro2,
        &pav::progress::Silent,
        &std::sync::atomic::AtomicBool::new(false),
    )
    .unwrap();
    assert!(o2.texture == o.texture, "a streamed run trains another texture");
    let losses = |o: &pav::attack::optimize::Outcome| o.log.iter().map(|r| r.total).collect::<Vec<_>>();
    assert_eq!(losses(&o2), losses(&o));
    // A car without photos: rendered views only, the same folder held out as `pbr_test`.
    cfg.views.train.clear();
    cfg.views.pbr_test = vec![dir.clone()];
    cfg.check().unwrap();
    let s = Setup::load(&cfg, None).unwrap();
    assert_eq!((s.train.len(), s.pbr.len(), s.test.len()), (0, 3, 3));
    for v in &s.test {
        // The held-out box is the silhouette's: 96² masks scaled to the 416² view.
        let b = s.boxes.get(&v.name).unwrap_or_else(|| panic!("no box for {}", v.name));
        let mask = image::open(dir.join("views").join(format!("{}_mask.png", &v.name[4..]))).unwrap().to_luma8();
        let xs: Vec<u32> = mask.enumerate_pixels().filter(|p| p.2 .0[0] > 127).map(|p| p.0).collect();
        let k = 416.0f32 / 96.0;
        assert_eq!(b[0], *xs.iter().min().unwrap() as f32 * k, "{}", v.name);
        assert_eq!(b[2], (*xs.iter().max().unwrap() + 1) as f32 * k, "{}", v.name);
        assert!(b[1] > 0.0 && b[3] <= 416.0 && b[1] < b[3], "{b:?}");
    }
    cfg.views.pbr.clear();
    let e = cfg.check().expect_err("nothing to train on").to_string();
    assert!(e.contains("nothing to train on"), "{e}");
    cfg.views.pbr = vec![dir.clone()];
    // Views of another normalization are refused: their cameras are in another frame.
    cfg.mesh.camera = CameraConvention::PavCamou;
    let e = Setup::load(&cfg, None).err().expect("a frame mismatch is refused").to_string();
    assert!(e.contains("normalized `bbox`, but this config optimizes"), "{e}");
}

/// Views whose unattacked car no white box sees are dropped before training
/// (`views.pbr_min_score`): the e-tron from the side at 2.2 fills the frame and YOLOv3-tiny
/// misses it (0.03 at 16 samples), at 5.0 it fills a third and is found (0.95).
#[cfg(feature = "optimize")]
#[test]
fn rendered_views_whose_car_goes_unseen_are_dropped() {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::setup::Setup;
    use pav::attack::whitebox::Ensemble;
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("etron");
    let obj = common::shared_data().join("rauca-e2e/pytorch3d_Etron.obj");
    let cfg_path = dir.with_extension("toml");
    std::fs::write(
        &cfg_path,
        format!(
            "[mesh]\nobj = {:?}\nnormalize = \"bbox\"\nup = \"+z\"\n[render]\nsize = 416\nsamples = 8\n\
             effects = [\"shadows\", \"reflections\"]\n[[environments]]\nname = \"city\"\n\
             [[poses]]\ndistances = [2.2, 5.0]\nelevations = [20]\nazimuths = [0]\n",
            obj.display().to_string()
        ),
    )
    .unwrap();
    let vc = ViewsConfig::load(&cfg_path).unwrap();
    assert_eq!(
        render_views(&vc, &dir, None, Some(&Blender::find().unwrap()), &pav::progress::Silent).unwrap().rendered,
        2
    );
    let path = common::repo().join("configs/optimize/paper.toml");
    let mut cfg = OptimizeConfig::load(&path).unwrap();
    cfg.views.train = cfg.views.train[1..2].to_vec();
    cfg.views.test.clear();
    cfg.views.pbr = vec![dir.clone()];
    let mut s = Setup::load(&cfg, None).unwrap();
    assert_eq!(s.pbr.len(), 2);
    let wb = Ensemble::load(&cfg, cfg.views.size).unwrap();
    let scores: Vec<f32> = s
        .pbr
        .iter()
        .map(|v| {
            let v = s.view(v.as_ref()).unwrap();
            wb.first().loss(&v.photo, v.size).unwrap().max_score
        })
        .collect();
    eprintln!("car scores as rendered: {scores:?}");
    // A stop before the first view scores none and keeps the views untouched for the rerun.
    let go = std::sync::atomic::AtomicBool::new(false);
    let halt = std::sync::atomic::AtomicBool::new(true);
    let mut stopped = Setup::load(&cfg, None).unwrap();
    let e = stopped.keep_detected_pbr(&wb, 0.5, &halt).unwrap_err();
    assert!(matches!(e, pav::attack::setup::KeepError::Stopped { scored: 0, total: 2 }), "{e}");
    assert!(e.to_string().contains("the same command goes on"), "{e}");
    let k = s.keep_detected_pbr(&wb, 0.5, &go).unwrap();
    assert_eq!((k.kept, k.total), (1, 2), "{k}");
    assert_eq!(k.seen_by, vec![("yolov3-tiny".to_string(), 1)]);
    assert_eq!(s.pbr.len(), 1);
    assert!(s.pbr[0].name().contains("_d5.00_"), "{}", s.pbr[0].name());
    // Streamed views are filtered alike.
    cfg.views.stream = true;
    let mut ss = Setup::load(&cfg, None).unwrap();
    assert_eq!(ss.keep_detected_pbr(&wb, 0.5, &go).unwrap(), k);
    assert_eq!(ss.pbr[0].name(), s.pbr[0].name());
    cfg.views.stream = false;
    // Each white box's score of each image is kept beside the images, as computed, and a later
    // filter reads it instead of running the white box: a doctored score is believed.
    use pav::attack::view_scores::ViewScores;
    let images = dir.join("views");
    let id = wb.first().identity().to_string();
    let files: Vec<(String, String)> = unfiltered_pbr(&cfg)
        .iter()
        .map(|p| {
            let sha = pav::data::store::sha256_hex(&std::fs::read(p.image()).unwrap());
            (p.image().file_name().unwrap().to_string_lossy().into_owned(), sha)
        })
        .collect();
    let cached = ViewScores::read(&images);
    let back: Vec<f32> = files.iter().map(|(f, h)| cached.get(&id, f, h).expect("cached")).collect();
    assert_eq!(
        back.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        scores.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    let mut doctored = ViewScores::read(&images);
    files.iter().for_each(|(f, h)| doctored.put(&id, f, h, 0.0));
    doctored.save(&images).unwrap();
    let mut none = Setup::load(&cfg, None).unwrap();
    assert_eq!(none.keep_detected_pbr(&wb, 0.5, &go).unwrap().kept, 0);
    // Without the file the white box runs again and writes it anew.
    std::fs::remove_file(images.join(pav::attack::view_scores::FILE)).unwrap();
    let mut again = Setup::load(&cfg, None).unwrap();
    assert_eq!(again.keep_detected_pbr(&wb, 0.5, &go).unwrap(), k);
    assert_eq!(s.train.len(), 1, "photos are kept whatever they score");
    // A threshold outside (0, 1) is refused by the config's check.
    cfg.views.pbr_min_score = Some(1.5);
    let e = cfg.check().expect_err("refused").to_string();
    assert!(e.contains("views.pbr_min_score must be in (0, 1), got 1.5"), "{e}");
}

/// Every rendered view of `cfg`, before any filter.
#[cfg(feature = "optimize")]
fn unfiltered_pbr(cfg: &pav::attack::config::OptimizeConfig) -> Vec<pav::attack::setup::PbrView> {
    pav::attack::setup::Setup::load(cfg, None).unwrap().pbr
}

/// Mean absolute RGB difference between two renders over the pixels at least 3 px from the car
/// in both (pav's masks), i.e. the room behind it.
fn background_difference(dir: &std::path::Path, a: &str, b: &str) -> (f64, usize) {
    let load = |n: &str| pav::image::Rgb::load(&dir.join(format!("views/{n}.png"))).unwrap();
    let mask = |n: &str| pav::image::Rgb::load(&dir.join(format!("views/{n}_mask.png"))).unwrap();
    let (ia, ib, ma, mb) = (load(a), load(b), mask(a), mask(b));
    let s = ia.width as i64;
    let near_car = |i: i64| {
        let (x, y) = (i % s, i / s);
        (-3..=3).any(|dy| {
            (-3..=3).any(|dx| {
                let (u, v) = (x + dx, y + dy);
                (0..s).contains(&u) && (0..s).contains(&v) && {
                    let k = 3 * (v * s + u) as usize;
                    ma.rgb[k] > 0.5 || mb.rgb[k] > 0.5
                }
            })
        })
    };
    let bg: Vec<usize> = (0..s * s).filter(|&i| !near_car(i)).map(|i| i as usize).collect();
    let sum: f64 =
        bg.iter().map(|&i| (0..3).map(|c| (ia.rgb[3 * i + c] - ib.rgb[3 * i + c]).abs() as f64).sum::<f64>()).sum();
    (sum / (3 * bg.len()) as f64, bg.len())
}

#[test]
fn on_a_turntable_the_room_stays_put_and_the_videos_carry_the_angles() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let cfg_text = |turntable: bool| {
        format!(
            "[mesh]\nobj = \"data:pav-camou/xfl_yxz.obj\"\nnormalize = \"pav\"\nup = \"+y\"\n\
             [render]\nsize = 96\nsamples = 2\nturntable = {turntable}\n\
             [[environments]]\nname = \"city\"\n\
             [[poses]]\ndistances = [2.2]\nelevations = [10]\nazimuths = [0, 90, 200]\n"
        )
    };
    let blender = Blender::find().expect("blender (scripts/setup.sh installs it)");
    let mut diffs = Vec::new();
    for turntable in [true, false] {
        let path = tmp.path().join(format!("t{turntable}.toml"));
        std::fs::write(&path, cfg_text(turntable)).unwrap();
        let cfg = ViewsConfig::load(&path).unwrap();
        let dir = tmp.path().join(format!("views_{turntable}"));
        render_views(&cfg, &dir, None, Some(&blender), &pav::progress::Silent).unwrap();
        let names: Vec<String> = cfg.views().iter().map(|v| v.name.clone()).collect();
        let d: Vec<(f64, usize)> = names[1..].iter().map(|n| background_difference(&dir, &names[0], n)).collect();
        eprintln!("turntable {turntable}: background differences {d:?}");
        assert!(d.iter().all(|x| x.1 > 4000), "{d:?}");
        diffs.push(d);
    }
    // The camera went round by 90° and 200°: on a turntable the room behind the car is the same
    // picture (Cycles' noise apart); with the room fixed it is another part of the city.
    for k in 0..2 {
        assert!(diffs[0][k].0 < 0.02, "turntable: the room moved: {:?}", diffs[0]);
        assert!(diffs[1][k].0 > 5.0 * diffs[0][k].0 && diffs[1][k].0 > 0.05, "{diffs:?}");
    }
    // Videos: the turntable set makes one, frames in angle order, angles in its sidecar; the
    // fixed-room set is refused.
    let dir = tmp.path().join("views_true");
    let videos = pav::scene::turntable::write_videos(&dir, 28.0).unwrap();
    assert_eq!(videos.len(), 1);
    assert_eq!(videos[0].frames, 3);
    let mut r = pav::video::VideoReader::open(&videos[0].path).unwrap();
    let mut n = 0;
    while let Some((_, f)) = r.read().unwrap() {
        assert_eq!((f.width, f.height), (96, 96));
        n += 1;
    }
    assert_eq!(n, 3);
    let rows = pav::sidecar::read(&pav::sidecar::sidecar_path(&videos[0].path)).unwrap();
    let angles: Vec<f64> = rows.iter().map(|s| s.angle_deg).collect();
    assert_eq!(angles, [0.0, 90.0, 200.0]);
    let e = pav::scene::turntable::write_videos(&tmp.path().join("views_false"), 28.0).unwrap_err();
    assert!(e.to_string().contains("not a car turned in it"), "{e}");
    // `pav views turntable` turns the room itself, with another paint, and says what to run next;
    // that paint cannot be resumed into a folder rendered with another.
    let tex = common::shared_data().join("rauca-e2e/RAUCA_E2E.png");
    let cli = tmp.path().join("cli");
    let out = run_ok(
        pav()
            .args(["views", "turntable"])
            .arg(tmp.path().join("tfalse.toml"))
            .arg("-o")
            .arg(&cli)
            .arg("--texture")
            .arg(&tex),
    );
    assert!(out.contains("city_d2.20_e10.mp4: 3 frames"), "{out}");
    assert!(out.contains("pav-rig evaluate ") && out.contains("uncalibrated"), "{out}");
    // Two shards render their frames; the merge joins them in the order one process renders
    // them and cuts the same video.
    let sharded = tmp.path().join("sharded");
    let tt = |extra: &[&str]| {
        run_ok(
            pav()
                .args(["views", "turntable"])
                .arg(tmp.path().join("tfalse.toml"))
                .arg("-o")
                .arg(&sharded)
                .arg("--texture")
                .arg(&tex)
                .args(extra),
        )
    };
    assert!(tt(&["--shard", "1/2"]).contains("2 views: 2 rendered now"));
    assert!(tt(&["--shard", "2/2"]).contains("1 views: 1 rendered now"));
    let out = tt(&["--merge"]);
    assert!(out.contains("3 views from 2 shards") && out.contains("city_d2.20_e10.mp4: 3 frames"), "{out}");
    // Timing aside: the render seconds of each view.
    let manifest = |d: &std::path::Path| {
        let text = std::fs::read_to_string(d.join("manifest.csv")).unwrap();
        let at = text.lines().next().unwrap().split(',').position(|c| c == "seconds").unwrap();
        let row =
            |l: &str| l.split(',').enumerate().filter(|(i, _)| *i != at).map(|(_, c)| c).collect::<Vec<_>>().join(",");
        text.lines().map(row).collect::<Vec<_>>()
    };
    assert_eq!(manifest(&cli), manifest(&sharded), "the merged manifest is the one-process one");
    let frames = |d: &std::path::Path| {
        let mut r = pav::video::VideoReader::open(&d.join("videos/city_d2.20_e10.mp4")).unwrap();
        std::iter::from_fn(|| r.read().unwrap().map(|(_, f)| f)).collect::<Vec<_>>()
    };
    for (a, b) in frames(&cli).iter().zip(frames(&sharded)) {
        let d = a.bgr.iter().zip(&b.bgr).map(|(x, y)| (*x as f64 - *y as f64).abs()).sum::<f64>() / a.bgr.len() as f64;
        assert!(d < 1.0, "a merged frame differs from the one-process frame by {d} levels on average");
    }
    let o =
        pav().args(["views", "turntable"]).arg(tmp.path().join("tfalse.toml")).arg("-o").arg(&cli).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("another texture, turntable setting or rig"), "{err}");
}

#[test]
fn a_rig_films_the_model_on_its_table_before_its_backdrop_at_its_frame_size() {
    let tmp = tempfile::tempdir().unwrap();
    common::shared_data();
    let text = std::fs::read_to_string(common::repo().join("configs/rig/webcam.toml")).unwrap();
    let small = text
        .replace("width = 640", "width = 160")
        .replace("samples = 16", "samples = 2")
        .replace("frames = 22", "frames = 2")
        .replace(r#"effects = ["motion-blur", "noise", "codec"]"#, "effects = []");
    assert_ne!(small, text);
    let rig = tmp.path().join("rig.toml");
    std::fs::write(&rig, small).unwrap();
    let dir = tmp.path().join("tt");
    let out = run_ok(pav().args(["views", "turntable", "--rig"]).arg(&rig).arg("-o").arg(&dir));
    assert!(out.contains("2 frames"), "{out}");
    // The rows of a 16:9 frame alone are rendered; the mask is cut alike.
    let rows = pav::scene::views::read_manifest(&dir.join("manifest.csv")).unwrap();
    assert_eq!(rows.len(), 2);
    let img = pav::image::Rgb::load(&dir.join(&rows[1].image)).unwrap();
    let mask = pav::image::Rgb::load(&dir.join(&rows[1].mask)).unwrap();
    assert_eq!((img.width, img.height, mask.width, mask.height), (160, 90, 160, 90));
    // Above the model the camera sees the backdrop's colour, not the light map; on it, the model.
    let backdrop = [0.7f32, 0.68, 0.62];
    let covered: Vec<bool> = mask.rgb.chunks(3).map(|p| p[0] > 0.5).collect();
    let near_model = |x: usize, y: usize| {
        (y.saturating_sub(3)..(y + 4).min(90))
            .any(|yy| (x.saturating_sub(3)..(x + 4).min(160)).any(|xx| covered[yy * 160 + xx]))
    };
    let inside = |x: usize, y: usize| {
        (x >= 3 && y >= 3 && x + 3 < 160 && y + 3 < 90)
            && (y - 3..=y + 3).all(|yy| (x - 3..=x + 3).all(|xx| covered[yy * 160 + xx]))
    };
    let first_model_row = covered.iter().position(|c| *c).unwrap() / 160;
    let mut sky = Vec::new();
    let mut model = Vec::new();
    for y in 0..90 {
        for x in 0..160 {
            let p = &img.rgb[3 * (y * 160 + x)..3 * (y * 160 + x) + 3];
            let d: f32 = (0..3).map(|c| (p[c] - backdrop[c]).abs()).sum::<f32>() / 3.0;
            if y + 3 < first_model_row && !near_model(x, y) {
                sky.push(d);
            } else if inside(x, y) {
                model.push(d);
            }
        }
    }
    let (sky_max, model_mean) =
        (sky.iter().cloned().fold(0.0, f32::max), model.iter().sum::<f32>() / model.len().max(1) as f32);
    eprintln!(
        "backdrop: {} pixels, max difference {sky_max}; model: {} pixels, mean {model_mean}",
        sky.len(),
        model.len()
    );
    assert!(sky.len() > 1000 && sky_max < 2.5 / 255.0, "{} pixels, {sky_max}", sky.len());
    assert!(model.len() > 200 && model_mean > 0.05, "{} pixels, {model_mean}", model.len());
    // One video for the one camera height, at the rig's frame size, with the table's angles.
    let video = dir
        .join("videos")
        .read_dir()
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mp4"))
        .unwrap();
    let mut r = pav::video::VideoReader::open(&video).unwrap();
    let mut n = 0;
    while let Some((_, f)) = r.read().unwrap() {
        assert_eq!((f.width, f.height), (160, 90));
        n += 1;
    }
    assert_eq!(n, 2);
    let angles: Vec<f64> =
        pav::sidecar::read(&pav::sidecar::sidecar_path(&video)).unwrap().iter().map(|s| s.angle_deg).collect();
    assert_eq!(angles, [0.0, 180.0]);
    // The run records the rig it filmed.
    let run = std::fs::read_to_string(dir.join("run.toml")).unwrap();
    assert!(run.contains("rig.toml") && run.contains("rig = \"true\""), "{run}");
    // Other camera effects reuse the renders and cut new videos; another shot is refused.
    let first = {
        let mut r = pav::video::VideoReader::open(&video).unwrap();
        r.read().unwrap().unwrap().1
    };
    let text = std::fs::read_to_string(&rig).unwrap();
    std::fs::write(&rig, text.replace("effects = []", r#"effects = ["noise"]"#)).unwrap();
    let out = run_ok(pav().args(["views", "turntable", "--rig"]).arg(&rig).arg("-o").arg(&dir));
    assert!(out.contains("0 rendered now, 2 from an earlier run"), "{out}");
    let noisy = {
        let mut r = pav::video::VideoReader::open(&video).unwrap();
        r.read().unwrap().unwrap().1
    };
    assert_ne!(first.bgr, noisy.bgr, "the noise effect left the video as it was");
    std::fs::write(&rig, text.replace("distance_m = 0.4", "distance_m = 0.6")).unwrap();
    let o = pav().args(["views", "turntable", "--rig"]).arg(&rig).arg("-o").arg(&dir).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("or rig"), "{err}");
}

#[test]
fn every_shipped_views_config_loads() {
    common::shared_data();
    let mut n = 0;
    let root = common::repo().join("configs/views");
    let mut files: Vec<std::path::PathBuf> = Vec::new();
    for e in std::fs::read_dir(&root).unwrap().chain(std::fs::read_dir(root.join("fidelity")).unwrap()) {
        let p = e.unwrap().path();
        if p.is_file() {
            files.push(p);
        }
    }
    for p in files {
        let cfg = ViewsConfig::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        let views = cfg.views();
        assert!(!views.is_empty(), "{}", p.display());
        assert!(views.iter().all(|v| v.env_turn_deg == if cfg.render.turntable { v.pose[2] } else { 0.0 }));
        if p.ends_with("turntable.toml") {
            // The paper's cells: two polar angles × 44 frames a turn.
            assert_eq!(views.len(), 88);
        }
        n += 1;
    }
    assert!(n >= 5, "{n} configs");
}

/// A view folder's image as an RGB frame, and a car render's straight alpha.
fn load_view(dir: &std::path::Path, name: &str) -> (image::RgbImage, Vec<f32>, Vec<bool>) {
    let v = dir.join("views");
    let img = image::open(v.join(format!("{name}.png"))).unwrap().to_rgb8();
    let (_, alpha) = pav::image::load_rgba(&v.join(format!("{name}_car.png"))).unwrap();
    let mask =
        image::open(v.join(format!("{name}_mask.png"))).unwrap().to_luma8().pixels().map(|p| p[0] > 127).collect();
    (img, alpha, mask)
}

/// Plates: Cycles' e-tron laid over FCA's photos with their car painted out. At the photo's own
/// camera the rendered car covers the photo's car (FCA's mask) as well as pav's rasterizer does
/// and its wheels stand on the photo's contact rows; Blender and the rasterizer agree to a pixel
/// at every turn; the background outside the car and its shadow is the photo's own; the caught
/// shadow meets the car. (Under a soft environment the shadow check cannot see the ground moved
/// by 0.05 units, 12 cm: measured; the ground is the mesh's lowest point by construction.)
#[test]
fn plates_put_the_rendered_car_on_the_photos_ground() {
    let shared = common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let n = 304;
    let config = |effects: &str| {
        format!(
            "[mesh]\nobj = \"data:rauca-e2e/pytorch3d_Etron.obj\"\nnormalize = \"bbox\"\nup = \"+z\"\n\
             [render]\nsize = {n}\nsamples = 4\neffects = [{effects}]\n[[environments]]\nname = \"city\"\n\
             [plates]\nphotos = [\"data:fca/carla_dataset/test/data12501.npz\", \"data:fca/carla_dataset/test/data12506.npz\"]\n\
             camera = \"fca\"\nturns = [0, 40]\n"
        )
    };
    let render = |name: &str, effects: &str| {
        let cfg = tmp.path().join(format!("{name}.toml"));
        std::fs::write(&cfg, config(effects)).unwrap();
        let out = tmp.path().join(name);
        run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&out));
        out
    };
    // Without shadows the film's alpha is the car alone.
    let bare = render("bare", "");
    for photo in ["data12501", "data12506"] {
        let (img0, alpha0, mask0) = load_view(&bare, &format!("city_{photo}_t+0"));
        let car0: Vec<bool> = alpha0.iter().map(|a| *a > 0.5).collect();
        let (iou, edge) = silhouettes(&mask0, &car0, n);
        // FCA's own mask at 608², halved by 2×2 majority.
        let fca = image::open(shared.join(format!("fca/carla_dataset/masks/{photo}.png"))).unwrap().to_luma8();
        let fca: Vec<bool> = (0..n * n)
            .map(|i| {
                let (x, y) = (2 * (i % n) as u32, 2 * (i / n) as u32);
                [(0, 0), (1, 0), (0, 1), (1, 1)]
                    .iter()
                    .filter(|(dx, dy)| fca.get_pixel(x + dx, y + dy)[0] > 127)
                    .count()
                    >= 2
            })
            .collect();
        let (iou_fca, _) = silhouettes(&fca, &car0, n);
        let (iou_pav_fca, _) = silhouettes(&fca, &mask0, n);
        eprintln!("{photo} turn 0: Blender vs pav IoU {iou:.4} edge {edge:.3} px; vs FCA's mask {iou_fca:.4} (pav's {iou_pav_fca:.4})");
        assert!(iou > 0.97 && edge < 1.0, "{photo}: Blender and pav disagree: IoU {iou}, edge {edge}");
        assert!(iou_fca > 0.9 && iou_fca > iou_pav_fca - 0.01, "{photo}: the car misses the photo's car: {iou_fca}");
        // It stands where the photo's car stands: the wheels' lowest rows are the photo's.
        let (median, within) = bottom_offset(&fca, &car0, n, 1);
        let (pav_median, pav_within) = bottom_offset(&fca, &mask0, n, 1);
        eprintln!("{photo}: bottom rows vs FCA's mask: median {median} px, {within:.2} within 1 px (pav's: {pav_median}, {pav_within:.2})");
        // Measured 1 and 2 px low at 304² (the fitted FCA camera's residual), as pav's own.
        assert!(median.abs() <= 2 && (median - pav_median).abs() <= 1, "{photo}: {median} vs pav's {pav_median}");
        // Outside the painted-out hole and the car, the view is the photo itself.
        let s = CarlaSample::load(&shared.join(format!("fca/carla_dataset/test/{photo}.npz"))).unwrap();
        let photo_px = pav::image::resize::resize(&s.image, n, n, pav::image::resize::Interpolation::Antialias);
        let hole = pav::render::fill::grow(&mask0, n, n, n / 50 + 1);
        let (mut same, mut outside) = (0, 0);
        for i in (0..n * n).filter(|&i| !hole[i] && alpha0[i] == 0.0) {
            outside += 1;
            let p = img0.as_raw();
            same += (0..3).all(|c| p[i * 3 + c] == photo_px[i * 3 + 2 - c].round() as u8) as usize;
        }
        assert!(outside > n * n / 2 && same == outside, "{photo}: {same} of {outside} background pixels kept");
        // The car turned: another silhouette, still Blender's and pav's alike.
        let (_, alpha40, mask40) = load_view(&bare, &format!("city_{photo}_t+40"));
        let car40: Vec<bool> = alpha40.iter().map(|a| *a > 0.5).collect();
        let (iou40, edge40) = silhouettes(&mask40, &car40, n);
        let (turned, _) = silhouettes(&car0, &car40, n);
        eprintln!("{photo} turn 40: Blender vs pav IoU {iou40:.4} edge {edge40:.3} px; IoU with turn 0 {turned:.3}");
        assert!(iou40 > 0.97 && edge40 < 1.0 && turned < 0.9, "{photo}: {iou40} {edge40} {turned}");
    }
    // Training leaves out the views over a held-out photo's background, fold by fold.
    #[cfg(feature = "optimize")]
    {
        use pav::attack::config::OptimizeConfig;
        use pav::attack::setup::Setup;
        let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
        let photo = |p: &str| shared.join(format!("fca/carla_dataset/test/{p}.npz"));
        (cfg.views.train, cfg.views.test) = (vec![photo("data12501")], vec![photo("data12506")]);
        cfg.views.pbr = vec![bare.clone()];
        let s = Setup::load(&cfg, None).unwrap();
        let names = |s: &Setup| {
            s.training_views()
                .iter()
                .filter(|v| v.name().starts_with("pbr:"))
                .map(|v| v.name().to_string())
                .collect::<Vec<_>>()
        };
        assert_eq!(names(&s), ["pbr:city_data12501_t+0", "pbr:city_data12501_t+40"]);
        assert_eq!((s.pbr.len(), s.plates_held_out()), (4, 2));
        let swapped = s.with_views(s.test.clone(), Vec::new(), s.train.clone());
        assert_eq!(names(&swapped), ["pbr:city_data12506_t+0", "pbr:city_data12506_t+40"]);
        plates_are_scored_with_their_photos_fold(cfg, &bare);
    }
    // With shadows: the caught shadow is there, and meets the car's underside.
    let shadowed = render("shadowed", "\"shadows\"");
    for photo in ["data12501", "data12506"] {
        let (_, alpha, mask) = load_view(&shadowed, &format!("city_{photo}_t+0"));
        let grown = pav::render::fill::grow(&mask, n, n, 1);
        let shadow: Vec<bool> = (0..n * n).map(|i| !grown[i] && alpha[i] > 0.1).collect();
        // The car's lowest pixel per column, and whether shadow lies within 3 px below it.
        let (mut cols, mut touching) = (0, 0);
        for x in 0..n {
            let Some(y) = (0..n).rev().find(|y| mask[y * n + x]) else { continue };
            cols += 1;
            touching += (y + 1..(y + 5).min(n)).any(|yy| shadow[yy * n + x]) as usize;
        }
        let share = touching as f64 / cols as f64;
        eprintln!("{photo}: shadow under {touching} of {cols} bottom columns ({share:.2})");
        assert!(share > 0.5, "{photo}: the shadow does not meet the car ({share})");
    }
}

/// Per column where both cover a pixel, the lowest row of `b` minus that of `a`: the median
/// and the share of columns within `tol` pixels.
fn bottom_offset(a: &[bool], b: &[bool], n: usize, tol: i64) -> (i64, f64) {
    let low = |m: &[bool], x: usize| (0..n).rev().find(|y| m[y * n + x]).map(|y| y as i64);
    let mut d: Vec<i64> = (0..n).filter_map(|x| Some(low(b, x)? - low(a, x)?)).collect();
    d.sort();
    let within = d.iter().filter(|v| v.abs() <= tol).count() as f64 / d.len().max(1) as f64;
    (d[d.len() / 2], within)
}

/// `pav crossval --held-out-views`: each rendered view over a plate is scored in the fold that
/// holds its photo out (never in another), with its silhouette's box as the ground truth; per
/// photo the records average its views, and `pav table1` reads those averages as a run.
#[cfg(feature = "optimize")]
fn plates_are_scored_with_their_photos_fold(mut cfg: pav::attack::config::OptimizeConfig, plates: &std::path::Path) {
    use pav::studies::crossval::{crossval, per_photo};
    cfg.views.pbr.clear();
    cfg.optimizer.epochs = 1;
    let path = common::repo().join("configs/optimize/paper.toml");
    let mut setup = pav::attack::setup::Setup::load(&cfg, None).unwrap();
    let rendered = setup.rendered_over_plates(&cfg, &[plates.to_path_buf()]).unwrap();
    assert_eq!(rendered.len(), 4);
    assert!(rendered.iter().all(|v| setup.boxes.contains_key(&v.name)), "every view has its silhouette's box");
    let wb = pav::attack::whitebox::Ensemble::load(&cfg, cfg.views.size).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (opts, mut dets) = common::two_folds(dir.path(), 1, Vec::new(), rendered);
    let never = std::sync::atomic::AtomicBool::new(false);
    let cv = crossval(&path, &cfg, &setup, &wb, &mut dets, &opts, &pav::progress::Silent, &never).unwrap();
    let r = cv.rendered.expect("rendered views were given");
    // Fold 0 holds out data12501, fold 1 data12506: each photo's two views, in its fold only,
    // under each of the four textures (original, optimized, random, random32).
    for (fold, photo) in [(0, "data12501"), (1, "data12506")] {
        let mut seen: Vec<&str> = r
            .records
            .iter()
            .filter(|x| x.fold == fold && x.texture == "original")
            .map(|x| {
                assert_eq!(x.photo, photo);
                x.view.as_str()
            })
            .collect();
        seen.sort();
        assert_eq!(seen, [format!("pbr:city_{photo}_t+0"), format!("pbr:city_{photo}_t+40")]);
    }
    assert_eq!(r.records.len(), 4 * 4);
    assert!(r.records.iter().all(|x| x.own_box <= x.score && (0.0..=1.0).contains(&x.score)), "{:?}", r.records);
    let held = |t: &str| r.rows.iter().find(|x| x.texture == t).unwrap().images;
    assert_eq!((held("original"), held("optimized"), held("random")), (4, 4, 4));
    // Per photo: the mean of its two views.
    let scores = per_photo(&r.records, false);
    let own = per_photo(&r.records, true);
    assert_eq!(scores.len(), 2 * 4);
    for p in &scores {
        let views: Vec<f64> = r
            .records
            .iter()
            .filter(|x| x.photo == p.view && x.texture == p.texture && x.seed == p.seed)
            .map(|x| x.score as f64)
            .collect();
        assert_eq!(views.len(), 2);
        assert!((p.score as f64 - views.iter().sum::<f64>() / 2.0).abs() < 1e-6, "{p:?} vs {views:?}");
    }
    // `pav table1` reads the folder as a run: two photos paired, own box from the averages.
    pav::table::write_csv(&dir.path().join("crossval.csv"), &r.rows).unwrap();
    pav::table::write_csv(&dir.path().join("crossval_views.csv"), &scores).unwrap();
    pav::table::write_csv(&dir.path().join("crossval_own_views.csv"), &own).unwrap();
    let t = pav::studies::table1::table1(&[("plates".into(), dir.path().to_path_buf())], &[]).unwrap();
    let d = t.own_box.iter().find(|x| x.against == "random").unwrap();
    let of = |t: &str| own.iter().filter(|x| x.texture == t).map(|x| x.score as f64).collect::<Vec<_>>();
    let want = of("optimized").iter().zip(of("random")).map(|(a, b)| a - b).sum::<f64>() / 2.0;
    assert!(d.views == 2 && (d.mean - want).abs() < 1e-6, "{d:?} vs {want}");
}

/// A rig's turntable renders are training views like any other (`views.pbr`): each keeps only
/// the centre rows of the square its camera sees, and set-up puts them back in place, so that
/// the car Blender drew and the car pav's rasterizer lays the texture on coincide. Stretching
/// the rows over the square instead would move the silhouette's top and bottom by tens of pixels.
#[cfg(feature = "optimize")]
#[test]
fn a_rigs_landscape_renders_train_where_the_rasterizer_puts_the_car() {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::setup::Setup;
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let rig = common::small_rig(tmp.path(), "train-etron-near.toml", 160, 2);
    let dir = tmp.path().join("rig");
    run_ok(pav().args(["views", "turntable", "--rig"]).arg(&rig).arg("-o").arg(&dir));
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/studies/print-base.toml")).unwrap();
    cfg.views.train = cfg.views.train[..1].to_vec();
    cfg.views.test.clear();
    cfg.views.pbr_test = vec![dir.clone()];
    let s = Setup::load(&cfg, None).unwrap();
    assert_eq!(s.test.len(), 4, "two elevations, two angles");
    for v in &s.test {
        let b = s.boxes.get(&v.name).unwrap_or_else(|| panic!("no box for {}", v.name));
        let r = v.car_box.unwrap_or_else(|| panic!("no car in {}", v.name));
        let worst = (0..4).map(|i| (b[i] - r[i]).abs()).fold(0.0, f32::max);
        eprintln!("{}: Blender's silhouette {b:?}, the rasterizer's {r:?}", v.name);
        // A render pixel is 2.6 view pixels here.
        assert!(worst < 6.0, "{}: Blender's silhouette {b:?} against the rasterizer's {r:?}", v.name);
        // Above and below the rendered rows the view shows the backdrop, not black.
        let top = &v.photo[..3 * v.size];
        assert!(top.iter().all(|c| *c > 0.3), "{}: the rows outside the render are dark", v.name);
    }
}

/// The rasterizer draws a views config without Blender: plate views are the photo's plate
/// outside the car's silhouette (the same pixels at every turn), the shaded car inside it; grid
/// views stand on a grey backdrop; the manifest says 0 samples. Settings only Cycles has, and
/// environments it would draw alike, are refused by name.
#[test]
fn the_rasterizer_draws_views_without_blender() {
    common::shared_data();
    let tmp = tempfile::tempdir().unwrap();
    let n = 128;
    let config = |extra: &str| {
        format!(
            "[mesh]\nobj = \"data:rauca-e2e/pytorch3d_Etron.obj\"\nnormalize = \"bbox\"\nup = \"+z\"\n\
             [render]\nsize = {n}\nrenderer = \"rasterizer\"\n{extra}[[environments]]\nname = \"city\"\n\
             [[poses]]\ndistances = [2.2]\nelevations = [15]\nazimuths = [30]\n\
             [plates]\nphotos = [\"data:fca/carla_dataset/test/data12501.npz\"]\ncamera = \"fca\"\nturns = [0, 40]\n"
        )
    };
    let cfg = tmp.path().join("r.toml");
    std::fs::write(&cfg, config("")).unwrap();
    let out = tmp.path().join("out");
    run_ok(pav().args(["views", "render"]).arg(&cfg).arg("-o").arg(&out).env("PAV_BLENDER", "/nonexistent/blender"));
    let rows = pav::scene::views::read_manifest(&out.join("manifest.csv")).unwrap();
    assert_eq!(rows.len(), 3);
    assert!(rows.iter().all(|r| r.samples == 0 && r.size == n));
    let load = |name: &str| {
        let v = out.join("views");
        let img = image::open(v.join(format!("{name}.png"))).unwrap().to_rgb8();
        let mask: Vec<bool> =
            image::open(v.join(format!("{name}_mask.png"))).unwrap().to_luma8().pixels().map(|p| p[0] > 127).collect();
        (img, mask)
    };
    let (a, ma) = load("city_data12501_t+0");
    let (b, mb) = load("city_data12501_t+40");
    // Away from both silhouettes (an edge pixel is blended), the plate is all there is.
    let near = |m: &[bool], i: usize| {
        let (x, y) = ((i % n) as i64, (i / n) as i64);
        (-2..=2).any(|dy| {
            (-2..=2).any(|dx| {
                let (u, v) = (x + dx, y + dy);
                (0..n as i64).contains(&u) && (0..n as i64).contains(&v) && m[v as usize * n + u as usize]
            })
        })
    };
    let (mut outside, mut inside_differs) = (0, 0);
    for i in 0..n * n {
        let (pa, pb) = (a.get_pixel((i % n) as u32, (i / n) as u32), b.get_pixel((i % n) as u32, (i / n) as u32));
        if !near(&ma, i) && !near(&mb, i) {
            assert_eq!(pa, pb, "pixel {i} outside the car differs between turns");
            outside += 1;
        } else if ma[i] && !mb[i] && pa.0.iter().zip(pb.0).map(|(x, y)| (*x as i32 - y as i32).abs()).sum::<i32>() > 30
        {
            inside_differs += 1;
        }
    }
    let only_a = (0..n * n).filter(|&i| ma[i] && !mb[i]).count();
    assert!(outside > n * n / 2, "{outside}");
    assert!(inside_differs * 2 > only_a, "the car was not drawn: {inside_differs} of {only_a}");
    // A grid view has no plate: its corner is the grey backdrop.
    let (g, gm) = load("city_d2.20_e15_a030.0");
    assert!(!gm[0] && g.get_pixel(0, 0).0 == [115, 115, 115], "{:?}", g.get_pixel(0, 0));
    for (extra, env, says) in [
        ("samples = 16\n", "", "takes no samples"),
        ("effects = [\"shadows\"]\n", "", "simulates none of them"),
        ("", "[[environments]]\nname = \"forest\"\n", "list one"),
    ] {
        let bad = tmp.path().join("bad.toml");
        std::fs::write(&bad, config(extra) + env).unwrap();
        let o = pav().args(["views", "render"]).arg(&bad).arg("-o").arg(tmp.path().join("bad")).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{says}: {err}");
    }
}
