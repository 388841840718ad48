#!/usr/bin/env bash
# The "longer schedule" lever on the proxy of the attack study (docs/reports/transfer.md): the
# print-base recipe (three white boxes, photos and their turns, 2 epochs) against the same recipe
# trained three times as long (6 epochs), 3-fold crossval at seed 0 each, scored by the main and
# the wide detector sets (YOLOX-Nano, NanoDet-m and PP-PicoDet-XS held out). The base run is the
# one of lever_nanodet.sh; pass its folder as BASE to reuse it.
# usage: [BASE=DIR] docs/reports/scripts/lever_longer.sh OUT   (from the repository root; about 15 min)
set -euo pipefail
out=$1
source "$(dirname "$0")/lever_screen.sh"
variant "$out" longer <<TOML

[optimizer]
epochs = 6
TOML
screen "$out" longer "6 epochs"
