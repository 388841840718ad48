#!/usr/bin/env python3
"""NanoDet-m 416 on real images, written from the upstream demo (hpc203/nanodet-opncv-dnn-cpp-python,
main_nanodet.py) with onnxruntime in place of cv2.dnn, not from pav's decoder: BGR, centred
letterbox with cv2.INTER_AREA and zero padding, ImageNet-style mean/std in BGR order; per stride a
class map (sigmoid applied) and a box map of 4 x 8-bin distances (softmax, expectation, x stride)
from the cell centre x*stride + (stride-1)/2. The demo pairs the maps by output order under
OpenCV DNN; onnxruntime orders them differently, so they are paired by width (80 classes, 32 bins).
Prints per image: name, best car score (COCO class 2, before NMS) and its box in image pixels.
usage: reference_nanodet.py MODEL.onnx (FILE.npz | VIDEO.mp4[:every])..."""
import sys

import cv2
import numpy as np
import onnxruntime as ort
from reference_images import print_best

SIDE, STRIDES, BINS, CAR = 416, (8, 16, 32), 8, 2
MEAN = np.array([103.53, 116.28, 123.675], np.float32)
STD = np.array([57.375, 57.12, 58.395], np.float32)
sess = ort.InferenceSession(sys.argv[1], providers=["CPUExecutionProvider"])
name = sess.get_inputs()[0].name


def letterbox(img):
    h, w = img.shape[:2]
    top = left = 0
    newh, neww = SIDE, SIDE
    if h != w:
        hw = h / w
        if hw > 1:
            newh, neww = SIDE, int(SIDE / hw)
            small = cv2.resize(img, (neww, newh), interpolation=cv2.INTER_AREA)
            left = int((SIDE - neww) * 0.5)
            small = cv2.copyMakeBorder(small, 0, 0, left, SIDE - neww - left, cv2.BORDER_CONSTANT, value=0)
        else:
            newh, neww = int(SIDE * hw), SIDE
            small = cv2.resize(img, (neww, newh), interpolation=cv2.INTER_AREA)
            top = int((SIDE - newh) * 0.5)
            small = cv2.copyMakeBorder(small, top, SIDE - newh - top, 0, 0, cv2.BORDER_CONSTANT, value=0)
    else:
        small = cv2.resize(img, (SIDE, SIDE), interpolation=cv2.INTER_AREA)
    return small, newh, neww, top, left


def best_car(img):
    small, newh, neww, top, left = letterbox(img)
    x = ((small.astype(np.float32) - MEAN) / STD).transpose(2, 0, 1)[None]
    outs = sess.run(None, {name: np.ascontiguousarray(x)})
    best = (-1.0, None)
    for s in STRIDES:
        n = (SIDE // s) ** 2
        cls = next(o[0] for o in outs if o.shape[1] == n and o.shape[2] == 80)
        reg = next(o[0] for o in outs if o.shape[1] == n and o.shape[2] == 4 * BINS)
        i = int(cls[:, CAR].argmax())
        if cls[i, CAR] > best[0]:
            d = reg[i].reshape(4, BINS)
            d = np.exp(d - d.max(axis=1, keepdims=True))
            d = (d / d.sum(axis=1, keepdims=True)) @ np.arange(BINS) * s
            g = SIDE // s
            cx, cy = (i % g) * s + 0.5 * (s - 1), (i // g) * s + 0.5 * (s - 1)
            b = np.clip([cx - d[0], cy - d[1], cx + d[2], cy + d[3]], 0, SIDE)
            rw, rh = img.shape[1] / neww, img.shape[0] / newh
            best = (float(cls[i, CAR]), [(b[0] - left) * rw, (b[1] - top) * rh, (b[2] - left) * rw, (b[3] - top) * rh])
    return best


print_best(sys.argv[2:], best_car)
