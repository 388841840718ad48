#!/usr/bin/env bash
# The "new family as a white box" lever on the proxy of the attack study (docs/reports/transfer.md):
# the print-base recipe (three white boxes, photos and their turns) against the same recipe with
# NanoDet-m as a fourth white box, 3-fold crossval at seed 0 each, scored by the main and the wide
# detector sets (YOLOX-Nano and PP-PicoDet-XS stay held out in both).
# usage: docs/reports/scripts/lever_nanodet.sh OUT   (from the repository root; about 20 min)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
base=configs/studies/print-base.toml
d=$(realpath configs/detectors)
mkdir -p "$out/configs"
cat > "$out/configs/nanodet.toml" <<TOML
extends = "$(realpath $base)"
white_box = [
  { detector = "$d/yolov3-tiny.toml" },
  { detector = "$d/yolov8n_int8.toml", surrogate = true },
  { detector = "$d/deimv2_atto_int8.toml", surrogate = true },
  { detector = "$(realpath configs/detectors-wide/nanodet_m_416.toml)" },
]
TOML
common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
[ -f "$out/base/crossval.csv" ] || "$pav" crossval --config $base "${common[@]}" -o "$out/base"
[ -f "$out/nanodet/crossval.csv" ] || "$pav" crossval --config "$out/configs/nanodet.toml" "${common[@]}" -o "$out/nanodet"
"$pav" table1 "$out/base" "$out/nanodet" --label base --label "+nanodet" --against base -o "$out/table1"
