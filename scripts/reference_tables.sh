#!/usr/bin/env bash
# Rewrites the reference tables in tests/reference/ from the independent Python references, on
# FCA's 11 photos and frames of the turntable fixture (every fourth for the detectors, every
# eighth for the defences and clipping). Run it after the fixture changes.
# The references run in .venv-ref: onnxruntime 1.31.1, OpenCV 5.0, onnx and NumPy, e.g.
#   python3 -m venv .venv-ref && .venv-ref/bin/pip install onnxruntime==1.31.1 opencv-python-headless==5.0.0.* onnx numpy
# usage: scripts/reference_tables.sh [OUT_DIR]   (default tests/reference)
set -euo pipefail
out=${1:-tests/reference}
PY=${REF_PYTHON:-.venv-ref/bin/python}
PAV=${PAV:-target/release/pav}
"$PY" -c "import cv2, onnx, onnxruntime, numpy" \
  || { echo "reference_tables: $PY lacks cv2, onnx, onnxruntime or numpy (see the header of $0)" >&2; exit 1; }
fca=$("$PAV" data path fca/carla_dataset/train/data1.npz)
fca=${fca%/train/data1.npz}
photos=("$fca/train/data1.npz")
for k in 01 02 03 04 05 06 07 08 09 10; do photos+=("$fca/test/data125$k.npz"); done
mkdir -p "$out"
"$PY" scripts/reference_defences.py "${photos[@]}" fixtures/turntable.mp4:8 >"$out/defences.tsv"
"$PY" scripts/reference_clip.py "$("$PAV" data path models-yolox/yolox_nano.onnx)" 781,841,886 inf,1.5,1,0.8 \
  "${photos[@]}" fixtures/turntable.mp4:8 >"$out/clip_yolox_nano.tsv"
"$PY" scripts/reference_nanodet.py "$("$PAV" data path models-nanodet/nanodet_m_416.onnx)" \
  "${photos[@]}" fixtures/turntable.mp4:4 >"$out/nanodet_m_416.tsv"
"$PY" scripts/reference_picodet.py "$("$PAV" data path models-picodet/picodet_xs_320_lcnet_postprocessed.onnx)" \
  "${photos[@]}" fixtures/turntable.mp4:4 >"$out/picodet_xs_320.tsv"
