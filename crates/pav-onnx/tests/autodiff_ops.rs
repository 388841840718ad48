//! Every backward rule on a small graph of its own (one test per operator, named after it),
//! against central differences of the forward graph run by ONNX Runtime; graphs as detectors
//! write them (YOLOX's Focus and head, a DETR's LayerNorm, attention and query selection); and
//! max-pool ties routed to the first maximum of each window, as PyTorch routes them.
#![cfg(feature = "runtime")]

use pav_onnx::autodiff::{differentiate, differentiate_with, operators, Kernels};
use pav_onnx::proto::{Attr, Dim, Initializer, Model, Node, ValueInfo, FLOAT};
use pav_onnx::GradSession;

/// ONNX Runtime, or the fix when it is missing.
fn require_runtime() {
    if let Err(e) = pav_onnx::runtime::runtime() {
        panic!("{e}");
    }
}

fn node(op: &str, inputs: &[&str], out: &str, attrs: Vec<(&str, Attr)>) -> Node {
    attrs.into_iter().fold(Node::new(op, inputs, &[out]), |n, (k, a)| n.attr(k, a))
}

/// A float value of symbolic shape: the differentiation fixes the shapes.
fn value(name: &str) -> ValueInfo {
    ValueInfo { name: name.into(), elem_type: FLOAT, dims: vec![Dim::Symbolic("?".into()); 4] }
}

fn model(nodes: Vec<Node>, inits: Vec<Initializer>, outputs: &[&str]) -> Model {
    Model::graph(13, nodes, inits, vec![value("x")], outputs.iter().map(|o| value(o)).collect())
}

/// Values in [−1, 1], spread so that no two are closer than 1e-3 apart (no kink within a step).
fn spread(n: usize, seed: usize) -> Vec<f32> {
    let mut v: Vec<f32> = (0..n).map(|i| ((i * 7919 + seed * 104729) % n) as f32).collect();
    let m = n as f32;
    v.iter_mut().for_each(|x| *x = 2.0 * (*x + 0.5) / m - 1.0);
    v
}

/// The gradient of Σ w·outputs from the graphs, with either kind of kernels, against central
/// differences of the forward.
fn check(m: Model, shape: [i64; 4], tol: f32) {
    for kernels in [Kernels::Onnx, Kernels::Fused] {
        check_with(m.clone(), shape, tol, kernels);
    }
}

fn check_with(m: Model, shape: [i64; 4], tol: f32, kernels: Kernels) {
    require_runtime();
    let d = differentiate_with(&m, &shape, kernels).unwrap_or_else(|e| panic!("{e}"));
    let mut g = GradSession::new("test", d, 1).unwrap();
    let n = shape.iter().product::<i64>() as usize;
    let x = spread(n, 1);
    let (outs, pass) = g.forward(x.clone()).unwrap();
    let w: Vec<Vec<f32>> = outs.iter().enumerate().map(|(k, o)| spread(o.len(), k + 2)).collect();
    let grad = g.backward(&pass, w.clone()).unwrap();
    let loss = |g: &mut GradSession, x: Vec<f32>| -> f64 {
        let (o, _) = g.forward(x).unwrap();
        o.iter().zip(&w).map(|(o, w)| o.iter().zip(w).map(|(a, b)| *a as f64 * *b as f64).sum::<f64>()).sum()
    };
    let eps = 2e-4;
    for i in 0..n {
        let (mut p, mut q) = (x.clone(), x.clone());
        p[i] += eps;
        q[i] -= eps;
        let fd = ((loss(&mut g, p) - loss(&mut g, q)) / (2.0 * eps as f64)) as f32;
        assert!(
            (fd - grad[i]).abs() <= tol * (1.0 + fd.abs()),
            "{kernels:?}, input {i}: graph {} vs differences {fd}",
            grad[i]
        );
    }
}

fn ints(n: &str, v: Vec<i64>) -> Initializer {
    Initializer::i64(n, &[v.len() as i64], v)
}

fn scalar(n: &str, v: f32) -> Initializer {
    Initializer::f32(n, &[], vec![v])
}

fn weights(n: &str, dims: Vec<i64>, seed: usize) -> Initializer {
    let k = dims.iter().product::<i64>() as usize;
    Initializer::f32(n, &dims, spread(k, seed))
}

/// One `op` node reading `x` (and `more`), writing `y`.
fn single(op: &str, more: &[&str], attrs: Vec<(&str, Attr)>, inits: Vec<Initializer>) -> Model {
    let inputs: Vec<&str> = std::iter::once("x").chain(more.iter().copied()).collect();
    model(vec![node(op, &inputs, "y", attrs)], inits, &["y"])
}

/// Every operator with a backward rule has a test of its own in this file, named after it.
#[test]
fn every_rule_has_a_test() {
    let source = include_str!("autodiff_ops.rs");
    for op in operators() {
        let mut snake = String::new();
        let mut previous_upper = true;
        for ch in op.chars() {
            if ch.is_uppercase() && !previous_upper {
                snake.push('_');
            }
            previous_upper = ch.is_uppercase();
            snake.extend(ch.to_lowercase());
        }
        assert!(source.contains(&format!("#[test]\nfn {snake}(")), "no test `fn {snake}()` for {op}");
    }
}

#[test]
fn conv() {
    for (stride, group, pads) in
        [(1, 1, [1, 1, 1, 1]), (2, 1, [1, 1, 1, 1]), (2, 1, [0, 0, 1, 1]), (1, 2, [1, 0, 1, 0])]
    {
        let (c, m) = (2, 4);
        let attrs = vec![
            ("kernel_shape", Attr::Ints(vec![3, 3])),
            ("strides", Attr::Ints(vec![stride, stride])),
            ("pads", Attr::Ints(pads.to_vec())),
            ("group", Attr::Int(group)),
        ];
        let w = weights("w", vec![m, c / group, 3, 3], 9);
        check(single("Conv", &["w"], attrs, vec![w]), [1, c, 7, 6], 2e-3);
    }
}

#[test]
fn max_pool() {
    // Tiled, padded at the end as darknet pads, overlapping with padding on every side.
    for (k, s, p) in
        [(2, 2, [0, 0, 0, 0]), (2, 2, [0, 0, 1, 1]), (2, 1, [0, 0, 1, 1]), (3, 2, [1, 1, 1, 1]), (5, 1, [2, 2, 2, 2])]
    {
        let attrs = vec![
            ("kernel_shape", Attr::Ints(vec![k, k])),
            ("strides", Attr::Ints(vec![s, s])),
            ("pads", Attr::Ints(p.to_vec())),
        ];
        check(single("MaxPool", &[], attrs, vec![]), [1, 2, 6, 6], 2e-3);
    }
}

#[test]
fn leaky_relu() {
    for alpha in [0.1, -0.2] {
        check(single("LeakyRelu", &[], vec![("alpha", Attr::Float(alpha))], vec![]), [1, 2, 4, 4], 2e-3);
    }
}

#[test]
fn relu() {
    check(single("Relu", &[], vec![], vec![]), [1, 2, 4, 4], 2e-3);
}

#[test]
fn hard_sigmoid() {
    // PP-LCNet's squeeze-excitation gate (alpha 1/6, beta 1/2): the inputs in [−1, 1] reach past
    // both kinks at the larger slope.
    for alpha in [1.0 / 6.0, 0.8] {
        let attrs = vec![("alpha", Attr::Float(alpha)), ("beta", Attr::Float(0.5))];
        check(single("HardSigmoid", &[], attrs, vec![]), [1, 2, 4, 4], 2e-3);
    }
}

#[test]
fn sigmoid() {
    // SiLU as YOLOX writes it: x · sigmoid(x), one value read twice.
    let silu = model(vec![node("Sigmoid", &["x"], "s", vec![]), node("Mul", &["x", "s"], "y", vec![])], vec![], &["y"]);
    check(silu, [1, 2, 4, 4], 2e-3);
}

#[test]
fn add() {
    // A broadcast constant, and the input added to a function of itself.
    check(single("Add", &["b"], vec![], vec![weights("b", vec![2, 1, 1], 3)]), [1, 2, 3, 4], 2e-3);
    let m = model(
        vec![node("Mul", &["x", "k"], "a", vec![]), node("Add", &["a", "x"], "y", vec![])],
        vec![scalar("k", 1.5)],
        &["y"],
    );
    check(m, [1, 2, 4, 4], 2e-3);
}

#[test]
fn sub() {
    // Both operands live, the subtrahend broadcast along the last axis.
    let m = model(
        vec![
            node("ReduceMean", &["x"], "m", vec![("axes", Attr::Ints(vec![3])), ("keepdims", Attr::Int(1))]),
            node("Sub", &["x", "m"], "y", vec![]),
        ],
        vec![],
        &["y"],
    );
    check(m, [1, 2, 3, 4], 2e-3);
}

#[test]
fn mul() {
    check(single("Mul", &["k"], vec![], vec![weights("k", vec![1, 3, 4], 5)]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn div() {
    // A live divisor broadcast over two axes (kept away from zero by a sigmoid), and a constant one.
    let m = model(
        vec![
            node("ReduceMean", &["x"], "m", vec![("axes", Attr::Ints(vec![1, 3])), ("keepdims", Attr::Int(1))]),
            node("Sigmoid", &["m"], "sm", vec![]),
            node("Div", &["x", "sm"], "y", vec![]),
            node("Div", &["x", "k"], "z", vec![]),
        ],
        vec![scalar("k", 0.7)],
        &["y", "z"],
    );
    check(m, [1, 2, 4, 3], 3e-3);
}

#[test]
fn mat_mul() {
    // A weight on the right, two activations with a broadcast batch axis, a vector on the right.
    let m = model(
        vec![
            node("Reshape", &["x", "seq"], "s", vec![]),
            node("MatMul", &["s", "w"], "q", vec![]),
            node("Reshape", &["x", "mat"], "a", vec![]),
            node("Sigmoid", &["a"], "sa", vec![]),
            node("Reshape", &["sa", "col"], "b", vec![]),
            node("Slice", &["b", "z", "four", "ax0"], "b4", vec![]),
            node("Reshape", &["b4", "col4"], "bc", vec![]),
            node("MatMul", &["a", "bc"], "ab", vec![]),
            node("MatMul", &["s", "v"], "sv", vec![]),
        ],
        vec![
            ints("seq", vec![1, 6, 4]),
            weights("w", vec![4, 3], 5),
            ints("mat", vec![2, 3, 4]),
            ints("col", vec![24]),
            ints("z", vec![0]),
            ints("four", vec![4]),
            ints("ax0", vec![0]),
            ints("col4", vec![4, 1]),
            weights("v", vec![4], 6),
        ],
        &["q", "ab", "sv"],
    );
    check(m, [1, 2, 3, 4], 3e-3);
}

#[test]
fn pow() {
    for c in [2.0, 3.0] {
        check(single("Pow", &["c"], vec![], vec![scalar("c", c)]), [1, 2, 3, 3], 3e-3);
    }
}

#[test]
fn sqrt() {
    // On x² + 1, so that the input stays positive.
    let m = model(
        vec![
            node("Mul", &["x", "x"], "x2", vec![]),
            node("Add", &["x2", "one"], "p", vec![]),
            node("Sqrt", &["p"], "y", vec![]),
        ],
        vec![scalar("one", 1.0)],
        &["y"],
    );
    check(m, [1, 2, 3, 3], 2e-3);
    // PicoDet's score sqrt(σ(a)·σ(b)): where both sigmoids saturate the product is exactly 0 in
    // f32, and the gradient stays finite (0) instead of ∞·0 = NaN.
    let m = model(
        vec![
            node("Mul", &["x", "big"], "a", vec![]),
            node("Sigmoid", &["a"], "s", vec![]),
            node("Mul", &["s", "s"], "p", vec![]),
            node("Sqrt", &["p"], "y", vec![]),
        ],
        vec![scalar("big", 300.0)],
        &["y"],
    );
    for kernels in [Kernels::Onnx, Kernels::Fused] {
        let mut g = GradSession::new("test", differentiate_with(&m, &[1, 1, 2, 2], kernels).unwrap(), 1).unwrap();
        let (outs, pass) = g.forward(vec![-1.0, -0.5, 0.5, 1.0]).unwrap();
        assert_eq!(&outs[0][..2], &[0.0, 0.0], "the saturated scores are exactly 0");
        let grad = g.backward(&pass, vec![vec![1.0; 4]]).unwrap();
        assert!(grad.iter().all(|v| v.is_finite()), "{kernels:?}: {grad:?}");
    }
}

#[test]
fn log() {
    let m = model(vec![node("Sigmoid", &["x"], "s", vec![]), node("Log", &["s"], "y", vec![])], vec![], &["y"]);
    check(m, [1, 2, 3, 3], 2e-3);
}

#[test]
fn neg() {
    check(single("Neg", &[], vec![], vec![]), [1, 2, 3, 3], 2e-3);
}

#[test]
fn exp() {
    check(single("Exp", &[], vec![], vec![]), [1, 2, 3, 3], 2e-3);
}

#[test]
fn tanh() {
    check(single("Tanh", &[], vec![], vec![]), [1, 2, 3, 3], 2e-3);
}

#[test]
fn min() {
    // A cap inside the inputs' range: some values pass, some are capped.
    check(single("Min", &["cap"], vec![], vec![scalar("cap", 0.1)]), [1, 2, 4, 4], 2e-3);
    // A second operand that depends on the input is refused by name.
    let m = model(vec![node("Neg", &["x"], "n", vec![]), node("Min", &["x", "n"], "y", vec![])], vec![], &["y"]);
    let e = differentiate_with(&m, &[1, 1, 2, 2], Kernels::Onnx).unwrap_err().to_string();
    assert!(e.contains("Min") && e.contains("constant"), "{e}");
}

#[test]
fn max() {
    check(single("Max", &["floor"], vec![], vec![scalar("floor", -0.2)]), [1, 2, 4, 4], 2e-3);
}

#[test]
fn clip() {
    check(single("Clip", &["lo", "hi"], vec![], vec![scalar("lo", -0.3), scalar("hi", 0.4)]), [1, 2, 4, 4], 2e-3);
    // Only a lower bound (the upper input left empty).
    check(single("Clip", &["lo", ""], vec![], vec![scalar("lo", -0.3)]), [1, 2, 4, 4], 2e-3);
}

#[test]
fn softmax() {
    for axis in [-1, 1] {
        check(single("Softmax", &[], vec![("axis", Attr::Int(axis))], vec![]), [1, 3, 2, 4], 2e-3);
    }
}

#[test]
fn reduce_mean() {
    let attrs = vec![("axes", Attr::Ints(vec![1, 3])), ("keepdims", Attr::Int(0))];
    check(single("ReduceMean", &[], attrs, vec![]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn reduce_sum() {
    // Axes as a constant input (opset 13), kept.
    check(
        single("ReduceSum", &["ax"], vec![("keepdims", Attr::Int(1))], vec![ints("ax", vec![2])]),
        [1, 2, 3, 4],
        2e-3,
    );
}

#[test]
fn concat() {
    let m = model(
        vec![
            node("Sigmoid", &["x"], "s", vec![]),
            node("Concat", &["x", "s", "k", "x"], "y", vec![("axis", Attr::Int(1))]),
        ],
        vec![weights("k", vec![1, 1, 4, 4], 7)],
        &["y"],
    );
    check(m, [1, 2, 4, 4], 2e-3);
}

#[test]
fn resize() {
    let attrs = vec![
        ("mode", Attr::Str("nearest".into())),
        ("coordinate_transformation_mode", Attr::Str("asymmetric".into())),
        ("nearest_mode", Attr::Str("floor".into())),
    ];
    let scales = Initializer::f32("sc", &[4], vec![1.0, 1.0, 2.0, 2.0]);
    check(single("Resize", &["", "sc"], attrs, vec![scales]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn resize_linear() {
    // NanoDet's FPN: up to twice and down to half by sizes under pytorch_half_pixel; and a
    // factor of 5/3 under each other transformation, whose source coordinates leave the input
    // at the edges (clamped there).
    let linear = |ctm: &str| {
        vec![("mode", Attr::Str("linear".into())), ("coordinate_transformation_mode", Attr::Str(ctm.into()))]
    };
    for (shape, to) in [([1, 2, 3, 4], [1, 2, 6, 8]), ([1, 2, 6, 4], [1, 2, 3, 2])] {
        let sizes = ints("sz", to.to_vec());
        check(single("Resize", &["", "", "sz"], linear("pytorch_half_pixel"), vec![sizes]), shape, 2e-3);
    }
    for ctm in ["half_pixel", "align_corners", "asymmetric"] {
        let scales = Initializer::f32("sc", &[4], vec![1.0, 1.0, 5.0 / 3.0, 5.0 / 3.0]);
        check(single("Resize", &["", "sc"], linear(ctm), vec![scales]), [1, 1, 3, 3], 2e-3);
    }
}

#[test]
fn slice() {
    // Negative bounds and axis, two axes in one node; the last step of 3 runs past the end.
    let m = single(
        "Slice",
        &["st", "en", "ax", "sp"],
        vec![],
        vec![ints("st", vec![-5, 1]), ints("en", vec![-1, 100]), ints("ax", vec![-1, 2]), ints("sp", vec![3, 2])],
    );
    check(m, [1, 2, 5, 7], 2e-3);
}

#[test]
fn reshape() {
    // 0 copies an axis, −1 takes the rest.
    check(single("Reshape", &["shape"], vec![], vec![ints("shape", vec![0, 3, -1])]), [1, 3, 4, 5], 2e-3);
}

#[test]
fn flatten() {
    check(single("Flatten", &[], vec![("axis", Attr::Int(2))], vec![]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn squeeze() {
    check(single("Squeeze", &["ax"], vec![], vec![ints("ax", vec![0])]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn unsqueeze() {
    check(single("Unsqueeze", &["ax"], vec![], vec![ints("ax", vec![-1, 2])]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn transpose() {
    check(single("Transpose", &[], vec![("perm", Attr::Ints(vec![0, 3, 1, 2]))], vec![]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn cast() {
    check(single("Cast", &[], vec![("to", Attr::Int(FLOAT as i64))], vec![]), [1, 2, 3, 3], 2e-3);
    let m = single("Cast", &[], vec![("to", Attr::Int(7))], vec![]);
    let e = differentiate(&m, &[1, 2, 3, 3]).unwrap_err().to_string();
    assert!(e.contains("Cast") && e.contains("float"), "{e}");
}

#[test]
fn identity() {
    // Two outputs, one read through an Identity of the other.
    let m = model(vec![node("Relu", &["x"], "a", vec![]), node("Identity", &["a"], "b", vec![])], vec![], &["a", "b"]);
    check(m, [1, 2, 4, 4], 2e-3);
}

#[test]
fn pad() {
    let attrs = vec![("mode", Attr::Str("constant".into()))];
    check(single("Pad", &["pads"], attrs, vec![ints("pads", vec![0, 0, 1, 0, 0, 0, 2, 1])]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn average_pool() {
    let attrs = vec![
        ("kernel_shape", Attr::Ints(vec![3, 3])),
        ("strides", Attr::Ints(vec![2, 2])),
        ("pads", Attr::Ints(vec![1, 1, 1, 1])),
        ("count_include_pad", Attr::Int(1)),
    ];
    check(single("AveragePool", &[], attrs, vec![]), [1, 2, 6, 5], 2e-3);
}

#[test]
fn global_average_pool() {
    check(single("GlobalAveragePool", &[], vec![], vec![]), [1, 3, 4, 5], 2e-3);
}

#[test]
fn reduce_max() {
    check(
        single("ReduceMax", &[], vec![("axes", Attr::Ints(vec![-1])), ("keepdims", Attr::Int(0))], vec![]),
        [1, 2, 3, 5],
        2e-3,
    );
}

#[test]
fn top_k() {
    let mut m = single("TopK", &["k"], vec![("axis", Attr::Int(-1))], vec![ints("k", vec![2])]);
    m.nodes[0].outputs.push("idx".into());
    check(m, [1, 2, 3, 5], 2e-3);
}

#[test]
fn gather() {
    // Constant indices, one of them negative, along the last axis; and a matrix of indices.
    check(single("Gather", &["i"], vec![("axis", Attr::Int(3))], vec![ints("i", vec![2, -1, 0])]), [1, 2, 3, 4], 2e-3);
    let idx = Initializer::i64("i", &[2, 2], vec![0, 2, 1, 1]);
    check(single("Gather", &["i"], vec![("axis", Attr::Int(2))], vec![idx]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn gather_elements() {
    let idx = Initializer::i64("i", &[1, 2, 2, 4], vec![0, 2, 1, 1, 2, 0, 0, 1, 1, 1, 2, 0, 0, 2, 2, 1]);
    check(single("GatherElements", &["i"], vec![("axis", Attr::Int(2))], vec![idx]), [1, 2, 3, 4], 2e-3);
}

#[test]
fn expand() {
    // [1, 2, 1, 4] expanded along the third axis.
    let m = model(
        vec![
            node("ReduceMean", &["x"], "m", vec![("axes", Attr::Ints(vec![2])), ("keepdims", Attr::Int(1))]),
            node("Expand", &["m", "to"], "y", vec![]),
        ],
        vec![ints("to", vec![1, 2, 3, 4])],
        &["y"],
    );
    check(m, [1, 2, 3, 4], 2e-3);
}

#[test]
fn grid_sample() {
    // A grid computed from the input (partly outside [−1, 1], where zero padding applies) samples
    // that same input: both paths carry a gradient.
    let nodes = vec![
        node("Slice", &["x", "c0", "c1", "ax1"], "ch", vec![]),
        node("Reshape", &["ch", "gshape"], "g0", vec![]),
        node("Mul", &["g0", "k"], "grid", vec![]),
        node(
            "GridSample",
            &["x", "grid"],
            "y",
            vec![
                ("mode", Attr::Str("bilinear".into())),
                ("padding_mode", Attr::Str("zeros".into())),
                ("align_corners", Attr::Int(0)),
            ],
        ),
    ];
    let inits = vec![ints("c0", vec![0]), ints("c1", vec![1]), ints("ax1", vec![1]), ints("gshape", vec![1, 2, 5, 2])];
    let mut m = model(nodes, [inits, vec![scalar("k", 1.3)]].concat(), &["y"]);
    m.opset = 16; // GridSample's first opset
    check(m, [1, 2, 4, 5], 3e-3);
}

#[test]
fn split() {
    // YOLOv8's C2f: a Split along channels whose parts are read (or not) further on.
    let split = |inputs: &[&str], outs: &[&str]| Node {
        outputs: outs.iter().map(|o| o.to_string()).collect(),
        ..node("Split", inputs, outs[0], vec![("axis", Attr::Int(1))])
    };
    let sizes = Initializer::i64("sizes", &[2], vec![1, 3]);
    let graphs = vec![
        // Sizes as an input; both parts read, one of them twice.
        model(
            vec![
                split(&["x", "sizes"], &["a", "b"]),
                node("Sigmoid", &["b"], "s", vec![]),
                node("Mul", &["b", "s"], "m", vec![]),
                node("Concat", &["m", "a"], "y", vec![("axis", Attr::Int(1))]),
            ],
            vec![sizes],
            &["y", "a"],
        ),
        // Equal parts; the second part is read by nothing, so its gradient is zero.
        model(vec![split(&["x"], &["a", "b"]), node("Sigmoid", &["a"], "y", vec![])], vec![], &["y"]),
    ];
    for m in graphs {
        check(m, [1, 4, 3, 3], 2e-3);
    }
    // Sizes that do not add up are refused by name.
    let bad = Initializer::i64("sizes", &[2], vec![1, 1]);
    let m = model(vec![split(&["x", "sizes"], &["a", "b"]), node("Sigmoid", &["a"], "y", vec![])], vec![bad], &["y"]);
    let e = differentiate(&m, &[1, 4, 3, 3]).unwrap_err().to_string();
    assert!(e.contains("Split") && e.contains("sizes [1, 1]"), "{e}");
}

#[test]
fn max_pool_ties_go_to_the_first_maximum() {
    require_runtime();
    // Every window of a constant image ties: only its first (top-left) position gets gradient.
    let cases = [(2, 2, vec![0, 0, 0, 0]), (2, 1, vec![0, 0, 1, 1])];
    for ((k, s, p), kernels) in cases.into_iter().flat_map(|c| [(c.clone(), Kernels::Onnx), (c, Kernels::Fused)]) {
        let attrs = vec![
            ("kernel_shape", Attr::Ints(vec![k, k])),
            ("strides", Attr::Ints(vec![s, s])),
            ("pads", Attr::Ints(p)),
        ];
        let m = model(vec![node("MaxPool", &["x"], "y", attrs)], vec![], &["y"]);
        let d = differentiate_with(&m, &[1, 1, 4, 4], kernels).unwrap();
        let mut g = GradSession::new("ties", d, 1).unwrap();
        let (y, pass) = g.forward(vec![0.5; 16]).unwrap();
        let grad = g.backward(&pass, vec![vec![1.0; y[0].len()]]).unwrap();
        let expect: Vec<f32> = if s == 2 {
            (0..16).map(|i| if (i / 4) % 2 == 0 && (i % 4) % 2 == 0 { 1.0 } else { 0.0 }).collect()
        } else {
            // Stride 1 with end padding: output (i, j) reads (i, j) first, so each input gets one.
            vec![1.0; 16]
        };
        assert_eq!(grad, expect, "k{k} s{s} {kernels:?}");
    }
}

#[test]
fn unsupported_operators_are_named() {
    let m = model(vec![node("Erf", &["x"], "y", vec![])], vec![], &["y"]);
    let e = differentiate(&m, &[1, 1, 2, 2]).unwrap_err().to_string();
    assert!(e.contains("Erf") && e.contains("no backward rule"), "{e}");
}

#[test]
fn yolox_focus_and_head() {
    // YOLOX's Focus: four step-2 slices (every other row and column, from 0 and 1) concatenated.
    let c = |n: &str, v: i64| ints(n, vec![v]);
    let focus = model(
        vec![
            node("Slice", &["x", "s0", "big", "ax2", "two"], "r0", vec![]),
            node("Slice", &["x", "s1", "big", "ax2", "two"], "r1", vec![]),
            node("Slice", &["r0", "s0", "big", "ax3", "two"], "a", vec![]),
            node("Slice", &["r1", "s0", "big", "ax3", "two"], "b", vec![]),
            node("Slice", &["r0", "s1", "big", "ax3", "two"], "c", vec![]),
            node("Slice", &["r1", "s1", "big", "ax3", "two"], "d", vec![]),
            node("Concat", &["a", "b", "c", "d"], "y", vec![("axis", Attr::Int(1))]),
        ],
        vec![c("s0", 0), c("s1", 1), c("big", i64::MAX), c("ax2", 2), c("ax3", 3), c("two", 2)],
        &["y"],
    );
    check(focus, [1, 2, 6, 4], 2e-3);
    // YOLOX's head: [1, C, H, W] → [1, C, H·W] → [1, H·W, C].
    let head = model(
        vec![
            node("Sigmoid", &["x"], "s", vec![]),
            node("Reshape", &["s", "shape"], "r", vec![]),
            node("Transpose", &["r"], "y", vec![("perm", Attr::Ints(vec![0, 2, 1]))]),
        ],
        vec![ints("shape", vec![0, 3, -1])],
        &["y"],
    );
    check(head, [1, 3, 4, 5], 2e-3);
}

#[test]
fn a_negative_slice_step_is_refused_by_name() {
    let m = model(
        vec![node("Slice", &["x", "st", "en", "ax", "sp"], "y", vec![])],
        vec![ints("st", vec![3]), ints("en", vec![0]), ints("ax", vec![3]), ints("sp", vec![-1])],
        &["y"],
    );
    let e = differentiate(&m, &[1, 1, 4, 4]).unwrap_err().to_string();
    assert!(e.contains("Slice") && e.contains("positive steps"), "{e}");
}

#[test]
fn layer_norm_attention_and_reductions_as_a_detr_writes_them() {
    // A DETR decoder's pieces on a [1, 6, 4] sequence: LayerNorm spelled out (ReduceMean, Sub,
    // Pow, Sqrt, Div, a broadcast scale and shift), self-attention (MatMul with a weight, Q·Kᵀ of
    // two activations, Softmax, the product with the values), and the reshapes and reductions
    // around them.
    let mean = |x: &str, y: &str| node("ReduceMean", &[x], y, vec![("axes", Attr::Ints(vec![-1]))]);
    let nodes = vec![
        node("Reshape", &["x", "seq"], "s", vec![]),
        mean("s", "m"),
        node("Sub", &["s", "m"], "d", vec![]),
        node("Pow", &["d", "two"], "d2", vec![]),
        mean("d2", "v"),
        node("Add", &["v", "eps"], "ve", vec![]),
        node("Sqrt", &["ve"], "sd", vec![]),
        node("Div", &["d", "sd"], "nrm", vec![]),
        node("Mul", &["nrm", "gamma"], "ng", vec![]),
        node("Add", &["ng", "beta"], "ln", vec![]),
        node("MatMul", &["ln", "wq"], "q", vec![]),
        node("MatMul", &["ln", "wk"], "k", vec![]),
        node("Transpose", &["k"], "kt", vec![("perm", Attr::Ints(vec![0, 2, 1]))]),
        node("MatMul", &["q", "kt"], "att", vec![]),
        node("Softmax", &["att"], "p", vec![("axis", Attr::Int(-1))]),
        node("MatMul", &["p", "ln"], "o", vec![]),
        node("Clip", &["o", "lo", "hi"], "oc", vec![]),
        node("ReduceSum", &["oc", "ax1"], "rs", vec![("keepdims", Attr::Int(0))]),
        node("Unsqueeze", &["rs", "ax0"], "u", vec![]),
        node("Squeeze", &["u", "ax0"], "sq", vec![]),
        node("Sigmoid", &["o"], "sig", vec![]),
        node("Log", &["sig"], "lg", vec![]),
        node("Neg", &["lg"], "nl", vec![]),
        node("Flatten", &["nl"], "fl", vec![("axis", Attr::Int(1))]),
        node("Cast", &["fl"], "y2", vec![("to", Attr::Int(FLOAT as i64))]),
    ];
    let inits = vec![
        ints("seq", vec![1, 6, 4]),
        scalar("two", 2.0),
        scalar("eps", 1e-5),
        weights("gamma", vec![4], 3),
        weights("beta", vec![4], 4),
        weights("wq", vec![4, 4], 5),
        weights("wk", vec![4, 4], 6),
        scalar("lo", -0.3),
        scalar("hi", 0.3),
        ints("ax1", vec![1]),
        ints("ax0", vec![0]),
    ];
    check(model(nodes, inits, &["sq", "y2", "ln"]), [1, 1, 6, 4], 3e-3);
    // A broadcast divisor that depends on the input, and a batch-broadcast product of two
    // activations: both gradients summed back over the broadcast axes.
    let nodes = vec![
        node("ReduceMean", &["x"], "m", vec![("axes", Attr::Ints(vec![1, 3])), ("keepdims", Attr::Int(1))]),
        node("Sigmoid", &["m"], "sm", vec![]),
        node("Div", &["x", "sm"], "y", vec![]),
        node("Reshape", &["x", "mat"], "a", vec![]),
        node("Reshape", &["sm", "col"], "b", vec![]),
        node("MatMul", &["a", "b"], "z", vec![]),
    ];
    let inits = vec![ints("mat", vec![2, 3, 4]), ints("col", vec![4, 1])];
    check(model(nodes, inits, &["y", "z"]), [1, 2, 4, 3], 3e-3);
}

#[test]
fn selection_and_pooling_as_a_detr_writes_them() {
    // Query selection: the best class score per query (ReduceMax), the top 3 queries (TopK), their
    // features picked by the TopK's indices (GatherElements), and a constant Gather.
    let select = vec![
        node("Reshape", &["x", "seq"], "s", vec![]),
        node("ReduceMax", &["s"], "best", vec![("axes", Attr::Ints(vec![-1])), ("keepdims", Attr::Int(0))]),
        {
            let mut t = node("TopK", &["best", "three"], "top", vec![("axis", Attr::Int(-1))]);
            t.outputs.push("idx".into());
            t
        },
        node("Unsqueeze", &["idx", "ax2"], "idx3", vec![]),
        node("Expand", &["idx3", "wide"], "idxe", vec![]),
        node("GatherElements", &["s", "idxe"], "picked", vec![("axis", Attr::Int(1))]),
        node("Gather", &["s", "cols"], "cols2", vec![("axis", Attr::Int(2))]),
    ];
    let inits = vec![
        ints("seq", vec![1, 6, 4]),
        ints("three", vec![3]),
        ints("ax2", vec![2]),
        ints("wide", vec![1, 3, 4]),
        ints("cols", vec![2, 0]),
    ];
    check(model(select, inits, &["top", "picked", "cols2"]), [1, 1, 6, 4], 3e-3);
    // The backbone's pads and pools (ONNX Runtime folds a Pad into the pool after it, and then
    // refuses pads that reach the kernel size: kept small).
    let pools = vec![
        node("Pad", &["x", "pads"], "p", vec![("mode", Attr::Str("constant".into()))]),
        node(
            "AveragePool",
            &["p"],
            "a",
            vec![
                ("kernel_shape", Attr::Ints(vec![3, 3])),
                ("strides", Attr::Ints(vec![2, 2])),
                ("pads", Attr::Ints(vec![1, 1, 1, 1])),
                ("count_include_pad", Attr::Int(1)),
            ],
        ),
        node("GlobalAveragePool", &["x"], "gap", vec![]),
    ];
    check(model(pools, vec![ints("pads", vec![0, 0, 1, 0, 0, 0, 0, 1])], &["a", "gap"]), [1, 2, 6, 6], 3e-3);
}

/// Feature norm clipping (`rewrite::clip_feature_norms`) after a convolution, at a level that
/// clips some positions and not others: differentiable through the bound (the mean norm) and
/// the scale, with the axes as attribute (opset 11) and as input (opset 13).
#[test]
fn feature_norm_clipping_rewrite() {
    for opset in [11, 13] {
        let mut m = model(
            vec![node("Conv", &["x", "w"], "f", vec![]), node("Sigmoid", &["f"], "y", vec![])],
            vec![weights("w", vec![4, 2, 1, 1], 3)],
            &["y"],
        );
        m.opset = opset;
        pav_onnx::rewrite::clip_feature_norms(&mut m, "f", 0.9).unwrap();
        check(m, [1, 2, 3, 3], 2e-2);
    }
}
