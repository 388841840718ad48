#!/usr/bin/env bash
# Leave one family out at scale (docs/reports/scale.md): draw the 3,096 training views of
# configs/views/scale.toml, train every arm of configs/studies/scale/ at four seeds and score
# each on the held-out set, then film every arm's textures on the simulated rig from four camera
# heights (configs/rig/phone-etron-dense.toml) on screen and as printed, and score the held-out
# set again with every texture printed (into OUT-printed). Every step resumes, so rerunning the
# script after a stop goes on where it stopped.
# usage: docs/reports/scripts/scale.sh [OUT]   (needs out/views_heldout; default OUT out/scale)
set -euo pipefail
out=${1:-out/scale}
pav=${PAV:-target/release/pav}
seeds=${SEEDS:-0,1,2,3}
"$pav" views render configs/views/scale.toml -o out/views_scale
"$pav" lofo configs/studies/scale/without-*.toml --seeds "$seeds" -o "$out"
SEEDS="${seeds//,/ }" RIG_CONFIG=configs/rig/phone-etron-dense.toml \
  bash "$(dirname "$0")/lofo_rig.sh" "$out/rig" "$out" configs/studies/scale/without-*.toml
SEEDS="$seeds" bash "$(dirname "$0")/lofo_printed.sh" "$out" "$out-printed" configs/studies/scale/without-*.toml
