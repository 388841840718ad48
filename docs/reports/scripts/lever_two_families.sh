#!/usr/bin/env bash
# The "new families as white boxes" lever on the proxy of the attack study (docs/reports/transfer.md):
# the print-base recipe (three white boxes, photos and their turns) against the same recipe with
# NanoDet-m and PP-PicoDet-XS (cut before its NMS) as a fourth and fifth white box, 3-fold crossval
# at seed 0 each, scored by the main and the wide detector sets: YOLOX-Nano is the only detector
# held out. The base run is the one of lever_nanodet.sh; pass its folder as BASE to reuse it.
# usage: [BASE=DIR] docs/reports/scripts/lever_two_families.sh OUT   (from the repository root; about 25 min)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
base=configs/studies/print-base.toml
d=$(realpath configs/detectors)
w=$(realpath configs/detectors-wide)
mkdir -p "$out/configs"
cat > "$out/configs/two-families.toml" <<TOML
extends = "$(realpath $base)"
white_box = [
  { detector = "$d/yolov3-tiny.toml" },
  { detector = "$d/yolov8n_int8.toml", surrogate = true },
  { detector = "$d/deimv2_atto_int8.toml", surrogate = true },
  { detector = "$w/nanodet_m_416.toml" },
  { detector = "$w/picodet_xs_320.toml" },
]
TOML
common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
if [ -n "${BASE:-}" ] && [ ! -e "$out/base" ]; then ln -s "$(realpath "$BASE")" "$out/base"; fi
[ -f "$out/base/crossval.csv" ] || "$pav" crossval --config $base "${common[@]}" -o "$out/base"
[ -f "$out/two-families/crossval.csv" ] || "$pav" crossval --config "$out/configs/two-families.toml" "${common[@]}" -o "$out/two-families"
"$pav" table1 "$out/base" "$out/two-families" --label base --label "+nanodet+picodet" --against base -o "$out/table1"
