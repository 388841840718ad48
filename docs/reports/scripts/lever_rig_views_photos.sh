#!/usr/bin/env bash
# The "views of the model on the rig" lever on FCA's held-out photos (docs/reports/transfer.md):
# configs/studies/rig-views.toml against its base, configs/studies/print-base.toml, each a 3-fold
# crossval at seed 0 scored by the main and the wide detector sets, as the other lever screens
# (lever_screen.sh; BASE=FOLDER links a finished base run). The rig views are rendered first
# (lever_rig_views.sh renders the same folders).
# usage: [BASE=DIR] docs/reports/scripts/lever_rig_views_photos.sh OUT   (from the repository root)
set -euo pipefail
out=$1
source "$(dirname "$0")/lever_screen.sh"
mkdir -p "$out/configs"
printf 'extends = "%s"\n' "$(realpath configs/studies/rig-views.toml)" > "$out/configs/rig.toml"
screen "$out" rig "rig views"
