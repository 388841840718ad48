#!/usr/bin/env python3
"""Input defences on real images, written with OpenCV and NumPy, not from pav's code: median
smoothing is cv2.medianBlur, bit-depth squeezing Xu et al.'s round(x * (2^b - 1)) / (2^b - 1) on
x = v / 255, JPEG cv2.imencode/cv2.imdecode at IMWRITE_JPEG_QUALITY q, Gaussian noise NumPy's
normal(0, sigma) added, rounded and clipped to 0-255.
Prints per image and defence: the SHA-256 of the output's BGR bytes (row-major; not for noise,
whose draws differ from pav's), the mean absolute change in levels, and the mean and standard
deviation of the change (noise: how clipping at 0 and 255 shapes it on this image).
usage: reference_defences.py (FILE.npz | VIDEO.mp4[:every])..."""
import hashlib
import sys

import cv2
import numpy as np
from reference_images import images

DEFENCES = ["median:k=3", "median:k=5", "median:k=7", "bits:b=1", "bits:b=3", "bits:b=5", "bits:b=7",
            "jpeg:q=10", "jpeg:q=50", "jpeg:q=75", "jpeg:q=95", "noise:sigma=8", "noise:sigma=25"]


def apply(spec, img, rng):
    kind, param = spec.split(":")
    value = float(param.split("=")[1])
    if kind == "median":
        return cv2.medianBlur(img, int(value))
    if kind == "bits":
        steps = 2 ** int(value) - 1
        return np.round(np.round(img / 255.0 * steps) / steps * 255.0).astype(np.uint8)
    if kind == "jpeg":
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(value)])
        assert ok
        return cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if kind == "noise":
        return np.clip(np.round(img + rng.normal(0.0, value, img.shape)), 0, 255).astype(np.uint8)
    raise ValueError(spec)


rng = np.random.default_rng(0)
print("image\tdefence\tsha256\tmean_abs\tmean\tsd")
for label, img in images(sys.argv[1:]):
    img = np.ascontiguousarray(img)
    for spec in DEFENCES:
        out = np.ascontiguousarray(apply(spec, img, rng))
        d = out.astype(np.float64) - img
        digest = "-" if spec.startswith("noise") else hashlib.sha256(out.tobytes()).hexdigest()
        print(f"{label}\t{spec}\t{digest}\t{np.abs(d).mean():.4f}\t{d.mean():.4f}\t{d.std():.4f}")
