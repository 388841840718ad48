#!/usr/bin/env python3
"""PP-PicoDet-XS 320 (NMS inside the graph) on real images, written from PaddleDetection's ONNX
Runtime demo (deploy/third_engine/demo_onnxruntime/infer_demo.py), not from pav's decoder: BGR
as OpenCV reads it, stretched to 320x320 with cv2.INTER_AREA, mean/std in BGR order, a second
input scale_factor = [[320/H, 320/W]]; the first output holds rows (class, score, x1, y1, x2, y2)
in image pixels, class -1 for an empty row.
Prints per image: name, best car score (COCO class 2, after the graph's NMS; 0 and an empty box
when no car row) and its box in image pixels.
usage: reference_picodet.py MODEL.onnx (FILE.npz | VIDEO.mp4[:every])..."""
import sys

import cv2
import numpy as np
import onnxruntime as ort
from reference_images import print_best

SIDE, CAR = 320, 2
MEAN = np.array([103.53, 116.28, 123.675], np.float32)
STD = np.array([57.375, 57.12, 58.395], np.float32)
sess = ort.InferenceSession(sys.argv[1], providers=["CPUExecutionProvider"])
image, scale = (i.name for i in sess.get_inputs())


def best_car(img):
    h, w = img.shape[:2]
    small = cv2.resize(img, (SIDE, SIDE), interpolation=cv2.INTER_AREA)
    x = ((small.astype(np.float32) / 255.0 - MEAN / 255.0) / (STD / 255.0)).transpose(2, 0, 1)[None]
    factor = np.array([[SIDE / h, SIDE / w]], np.float32)
    rows = sess.run(None, {image: np.ascontiguousarray(x), scale: factor})[0]
    cars = rows[(rows[:, 0] == CAR)]
    if len(cars) == 0:
        return 0.0, [0.0, 0.0, 0.0, 0.0]
    r = cars[cars[:, 1].argmax()]
    return float(r[1]), [float(v) for v in r[2:6]]


print_best(sys.argv[2:], best_car)
