#!/usr/bin/env python3
"""Feature norm clipping in YOLOX-Nano, rewritten with the onnx package and other operators than
pav's rewrite: after each named tensor X [N, C, H, W], n = ReduceL2(X, axes=[1]),
bound = level * ReduceMean(n, axes=[2, 3]), X' = X * Min(1, bound / n); every consumer of X reads
X'. Then YOLOX's demo preprocessing (top-left letterbox to 416 with grey 114, BGR 0-255), ONNX
Runtime, and the best car score (objectness x class 2 over all rows, before NMS).
Prints per image and level the best car score.
usage: reference_clip.py MODEL.onnx LAYERS(comma-separated) LEVELS(comma-separated) (FILE.npz | VIDEO.mp4[:every])..."""
import sys

import cv2
import numpy as np
import onnx
import onnxruntime as ort
from onnx import helper, numpy_helper
from reference_images import images


def clipped(path, layers, level):
    m = onnx.load(path)
    g = m.graph
    for k, x in enumerate(layers):
        out = f"ref_clip{k}"
        for node in g.node:
            node.input[:] = [out if i == x else i for i in node.input]
        lvl = numpy_helper.from_array(np.array(level, np.float32), f"ref_level{k}")
        one = numpy_helper.from_array(np.array(1.0, np.float32), f"ref_one{k}")
        g.initializer.extend([lvl, one])
        new = [
            helper.make_node("ReduceL2", [x], [f"ref_n{k}"], axes=[1], keepdims=1),
            helper.make_node("ReduceMean", [f"ref_n{k}"], [f"ref_m{k}"], axes=[2, 3], keepdims=1),
            helper.make_node("Mul", [f"ref_m{k}", f"ref_level{k}"], [f"ref_b{k}"]),
            helper.make_node("Div", [f"ref_b{k}", f"ref_n{k}"], [f"ref_r{k}"]),
            helper.make_node("Min", [f"ref_r{k}", f"ref_one{k}"], [f"ref_s{k}"]),
            helper.make_node("Mul", [x, f"ref_s{k}"], [out]),
        ]
        at = next(i for i, n in enumerate(g.node) if x in n.output) + 1
        for j, n in enumerate(new):
            g.node.insert(at + j, n)
    return ort.InferenceSession(m.SerializeToString(), providers=["CPUExecutionProvider"])


def best_car(sess, img):
    r = min(416 / img.shape[0], 416 / img.shape[1])
    small = cv2.resize(img, (round(img.shape[1] * r), round(img.shape[0] * r)), interpolation=cv2.INTER_LINEAR)
    x = np.full((416, 416, 3), 114, np.uint8)
    x[: small.shape[0], : small.shape[1]] = small
    x = np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32)
    out = sess.run(None, {sess.get_inputs()[0].name: x})[0][0]
    return float((out[:, 4] * out[:, 5 + 2]).max())


model, layers, levels = sys.argv[1], sys.argv[2].split(","), [float(v) for v in sys.argv[3].split(",")]
sessions = [(lv, clipped(model, layers, lv)) for lv in levels]
print("image\tlevel\tcar_score")
for label, img in images(sys.argv[4:]):
    for lv, sess in sessions:
        print(f"{label}\t{lv:g}\t{best_car(sess, img):.6f}")
