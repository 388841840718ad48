#!/usr/bin/env bash
# The recommended recipe with and without the rig views on FCA's held-out photos, the full
# protocol (docs/reports/transfer.md, "The rig views on FCA's photos"): 11-fold crossval of
# configs/optimize/recommended.toml (rec) and configs/studies/recommended-rig-views.toml (recrig),
# one seed after the other for both recipes, scored by the main and the wide detector sets beside
# RAUCA-E2E's texture; then table1 of the seeds done so far, each recipe's seeds under one label.
# Folds resume, so a stopped run picks up where it was.
# usage: [SEEDS="0 1 2 3"] docs/reports/scripts/confirm_rig_views_photos.sh OUT   (from the repository root)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
common=(--random-seeds 2 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
declare -A config=([rec]=configs/optimize/recommended.toml [recrig]=configs/studies/recommended-rig-views.toml)
for s in ${SEEDS:-0 1 2 3}; do
  for name in rec recrig; do
    [ -f "$out/$name/seed$s/crossval.csv" ] || "$pav" crossval --config "${config[$name]}" --seeds "$s" "${common[@]}" -o "$out/$name"
  done
done
args=(); labels=()
for name in rec recrig; do
  for d in "$out/$name"/seed*/; do
    [ -f "$d/crossval.csv" ] && args+=("$d") && labels+=(--label "$name")
  done
done
"$pav" table1 "${args[@]}" "${labels[@]}" --against rec -o "$out/table1"
