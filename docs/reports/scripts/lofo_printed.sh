#!/usr/bin/env bash
# A finished `pav lofo` run scored again with every texture printed (configs/studies/lofo/
# heldout-printed.toml): OUT links the run's trained units, so `pav lofo` trains nothing there
# and scores each arm's textures, RAUCA-E2E's and random blocks through the printer.
# usage: docs/reports/scripts/lofo_printed.sh LOFO_OUT OUT ARM.toml...   (SEEDS="0,1,2,3")
set -euo pipefail
lofo=$(realpath "$1")
out=$2
shift 2
pav=${PAV:-target/release/pav}
seeds=${SEEDS:-0,1,2,3}
for arm in "$@"; do
  name=$(basename "$arm" .toml)
  mkdir -p "$out/$name"
  for s in ${seeds//,/ }; do ln -sfn "$lofo/$name/seed$s" "$out/$name/seed$s"; done
done
"$pav" lofo "$@" --seeds "$seeds" --heldout configs/studies/lofo/heldout-printed.toml -o "$out"
