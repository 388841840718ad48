//! Regenerates the recorded-video fixtures in `fixtures/` from the real CARLA samples in
//! `fca/carla_dataset` in pav's data store (`pav data fetch fca/`):
//!
//! - `carla_orbit.mp4`: the 11 CARLA views ordered by camera azimuth around the car, each held
//!   for 3 frames, followed by 4 of them with the car painted out (3 frames each); 45 frames.
//!   Only views whose painted-out frame leaves no other car that any shipped detector scores
//!   above 0.25 are painted out (others show parked cars in the background).
//! - `carla_orbit.angles.csv`: the capture sidecar (frame, timestamp_s, angle_deg = azimuth).
//! - `carla_orbit.truth.csv`: per frame, the source view, whether the car is visible, and the
//!   reference car scores from `derived_test_labels.tsv` (0 where the car was painted out).
//!
//! Run: `cargo run --release --example make_fixtures`

use anyhow::{bail, Context, Result};
use opencv::core::Size;
use opencv::prelude::*;
use opencv::videoio::{VideoWriter, CAP_FFMPEG};
use pav::dataset::fca::CarlaSample;
use pav::image::Frame;
use pav::sidecar::{self, AngleSample};
use pav::video::frame_to_mat;
use std::path::PathBuf;

const HOLD: usize = 3;
const FPS: f64 = 10.0;
const ERASED: [&str; 4] = ["data12501", "data12502", "data12505", "data12508"];

/// Paints the car's box (grown by 10 %) with the mean colour of a ring of pixels around it.
fn erase_car(img: &Frame, b: [usize; 4]) -> Frame {
    let (w, h) = (img.width, img.height);
    let (gx, gy) = ((b[2] - b[0]) / 10, (b[3] - b[1]) / 10);
    let (x1, y1, x2, y2) =
        (b[0].saturating_sub(gx), b[1].saturating_sub(gy), (b[2] + gx).min(w - 1), (b[3] + gy).min(h - 1));
    let ring = 12;
    let mut sum = [0f64; 3];
    let mut n = 0f64;
    for y in y1.saturating_sub(ring)..=(y2 + ring).min(h - 1) {
        for x in x1.saturating_sub(ring)..=(x2 + ring).min(w - 1) {
            if x < x1 || x > x2 || y < y1 || y > y2 {
                for (c, s) in sum.iter_mut().enumerate() {
                    *s += img.bgr[(y * w + x) * 3 + c] as f64;
                }
                n += 1.0;
            }
        }
    }
    let fill: Vec<u8> = sum.iter().map(|s| (s / n).round() as u8).collect();
    let mut out = img.clone();
    for y in y1..=y2 {
        for x in x1..=x2 {
            out.bgr[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&fill);
        }
    }
    out
}

fn main() -> Result<()> {
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let store = pav::data::store::Store::from_env();
    let tsv = std::fs::read_to_string(store.require("fca/carla_dataset/derived_test_labels.tsv")?)?;
    let mut lines = tsv.lines();
    let header: Vec<&str> = lines.next().context("empty tsv")?.split('\t').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).with_context(|| format!("tsv lacks {name}"));
    let (c_box, c_x, c_v8) = (col("gt_x1")?, col("car_score_yolox_nano")?, col("car_score_yolov8n_int8")?);
    struct View {
        name: String,
        sample: CarlaSample,
        bbox: [usize; 4],
        yolox: String,
        yolov8n: String,
    }
    let mut views = Vec::new();
    for l in lines.filter(|l| !l.trim().is_empty()) {
        let c: Vec<&str> = l.split('\t').collect();
        let path = store.require(c[0].strip_prefix("data/").unwrap_or(c[0]))?;
        let sample = CarlaSample::load(&path)?;
        let bbox = [c[c_box].parse()?, c[c_box + 1].parse()?, c[c_box + 2].parse()?, c[c_box + 3].parse()?];
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        views.push(View { name, sample, bbox, yolox: c[c_x].into(), yolov8n: c[c_v8].into() });
    }
    views.sort_by(|a, b| a.sample.relative_azimuth_deg().total_cmp(&b.sample.relative_azimuth_deg()));
    let (w, h) = (views[0].sample.image.width, views[0].sample.image.height);

    let out_dir = repo.join("fixtures");
    std::fs::create_dir_all(&out_dir)?;
    let video = out_dir.join("carla_orbit.mp4");
    let fourcc = VideoWriter::fourcc('a', 'v', 'c', '1')?;
    let mut writer = VideoWriter::new_with_backend(
        &*video.to_string_lossy(),
        CAP_FFMPEG,
        fourcc,
        FPS,
        Size::new(w as i32, h as i32),
        true,
    )?;
    if !writer.is_opened()? {
        bail!("OpenCV could not open an H.264 writer for {}", video.display());
    }
    let mut side = sidecar::Writer::create(&sidecar::sidecar_path(&video))?;
    let mut truth = csv::Writer::from_path(out_dir.join("carla_orbit.truth.csv"))?;
    truth.write_record([
        "frame",
        "view",
        "car_visible",
        "angle_deg",
        "ref_score_yolox_nano",
        "ref_score_yolov8n_int8",
    ])?;
    let mut frame = 0usize;
    let mut emit = |img: &Frame, v: &View, visible: bool| -> Result<()> {
        let mat = frame_to_mat(img)?;
        let az = v.sample.relative_azimuth_deg();
        for _ in 0..HOLD {
            writer.write(&mat)?;
            side.push(AngleSample { frame, timestamp_s: frame as f64 / FPS, angle_deg: az })?;
            let (sx, s8) = if visible { (v.yolox.clone(), v.yolov8n.clone()) } else { ("0".into(), "0".into()) };
            truth.write_record([frame.to_string(), v.name.clone(), visible.to_string(), format!("{az:.1}"), sx, s8])?;
            frame += 1;
        }
        Ok(())
    };
    for v in &views {
        emit(&v.sample.image, v, true)?;
    }
    for v in views.iter().filter(|v| ERASED.contains(&v.name.as_str())) {
        emit(&erase_car(&v.sample.image, v.bbox), v, false)?;
    }
    writer.release()?;
    truth.flush()?;
    eprintln!(
        "wrote {} ({frame} frames, {:.0} KB) with sidecar and truth",
        video.display(),
        std::fs::metadata(&video)?.len() as f64 / 1e3
    );
    Ok(())
}
