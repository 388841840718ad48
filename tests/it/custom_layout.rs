//! Output layouts written out as descriptions (`layout = "custom"`), run through ONNX Runtime:
//! - anchor-based rows flattened into one matrix with their values already decoded (YOLOv5's
//!   export writes them so): the real YOLOv3-tiny with that decoding appended to its graph gives
//!   the darknet preset's proposals on real images;
//! - SSD-style separate box and score tensors over prior boxes: a small graph built here with
//!   known outputs;
//! - a description that does not fit its model is refused when the model loads, naming the
//!   model's outputs;
//! - `model inspect` guesses both as `custom` and writes skeletons that load once completed;
//! - the forms other exports take: values the graph already activated (for the encoding too),
//!   several anchors side by side in one row with a shared class block, scores as a product of
//!   powers, centre offsets through tanh with sizes as shares of the input, and outputs without
//!   a batch dimension, each from a graph built here with known outputs;
//! - every `custom` layout docs/detectors.md shows loads as written.

use crate::common;

use pav::detect::inspect::Inspection;
use pav::detect::onnx::OnnxDetector;
use pav::detect::{Detector, DetectorConfig};
use pav_onnx::proto::{Attr, Initializer, Model, Node, ValueInfo};
use std::path::{Path, PathBuf};

/// YOLOv3-tiny's heads in config order (name, grid side, anchors).
const HEADS: [(&str, usize, [[f32; 2]; 3]); 2] = [
    ("head0", 13, [[81.0, 82.0], [135.0, 169.0], [344.0, 319.0]]),
    ("head1", 26, [[10.0, 14.0], [23.0, 27.0], [37.0, 58.0]]),
];

/// YOLOv3-tiny with its heads decoded in the graph and flattened to `[1, 2535, 85]` rows
/// (cx, cy, w, h in input pixels, objectness, class probabilities), anchor by anchor.
pub(crate) fn flattened_yolov3_tiny(out: &Path) -> PathBuf {
    let src = common::repo().join(".deps/models/yolov3-tiny/yolov3-tiny.onnx");
    let mut m = Model::from_bytes(&std::fs::read(src).unwrap()).unwrap();
    let f = 85;
    let mut parts = Vec::new();
    m.initializers.push(Initializer::f32("cap", &[], vec![30.0]));
    for (head, g, anchors) in HEADS {
        let (rows, stride) = (3 * g * g, 416.0 / g as f32);
        let v = |s: &str| format!("{head}_{s}");
        // Per value: sigmoid(x)·m1 + b1 + exp(min(x, 30))·m2.
        let (mut m1, mut b1, mut m2) = (vec![0f32; rows * f], vec![0f32; rows * f], vec![0f32; rows * f]);
        for r in 0..rows {
            let (a, cell) = (r / (g * g), r % (g * g));
            let at = r * f;
            m1[at] = stride;
            m1[at + 1] = stride;
            b1[at] = (cell % g) as f32 * stride;
            b1[at + 1] = (cell / g) as f32 * stride;
            m2[at + 2] = anchors[a][0];
            m2[at + 3] = anchors[a][1];
            m1[at + 4..at + f].fill(1.0);
        }
        let dims = [1, rows as i64, f as i64];
        m.initializers.extend([
            Initializer::i64(&v("s1"), &[4], vec![1, 3, f as i64, (g * g) as i64]),
            Initializer::i64(&v("s2"), &[3], dims.to_vec()),
            Initializer::f32(&v("m1"), &dims, m1),
            Initializer::f32(&v("b1"), &dims, b1),
            Initializer::f32(&v("m2"), &dims, m2),
        ]);
        m.nodes.extend([
            Node::new("Reshape", &[head, &v("s1")], &[&v("r1")]),
            Node::new("Transpose", &[&v("r1")], &[&v("t")]).attr("perm", Attr::Ints(vec![0, 1, 3, 2])),
            Node::new("Reshape", &[&v("t"), &v("s2")], &[&v("x")]),
            Node::new("Sigmoid", &[&v("x")], &[&v("sig")]),
            Node::new("Min", &[&v("x"), "cap"], &[&v("xc")]),
            Node::new("Exp", &[&v("xc")], &[&v("e")]),
            Node::new("Mul", &[&v("sig"), &v("m1")], &[&v("a")]),
            Node::new("Add", &[&v("a"), &v("b1")], &[&v("ab")]),
            Node::new("Mul", &[&v("e"), &v("m2")], &[&v("c")]),
            Node::new("Add", &[&v("ab"), &v("c")], &[&v("rows")]),
        ]);
        parts.push(v("rows"));
    }
    let parts: Vec<&str> = parts.iter().map(String::as_str).collect();
    m.nodes.push(Node::new("Concat", &parts, &["output"]).attr("axis", Attr::Int(1)));
    m.outputs = vec![ValueInfo::f32("output", &[1, 2535, f as i64])];
    let path = out.join("yolov3-tiny-flat.onnx");
    std::fs::write(&path, m.to_bytes()).unwrap();
    path
}

/// A config as YOLOv3-tiny's shipped one with another model and `[output]`.
pub(crate) fn config_like_yolov3_tiny(dir: &Path, model: &Path, output: &str) -> DetectorConfig {
    let shipped = std::fs::read_to_string(common::detector_config("yolov3-tiny")).unwrap();
    let input = &shipped[shipped.find("[input]").unwrap()..shipped.find("[output]").unwrap()];
    let names = common::repo().join(".deps/models/yolov3-tiny/coco.names");
    let body = format!(
        "name = \"flat\"\nmodel = \"{}\"\n{input}{output}\n[classes]\nnames = \"{}\"\ntarget = [\"car\"]\n",
        model.display(),
        names.display()
    );
    let path = dir.join("flat.toml");
    std::fs::write(&path, body).unwrap();
    DetectorConfig::load(&path).unwrap()
}

pub(crate) const FLAT: &str = "[output]\nlayout = \"custom\"\n[[output.levels]]\nstride = 32\nanchors = [[81, 82], [135, 169], [344, 319]]\n[[output.levels]]\nstride = 16\nanchors = [[10, 14], [23, 27], [37, 58]]\n[output.boxes]\nencoding = \"cxcywh\"\n[output.objectness]\ncolumn = 4\n[output.scores]\ncolumn = 5\n";

#[test]
fn flattened_anchor_rows_of_a_real_model_give_the_darknet_heads_proposals() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let model = flattened_yolov3_tiny(tmp.path());
    let mut flat = OnnxDetector::new(config_like_yolov3_tiny(tmp.path(), &model, FLAT), 1).unwrap();
    let mut dark =
        OnnxDetector::new(DetectorConfig::load(&common::detector_config("yolov3-tiny")).unwrap(), 1).unwrap();
    let mut found = 0;
    for label in ["data1.npz", "data12501.npz", "data12505.npz", "turntable.mp4#0", "turntable.mp4#20"] {
        let frame = common::reference_image(label);
        let (a, b) = (flat.propose(&frame).unwrap(), dark.propose(&frame).unwrap());
        assert_eq!((a.len(), a.num_classes), (2535, 80));
        assert_eq!(b.len(), 2535);
        let (mut worst_box, mut worst_score) = (0f32, 0f32);
        for i in 0..a.len() {
            worst_box = a.boxes[i].iter().zip(b.boxes[i]).map(|(x, y)| (x - y).abs()).fold(worst_box, f32::max);
            worst_score = a.row(i).iter().zip(b.row(i)).map(|(x, y)| (x - y).abs()).fold(worst_score, f32::max);
        }
        let (ta, tb) = (a.best(&[2]).unwrap(), b.best(&[2]).unwrap());
        eprintln!(
            "{label}: best car {:.4} vs {:.4}; worst box {worst_box:e} px, score {worst_score:e}",
            ta.score, tb.score
        );
        assert!(
            worst_box < 5e-3 && worst_score < 1e-5,
            "{label}: boxes differ by {worst_box} px, scores by {worst_score}"
        );
        found += usize::from(ta.score >= 0.5);
    }
    // Not vacuous: the car is found in some of them.
    assert!(found >= 2, "the car was found in {found} images");
    // The same rows described with two anchors per level do not fit and are refused at load,
    // with the model's actual output.
    let two = FLAT.replace(", [344, 319]", "").replace(", [37, 58]", "");
    let e = OnnxDetector::new(config_like_yolov3_tiny(tmp.path(), &model, &two), 1).err().unwrap().to_string();
    assert!(e.contains("[1690, 85]") && e.contains("`output` [1, 2535, 85]"), "{e}");
}

/// A graph of input `images` [1, 3, 32, 32] whose outputs are the given constants.
fn constant_model(dir: &Path, outputs: &[(&str, Vec<i64>, Vec<f32>)]) -> PathBuf {
    let mut nodes = vec![
        Node::new("ReduceMean", &["images"], &["mean"]).attr("keepdims", Attr::Int(0)),
        Node::new("Mul", &["mean", "zero"], &["nothing"]),
    ];
    let mut inits = vec![Initializer::f32("zero", &[], vec![0.0])];
    let mut outs = Vec::new();
    for (name, dims, values) in outputs {
        let c = format!("{name}_value");
        inits.push(Initializer::f32(&c, dims, values.clone()));
        nodes.push(Node::new("Add", &[&c, "nothing"], &[name]));
        outs.push(ValueInfo::f32(name, dims));
    }
    let m = Model::graph(13, nodes, inits, vec![ValueInfo::f32("images", &[1, 3, 32, 32])], outs);
    let path = dir.join("constant.onnx");
    std::fs::write(&path, m.to_bytes()).unwrap();
    path
}

fn config(dir: &Path, model: &Path, output: &str) -> Result<DetectorConfig, String> {
    let body = format!(
        "name = \"ssd\"\nmodel = \"{}\"\n[input]\nwidth = 32\nheight = 32\nchannels = \"rgb\"\nresize = \"stretch\"\n{output}\n[classes]\nnames = \"names.txt\"\ntarget = [\"car\"]\n",
        model.display()
    );
    std::fs::write(dir.join("names.txt"), "person\ncar\n").unwrap();
    let path = dir.join("ssd.toml");
    std::fs::write(&path, body).unwrap();
    DetectorConfig::load(&path).map_err(|e| e.to_string())
}

const SSD: &str = "[output]\nlayout = \"custom\"\norder = \"cell-anchor\"\n[[output.levels]]\nstride = 16\nanchors = [[10, 10], [20, 10]]\n[output.boxes]\noutput = \"boxes\"\nencoding = \"prior\"\ncoords = [1, 0, 3, 2]\nvariances = [0.1, 0.2]\n[output.scores]\noutput = \"scores\"\nactivation = \"softmax\"\nbackground = 0\n";

#[test]
fn ssd_boxes_over_priors_and_softmax_scores_from_separate_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    // Two cells by two at stride 16, two priors each, cell by cell. Row 5 (cell x 0, y 1,
    // prior 20 × 10 at (8, 24)): TensorFlow order (ty, tx, th, tw) moving it right by half its
    // width and doubling its height; scores (background, person, car) = softmax(0, 0, ln 4).
    let mut boxes = vec![0f32; 8 * 4];
    boxes[20..24].copy_from_slice(&[0.0, 0.5 / 0.1, 2f32.ln() / 0.2, 0.0]);
    let mut scores = vec![0f32; 8 * 3];
    scores[15..18].copy_from_slice(&[0.0, 0.0, 4f32.ln()]);
    let model = constant_model(tmp.path(), &[("scores", vec![1, 8, 3], scores), ("boxes", vec![1, 8, 4], boxes)]);
    let mut det = OnnxDetector::new(config(tmp.path(), &model, SSD).unwrap(), 1).unwrap();
    // A 64 × 48 frame stretched to 32²: boxes come back scaled by 2 and 1.5.
    let frame = pav::image::Frame { width: 64, height: 48, bgr: vec![90; 64 * 48 * 3] };
    let p = det.propose(&frame).unwrap();
    assert_eq!((p.len(), p.num_classes), (8, 2));
    let best = p.best(&[1]).unwrap();
    assert!((best.score - 4.0 / 6.0).abs() < 1e-6, "{}", best.score);
    // Input box (8, 14)–(28, 34) → frame (16, 21)–(56, 48), clipped to the frame's height.
    let want = [16.0, 21.0, 56.0, 48.0];
    assert!(best.bbox.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-3), "{:?}", best.bbox);
    assert!((p.row(0)[1] - 1.0 / 3.0).abs() < 1e-6);

    // Descriptions that do not fit the graph are refused when it loads, naming its outputs.
    for (change, want) in [
        (SSD.replace("stride = 16", "stride = 8"), "[32, 4]"),
        (SSD.replace("background = 0\n", ""), "[8, 2]"),
        (SSD.replace("output = \"boxes\"", "output = \"locations\""), "no output `locations`"),
    ] {
        let e = match config(tmp.path(), &model, &change) {
            Ok(cfg) => OnnxDetector::new(cfg, 1).err().unwrap().to_string(),
            Err(e) => e,
        };
        assert!(e.contains(want) && e.contains("boxes"), "{change}\n→ {e}");
    }
}

/// The skeleton `model inspect` writes for a model, at `side`, as a config file beside it.
fn skeleton(model: &Path, side: usize) -> (String, String, PathBuf) {
    let insp = Inspection::from_bytes(&std::fs::read(model).unwrap()).unwrap();
    let guess = insp.guess(side);
    assert_eq!(guess.layout, Some("custom"), "{}", guess.why);
    let path = model.with_extension("toml");
    let text = insp.skeleton("mine", &model.display().to_string(), side, &guess);
    std::fs::write(&path, &text).unwrap();
    (guess.why, text, path)
}

#[test]
fn inspect_guesses_both_as_custom_and_their_skeletons_load_once_completed() {
    common::real_data();
    let tmp = tempfile::tempdir().unwrap();
    let (why, _, path) = skeleton(&flattened_yolov3_tiny(tmp.path()), 416);
    assert!(why.contains("3 anchors × the grid cells of strides [16, 32]") && why.contains("80 classes"), "{why}");
    // Complete as it stands: it loads and its layout fits the model.
    OnnxDetector::new(DetectorConfig::load(&path).unwrap(), 1).unwrap();

    let model = constant_model(
        tmp.path(),
        &[("scores", vec![1, 8, 3], vec![0.0; 24]), ("boxes", vec![1, 8, 4], vec![0.0; 32])],
    );
    let (why, text, path) = skeleton(&model, 32);
    assert!(
        why.contains("`boxes` [.., N, 4]") && why.contains("`scores` [.., N, 3]") && why.contains("prior"),
        "{why}"
    );
    // The priors are the user's to fill in; until then the config says what is missing.
    let e = DetectorConfig::load(&path).unwrap_err().to_string();
    assert!(e.contains("need `anchors` on every level"), "{e}");
    // With COCO's 80 classes the scores do not fit: refused at load, naming the outputs.
    std::fs::write(&path, text.replace("anchors = []", "anchors = [[10, 10], [20, 10]]")).unwrap();
    let e = OnnxDetector::new(DetectorConfig::load(&path).unwrap(), 1).err().unwrap().to_string();
    assert!(e.contains("`scores` as [8, 81]; it is [1, 8, 3]"), "{e}");
    std::fs::write(tmp.path().join("names.txt"), "person\ncar\n").unwrap();
    let text = text.replace("anchors = []", "anchors = [[10, 10], [20, 10]]").replace("\"coco80\"", "\"names.txt\"");
    std::fs::write(&path, text).unwrap();
    let cfg = DetectorConfig::load(&path).unwrap();
    assert_eq!(
        OnnxDetector::new(cfg, 1).unwrap().propose(&common::reference_image("turntable.mp4#0")).unwrap().len(),
        8
    );
}

#[test]
fn every_documented_custom_layout_loads_as_written() {
    let tmp = tempfile::tempdir().unwrap();
    let mut seen = 0;
    for doc in ["docs/detectors.md"] {
        let text = std::fs::read_to_string(common::repo().join(doc)).unwrap();
        for block in text.split("```toml\n").skip(1).filter_map(|b| b.split("```").next()) {
            if !block.contains("layout = \"custom\"") {
                continue;
            }
            // A whole config (its file name on line one) loads as it is; an `[output]` table
            // loads in a config around it.
            let cfg = match block.lines().next().and_then(|l| l.strip_prefix("# ")) {
                Some(name) => {
                    common::real_data();
                    std::fs::write(tmp.path().join(name), block).unwrap();
                    DetectorConfig::load(&tmp.path().join(name)).map_err(|e| e.to_string())
                }
                None => config(tmp.path(), Path::new("m.onnx"), block),
            }
            .unwrap_or_else(|e| panic!("{doc}:\n{block}\n→ {e}"));
            assert!(matches!(cfg.output, pav::detect::config::OutputLayout::Custom(_)));
            seen += 1;
        }
    }
    assert_eq!(seen, 4, "docs/detectors.md's YOLOv5 export, raw heads, SSD and own detector");
}

/// The logit of `p`.
fn logit(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

/// A 32² frame of one colour: the constant models ignore it.
fn blank() -> pav::image::Frame {
    pav::image::Frame { width: 32, height: 32, bgr: vec![90; 32 * 32 * 3] }
}

/// Proposals of a constant model of `outputs` under the `[output]` table `output`.
fn proposals(dir: &Path, outputs: &[(&str, Vec<i64>, Vec<f32>)], output: &str) -> pav::detect::decode::Proposals {
    let model = constant_model(dir, outputs);
    let cfg = config(dir, &model, output).unwrap_or_else(|e| panic!("{output}\n→ {e}"));
    OnnxDetector::new(cfg, 1).unwrap_or_else(|e| panic!("{e}")).propose(&blank()).unwrap()
}

fn close(a: [f32; 4], b: [f32; 4]) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-3)
}

const YOLOV5_PLANES: &str = "[output]\nlayout = \"custom\"\n[[output.levels]]\nstride = 16\nanchors = [[10, 14], [20, 30]]\n[output.boxes]\noutput = [\"h\"]\narrange = \"planes\"\nper_level = true\nencoding = \"yolov5\"\n[output.objectness]\noutput = [\"h\"]\narrange = \"planes\"\nper_level = true\ncolumn = 4\nactivation = \"sigmoid\"\n[output.scores]\noutput = [\"h\"]\narrange = \"planes\"\nper_level = true\ncolumn = 5\nactivation = \"sigmoid\"\n";

#[test]
fn values_the_graph_already_activated_decode_as_their_logits_do() {
    // YOLOv5 heads at 32² (stride 16, 2×2 cells, two anchors, two classes): logits, and the same
    // values through the sigmoid as an export that applies it writes them.
    let tmp = tempfile::tempdir().unwrap();
    let n = 2 * 7 * 4;
    let mut raw: Vec<f32> = (0..n).map(|k| ((k * 5 % 13) as f32 - 6.0) / 4.0).collect();
    // Anchor 1 (20 × 30), cell (0, 1): box logits 0, objectness 0.9, car 0.8.
    let at = |k: usize| (7 + k) * 4 + 2;
    (0..4).for_each(|k| raw[at(k)] = 0.0);
    raw[at(4)] = logit(0.9);
    raw[at(6)] = logit(0.8);
    let sig: Vec<f32> = raw.iter().map(|&x| 1.0 / (1.0 + (-x).exp())).collect();
    let a = proposals(tmp.path(), &[("h", vec![1, 14, 2, 2], raw)], YOLOV5_PLANES);
    let activated = YOLOV5_PLANES.replace("encoding = \"yolov5\"\n", "encoding = \"yolov5\"\nactivated = true\n");
    let b =
        proposals(tmp.path(), &[("h", vec![1, 14, 2, 2], sig)], &activated.replace("activation = \"sigmoid\"\n", ""));
    assert_eq!(a.len(), 8);
    for i in 0..8 {
        assert!(close(a.boxes[i], b.boxes[i]), "{i}: {:?} vs {:?}", a.boxes[i], b.boxes[i]);
        assert!(a.row(i).iter().zip(b.row(i)).all(|(x, y)| (x - y).abs() < 1e-5), "{i}");
    }
    // Row 6 = anchor 1, cell 2: centre ((2·0.5 − 0.5 + 0)·16, (0.5 + 1)·16) = (8, 24), size
    // (2·0.5)² × (20, 30).
    assert!(close(b.boxes[6], [0.0, 9.0, 18.0, 32.0]), "{:?}", b.boxes[6]);
    assert!((b.row(6)[1] - 0.72).abs() < 1e-5, "{:?}", b.row(6));
    // A sigmoid the encoding does not have is refused.
    let e = config(
        tmp.path(),
        Path::new("m.onnx"),
        &SSD.replace("encoding = \"prior\"\n", "encoding = \"prior\"\nactivated = true\n"),
    )
    .unwrap_err();
    assert!(e.contains("`prior` applies none"), "{e}");
}

const FASTEST_V2: &str = "[output]\nlayout = \"custom\"\norder = \"in-row\"\n[[output.levels]]\nstride = 16\nanchors = [[8, 8], [16, 24], [24, 12]]\n[output.boxes]\noutput = [\"o\"]\nper_level = true\nencoding = \"yolov5\"\nactivated = true\nanchor_step = 4\n[output.objectness]\noutput = [\"o\"]\nper_level = true\ncolumn = 12\nanchor_step = 1\npower = 0.6\n[output.scores]\noutput = [\"o\"]\nper_level = true\ncolumn = 15\npower = 0.4\n";

#[test]
fn several_anchors_in_one_row_share_its_class_block_and_score_as_a_product_of_powers() {
    // YOLO-FastestV2's head at 32²: [1, 2, 2, 3·4 + 3 + 2] channels last, already activated.
    let tmp = tempfile::tempdir().unwrap();
    let mut v = vec![0.25f32; 2 * 2 * 17];
    // Cell (0, 1) (row 2): anchor 0 (8 × 8) at the cell's centre, objectness 0.64; anchor 1
    // objectness 0; classes (0.2, 0.8) for all three.
    let row = 2 * 17;
    v[row..row + 4].copy_from_slice(&[0.5, 0.5, 0.5, 0.5]);
    v[row + 12] = 0.64;
    v[row + 13] = 0.0;
    v[row + 15..row + 17].copy_from_slice(&[0.2, 0.8]);
    let p = proposals(tmp.path(), &[("o", vec![1, 2, 2, 17], v)], FASTEST_V2);
    assert_eq!((p.len(), p.num_classes), (12, 2));
    // Cell by cell, each cell's anchors together: proposal 6 is cell 2's anchor 0.
    assert!(close(p.boxes[6], [4.0, 20.0, 12.0, 28.0]), "{:?}", p.boxes[6]);
    let want = 0.64f32.powf(0.6) * 0.8f32.powf(0.4);
    assert!((p.row(6)[1] - want).abs() < 1e-5, "{:?} vs {want}", p.row(6));
    // Anchor 1 of the same cell reads its own objectness (0) and box (anchor 16 × 24).
    assert_eq!(p.row(7), [0.0, 0.0]);
    // Its values 0.25: height (2·0.25)²·24 = 6 about the centre (0·16 + 16).
    assert!(close([p.boxes[7][1], p.boxes[7][3], 0.0, 0.0], [13.0, 19.0, 0.0, 0.0]), "{:?}", p.boxes[7]);
    // `model inspect` names the head; its skeleton decodes it once the anchors are filled in.
    let model = constant_model(tmp.path(), &[("o", vec![1, 2, 2, 17], vec![0.5; 68])]);
    let insp = Inspection::from_bytes(&std::fs::read(&model).unwrap()).unwrap();
    let guess = insp.guess(32);
    assert!(
        guess.layout == Some("custom") && guess.why.contains("YOLO-FastestV2") && guess.why.contains("2 classes"),
        "{}",
        guess.why
    );
    let text = insp.skeleton("mine", &model.display().to_string(), 32, &guess);
    let out = &text[text.find("[output]").unwrap()..text.find("[classes]").unwrap()];
    let out = out.replace("anchors = []", "anchors = [[8, 8], [16, 24], [24, 12]]");
    assert_eq!(proposals(tmp.path(), &[("o", vec![1, 2, 2, 17], vec![0.5; 68])], &out).len(), 12, "{out}");
}

const FASTEST_DET: &str = "[output]\nlayout = \"custom\"\n[[output.levels]]\nstride = 16\n[output.boxes]\noutput = [\"o\"]\narrange = \"planes\"\nper_level = true\ncolumn = 1\nencoding = \"tanh-share\"\n[output.objectness]\noutput = [\"o\"]\narrange = \"planes\"\nper_level = true\ncolumn = 0\npower = 0.6\n[output.scores]\noutput = [\"o\"]\narrange = \"planes\"\nper_level = true\ncolumn = 5\npower = 0.4\n";

#[test]
fn centre_offsets_through_tanh_and_sizes_as_shares_of_the_input_decode_as_fastestdet() {
    // FastestDet's head at 32²: [1, 1 + 4 + 2, 2, 2] planes: objectness, box, classes.
    let tmp = tempfile::tempdir().unwrap();
    let mut v = vec![0.1f32; 7 * 4];
    // Cell (1, 1): objectness 0.81, offsets tanh⁻¹(0.5) and 0, sizes σ⁻¹ of 1/4 and 1/2, car 0.9.
    let at = |c: usize| c * 4 + 3;
    for (c, x) in [(0, 0.81), (1, 0.5f32.atanh()), (2, 0.0), (3, logit(0.25)), (4, logit(0.5)), (5, 0.1), (6, 0.9)] {
        v[at(c)] = x;
    }
    let p = proposals(tmp.path(), &[("o", vec![1, 7, 2, 2], v)], FASTEST_DET);
    assert_eq!(p.len(), 4);
    // Centre ((1 + 0.5)·16, (1 + 0)·16) = (24, 16), size (8, 16).
    assert!(close(p.boxes[3], [20.0, 8.0, 28.0, 24.0]), "{:?}", p.boxes[3]);
    let want = 0.81f32.powf(0.6) * 0.9f32.powf(0.4);
    assert!((p.row(3)[1] - want).abs() < 1e-5, "{:?} vs {want}", p.row(3));
    // `model inspect` names the head and its skeleton decodes it once the classes are the model's.
    let model = constant_model(tmp.path(), &[("o", vec![1, 7, 2, 2], vec![0.5; 28])]);
    let insp = Inspection::from_bytes(&std::fs::read(&model).unwrap()).unwrap();
    let guess = insp.guess(32);
    assert!(guess.layout == Some("custom") && guess.why.contains("FastestDet"), "{}", guess.why);
    let text = insp.skeleton("mine", &model.display().to_string(), 32, &guess);
    let out = &text[text.find("[output]").unwrap()..text.find("[classes]").unwrap()];
    assert_eq!(proposals(tmp.path(), &[("o", vec![1, 7, 2, 2], vec![0.5; 28])], out).len(), 4, "{out}");
}

#[test]
fn outputs_without_a_batch_dimension_decode_and_inspect_as_with_one() {
    // NanoDet's legacy export: class maps [R, 2] and box maps [R, 4·4] per level of strides 8,
    // 16, 32 at 32², no batch dimension.
    let tmp = tempfile::tempdir().unwrap();
    let mut outputs = Vec::new();
    for (l, s) in [8i64, 16, 32].iter().enumerate() {
        let r = (32 / s) * (32 / s);
        let mut cls = vec![0.05f32; r as usize * 2];
        let mut reg = vec![0f32; r as usize * 16];
        if l == 0 {
            // Cell (1, 1) of stride 8: car 0.7, each side's distance one stride (bin 1).
            cls[5 * 2 + 1] = 0.7;
            (0..4).for_each(|side| reg[5 * 16 + side * 4 + 1] = 20.0);
        }
        outputs.push((format!("cls{l}"), vec![r, 2], cls));
        outputs.push((format!("reg{l}"), vec![r, 16], reg));
    }
    let named: Vec<(&str, Vec<i64>, Vec<f32>)> =
        outputs.iter().map(|(n, s, v)| (n.as_str(), s.clone(), v.clone())).collect();
    let p = proposals(tmp.path(), &named, "[output]\nlayout = \"gfl\"\nstrides = [8, 16, 32]\nbins = 4\n");
    assert_eq!(p.len(), 21);
    // Centre (1·8 + 3.5, 1·8 + 3.5), one stride to each side.
    assert!(close(p.boxes[5], [3.5, 3.5, 19.5, 19.5]), "{:?}", p.boxes[5]);
    assert!((p.row(5)[1] - 0.7).abs() < 1e-6);
    let model = constant_model(tmp.path(), &named);
    let guess = Inspection::from_bytes(&std::fs::read(&model).unwrap()).unwrap().guess(32);
    assert_eq!(guess.layout, Some("gfl"), "{}", guess.why);
}
