#!/usr/bin/env bash
# Held-out detector families for the quick recipe (docs/reports/transfer.md): the four seeds
# of the print study's unprinted base runs (their fold textures reused; only the scoring runs
# again) scored by the four shipped detectors and by NanoDet-m 416 and PP-PicoDet-XS, which no
# recipe trains against; then `pav table1` over the four seeds as one row.
# usage: docs/reports/scripts/wide_heldout.sh STUDY OUT (STUDY: the folder print_study.sh wrote)
set -euo pipefail
study=$1; out=$2
pav=${PAV:-target/release/pav}
mkdir -p "$out"
runs=()
for s in 0 1 2 3; do
  dir=$out/base-s$s
  if [ ! -f "$dir/crossval.csv" ]; then
    mkdir -p "$dir" && cp -r "$study/base-s$s"/fold* "$dir/"
    "$pav" crossval --config "$study/configs/base-s$s.toml" --folds 3 --random-seeds 1 \
      --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide -o "$dir" > "$dir.log" 2>&1
  fi
  runs+=("$dir")
done
"$pav" table1 "${runs[@]}" --label recommended --label recommended --label recommended --label recommended -o "$out/table1"
