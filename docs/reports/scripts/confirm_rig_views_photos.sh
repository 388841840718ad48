#!/usr/bin/env bash
# The recommended recipe with and without the rig views on FCA's held-out photos, the full
# protocol (docs/reports/transfer.md, "The rig views on FCA's held-out photos"): 11-fold crossval
# of configs/optimize/recommended.toml (rec) and configs/studies/recommended-rig-views.toml
# (recrig), one seed after the other for both recipes, scored by the main and the wide detector
# sets beside RAUCA-E2E's texture. Then table1 of the seeds both recipes have finished: each
# recipe's seeds under one label into OUT/table1, and each seed alone into OUT/table1-seedS (the
# spread over seeds). Folds resume, so a stopped run picks up where it was; TABLES_ONLY=1 only
# writes the tables.
# usage: [SEEDS="0 1 2 3"] [TABLES_ONLY=1] docs/reports/scripts/confirm_rig_views_photos.sh OUT
#        (from the repository root)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
common=(--random-seeds 2 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
declare -A config=([rec]=configs/optimize/recommended.toml [recrig]=configs/studies/recommended-rig-views.toml)
if [ -z "${TABLES_ONLY:-}" ]; then
  for s in ${SEEDS:-0 1 2 3}; do
    for name in rec recrig; do
      [ -f "$out/$name/seed$s/crossval.csv" ] || "$pav" crossval --config "${config[$name]}" --seeds "$s" "${common[@]}" -o "$out/$name"
    done
  done
fi
args=(); labels=()
for d in "$out"/rec/seed*/; do
  s=$(basename "$d")
  [ -f "$d/crossval.csv" ] && [ -f "$out/recrig/$s/crossval.csv" ] || continue
  "$pav" table1 "$d" "$out/recrig/$s" --label rec --label recrig --against rec -o "$out/table1-$s" > /dev/null
  args+=("$d" "$out/recrig/$s"); labels+=(--label rec --label recrig)
done
"$pav" table1 "${args[@]}" "${labels[@]}" --against rec -o "$out/table1"
