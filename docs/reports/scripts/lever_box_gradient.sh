#!/usr/bin/env bash
# The "gradients through the boxes" lever on the proxy of the attack study
# (docs/reports/transfer.md): the print-base recipe (three white boxes, photos and their turns,
# RAUCA-E2E's IoU-weighted log-max) against the same recipe with that weight differentiated
# (`loss.box_gradient = true`: each step also moves the boxes off the car), 3-fold crossval at
# seed 0 each, scored by the main and the wide detector sets (YOLOX-Nano, NanoDet-m and
# PP-PicoDet-XS held out). Pass an earlier base run of lever_screen.sh as BASE to reuse it.
# usage: [BASE=DIR] docs/reports/scripts/lever_box_gradient.sh OUT   (from the repository root)
set -euo pipefail
out=$1
source "$(dirname "$0")/lever_screen.sh"
variant "$out" box-gradient <<TOML

[loss]
box_gradient = true
TOML
screen "$out" box-gradient "box gradient"
