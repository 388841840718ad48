#!/usr/bin/env bash
# The rig views with a lower `views.pbr_min_score` (0.2 instead of 0.5, so that more of the 144
# views reach training), at seed 0, filmed and scored by lever_rig_views.sh beside that script's
# seed-0 textures (kept from its run into the same OUT), and compared with the rig views at 0.5.
# usage: docs/reports/scripts/lever_rig_views_threshold.sh OUT   (from the repository root)
set -euo pipefail
out=$1
mkdir -p "$out/configs"
printf 'extends = "%s/configs/studies/rig-views.toml"\n\n[views]\npbr_min_score = 0.2\n' "$(pwd)" > "$out/configs/rig02.toml"
SEEDS=0 EVAL=eval-threshold AGAINST=rig \
  VARIANTS="plain=configs/studies/print-base.toml rig=configs/studies/rig-views.toml rig02=$(realpath "$out/configs/rig02.toml")" \
  "$(dirname "$0")/lever_rig_views.sh" "$out"
