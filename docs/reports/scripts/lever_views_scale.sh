#!/usr/bin/env bash
# The "views at scale" lever on the proxy of the attack study (docs/reports/transfer.md): the
# recommended recipe, trained beside the e-tron over FCA's plates under 3 light maps (297 views,
# configs/views/etron-plates-wide.toml), against the same recipe under 6 light maps (594 views,
# configs/views/etron-plates-lights.toml); 3-fold crossval at seed 0 each,
# scored by the main and the wide detector sets (YOLOX-Nano, NanoDet-m and PP-PicoDet-XS held
# out). Renders what is missing first: the 297 views (about 30 min on two cores), then the other
# 297 (about 30 min), resuming from the first folder. The larger set is streamed (`views.stream`:
# the same texture, each view rebuilt from its files when stepped on), which also measures what
# streaming costs per step and saves in memory.
# usage: docs/reports/scripts/lever_views_scale.sh OUT   (from the repository root)
set -euo pipefail
out=$1
source "$(dirname "$0")/lever_screen.sh"
base=configs/optimize/quick.toml
wide=out/views_etron_plates_wide lights=out/views_etron_plates_lights
"$pav" views render configs/views/etron-plates-wide.toml -o $wide
[ -d $lights ] || cp -r $wide $lights
"$pav" views render configs/views/etron-plates-lights.toml -o $lights
variant "$out" lights <<TOML

[views]
pbr = ["$(realpath $lights)"]
render = ["$(realpath configs/views/etron-plates-lights.toml)"]
stream = true
TOML
screen "$out" lights "6 light maps"
