//! A detector described in TOML is a white box, through the same description that scores it:
//! YOLOv3-tiny with its heads decoded in the graph and flattened to rows (`layout = "custom"`,
//! `custom_layout::flattened_yolov3_tiny`) gives the darknet preset's loss and input gradient on
//! real photos, and as the only white box of a short `pav optimize` it lowers its own car score
//! as the preset does; written as exporters write graphs (`Constant` nodes, reshape sizes
//! computed at run time) it gives the same loss and gradient.

use crate::common;
use crate::custom_layout::{config_like_yolov3_tiny, flattened_yolov3_tiny, FLAT};

use pav::attack::config::OptimizeConfig;
use pav::attack::loss::{DetectionLoss, ProposalSet, Reduce};
use pav::attack::optimize::{optimize_texture, RunOptions};
use pav::attack::setup::Setup;
use pav::attack::whitebox::{Ensemble, WhiteBox, WhiteBoxOptions};
use pav::detect::DetectorConfig;
use pav::progress::Silent;
use pav::studies::outputs::score_views;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The relative L2 distance of `a` from `b`.
fn relative(a: &[f32], b: &[f32]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    let n: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    (d / n).sqrt()
}

#[test]
fn a_flattened_model_as_a_white_box_gives_the_darknet_presets_loss_and_gradient() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let flat = config_like_yolov3_tiny(tmp.path(), &flattened_yolov3_tiny(tmp.path()), FLAT);
    let dark = DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap();
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(3);
    cfg.views.test.clear();
    let s = Setup::load(&cfg, Some(416)).unwrap();
    // The paper's means, and RAUCA-E2E's IoU-weighted log-max with its weight differentiated
    // through the boxes: cx, cy, w, h rows against the darknet decoder.
    let losses = [(Reduce::Mean, false), (Reduce::LogMax, true)];
    for (reduce, iou) in losses {
        let loss = DetectionLoss {
            box_threshold: 0.05,
            target: vec![2],
            reduce,
            proposals: ProposalSet::ArgMax,
            iou,
            box_gradient: iou,
        };
        let o = WhiteBoxOptions { composite: 416, input: None, threads: 2, surrogate: false };
        let (a, b) =
            (WhiteBox::with_options(&flat, loss.clone(), o).unwrap(), WhiteBox::with_options(&dark, loss, o).unwrap());
        for v in &s.train {
            let (ga, gb) = (
                a.loss_and_grad(&v.photo, 416, 1.0, v.car_box).unwrap(),
                b.loss_and_grad(&v.photo, 416, 1.0, v.car_box).unwrap(),
            );
            let (la, lb) = (ga.loss.l1 + ga.loss.l2, gb.loss.l1 + gb.loss.l2);
            let rel = relative(&ga.grad, &gb.grad);
            eprintln!("{reduce:?} {}: loss {la:.6} vs {lb:.6}, gradient {rel:e} apart", v.name);
            assert_eq!((ga.loss.boxes, ga.loss.proposals), (gb.loss.boxes, gb.loss.proposals), "{}", v.name);
            assert!(((la - lb) / lb).abs() < 1e-5, "{reduce:?} {}: loss {la} vs {lb}", v.name);
            assert!(rel < 1e-5, "{reduce:?} {}: gradients {rel} apart", v.name);
            // Not vacuous: there is a gradient, and the car is seen.
            assert!(gb.grad.iter().any(|g| g.abs() > 1e-6) && gb.loss.max_score > 0.5, "{}", v.name);
        }
    }
}

/// The flattened YOLOv3-tiny as an exporter writes such graphs: its reshape sizes as `Constant`
/// nodes, and the first head's computed at run time from the head's shape (Shape, Gather,
/// Concat), as PyTorch exports a `view(batch, ...)`.
fn exported_like_pytorch(dir: &Path) -> std::path::PathBuf {
    use pav_onnx::proto::{Attr, Initializer, Model, Node};
    let flat = flattened_yolov3_tiny(dir);
    let mut m = Model::from_bytes(&std::fs::read(&flat).unwrap()).unwrap();
    let constant =
        |init: Initializer| Node::new("Constant", &[], &[&init.name.clone()]).attr("value", Attr::Tensor(init));
    let mut front = Vec::new();
    for name in ["head0_s2", "head1_s1", "head1_s2"] {
        let k = m.initializers.iter().position(|i| i.name == name).unwrap();
        front.push(constant(m.initializers.remove(k)));
    }
    m.initializers.retain(|i| i.name != "head0_s1");
    for (name, v) in [("zero", 0), ("axis0", 0), ("three", 3), ("row", 85), ("cells", 169)] {
        let dims: &[i64] = if name == "zero" { &[] } else { &[1] };
        front.push(constant(Initializer::i64(name, dims, vec![v])));
    }
    let at = m.nodes.iter().position(|n| n.inputs.iter().any(|i| i == "head0_s1")).unwrap();
    let runtime = [
        Node::new("Shape", &["head0"], &["head0_shape"]),
        Node::new("Gather", &["head0_shape", "zero"], &["batch"]).attr("axis", Attr::Int(0)),
        Node::new("Unsqueeze", &["batch", "axis0"], &["batch1"]),
        Node::new("Concat", &["batch1", "three", "row", "cells"], &["head0_s1"]).attr("axis", Attr::Int(0)),
    ];
    m.nodes.splice(at..at, runtime);
    m.nodes.splice(0..0, front);
    let path = dir.join("yolov3-tiny-exported.onnx");
    std::fs::write(&path, m.to_bytes()).unwrap();
    path
}

/// An export with `Constant` nodes and run-time shape arithmetic, described at its own
/// outputs, is a white box as it comes: its loss and gradient are the plain graph's.
#[test]
fn constant_nodes_and_shape_arithmetic_are_folded_for_the_white_box() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let plain = config_like_yolov3_tiny(tmp.path(), &flattened_yolov3_tiny(tmp.path()), FLAT);
    let exported_dir = tmp.path().join("exported");
    std::fs::create_dir_all(&exported_dir).unwrap();
    let exported = config_like_yolov3_tiny(&exported_dir, &exported_like_pytorch(&exported_dir), FLAT);
    let mut cfg = OptimizeConfig::load(&common::repo().join("configs/optimize/paper.toml")).unwrap();
    cfg.views.train.truncate(2);
    cfg.views.test.clear();
    let s = Setup::load(&cfg, Some(416)).unwrap();
    let loss = DetectionLoss {
        box_threshold: 0.05,
        target: vec![2],
        reduce: Reduce::LogMax,
        proposals: ProposalSet::ArgMax,
        iou: true,
        box_gradient: true,
    };
    let o = WhiteBoxOptions { composite: 416, input: None, threads: 2, surrogate: false };
    let a = WhiteBox::with_options(&exported, loss.clone(), o).unwrap();
    let b = WhiteBox::with_options(&plain, loss, o).unwrap();
    for v in &s.train {
        let (ga, gb) = (
            a.loss_and_grad(&v.photo, 416, 1.0, v.car_box).unwrap(),
            b.loss_and_grad(&v.photo, 416, 1.0, v.car_box).unwrap(),
        );
        let (la, lb) = (ga.loss.l1 + ga.loss.l2, gb.loss.l1 + gb.loss.l2);
        assert!(((la - lb) / lb).abs() < 1e-6, "{}: loss {la} vs {lb}", v.name);
        assert!(relative(&ga.grad, &gb.grad) < 1e-6, "{}", v.name);
        assert!(gb.grad.iter().any(|g| g.abs() > 1e-6), "{}", v.name);
    }
}

/// `paper.toml` with `detector` as its only white box, written into `dir`.
fn paper_against(dir: &Path, detector: &Path) -> (std::path::PathBuf, OptimizeConfig) {
    let path = dir.join(format!("against-{}.toml", detector.file_stem().unwrap().to_string_lossy()));
    let paper = common::repo().join("configs/optimize/paper.toml");
    std::fs::write(&path, format!("extends = {:?}\nwhite_box = [{{ detector = {:?} }}]\n", paper, detector)).unwrap();
    let mut cfg = OptimizeConfig::load(&path).unwrap();
    cfg.views.test.clear();
    (path, cfg)
}

#[test]
fn a_custom_layout_is_the_only_white_box_of_a_short_optimization() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    config_like_yolov3_tiny(tmp.path(), &flattened_yolov3_tiny(tmp.path()), FLAT);
    let never = AtomicBool::new(false);
    let mut drops = Vec::new();
    for detector in [tmp.path().join("flat.toml"), common::detector_config("yolov3-tiny")] {
        let (path, cfg) = paper_against(tmp.path(), &detector);
        let s = Setup::load(&cfg, None).unwrap();
        let wb = Ensemble::load(&cfg, cfg.views.size).unwrap();
        let out = tmp.path().join(wb.first().name());
        let opts =
            RunOptions { out, resume: false, checkpoint_every: 1000, max_skips: 3, epochs: Some(5), snapshot_every: 0 };
        let run = optimize_texture(&path, &cfg, &s, &wb, &opts, &Silent, &never).unwrap();
        assert_eq!(run.log.len(), 5 * s.train.len());
        let init = s.initial_texture(&cfg.mesh.init, cfg.optimizer.seed).unwrap();
        let scores = score_views(&s, wb.first(), &init, &run.texture).unwrap();
        let mean =
            |f: fn(&pav::studies::outputs::ViewScore) -> f32| scores.iter().map(f).sum::<f32>() / scores.len() as f32;
        let (before, after) = (mean(|v| v.initial), mean(|v| v.optimized));
        eprintln!(
            "{}: mean car score over {} training photos {before:.3} → {after:.3}",
            wb.first().name(),
            scores.len()
        );
        drops.push(before - after);
    }
    let [custom, preset] = drops[..] else { unreachable!() };
    assert!(preset > 0.2, "the preset's steps lowered the score by {preset}");
    assert!(custom >= 0.5 * preset, "the custom layout lowered it by {custom}, the preset by {preset}");
}
