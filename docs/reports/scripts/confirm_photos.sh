#!/usr/bin/env bash
# The quick recipe against its variants on FCA's held-out photos, the full protocol
# (docs/reports/transfer.md): 11-fold crossval of configs/optimize/quick.toml (rec) and of
# each variant of VARIANTS (LABEL=CONFIG; by default recrig, the recipe with the rig views),
# one seed after the other, each seed all recipes, scored by the main and the wide detector sets
# beside RAUCA-E2E's texture. Then, for each variant, table1 of the seeds it and rec have both
# finished: those seeds under one label each into OUT/table1-LABEL, and each seed alone into
# OUT/table1-LABEL-seedS (the spread over seeds). Folds resume, so a stopped run picks up where
# it was; TABLES_ONLY=1 only writes the tables.
# usage: [SEEDS="0 1 2 3"] [VARIANTS="recrig=configs/studies/recommended-rig-views.toml"]
#        [TABLES_ONLY=1] docs/reports/scripts/confirm_photos.sh OUT   (from the repository root)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
variants=${VARIANTS:-recrig=configs/studies/recommended-rig-views.toml}
common=(--random-seeds 2 --reference data:rauca-e2e/RAUCA_E2E.png -d configs/detectors -d configs/detectors-wide)
if [ -z "${TABLES_ONLY:-}" ]; then
  for s in ${SEEDS:-0 1 2 3}; do
    for v in rec=configs/optimize/quick.toml $variants; do
      name=${v%%=*} cfg=${v#*=}
      [ -f "$out/$name/seed$s/crossval.csv" ] || "$pav" crossval --config "$cfg" --seeds "$s" "${common[@]}" -o "$out/$name"
    done
  done
fi
for v in $variants; do
  name=${v%%=*}
  args=(); labels=()
  for d in "$out"/rec/seed*/; do
    s=$(basename "$d")
    [ -f "$d/crossval.csv" ] && [ -f "$out/$name/$s/crossval.csv" ] || continue
    "$pav" table1 "$d" "$out/$name/$s" --label rec --label "$name" --against rec -o "$out/table1-$name-$s" > /dev/null
    args+=("$d" "$out/$name/$s"); labels+=(--label rec --label "$name")
  done
  if [ ${#args[@]} -gt 0 ]; then
    "$pav" table1 "${args[@]}" "${labels[@]}" --against rec -o "$out/table1-$name"
  fi
done
