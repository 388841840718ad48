#!/usr/bin/env bash
# What a training view's fidelity is worth (docs/reports/fidelity.md). For each level, from the
# cheapest: draw the 99 training views of configs/views/fidelity/LEVEL.toml, then leave
# YOLOX-Nano and NanoDet-m out in turn (configs/studies/fidelity/LEVEL/) at seeds 0 and 1 and
# score each on the held-out set. Every step resumes, so rerunning the script after a stop goes
# on where it stopped. Then the table of held-out results against each level's cost per view.
# usage: docs/reports/scripts/fidelity.sh [OUT]   (needs out/views_heldout; default OUT out/fidelity)
set -euo pipefail
out=${1:-out/fidelity}
pav=${PAV:-target/release/pav}
seeds=${SEEDS:-0,1}
for level in rasterizer cycles4 cycles16 cycles64 cycles16-208; do
  "$pav" views render "configs/views/fidelity/$level.toml" -o "$out/$level/views"
  "$pav" lofo configs/studies/fidelity/$level/without-*.toml --seeds "$seeds" -o "$out/$level"
done
