//! `pav`: the texture side of PAV-Camou — rendering (and, as it lands, optimization).

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use pav::dataset::fca::CarlaSample;
use pav::eval::report::write_csv;
use pav::geometry::camera::{pav_camou, spherical, Camera};
use pav::geometry::mesh::Mesh;
use pav::render::raster::GBuffer;
use pav::render::texture::{save_rgb, Gather, Texture};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "pav", version, about = "PAV-Camou texture tools: render the textured car")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Optimize an adversarial texture (PAV-Camou, paper Algorithm 1) against the white-box
    /// YOLOv3-tiny; writes the texture, a printable sheet, loss curves, previews and scores.
    #[cfg(feature = "optimize")]
    Optimize {
        /// Optimization config.
        #[arg(long, default_value = "configs/optimize/paper.toml")]
        config: PathBuf,
        /// Output folder.
        #[arg(long, short = 'o', default_value = "out/optimize")]
        out: PathBuf,
        /// Continue from the checkpoint in the output folder.
        #[arg(long)]
        resume: bool,
        /// Override the config's epochs.
        #[arg(long)]
        epochs: Option<usize>,
        /// Override the config's render size (views.size).
        #[arg(long)]
        size: Option<usize>,
        /// Model scale of the printable sheet (20 = 1:20).
        #[arg(long, default_value_t = 20.0)]
        scale: f64,
        /// Printer resolution of the sheet.
        #[arg(long, default_value_t = 300.0)]
        dpi: f64,
    },
    /// Digital evaluation in the shape of the paper's Table 2: ASR and P@0.5 of every detector on
    /// the views composited with the original paint, a random texture and each given texture.
    #[cfg(feature = "optimize")]
    EvalDigital {
        /// Optimization config (mesh, views, scene lighting).
        #[arg(long, default_value = "configs/optimize/paper.toml")]
        config: PathBuf,
        /// Texture PNGs to evaluate (named by their folder).
        #[arg(long = "texture", short = 't')]
        textures: Vec<PathBuf>,
        #[command(flatten)]
        scoring: Scoring,
        /// Output folder.
        #[arg(long, short = 'o', default_value = "out/digital")]
        out: PathBuf,
    },
    /// k-fold cross-validation of the attack: every view is held out once, the texture is
    /// optimized on the rest, and the held-out views are scored by every detector against the
    /// photo and several random textures (a Table 2 in which no texture has seen its test views).
    #[cfg(feature = "optimize")]
    Crossval {
        /// Optimization config; its training and held-out views are pooled and re-split.
        #[arg(long, default_value = "configs/optimize/half.toml")]
        config: PathBuf,
        /// Number of folds (default: one per view, leave-one-out).
        #[arg(long)]
        folds: Option<usize>,
        /// Random textures per fold (pooled as "random").
        #[arg(long, default_value_t = 5)]
        random_seeds: u64,
        #[command(flatten)]
        scoring: Scoring,
        /// Output folder; an interrupted run resumes from it.
        #[arg(long, short = 'o', default_value = "out/crossval")]
        out: PathBuf,
    },
    /// UV map tools.
    #[command(subcommand)]
    Uv(UvCmd),
    /// Time the render stages on a mesh (G-buffer per view, texture gather and its adjoint,
    /// shading) at several image sizes; writes CSV.
    BenchRender {
        /// OBJ mesh with UVs.
        #[arg(long, default_value = "../shared/data/pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// Image sizes.
        #[arg(long, value_delimiter = ',', default_value = "416,800")]
        sizes: Vec<usize>,
        /// Views (orbit azimuths) per size.
        #[arg(long, default_value_t = 8)]
        views: usize,
        /// Output CSV.
        #[arg(long, short = 'o', default_value = "bench/render.csv")]
        out: PathBuf,
    },
    /// Render the mesh with its UV texture (flat, unlit) and the textured-region mask as PNGs.
    Render {
        /// OBJ mesh with UVs.
        #[arg(long, default_value = "../shared/data/pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// UV texture (default: the body material's map_Kd).
        #[arg(long)]
        texture: Option<PathBuf>,
        /// Camera from a CARLA npz sample's cam_trans (PAV-Camou convention).
        #[arg(long, conflicts_with = "orbit")]
        pose: Option<PathBuf>,
        /// Camera at "dist,elev,azim" (normalized units, degrees) looking at the origin.
        #[arg(long)]
        orbit: Option<String>,
        /// Image side in pixels.
        #[arg(long, default_value_t = 800)]
        size: usize,
        /// Output PNG; the mask goes beside it as NAME_mask.png.
        #[arg(long, short = 'o', default_value = "out/render.png")]
        out: PathBuf,
    },
}

#[derive(Subcommand)]
enum UvCmd {
    /// Per-face stretch/compression of the optimizable patch: CSV, summary and heat maps
    /// (grey = none, purple = stretched, red = compressed, as MAYA shows them).
    Check {
        /// OBJ mesh with UVs.
        #[arg(long, default_value = "../shared/data/pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// UV map whose pure-white texels mark the optimizable patch.
        #[arg(long, default_value = "../shared/data/pav-camou/half.png")]
        mask: PathBuf,
        /// Output directory.
        #[arg(long, short = 'o', default_value = "out/uv")]
        out: PathBuf,
    },
    /// Re-flatten the optimizable patch automatically at one common texel density; writes the
    /// adjusted OBJ, its UV mask, and before/after heat maps.
    Adjust {
        /// OBJ mesh with UVs.
        #[arg(long, default_value = "../shared/data/pav-camou/xfl_yxz.obj")]
        mesh: PathBuf,
        /// UV map whose pure-white texels mark the optimizable patch.
        #[arg(long, default_value = "../shared/data/pav-camou/half.png")]
        mask: PathBuf,
        /// charts: cut by the 3D surface (a door is one piece) and pack into the free texels;
        /// islands: LSCM per original UV island, kept inside its original box.
        #[arg(long, value_enum, default_value_t = AdjustMode::Charts)]
        mode: AdjustMode,
        /// Charts: largest angle between a face's normal and its chart's seed normal.
        #[arg(long, default_value_t = 45.0)]
        max_angle: f64,
        /// Output directory.
        #[arg(long, short = 'o', default_value = "out/uv_adjusted")]
        out: PathBuf,
    },
}

/// How `eval-digital` and `crossval` score composites.
#[cfg(feature = "optimize")]
#[derive(clap::Args, Debug)]
struct Scoring {
    /// Detector configs or folders of them.
    #[arg(long = "detectors", short = 'd', default_value = "configs/detectors")]
    detectors: Vec<PathBuf>,
    /// A car counts as detected above this score (paper 0.5; the authors' code 0.6).
    #[arg(long, default_value_t = 0.5)]
    threshold: f32,
    /// Name of the white-box detector (starred).
    #[arg(long, default_value = "yolov3-tiny")]
    white_box: String,
}

/// Writes a Markdown report to `out/name` and prints it.
#[cfg(feature = "optimize")]
fn write_markdown(out: &std::path::Path, name: &str, md: &str) -> Result<()> {
    let path = out.join(name);
    std::fs::write(&path, md).with_context(|| format!("writing {}", path.display()))?;
    println!("{md}");
    Ok(())
}

/// How `pav uv adjust` re-flattens the patch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum AdjustMode {
    /// 3D charts packed into the free texels.
    Charts,
    /// Original UV islands, each kept in its box.
    Islands,
}

fn uv_adjust(
    mesh_path: &std::path::Path,
    mask: &std::path::Path,
    mode: AdjustMode,
    max_angle: f64,
    out: &std::path::Path,
) -> Result<()> {
    use pav::geometry::uv::{distortion, faces_in_mask, faces_mask, summary};
    use pav::geometry::uv_adjust::adjust;
    use pav::geometry::uv_charts::adjust_charts;
    let original = Mesh::load_obj(mesh_path)?;
    let tex = Texture::load(mask).map_err(anyhow::Error::msg)?;
    let was_white = tex.white_mask();
    let patch = faces_in_mask(&original, &was_white, tex.width, tex.height);
    if patch.is_empty() {
        bail!("{} marks no face of {}", mask.display(), mesh_path.display());
    }
    let before = summary(&distortion(&original, &patch));
    let mut m = original.clone();
    anyhow::ensure!(tex.width == tex.height, "the UV mask must be square, got {}x{}", tex.width, tex.height);
    let (density, pieces) = match mode {
        AdjustMode::Islands => (adjust(&mut m, &patch), String::new()),
        AdjustMode::Charts => {
            // One packing cell per 4 texels, one free cell around each chart.
            let r = adjust_charts(&mut m, &patch, max_angle, (tex.width / 4).max(64), 1)?;
            let pieces = format!(
                "; {} charts (one joins up to {} original UV islands), {} folded faces",
                r.charts, r.max_islands_joined, r.flipped
            );
            (r.density, pieces)
        }
    };
    let after = summary(&distortion(&m, &patch));
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    m.write_obj(&out.join("adjusted.obj"), None).with_context(|| format!("writing {}", out.display()))?;
    // The new mask: the original map with the patch painted over in the body colour, then the
    // adjusted islands painted white.
    let (w, h) = (tex.width, tex.height);
    let mut rgb: Vec<u8> = tex.rgb.iter().map(|v| (v * 255.0).round() as u8).collect();
    let body = [67u8, 74, 114];
    for (i, px) in rgb.chunks_mut(3).enumerate() {
        if was_white[i] == 1.0 {
            px.copy_from_slice(&body);
        }
    }
    let white = faces_mask(&m, &patch, w);
    for (px, wv) in rgb.chunks_mut(3).zip(&white) {
        if *wv {
            px.copy_from_slice(&[255, 255, 255]);
        }
    }
    image::RgbImage::from_raw(w as u32, h as u32, rgb).context("mask image")?.save(out.join("adjusted_mask.png"))?;
    uv_check(&out.join("adjusted.obj"), &out.join("adjusted_mask.png"), &out.join("after"))?;
    uv_check(mesh_path, mask, &out.join("before"))?;
    println!(
        "adjusted {} faces: mean |log2 stretch| {:.3} -> {:.3}, 95th-percentile anisotropy {:.2} -> {:.2}; texel density {:.0} % of the original{pieces}",
        patch.len(),
        before.0,
        after.0,
        before.1,
        after.1,
        100.0 * density
    );
    eprintln!("wrote {}/adjusted.obj, adjusted_mask.png, before/ and after/", out.display());
    Ok(())
}

fn uv_check(mesh: &std::path::Path, mask: &std::path::Path, out: &std::path::Path) -> Result<()> {
    use pav::geometry::uv::{distortion, faces_in_mask, heat_colour, paint_uv, summary};
    let mut m = Mesh::load_obj(mesh)?;
    m.normalize();
    let tex = Texture::load(mask).map_err(anyhow::Error::msg)?;
    let patch = faces_in_mask(&m, &tex.white_mask(), tex.width, tex.height);
    if patch.is_empty() {
        bail!("{} marks no face of {} (no pure-white texel under any face centroid)", mask.display(), mesh.display());
    }
    let d = distortion(&m, &patch);
    let (mean_abs, p95) = summary(&d);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_csv(&out.join("uv_distortion.csv"), &d)?;
    let colours: Vec<(usize, [u8; 3])> = d.iter().map(|r| (r.face, heat_colour(r.log2_stretch))).collect();
    let size = 1024;
    let uv_img = paint_uv(&m, &colours, size, [255, 255, 255]);
    image::RgbImage::from_raw(size as u32, size as u32, uv_img)
        .context("uv image")?
        .save(out.join("uv_heat_uv.png"))?;
    // On the mesh: patch faces in their heat colour, the rest light grey.
    let mut face_col = vec![[225u8, 225, 225]; m.faces.len()];
    for (f, c) in &colours {
        face_col[*f] = *c;
    }
    let mut views = Vec::new();
    for azim in [45.0f32, 135.0, 225.0, 315.0] {
        let g = GBuffer::render(&m, &Camera::look_at(spherical(2.2, 25.0, azim), [0.0; 3], [0.0, 1.0, 0.0], 60.0), 400);
        views.push(
            g.face
                .iter()
                .flat_map(|f| if *f == pav::render::raster::EMPTY { [255, 255, 255] } else { face_col[*f as usize] })
                .collect::<Vec<u8>>(),
        );
    }
    // 2×2 grid of views.
    let mut grid = vec![255u8; 800 * 800 * 3];
    for (k, v) in views.iter().enumerate() {
        let (ox, oy) = ((k % 2) * 400, (k / 2) * 400);
        for y in 0..400 {
            let dst = ((oy + y) * 800 + ox) * 3;
            grid[dst..dst + 1200].copy_from_slice(&v[y * 1200..(y + 1) * 1200]);
        }
    }
    image::RgbImage::from_raw(800, 800, grid).context("mesh image")?.save(out.join("uv_heat_mesh.png"))?;
    println!(
        "{} patch faces: area-weighted mean |log2 stretch| {mean_abs:.3} (1.0 = a factor of 2), 95th-percentile anisotropy {p95:.2}",
        d.len()
    );
    eprintln!("wrote {}/uv_distortion.csv, uv_heat_uv.png, uv_heat_mesh.png", out.display());
    Ok(())
}

#[derive(serde::Serialize)]
struct RenderTiming {
    size: usize,
    views: usize,
    gbuffer_ms: f64,
    coverage: f64,
    gather_ms: f64,
    adjoint_ms: f64,
    shade_ms: f64,
}

fn ms_per(views: usize, t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3 / views as f64
}

fn bench_render(mesh: &std::path::Path, sizes: &[usize], views: usize, out: &std::path::Path) -> Result<()> {
    use pav::render::shade::{vertex_normals, Lights, Shading};
    use std::time::Instant;
    let mut m = Mesh::load_obj(mesh)?;
    m.normalize();
    let normals = vertex_normals(&m);
    let (tw, th) = (2048, 2048);
    let tex: Vec<f32> = (0..tw * th * 3).map(|i| (i % 251) as f32 / 250.0).collect();
    let views = views.max(1);
    let cams: Vec<Camera> = (0..views)
        .map(|k| {
            Camera::look_at(spherical(2.2, 20.0, k as f32 * 360.0 / views as f32), [0.0; 3], [0.0, 1.0, 0.0], 60.0)
        })
        .collect();
    let mut rows = Vec::new();
    for &size in sizes {
        let t = Instant::now();
        let gb: Vec<GBuffer> = cams.iter().map(|c| GBuffer::render(&m, c, size)).collect();
        let gbuffer_ms = ms_per(views, t);
        let gathers: Vec<Gather> = gb.iter().map(|g| Gather::new(g.uv_samples(&m), tw, th)).collect();
        let mut img = vec![0.0; size * size * 3];
        let t = Instant::now();
        for g in &gathers {
            g.apply(&tex, 3, &mut img);
        }
        let gather_ms = ms_per(views, t);
        let mut grad = vec![0.0; tw * th * 3];
        let t = Instant::now();
        for g in &gathers {
            g.adjoint(&img, 3, &mut grad);
        }
        let adjoint_ms = ms_per(views, t);
        let t = Instant::now();
        for (g, c) in gb.iter().zip(&cams) {
            Shading::new(g, &m, &normals, c, &Lights::PAV_CAMOU).apply(&mut img, 3);
        }
        let shade_ms = ms_per(views, t);
        let coverage = gb.iter().map(|g| g.coverage() as f64).sum::<f64>() / views as f64;
        eprintln!(
            "{size}²: G-buffer {gbuffer_ms:.1} ms/view, gather {gather_ms:.2} ms, adjoint {adjoint_ms:.2} ms, shading {shade_ms:.2} ms (car covers {:.0} %)",
            100.0 * coverage
        );
        rows.push(RenderTiming { size, views, gbuffer_ms, coverage, gather_ms, adjoint_ms, shade_ms });
    }
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    write_csv(out, &rows)?;
    eprintln!("wrote {}", out.display());
    Ok(())
}

#[cfg(feature = "optimize")]
#[allow(clippy::too_many_arguments)]
fn optimize(
    config: &std::path::Path,
    out: &std::path::Path,
    resume: bool,
    epochs: Option<usize>,
    size: Option<usize>,
    scale: f64,
    dpi: f64,
) -> Result<()> {
    use pav::attack::config::OptimizeConfig;
    use pav::attack::export::{atlas_side_m, write_sheet, PrintSpec};
    use pav::attack::optimize::{run, Finish, RunOptions};
    use pav::attack::outputs::{eval_scene, plot_log, preview, score_views};
    use pav::attack::setup::Setup;
    use pav::attack::whitebox::WhiteBox;
    let mut cfg = OptimizeConfig::load(config)?;
    cfg.views.size = size.unwrap_or(cfg.views.size);
    let t = std::time::Instant::now();
    let setup = Setup::load(&cfg, None)?;
    let wb = WhiteBox::load(&cfg.detector, cfg.views.size)?;
    eprintln!(
        "{} training (+{} synthetic) and {} held-out views at {}², texture {}² ({} optimizable values, {:.1} % of the atlas), scene {}; prepared in {:.1} s",
        setup.train.len(),
        setup.synthetic.len(),
        setup.test.len(),
        cfg.views.size,
        setup.tex_size,
        setup.region_values.len(),
        100.0 * setup.region_values.len() as f64 / (3 * setup.tex_size * setup.tex_size) as f64,
        setup.scene.describe(),
        t.elapsed().as_secs_f64()
    );
    let [none, one, more] = setup.region_views_shares();
    eprintln!(
        "region texels read by no training view {:.1} %, by one {:.1} %, by two or more {:.1} %",
        100.0 * none,
        100.0 * one,
        100.0 * more
    );
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let region_rgb: Vec<f32> = setup.region.iter().flat_map(|v| [*v; 3]).collect();
    save_rgb(&out.join("region.png"), setup.tex_size, setup.tex_size, &region_rgb).map_err(anyhow::Error::msg)?;
    let stop = stop_on_ctrl_c()?;
    let opts =
        RunOptions { out: out.to_path_buf(), resume, checkpoint_every: 20, max_skips: 5, epochs, progress: true };
    let o = run(config, &cfg, &setup, &wb, &opts, &stop)?;
    let n = setup.tex_size;
    save_rgb(&out.join("texture.png"), n, n, &o.texture).map_err(anyhow::Error::msg)?;
    plot_log(&out.join("loss.png"), &o.log, setup.training_views().len()).map_err(anyhow::Error::msg)?;
    if matches!(o.finish, Finish::Stopped) {
        eprintln!("stopped: state saved in {}; run again with --resume", out.join("checkpoint.bin").display());
        return Ok(());
    }
    let views: Vec<&pav::attack::view::View> = setup.train.iter().chain(&setup.test).collect();
    preview(&out.join("preview.png"), &views, &o.texture, &eval_scene(&setup)).map_err(anyhow::Error::msg)?;
    if !setup.synthetic.is_empty() {
        let synthetic: Vec<&pav::attack::view::View> = setup.synthetic.iter().collect();
        preview(&out.join("synthetic.png"), &synthetic, &o.texture, &eval_scene(&setup)).map_err(anyhow::Error::msg)?;
    }
    let initial = setup.initial_texture(cfg.mesh.init, cfg.optimizer.seed);
    let scores = score_views(&setup, &wb, &initial, &o.texture).map_err(anyhow::Error::msg)?;
    write_csv(&out.join("scores.csv"), &scores)?;
    println!("white-box YOLOv3-tiny car score per view (no EoT): original photo / initial texture / optimized");
    for s in &scores {
        println!("  {:5} {:10} {:.3} / {:.3} / {:.3}", s.split, s.view, s.original, s.initial, s.optimized);
    }
    let (side, spread) = atlas_side_m(&setup.mesh, &setup.region, n, cfg.mesh.car_length_m)
        .context("the optimizable region covers no face with area")?;
    let sheet = write_sheet(&out.join("texture_print.png"), &o.texture, n, side, spread, PrintSpec { scale, dpi })
        .map_err(anyhow::Error::msg)?;
    println!(
        "printable sheet: {} ({}x{} px at {dpi} dpi): print at 100 % so the atlas is {:.1} mm wide for a 1:{scale} model (the bar is 10 mm; texel density varies {:.2}x between faces, 10th-90th percentile)",
        out.join("texture_print.png").display(),
        sheet.width_px,
        sheet.height_px,
        sheet.atlas_mm,
        sheet.density_spread
    );
    eprintln!(
        "wrote region.png, texture.png, texture_print.png, loss.csv, loss.png, preview.png{}, scores.csv in {}",
        if setup.synthetic.is_empty() { "" } else { ", synthetic.png" },
        out.display()
    );
    Ok(())
}

/// A flag that Ctrl-C raises, so long runs save their state and stop between steps.
#[cfg(feature = "optimize")]
fn stop_on_ctrl_c() -> Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use std::sync::atomic::{AtomicBool, Ordering};
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    Ok(stop)
}

#[cfg(feature = "optimize")]
fn eval_digital(
    config: &std::path::Path,
    textures: &[PathBuf],
    scoring: &Scoring,
    out: &std::path::Path,
) -> Result<()> {
    let Scoring { detectors, threshold, white_box } = scoring;
    let threshold = *threshold;
    use pav::attack::config::OptimizeConfig;
    use pav::attack::digital::{evaluate, markdown, AP_MIN_SCORE};
    use pav::attack::setup::Setup;
    let cfg = OptimizeConfig::load(config)?;
    let setup = Setup::load_photos(&cfg, None)?;
    let mut conditions: Vec<(String, Option<Vec<f32>>)> =
        vec![("original".into(), None), ("random".into(), Some(setup.random_texture(setup.random_block(), 1)))];
    for t in textures {
        let tex = Texture::load(t).map_err(anyhow::Error::msg)?;
        if (tex.width, tex.height) != (setup.tex_size, setup.tex_size) {
            bail!("{} is {}x{}, the config's texture is {}²", t.display(), tex.width, tex.height, setup.tex_size);
        }
        let name = t
            .parent()
            .and_then(|p| p.file_name())
            .or(t.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| t.display().to_string());
        conditions.push((name, Some(tex.rgb)));
    }
    let mut dets = pav::eval::detectors::load_detectors(detectors, &[], 1)?;
    let total = (conditions.len() * (setup.train.len() + setup.test.len())) as u64;
    let bar = indicatif::ProgressBar::new(total);
    let rows = evaluate(&setup, &mut dets, &conditions, threshold, white_box, || bar.inc(1))?;
    bar.finish_and_clear();
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_csv(&out.join("digital.csv"), &rows)?;
    let mut md = format!(
        "# Digital evaluation (ASR / P@0.5 in %, * = white-box)\n\nCar = COCO `car`; detected above score {threshold}; P@0.5 is car AP at IoU 0.5 over boxes from score {AP_MIN_SCORE}. Views composited at {}² (lit, no EoT), 8-bit. Config: {}.\n",
        cfg.views.size,
        config.display()
    );
    for (split, title) in [("train", "training views"), ("test", "held-out views"), ("all", "all views")] {
        if rows.iter().any(|r| r.split == split) {
            let n = rows.iter().find(|r| r.split == split).map(|r| r.images).unwrap_or(0);
            md.push_str(&format!("\n## {title} ({n})\n\n{}", markdown(&rows, split)));
        }
    }
    write_markdown(out, "digital.md", &md)?;
    eprintln!("wrote {}/digital.csv and digital.md", out.display());
    Ok(())
}

#[cfg(feature = "optimize")]
fn crossval_cmd(
    config: &std::path::Path,
    folds: Option<usize>,
    random_seeds: u64,
    scoring: &Scoring,
    out: &std::path::Path,
) -> Result<()> {
    let Scoring { detectors, threshold, white_box } = scoring;
    let threshold = *threshold;
    use pav::attack::config::OptimizeConfig;
    use pav::attack::crossval::{crossval, CrossvalOptions};
    use pav::attack::digital::{markdown, markdown_scores, AP_MIN_SCORE};
    use pav::attack::setup::Setup;
    use pav::attack::whitebox::WhiteBox;
    let cfg = OptimizeConfig::load(config)?;
    let setup = Setup::load_photos(&cfg, None)?;
    let wb = WhiteBox::load(&cfg.detector, cfg.views.size)?;
    let mut dets = pav::eval::detectors::load_detectors(detectors, &[], 1)?;
    let n = setup.train.len() + setup.test.len();
    let k = folds.unwrap_or(n);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let stop = stop_on_ctrl_c()?;
    let opts = CrossvalOptions {
        folds: k,
        random_seeds,
        random_block: setup.random_block(),
        out: out.to_path_buf(),
        threshold,
        white_box: white_box.to_string(),
    };
    let bar = indicatif::ProgressBar::new(2 * k as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} (eta {eta}) {msg}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let t = std::time::Instant::now();
    let (rows, records) = crossval(config, &cfg, &setup, &wb, &mut dets, &opts, &stop, |f, stage| {
        bar.set_message(format!("fold {}/{k}: {stage}", f + 1));
        if stage != "optimizing" {
            bar.inc(1);
        }
    })?;
    bar.finish_and_clear();
    write_csv(&out.join("crossval.csv"), &rows)?;
    write_csv(&out.join("crossval_views.csv"), &records)?;
    let mut md = format!(
        "# Cross-validation, {k} folds over {n} views ({:.0} s)\n\nEach texture is optimized on the other folds' views{} ({}, {} epochs) and scored on its held-out views; \"random\" pools {random_seeds} random textures of {}-texel blocks per fold. Car detected above {threshold}; P@0.5 over boxes from score {AP_MIN_SCORE}; * = white-box.\n",
        t.elapsed().as_secs_f64(),
        if cfg.views.turns.is_empty() {
            String::new()
        } else {
            format!(" and their synthetic turns by {:?}° (baked from that fold's photos; scores are photos only)", cfg.views.turns)
        },
        config.display(),
        cfg.optimizer.epochs,
        setup.random_block(),
    );
    for (split, title) in
        [("held-out", "held-out views"), ("train", "training views (each view once per fold it trained in)")]
    {
        md.push_str(&format!("\n## {title}: ASR / P@0.5 (%)\n\n{}", markdown(&rows, split)));
        md.push_str(&format!("\n## {title}: mean best car score\n\n{}", markdown_scores(&rows, split)));
    }
    write_markdown(out, "crossval.md", &md)?;
    eprintln!("wrote crossval.csv, crossval_views.csv, crossval.md and a folder per fold in {}", out.display());
    Ok(())
}

fn main() -> Result<()> {
    let (mesh, texture, pose, orbit, size, out) = match Cli::parse().cmd {
        #[cfg(feature = "optimize")]
        Cmd::EvalDigital { config, textures, scoring, out } => return eval_digital(&config, &textures, &scoring, &out),
        #[cfg(feature = "optimize")]
        Cmd::Optimize { config, out, resume, epochs, size, scale, dpi } => {
            return optimize(&config, &out, resume, epochs, size, scale, dpi)
        }
        #[cfg(feature = "optimize")]
        Cmd::Crossval { config, folds, random_seeds, scoring, out } => {
            return crossval_cmd(&config, folds, random_seeds, &scoring, &out)
        }
        Cmd::BenchRender { mesh, sizes, views, out } => return bench_render(&mesh, &sizes, views, &out),
        Cmd::Uv(UvCmd::Check { mesh, mask, out }) => return uv_check(&mesh, &mask, &out),
        Cmd::Uv(UvCmd::Adjust { mesh, mask, mode, max_angle, out }) => {
            return uv_adjust(&mesh, &mask, mode, max_angle, &out)
        }
        Cmd::Render { mesh, texture, pose, orbit, size, out } => (mesh, texture, pose, orbit, size, out),
    };
    let mut m = Mesh::load_obj(&mesh)?;
    m.normalize();
    let tex_path = match texture {
        Some(t) => t,
        None => m
            .materials
            .iter()
            .find_map(|x| x.map_kd.clone())
            .context("the mesh names no map_Kd texture: pass --texture")?,
    };
    let tex = Texture::load(&tex_path).map_err(anyhow::Error::msg)?;
    let cam: Camera = match (pose, orbit) {
        (Some(p), _) => {
            let s = CarlaSample::load(&p)?;
            pav_camou(s.cam_trans, s.veh_trans[1][1])
        }
        (None, Some(o)) => {
            let v: Vec<f32> = o
                .split(',')
                .map(|s| s.trim().parse())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--orbit `{o}`: expected dist,elev,azim"))?;
            let [d, e, a] = v[..] else { bail!("--orbit `{o}`: expected three numbers dist,elev,azim") };
            Camera::look_at(spherical(d, e, a), [0.0; 3], [0.0, 1.0, 0.0], 60.0)
        }
        (None, None) => Camera::look_at(spherical(2.2, 20.0, 45.0), [0.0; 3], [0.0, 1.0, 0.0], 60.0),
    };
    let g = GBuffer::render(&m, &cam, size);
    let gather = Gather::new(g.uv_samples(&m), tex.width, tex.height);
    let mut rgb = vec![1.0f32; size * size * 3];
    gather.apply(&tex.rgb, 3, &mut rgb);
    let white = tex.white_mask();
    let mut mask = vec![0.0f32; size * size];
    gather.apply(&white, 1, &mut mask);
    if let Some(d) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(d)?;
    }
    save_rgb(&out, size, size, &rgb).map_err(anyhow::Error::msg)?;
    let mask_path = out.with_file_name(format!("{}_mask.png", out.file_stem().unwrap_or_default().to_string_lossy()));
    let mask_rgb: Vec<f32> = mask.iter().flat_map(|v| [*v; 3]).collect();
    save_rgb(&mask_path, size, size, &mask_rgb).map_err(anyhow::Error::msg)?;
    eprintln!(
        "car covers {:.1} % of the image; wrote {} and {}",
        100.0 * g.coverage(),
        out.display(),
        mask_path.display()
    );
    Ok(())
}
