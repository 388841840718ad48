//! Where each white box's best car score sits on FCA's 11 photos (original paint): the IoU of
//! its box with the car's box (the rendered silhouette's), unweighted and under `loss.iou`'s
//! weight. CSV on stdout: detector, photo, best score, its box's IoU with the car, the best
//! IoU-weighted score, its box's IoU. Run from the repository root:
//! `cargo run --release --features optimize --example argmax_iou > out/argmax_iou.csv`.
use pav::attack::config::OptimizeConfig;
use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::setup::Setup;
use pav::attack::whitebox::{WhiteBox, WhiteBoxOptions};
use pav::detect::nms::iou;
use pav::detect::DetectorConfig;
fn main() {
    println!("detector,photo,best_score,best_iou,weighted_best,weighted_iou");
    let mut cfg = OptimizeConfig::load(std::path::Path::new("configs/optimize/paper.toml")).unwrap();
    cfg.views.pbr.clear();
    let s = Setup::load(&cfg, Some(416)).unwrap();
    for (name, sur) in
        [("yolov3-tiny", false), ("yolov8n_int8", true), ("deimv2_atto_int8", true), ("yolox_nano", false)]
    {
        let d = DetectorConfig::load(std::path::Path::new(&format!("configs/detectors/{name}.toml"))).unwrap();
        let loss = DetectionLoss {
            box_threshold: 0.05,
            target: d.target_classes.clone(),
            reduce: Reduce::LogMax,
            proposals: ProposalSet::ArgMax,
            iou: true,
            box_gradient: false,
        };
        let wb = WhiteBox::with_options(
            &d,
            loss,
            WhiteBoxOptions { composite: 416, input: None, threads: 1, surrogate: sur },
        )
        .unwrap();
        for v in s.train.iter().chain(&s.test) {
            let car = v.car_box.unwrap();
            let p = wb.predictions(&v.photo, 416).unwrap();
            let (bb, bs) = p.iter().copied().fold(([0.0; 4], 0.0), |m, x| if x.1 > m.1 { x } else { m });
            let (wbx, ws) =
                p.iter()
                    .map(|(b, s)| (*b, iou(b, &car) * s))
                    .fold(([0.0; 4], 0.0), |m, x| if x.1 > m.1 { x } else { m });
            println!("{name},{},{bs:.3},{:.3},{ws:.3},{:.3}", v.name, iou(&bb, &car), iou(&wbx, &car));
        }
    }
}
