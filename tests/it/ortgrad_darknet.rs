//! YOLOv3-tiny's input gradient as ONNX graphs on ONNX Runtime (`detect::autodiff`,
//! `detect::ortgrad`): its forward is the evaluation model (the same heads as plain inference of
//! the exported ONNX), and its gradient matches central differences of an independent f64
//! implementation of the network.

use crate::common;

use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::prepare;
use pav::detect::DetectorConfig;
use pav_onnx::autodiff::{differentiate_with, Kernels};
use pav_onnx::darknet::cfg::DarknetActivation;
use pav_onnx::darknet::{to_onnx, Layer, Network, Weights};
use pav_onnx::session::GradSession;

fn session(size: usize) -> GradSession {
    session_with(size, Kernels::Fused)
}

fn session_with(size: usize, kernels: Kernels) -> GradSession {
    common::require_setup();
    let dir = common::repo().join(".deps/models/yolov3-tiny");
    let net = Network::from_file(&dir.join("yolov3-tiny.cfg")).unwrap();
    let w = Weights::from_file(&dir.join("yolov3-tiny.weights"), &net).unwrap();
    let model = to_onnx::export(&net, &w).unwrap();
    let d = differentiate_with(&model, &[1, 3, size as i64, size as i64], kernels).unwrap();
    GradSession::new("yolov3-tiny", d, 1).unwrap()
}

/// A smooth `n × n` test image with a little noise that breaks max-pool ties.
fn smooth(n: usize) -> Vec<f32> {
    (0..3 * n * n)
        .map(|i| {
            let (c, y, x) = (i / (n * n), (i / n) % n, i % n);
            (0.5 + 0.3 * ((x as f64 * 0.21 + c as f64).sin() * (y as f64 * 0.17).cos())
                + 1e-3 * ((i * 7919 % 101) as f64 / 101.0)) as f32
        })
        .collect()
}

/// Fixed pseudo-random weights in [−1, 1].
fn weights(n: usize, seed: usize) -> Vec<f32> {
    (0..n).map(|i| (((i * 2654435761 + seed * 97) % 2001) as f32 / 1000.0) - 1.0).collect()
}

#[test]
fn forward_heads_equal_plain_inference() {
    let shared = common::real_data();
    let cfg = DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap();
    let sample = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12503.npz")).unwrap();
    let (input, map) = prepare(&sample.image, &cfg.input).unwrap();
    let raw = OnnxDetector::new(cfg, 1).unwrap().infer(input.clone(), &map).unwrap();
    let mut g = session(416);
    let (heads, _) = g.forward(input).unwrap();
    for (k, h) in heads.iter().enumerate() {
        let theirs = &raw.iter().find(|o| o.name == format!("head{k}")).unwrap().data;
        assert_eq!(h.len(), theirs.len());
        let worst = h.iter().zip(theirs).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        eprintln!("head{k}: max |gradient graph − inference| = {worst:e}");
        assert!(worst < 1e-4, "head{k}: {worst}");
    }
}

/// YOLOv3-tiny in plain f64 from the darknet layers: an independent reference for finite
/// differences (ONNX Runtime's kernels are f32 only). Returns the head maps, flattened.
fn reference_heads(net: &Network, w: &Weights, x: &[f64], n: usize) -> Vec<Vec<f64>> {
    // Each layer's output as (channels, height, width, values).
    let mut outs: Vec<(usize, usize, usize, Vec<f64>)> = Vec::new();
    let mut heads = Vec::new();
    let mut convs = w.convs.iter();
    for layer in &net.layers {
        let (c, h, wd, v) = outs.last().cloned().unwrap_or((3, n, n, x.to_vec()));
        let y = match layer {
            Layer::Conv { size, stride, pad, activation, .. } => {
                let cw = convs.next().unwrap();
                let [m, ci, k, _] = cw.shape;
                assert_eq!(ci, c);
                let (oh, ow) = ((h + 2 * pad - size) / stride + 1, (wd + 2 * pad - size) / stride + 1);
                let mut y = vec![0f64; m * oh * ow];
                for mo in 0..m {
                    for oy in 0..oh {
                        for ox in 0..ow {
                            let mut acc = cw.bias[mo] as f64;
                            for cc in 0..c {
                                for ky in 0..k {
                                    for kx in 0..k {
                                        let (iy, ix) = (
                                            (oy * stride + ky) as i64 - *pad as i64,
                                            (ox * stride + kx) as i64 - *pad as i64,
                                        );
                                        if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < wd {
                                            acc += cw.weight[((mo * c + cc) * k + ky) * k + kx] as f64
                                                * v[(cc * h + iy as usize) * wd + ix as usize];
                                        }
                                    }
                                }
                            }
                            y[(mo * oh + oy) * ow + ox] =
                                if *activation == DarknetActivation::Leaky && acc < 0.0 { 0.1 * acc } else { acc };
                        }
                    }
                }
                (m, oh, ow, y)
            }
            Layer::MaxPool { size, stride } => {
                // Darknet pads size − 1 in total (the smaller half before) with values that never win.
                let lo = (size - 1) / 2;
                let (oh, ow) = ((h + size - 1 - size) / stride + 1, (wd + size - 1 - size) / stride + 1);
                let mut y = vec![f64::MIN; c * oh * ow];
                for cc in 0..c {
                    for oy in 0..oh {
                        for ox in 0..ow {
                            for ky in 0..*size {
                                for kx in 0..*size {
                                    let (iy, ix) =
                                        ((oy * stride + ky) as i64 - lo as i64, (ox * stride + kx) as i64 - lo as i64);
                                    if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < wd {
                                        let o = &mut y[(cc * oh + oy) * ow + ox];
                                        *o = o.max(v[(cc * h + iy as usize) * wd + ix as usize]);
                                    }
                                }
                            }
                        }
                    }
                }
                (c, oh, ow, y)
            }
            Layer::Upsample { stride } => {
                let (oh, ow) = (h * stride, wd * stride);
                let y = (0..c * oh * ow).map(|i| {
                    let (cc, oy, ox) = (i / (oh * ow), (i / ow) % oh, i % ow);
                    v[(cc * h + oy / stride) * wd + ox / stride]
                });
                (c, oh, ow, y.collect())
            }
            Layer::Route { layers } => {
                let (_, rh, rw, _) = outs[layers[0]];
                let mut y = Vec::new();
                let mut ch = 0;
                for &l in layers {
                    y.extend_from_slice(&outs[l].3);
                    ch += outs[l].0;
                }
                (ch, rh, rw, y)
            }
            Layer::Yolo(_) => {
                heads.push(v.clone());
                (c, h, wd, v)
            }
        };
        outs.push(y);
    }
    heads
}

#[test]
fn input_gradient_matches_central_differences_of_an_f64_reference() {
    common::require_setup();
    let n = 64;
    let dir = common::repo().join(".deps/models/yolov3-tiny");
    let net = Network::from_file(&dir.join("yolov3-tiny.cfg")).unwrap();
    let wts = Weights::from_file(&dir.join("yolov3-tiny.weights"), &net).unwrap();
    for kernels in [Kernels::Onnx, Kernels::Fused] {
        check_against_reference(n, &net, &wts, kernels);
    }
}

fn check_against_reference(n: usize, net: &Network, wts: &Weights, kernels: Kernels) {
    let mut g = session_with(n, kernels);
    let x = smooth(n);
    let xd: Vec<f64> = x.iter().map(|v| *v as f64).collect();
    let (heads, pass) = g.forward(x.clone()).unwrap();
    // The reference is the same network: its heads agree with the graph's to f32 precision.
    let refs = reference_heads(net, wts, &xd, n);
    for (a, b) in heads.iter().zip(&refs) {
        let worst = a.iter().zip(b).map(|(a, b)| (*a as f64 - b).abs()).fold(0f64, f64::max);
        assert!(worst < 1e-3, "reference heads differ by {worst}");
    }
    let w: Vec<Vec<f32>> = heads.iter().enumerate().map(|(k, h)| weights(h.len(), k)).collect();
    let grad = g.backward(&pass, w.clone()).unwrap();
    let loss = |x: &[f64]| -> f64 {
        reference_heads(net, wts, x, n)
            .iter()
            .zip(&w)
            .map(|(h, w)| h.iter().zip(w).map(|(a, b)| a * *b as f64).sum::<f64>())
            .sum()
    };
    let eps = 1e-6;
    for &i in &[5usize, 777, 2048, 3 * n * n - 9, 9000] {
        let at = |d: f64| {
            let mut v = xd.clone();
            v[i] += d;
            loss(&v)
        };
        let fd = (at(eps) - at(-eps)) / (2.0 * eps);
        eprintln!("{kernels:?}, pixel {i}: gradient graph {:.6e}, central difference {fd:.6e}", grad[i]);
        assert!((fd - grad[i] as f64).abs() <= 1e-4 * (1.0 + fd.abs()), "{kernels:?}, pixel {i}: {} vs {fd}", grad[i]);
    }
}
