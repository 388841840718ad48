#!/usr/bin/env python3
"""The loop a user would write instead of `pav-rig evaluate`: OpenCV decode, the model's upstream
preprocessing with cv2.resize (INTER_LINEAR), ONNX Runtime, the best car score per frame.
Usage: python_loop.py yolox|darknet MODEL.onnx VIDEO [THRESHOLD]; prints the frames and the share
with a car at or above the threshold."""
import sys

import cv2
import numpy as np
import onnxruntime as ort

layout, model, video = sys.argv[1:4]
threshold = float(sys.argv[4]) if len(sys.argv) > 4 else 0.5
sess = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
name = sess.get_inputs()[0].name
cap = cv2.VideoCapture(video)
frames = found = 0
while True:
    ok, img = cap.read()
    if not ok:
        break
    if layout == "yolox":  # YOLOX's demo: top-left letterbox, grey 114, BGR 0-255
        r = min(416 / img.shape[0], 416 / img.shape[1])
        small = cv2.resize(img, (round(img.shape[1] * r), round(img.shape[0] * r)), interpolation=cv2.INTER_LINEAR)
        x = np.full((416, 416, 3), 114, np.uint8)
        x[: small.shape[0], : small.shape[1]] = small
        x = np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32)
        out = sess.run(None, {name: x})[0][0]
        best = float((out[:, 4] * out[:, 5 + 2]).max())  # objectness × car (COCO class 2)
    else:  # darknet YOLOv3-tiny: stretched, RGB / 255, raw heads (3 anchors × 85 channels)
        x = cv2.cvtColor(cv2.resize(img, (416, 416), interpolation=cv2.INTER_LINEAR), cv2.COLOR_BGR2RGB)
        x = np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32) / 255.0
        best = 0.0
        for head in sess.run(None, {name: x}):
            t = head[0].reshape(3, 85, -1)
            s = 1 / (1 + np.exp(-t[:, 4])) / (1 + np.exp(-t[:, 5 + 2]))
            best = max(best, float(s.max()))
    frames += 1
    found += best >= threshold
print(f"{frames} frames, car in {found} ({100 * found / max(frames, 1):.1f} %)")
