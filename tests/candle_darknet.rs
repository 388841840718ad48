//! The differentiable YOLOv3-tiny (candle) is the evaluation model: same raw heads as the ONNX
//! export under ONNX Runtime on a real image, and input gradients that match finite differences.
#![cfg(feature = "optimize")]

mod common;

use candle_core::{DType, Device, Tensor, Var};
use pav::dataset::fca::CarlaSample;
use pav::detect::candle_darknet::CandleDarknet;
use pav::detect::darknet::{Network, Weights};
use pav::detect::onnx::OnnxDetector;
use pav::detect::preprocess::prepare;
use pav::detect::DetectorConfig;

fn model(dtype: DType) -> CandleDarknet {
    let dir = common::repo().join(".deps/models/yolov3-tiny");
    let net = Network::from_file(&dir.join("yolov3-tiny.cfg")).unwrap();
    let w = Weights::from_file(&dir.join("yolov3-tiny.weights"), &net).unwrap();
    CandleDarknet::new(net, &w, &Device::Cpu, dtype).unwrap()
}

#[test]
fn candle_heads_match_onnx_runtime() {
    let Some(shared) = common::real_data() else { return };
    let cfg = DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap();
    let sample = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12503.npz")).unwrap();
    let (input, _) = prepare(&sample.image, &cfg.input);
    let mut ort = OnnxDetector::new(cfg, 1).unwrap();
    let raw = ort.infer(input.clone()).unwrap();
    let x = Tensor::from_vec(input, (1, 3, 416, 416), &Device::Cpu).unwrap();
    let heads = model(DType::F32).forward(&x).unwrap();
    for (k, h) in heads.iter().enumerate() {
        let ours: Vec<f32> = h.flatten_all().unwrap().to_vec1().unwrap();
        let theirs = &raw.iter().find(|o| o.name == format!("head{k}")).unwrap().data;
        assert_eq!(ours.len(), theirs.len());
        let worst = ours.iter().zip(theirs).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        eprintln!("head{k}: max |candle - ORT| = {worst:e}");
        assert!(worst < 1e-4, "head{k}: {worst}");
    }
}

#[test]
fn input_gradient_matches_central_differences() {
    if common::real_data().is_none() {
        return;
    }
    let m = model(DType::F64);
    // A smooth 64×64 input (small, so f64 finite differences stay quick); tiny noise breaks
    // max-pool ties, where the function is not differentiable.
    let n = 64usize;
    let data: Vec<f64> = (0..3 * n * n)
        .map(|i| {
            let (c, y, x) = (i / (n * n), (i / n) % n, i % n);
            0.5 + 0.3 * ((x as f64 * 0.21 + c as f64).sin() * (y as f64 * 0.17).cos())
                + 1e-4 * ((i * 7919 % 101) as f64 / 101.0)
        })
        .collect();
    let loss_of = |x: &Tensor| -> Tensor {
        let heads = m.forward(x).unwrap();
        // Sum of objectness logits of all anchors of head 0 plus the car logit of head 1.
        let h0 = heads[0].narrow(1, 4, 1).unwrap().sum_all().unwrap();
        let h1 = heads[1].narrow(1, 5 + 2, 1).unwrap().sum_all().unwrap();
        (h0 + h1).unwrap()
    };
    let var = Var::from_tensor(&Tensor::from_vec(data.clone(), (1, 3, n, n), &Device::Cpu).unwrap()).unwrap();
    let grads = loss_of(var.as_tensor()).backward().unwrap();
    let g: Vec<f64> = grads.get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap();
    let eps = 1e-5;
    for &i in &[5usize, 777, 2048, 3 * n * n - 9, 9000] {
        let f = |d: f64| {
            let mut v = data.clone();
            v[i] += d;
            loss_of(&Tensor::from_vec(v, (1, 3, n, n), &Device::Cpu).unwrap()).to_scalar::<f64>().unwrap()
        };
        let fd = (f(eps) - f(-eps)) / (2.0 * eps);
        eprintln!("pixel {i}: backward {:.6e}, central difference {fd:.6e}", g[i]);
        assert!((fd - g[i]).abs() <= 1e-5 * (1.0 + fd.abs()), "pixel {i}: {} vs {fd}", g[i]);
    }
}

#[test]
fn frozen_conv_backward_equals_stock_backward() {
    if common::real_data().is_none() {
        return;
    }
    let n = 96usize;
    let data: Vec<f64> = (0..3 * n * n).map(|i| ((i * 2654435761usize) % 1000) as f64 / 1000.0).collect();
    let grad = |m: &CandleDarknet| -> Vec<f64> {
        let var = Var::from_tensor(&Tensor::from_vec(data.clone(), (1, 3, n, n), &Device::Cpu).unwrap()).unwrap();
        let heads = m.forward(var.as_tensor()).unwrap();
        let l = (heads[0].sqr().unwrap().sum_all().unwrap() + heads[1].sum_all().unwrap()).unwrap();
        l.backward().unwrap().get(var.as_tensor()).unwrap().flatten_all().unwrap().to_vec1().unwrap()
    };
    let (frozen, stock) = (grad(&model(DType::F64)), grad(&model(DType::F64).with_stock_conv()));
    let scale = stock.iter().fold(0f64, |a, v| a.max(v.abs()));
    let worst = frozen.iter().zip(&stock).map(|(a, b)| (a - b).abs()).fold(0f64, f64::max);
    eprintln!("max |frozen - stock| = {worst:e} (gradient scale {scale:e})");
    assert!(scale > 0.0 && worst <= 1e-10 * scale, "{worst} vs scale {scale}");
}
