//! The float surrogates of the int8 YOLOv8n and DEIMv2 (`pav-rig model surrogate`): every
//! quantized convolution and matrix product made float, and their car scores on FCA's real CARLA
//! photos measured against the int8 models they stand in for.

use crate::common;

use pav::dataset::fca::CarlaSample;
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav_onnx::proto::Model;
use pav_onnx::surrogate::{dequantize, SurrogateError};

fn best_car(det: &mut OnnxDetector, s: &CarlaSample) -> f32 {
    det.propose(&s.image).unwrap().best(det.target_classes()).map(|b| b.score).unwrap_or(0.0)
}

/// The surrogate `float` of the model `cfg` names, scored against it on FCA's 11 photos: mean and
/// worst |Δ best car score|, and the photos where they disagree at 0.5.
fn distance(
    shared: &std::path::Path,
    cfg: &DetectorConfig,
    float: &Model,
) -> (f32, f32, Vec<(std::path::PathBuf, f32, f32)>) {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("float.onnx");
    std::fs::write(&path, float.to_bytes()).unwrap();
    let mut q = OnnxDetector::new(cfg.clone(), 1).unwrap();
    let mut f = OnnxDetector::new(DetectorConfig { model: path, ..cfg.clone() }, 1).unwrap();
    let (mut worst, mut sum, mut n, mut disagree) = (0f32, 0f32, 0, Vec::new());
    for (npz, _) in common::reference_labels(shared) {
        let s = CarlaSample::load(&npz).unwrap();
        let (a, b) = (best_car(&mut q, &s), best_car(&mut f, &s));
        let d = (a - b).abs();
        eprintln!("{} {}: int8 {a:.3}, surrogate {b:.3}", cfg.name, npz.file_name().unwrap().to_string_lossy());
        worst = worst.max(d);
        sum += d;
        n += 1;
        if (a >= 0.5) != (b >= 0.5) {
            disagree.push((npz, a, b));
        }
    }
    assert!(n >= 11, "{n} photos");
    eprintln!(
        "{} surrogate vs int8 over {n} photos: mean |Δ car score| {:.4}, worst {worst:.4}",
        cfg.name,
        sum / n as f32
    );
    (sum / n as f32, worst, disagree)
}

#[test]
fn the_yolov8n_and_deimv2_surrogates_are_float_and_score_like_their_int8_models() {
    let shared = common::real_data();
    let cfg = DetectorConfig::load(&common::detector_config("yolov8n_int8")).unwrap();
    let int8 = Model::from_bytes(&std::fs::read(&cfg.model).unwrap()).unwrap();
    let (float, report) = dequantize(&int8).unwrap();
    // 64 ConvInteger chains; 59 input quantizers, 64 casts, 64 rescales, 64 scale products, and 63
    // bias Adds with their Reshapes go (the box decoder's convolution has no bias).
    assert_eq!((report.convs, report.nodes_removed), (64, 377));
    let integer = ["ConvInteger", "DynamicQuantizeLinear", "Cast"];
    assert_eq!(float.nodes.iter().filter(|n| n.op_type == "Conv" && n.inputs.len() == 3).count(), 63);
    assert!(float.nodes.iter().all(|n| !integer.contains(&n.op_type.as_str())));
    assert_eq!(float.nodes.iter().filter(|n| n.op_type == "Conv").count(), 64);
    let (mean, worst, disagree) = distance(&shared, &cfg, &float);
    // Measured on this machine: mean 0.0027, worst 0.011 over the 11 photos. Rounding every
    // activation to 8 bits is what the surrogate leaves out; a wrong weight layout, zero point or
    // scale puts the scores nowhere near the int8 model's. The margin allows for int8 kernels
    // that differ between ONNX Runtime builds and CPUs (see tests/it/detectors_reference.rs).
    assert!(mean < 0.01 && worst < 0.04, "mean {mean} worst {worst}");
    assert!(disagree.is_empty(), "{disagree:?}");

    // DEIMv2 (int8 DETR): its quantized products are MatMulIntegers (two read a transposed
    // quantized input, in the decoder's self-attention), besides ConvIntegers.
    let dcfg = DetectorConfig::load(&common::detector_config("deimv2_atto_int8")).unwrap();
    let deim = Model::from_bytes(&std::fs::read(&dcfg.model).unwrap()).unwrap();
    let count = |m: &Model, op: &str| m.nodes.iter().filter(|n| n.op_type == op).count();
    assert!(count(&deim, "GridSample") == 6 && count(&deim, "Constant") > 0);
    let constant = deim.nodes.iter().find(|n| n.op_type == "Constant").unwrap().clone();
    let again = Model::from_bytes(&Model { nodes: vec![constant.clone()], ..deim.clone() }.to_bytes()).unwrap();
    assert_eq!(
        format!("{:?}", again.nodes[0].attrs),
        format!("{:?}", constant.attrs),
        "a Constant's tensor reads back"
    );
    let (dfloat, report) = dequantize(&deim).unwrap();
    assert_eq!((report.convs, report.matmuls), (count(&deim, "ConvInteger"), count(&deim, "MatMulInteger")));
    assert_eq!((report.convs, report.matmuls), (57, 40));
    let quantized = ["ConvInteger", "MatMulInteger", "DynamicQuantizeLinear"];
    assert!(dfloat.nodes.iter().all(|n| !quantized.contains(&n.op_type.as_str())));
    assert_eq!(count(&dfloat, "MatMul"), count(&deim, "MatMul") + 40);
    let (mean, worst, disagree) = distance(&shared, &dcfg, &dfloat);
    // Measured on this machine: mean 0.060, worst 0.19, one photo on either side of 0.5 (int8
    // 0.622, float 0.435). The weights are exact: ONNX Runtime's own `quantize_dynamic` of this
    // surrogate gives back the int8 model's scores to the bit (docs/method.md). What differs is the 8-bit
    // rounding of every activation, which moves a DETR more than a YOLO: its queries are picked
    // by a TopK over rounded encoder scores. Wrong weights would leave the car near 0.
    assert!(mean < 0.1 && worst < 0.3, "DEIMv2: mean {mean} worst {worst}");
    assert!(disagree.len() <= 2, "DEIMv2: {disagree:?}");

    // A graph whose quantized convolution is fed by anything but a quantizer is refused by name.
    let mut broken = int8.clone();
    let ci = broken.nodes.iter().position(|n| n.op_type == "ConvInteger").unwrap();
    broken.nodes[ci].inputs[0] = "images".into();
    let name = broken.nodes[ci].name.clone();
    match dequantize(&broken) {
        Err(SurrogateError::Pattern { op, node, why }) => {
            assert!(op == "ConvInteger" && node == name && why.contains("DynamicQuantizeLinear"))
        }
        other => panic!("{:?}", other.map(|r| r.1)),
    }
}

/// Runs `m` on one 320² image (and the size input, where it has one) and returns every output as f32.
fn run(m: &Model, x: &[f32]) -> Vec<Vec<f32>> {
    use ort::value::Tensor;
    let mut s = ort::session::Session::builder(pav_onnx::runtime::runtime().unwrap())
        .unwrap()
        .commit_from_memory(&m.to_bytes())
        .unwrap();
    let image = Tensor::from_array((vec![1usize, 3, 320, 320], x.to_vec())).unwrap().into_dyn();
    let size = Tensor::from_array((vec![1usize, 2], vec![320i64, 320])).unwrap().into_dyn();
    let mut feed = vec![("images".to_string(), image)];
    if m.inputs.iter().any(|i| i.name == "orig_target_sizes") {
        feed.push(("orig_target_sizes".to_string(), size));
    }
    let outs = s.run(feed).unwrap();
    m.outputs.iter().map(|o| outs[o.name.as_str()].try_extract_tensor::<f32>().unwrap().1.to_vec()).collect()
}

#[test]
fn the_deimv2_surrogate_folds_to_its_data_path_with_the_same_outputs() {
    use pav_onnx::fold::fold_shapes;
    use pav_onnx::proto::{ValueInfo, FLOAT};
    let shared = common::real_data();
    let cfg = DetectorConfig::load(&common::detector_config("deimv2_atto_int8")).unwrap();
    let (mut float, _) = dequantize(&Model::from_bytes(&std::fs::read(&cfg.model).unwrap()).unwrap()).unwrap();
    // The last decoder layer's class logits and boxes, before the post-processor's TopK.
    float.outputs = ["/decoder/Gather_5_output_0", "/decoder/Gather_6_output_0"]
        .map(|n| ValueInfo { name: n.into(), elem_type: FLOAT, dims: vec![] })
        .to_vec();
    float.prune();
    let sizes = [("images", vec![1, 3, 320, 320]), ("orig_target_sizes", vec![1, 2])];
    let (folded, report) = fold_shapes(&float, &sizes, "deimv2").unwrap();
    let count = |m: &Model, op: &str| m.nodes.iter().filter(|n| n.op_type == op).count();
    eprintln!(
        "DEIMv2 surrogate: {} nodes → {} after folding {} values ({} removed); Shape {} → {}",
        float.nodes.len(),
        folded.nodes.len(),
        report.folded,
        report.nodes_removed,
        count(&float, "Shape"),
        count(&folded, "Shape")
    );
    let mut ops: Vec<String> = folded.nodes.iter().map(|n| n.op_type.clone()).collect();
    ops.sort();
    ops.dedup();
    eprintln!("operators on the data path: {}", ops.join(", "));
    for op in ["Shape", "Constant", "ConstantOfShape"] {
        assert_eq!(count(&folded, op), 0, "{op} left");
    }
    assert!(count(&float, "Shape") > 0 && report.folded > 0);
    assert_eq!(folded.nodes.len() + report.nodes_removed, float.nodes.len());
    // The same numbers on a real photo: folding only replaced values by what they always are.
    let s = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12509.npz")).unwrap();
    let (x, _) = pav::detect::preprocess::prepare(&s.image, &cfg.input).unwrap();
    let (a, b) = (run(&float, &x), run(&folded, &x));
    assert_eq!(a[0].len(), b[0].len());
    let worst = a.iter().flatten().zip(b.iter().flatten()).map(|(p, q)| (p - q).abs()).fold(0f32, f32::max);
    eprintln!("logits {} values, boxes {}; worst |Δ| {worst:e}", a[0].len(), a[1].len());
    // Measured: 7e-5 (ONNX Runtime fuses the folded graph differently); logits reach ±10.
    assert!(worst < 1e-3, "{worst}");
    // The post-processor's size input is read by nothing once the graph is cut: it goes. An input
    // that is read but given no size is refused by name.
    assert_eq!(folded.inputs.iter().map(|i| i.name.as_str()).collect::<Vec<_>>(), ["images"]);
    let e = fold_shapes(&float, &sizes[1..], "deimv2").unwrap_err().to_string();
    assert!(e.contains("images"), "{e}");
}

/// DEIMv2's float surrogate cut at `outputs`, shapes folded at 320², and the query selection
/// frozen at `x` when the cut lies after it.
fn deim_cut(outputs: &[&str], x: &[f32]) -> Model {
    use pav_onnx::fold::fold_shapes;
    use pav_onnx::proto::{InitData, Initializer, ValueInfo, FLOAT};
    let cfg = DetectorConfig::load(&common::detector_config("deimv2_atto_int8")).unwrap();
    let (mut float, _) = dequantize(&Model::from_bytes(&std::fs::read(&cfg.model).unwrap()).unwrap()).unwrap();
    float.outputs = outputs.iter().map(|n| ValueInfo { name: n.to_string(), elem_type: FLOAT, dims: vec![] }).collect();
    float.prune();
    let sizes = [("images", vec![1, 3, 320, 320]), ("orig_target_sizes", vec![1, 2])];
    let (mut folded, _) = fold_shapes(&float, &sizes, "deimv2").unwrap();
    // The 100 queries the encoder picks (a TopK over its scores) are piecewise constant in the
    // image: differences across a change of the picked set measure a jump, not a slope. They are
    // frozen at this image for the check (the gradient is the same with them live).
    let picked = "/decoder/TopK_output_1";
    if !folded.nodes.iter().any(|n| n.outputs.iter().any(|o| o == picked)) {
        return folded;
    }
    let mut probe = folded.clone();
    probe.outputs = vec![ValueInfo { name: picked.into(), elem_type: 0, dims: vec![] }];
    let mut sess = ort::session::Session::builder(pav_onnx::runtime::runtime().unwrap())
        .unwrap()
        .commit_from_memory(&probe.to_bytes())
        .unwrap();
    let image = ort::value::Tensor::from_array((vec![1usize, 3, 320, 320], x.to_vec())).unwrap().into_dyn();
    let outs = sess.run(vec![("images".to_string(), image)]).unwrap();
    let (dims, idx) = outs[0].try_extract_tensor::<i64>().unwrap();
    let frozen = Initializer { name: "frozen_queries".into(), dims: dims.to_vec(), data: InitData::I64(idx.to_vec()) };
    drop(outs);
    for n in &mut folded.nodes {
        n.inputs.iter_mut().filter(|i| *i == picked).for_each(|i| *i = frozen.name.clone());
    }
    folded.initializers.push(frozen);
    fold_shapes(&folded, &sizes, "deimv2").unwrap().0
}

#[test]
fn the_deimv2_surrogate_differentiates_and_its_input_gradient_matches_differences() {
    use pav_onnx::autodiff::{differentiate_with, Kernels};
    use pav_onnx::session::GradSession;
    let shared = common::real_data();
    let cfg = DetectorConfig::load(&common::detector_config("deimv2_atto_int8")).unwrap();
    let s = CarlaSample::load(&shared.join("fca/carla_dataset/test/data12509.npz")).unwrap();
    let (x, _) = pav::detect::preprocess::prepare(&s.image, &cfg.input).unwrap();
    // The last decoder layer's class logits of the 100 queries, as the DETR loss reads them.
    let m = deim_cut(&["/decoder/Gather_5_output_0"], &x);
    let d = differentiate_with(&m, &[1, 3, 320, 320], Kernels::Onnx).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("DEIMv2 surrogate: forward {} nodes, backward {} nodes", d.forward.nodes.len(), d.backward.nodes.len());
    let mut g = GradSession::new("deimv2", d, 0).unwrap();
    let (outs, pass) = g.forward(x.clone()).unwrap();
    let reference = run(&m, &x);
    let worst = outs[0].iter().zip(&reference[0]).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(worst < 1e-3, "forward graph vs the model: {worst}");
    let w: Vec<f32> = (0..outs[0].len()).map(|i| ((i * 7919) % 1000) as f32 / 1000.0 - 0.5).collect();
    let loss = |o: &[Vec<f32>]| o[0].iter().zip(&w).map(|(a, b)| *a as f64 * *b as f64).sum::<f64>();
    let grad = g.backward(&pass, vec![w.clone()]).unwrap();
    // Slopes along random directions over a 24² patch on the car, against differences: a
    // least-squares slope through ±ε for ε ≤ 1e-4, since f32 rounding dominates one small step and
    // ReLU kinks one large step.
    let mut r = pav::rng::Rng::new(7);
    let (mut dot, mut nn, mut ff) = (0f64, 0f64, 0f64);
    for k in 0..6 {
        let dir: Vec<f32> = (0..x.len())
            .map(|i| {
                let (yy, xx) = ((i % (320 * 320)) / 320, i % 320);
                if (148..172).contains(&yy) && (148..172).contains(&xx) {
                    r.uniform(-1.0, 1.0)
                } else {
                    0.0
                }
            })
            .collect();
        let along: f64 = grad.iter().zip(&dir).map(|(a, b)| *a as f64 * *b as f64).sum();
        let (mut num, mut den) = (0f64, 0f64);
        for e in [1e-4f32, 7.5e-5, 5e-5, 2.5e-5] {
            for sgn in [1.0f32, -1.0] {
                let (o, _) = g.forward(x.iter().zip(&dir).map(|(a, b)| a + sgn * e * b).collect()).unwrap();
                num += (sgn * e) as f64 * (loss(&o) - loss(&outs));
                den += (e as f64).powi(2);
            }
        }
        let fd = num / den;
        eprintln!("direction {k}: gradient {along:.3}, differences {fd:.3}");
        (dot, nn, ff) = (dot + along * fd, nn + along * along, ff + fd * fd);
    }
    let cosine = dot / (nn.sqrt() * ff.sqrt());
    eprintln!("cosine between gradient and differences over 6 directions: {cosine:.4}");
    assert!(cosine > 0.95, "{cosine}");
}
