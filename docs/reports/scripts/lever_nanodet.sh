#!/usr/bin/env bash
# The "new family as a white box" lever on the proxy of the attack study (docs/reports/transfer.md):
# the print-base recipe (three white boxes, photos and their turns) against the same recipe with
# NanoDet-m as a fourth white box, 3-fold crossval at seed 0 each, scored by the main and the wide
# detector sets (YOLOX-Nano and PP-PicoDet-XS stay held out in both).
# usage: docs/reports/scripts/lever_nanodet.sh OUT   (from the repository root; about 20 min)
set -euo pipefail
out=$1
source "$(dirname "$0")/lever_screen.sh"
d=$(realpath configs/detectors)
variant "$out" nanodet <<TOML
white_box = [
  { detector = "$d/yolov3-tiny.toml" },
  { detector = "$d/yolov8n_int8.toml", surrogate = true },
  { detector = "$d/deimv2_atto_int8.toml", surrogate = true },
  { detector = "$(realpath configs/detectors-wide/nanodet_m_416.toml)" },
]
TOML
screen "$out" nanodet "+nanodet"
