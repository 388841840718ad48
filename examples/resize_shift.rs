//! How much evaluate's car scores move between OpenCV's bilinear resize (what `prepare` calls) and
//! pav's float bilinear (`prepare_exact`, what it used before): per detector, on the turntable
//! fixture, the CARLA fixture and FCA's 11 photos, the largest and the median |Δ| of the best car
//! score per image. CSV on stdout. Run from the repository root:
//! `cargo run --release --example resize_shift > out/resize_shift.csv`.
use pav::detect::config::DetectorConfig;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::{prepare, prepare_exact};
use pav::detect::Detector;
use pav::image::Frame;
use std::path::Path;

fn video(path: &str) -> Vec<Frame> {
    let mut r = pav::video::VideoReader::open(Path::new(path)).unwrap();
    std::iter::from_fn(|| r.read().unwrap().map(|(_, f)| f)).collect()
}

fn main() {
    let store = pav::data::store::Store::from_env();
    let photos: Vec<Frame> = std::iter::once("train/data1".to_string())
        .chain((12501..=12510).map(|i| format!("test/data{i}")))
        .map(|n| store.require(&format!("fca/carla_dataset/{n}.npz")).unwrap())
        .map(|p| pav::dataset::fca::CarlaSample::load(&p).unwrap().image)
        .collect();
    let sets = [
        ("fixtures/turntable.mp4", video("fixtures/turntable.mp4")),
        ("fixtures/carla_orbit.mp4", video("fixtures/carla_orbit.mp4")),
        ("FCA photos", photos),
    ];
    println!("detector,images,n,max_abs_delta,median_abs_delta,changed_decisions");
    let mut paths: Vec<_> = std::fs::read_dir("configs/detectors").unwrap().map(|e| e.unwrap().path()).collect();
    paths.sort();
    for p in paths {
        let cfg = DetectorConfig::load(&p).unwrap();
        let mut det = OnnxDetector::new(cfg.clone(), 0).unwrap();
        for (name, frames) in &sets {
            let mut best = |input: (Vec<f32>, _)| {
                let props = det.propose_prepared(input.0, input.1).unwrap();
                props.best(det.target_classes()).map_or(0.0, |b| b.score)
            };
            let pairs: Vec<(f32, f32)> = frames
                .iter()
                .map(|f| (best(prepare(f, &cfg.input).expect("no defences")), best(prepare_exact(f, &cfg.input))))
                .collect();
            let mut d: Vec<f32> = pairs.iter().map(|(a, b)| (a - b).abs()).collect();
            d.sort_by(f32::total_cmp);
            let flips = pairs.iter().filter(|(a, b)| (*a >= 0.5) != (*b >= 0.5)).count();
            println!("{},{name},{},{:.4},{:.4},{flips}", cfg.name, d.len(), d[d.len() - 1], d[d.len() / 2]);
        }
    }
}
