//! A detector config's keys mean one thing wherever pav reads them: `nms_iou` is the suppression
//! of every path that turns proposals into detections (eval-digital's and crossval's P@0.5 read
//! `studies::table2::detect_view`), with 0.5 when the key is absent.

use crate::common;

use pav::attack::config::OptimizeConfig;
use pav::attack::setup::Setup;
use pav::studies::table2::detect_view;
use std::path::Path;

/// YOLOv3-tiny's config extended with `extra` (TOML keys), written into `dir`.
fn yolov3_tiny_with(dir: &Path, name: &str, extra: &str) -> std::path::PathBuf {
    let path = dir.join(format!("{name}.toml"));
    let base = common::detector_config("yolov3-tiny");
    std::fs::write(&path, format!("extends = {:?}\nname = {name:?}\n{extra}", base.display().to_string())).unwrap();
    path
}

#[test]
fn nms_iou_sets_the_suppression_of_the_detections_that_p50_scores() {
    common::real_data();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(2);
    cfg.views.test.clear();
    let setup = Setup::load_photos(&cfg, None).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let configs = [
        yolov3_tiny_with(tmp.path(), "absent", ""),
        yolov3_tiny_with(tmp.path(), "half", "nms_iou = 0.5\n"),
        yolov3_tiny_with(tmp.path(), "tight", "nms_iou = 0.05\n"),
        yolov3_tiny_with(tmp.path(), "loose", "nms_iou = 0.95\n"),
    ];
    let mut dets = pav::detect::load::load_detectors(&configs, &[], &[], 1).unwrap();
    assert_eq!(dets.iter().map(|d| d.nms_iou()).collect::<Vec<_>>(), [0.5, 0.5, 0.05, 0.95]);
    let mut counts = [0usize; 4];
    for view in &setup.train {
        let found = detect_view(view, None, &setup, &mut dets).unwrap();
        for (c, f) in counts.iter_mut().zip(&found) {
            *c += f.cars.len();
        }
        // The best box is the best box whatever the suppression.
        assert!(found.iter().all(|f| f.best_score() == found[0].best_score()));
    }
    eprintln!("car detections on {} photos: {counts:?}", setup.train.len());
    let [absent, half, tight, loose] = counts;
    assert_eq!(absent, half, "a config without nms_iou suppresses at 0.5");
    assert!(tight < half && half < loose, "suppression at 0.05, 0.5, 0.95 kept {tight}, {half}, {loose} boxes");
}
