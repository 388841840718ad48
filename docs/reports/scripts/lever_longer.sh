#!/usr/bin/env bash
# The "longer schedule" lever on the proxy of the attack study (docs/reports/transfer.md): the
# print-base recipe (three white boxes, photos and their turns, 2 epochs) against the same recipe
# trained three times as long (6 epochs), 3-fold crossval at seed 0 each, scored by the main and
# the wide detector sets (YOLOX-Nano, NanoDet-m and PP-PicoDet-XS held out). The base run is the
# one of lever_nanodet.sh; pass its folder as BASE to reuse it.
# usage: [BASE=DIR] docs/reports/scripts/lever_longer.sh OUT   (from the repository root; about 15 min)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
base=configs/studies/print-base.toml
mkdir -p "$out/configs"
cat > "$out/configs/longer.toml" <<TOML
extends = "$(realpath $base)"

[optimizer]
epochs = 6
TOML
common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
if [ -n "${BASE:-}" ] && [ ! -e "$out/base" ]; then ln -s "$(realpath "$BASE")" "$out/base"; fi
[ -f "$out/base/crossval.csv" ] || "$pav" crossval --config $base "${common[@]}" -o "$out/base"
[ -f "$out/longer/crossval.csv" ] || "$pav" crossval --config "$out/configs/longer.toml" "${common[@]}" -o "$out/longer"
"$pav" table1 "$out/base" "$out/longer" --label base --label "6 epochs" --against base -o "$out/table1"
