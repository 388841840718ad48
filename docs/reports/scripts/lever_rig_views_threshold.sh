#!/usr/bin/env bash
# The rig views with a lower `views.pbr_min_score` (0.2 instead of 0.5, so that more of the 144
# views reach training), at seed 0, filmed and scored as lever_rig_views.sh does, beside that
# script's seed-0 textures (run it first into the same OUT).
# usage: docs/reports/scripts/lever_rig_views_threshold.sh OUT   (from the repository root)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
here=$(pwd)
printf 'extends = "%s/configs/studies/rig-views.toml"\n\n[views]\npbr_min_score = 0.2\n\n[optimizer]\nseed = 0\n' "$here" > "$out/configs/rig02-s0.toml"
[ -f "$out/rig02-s0/texture.png" ] || "$pav" optimize --config "$out/configs/rig02-s0.toml" -o "$out/rig02-s0"
[ -f "$out/paint/rig02-s0.png" ] || "$pav" paint --config configs/studies/print-base.toml --texture "$out/rig02-s0/texture.png" -o "$out/paint/rig02-s0.png"
"$pav" views turntable --rig "$out/rig.toml" --texture "$out/paint/rig02-s0.png" -o "$out/film/rig02-s0" > /dev/null
videos=(); labels=()
for p in original/videos rauca/videos plain-s0/videos rig-s0/videos rig02-s0/videos; do
  for v in "$out/film/$p"/*.mp4; do videos+=("$v"); labels+=(--label "${p%%/*}"); done
done
"$rig" evaluate "${videos[@]}" "${labels[@]}" -d configs/detectors -d configs/detectors-wide -o "$out/eval-threshold"
"$rig" paired "$out/eval-threshold" --against rig-s0 -o "$out/paired-threshold"
