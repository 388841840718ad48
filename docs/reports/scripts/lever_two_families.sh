#!/usr/bin/env bash
# The "new families as white boxes" lever on the proxy of the attack study (docs/reports/transfer.md):
# the print-base recipe (three white boxes, photos and their turns) against the same recipe with
# NanoDet-m and PP-PicoDet-XS (cut before its NMS) as a fourth and fifth white box, 3-fold crossval
# at seed 0 each, scored by the main and the wide detector sets: YOLOX-Nano is the only detector
# held out. The base run is the one of lever_nanodet.sh; pass its folder as BASE to reuse it.
# usage: [BASE=DIR] docs/reports/scripts/lever_two_families.sh OUT   (from the repository root; about 25 min)
set -euo pipefail
out=$1
source "$(dirname "$0")/lever_screen.sh"
d=$(realpath configs/detectors)
w=$(realpath configs/detectors-wide)
variant "$out" two-families <<TOML
white_box = [
  { detector = "$d/yolov3-tiny.toml" },
  { detector = "$d/yolov8n_int8.toml", surrogate = true },
  { detector = "$d/deimv2_atto_int8.toml", surrogate = true },
  { detector = "$w/nanodet_m_416.toml" },
  { detector = "$w/picodet_xs_320.toml" },
]
TOML
screen "$out" two-families "+nanodet+picodet"
