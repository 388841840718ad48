#!/usr/bin/env bash
# The rig in the simulation (docs/reports/rig.md): four paints of the e-tron filmed on the paper's
# rig (configs/rig/phone-etron.toml) by both back-ends, first without camera effects, then with
# each effect alone and with all four, every video scored by the four shipped detectors.
# Blender renders each paint once; the effect variants cut its views again.
# usage: docs/reports/scripts/rig_study.sh OUT [PAV_TEXTURE] (run from the repository root)
#   PAV_TEXTURE: a pav texture.png for the e-tron's region of configs/studies/print-base.toml;
#   without it the script trains one (the defence study's undefended recipe at seed 0).
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
base=configs/rig/phone-etron.toml
mkdir -p "$out/rigs" "$out/paints"
here=$(pwd)
texture=${2:-$out/pav/texture.png}
if [ ! -f "$texture" ]; then
  source "$(dirname "$0")/defence_configs.sh"
  defence_configs "$out" 0
  "$pav" optimize --config "$out/configs/plain-s0.toml" -o "$out/pav"
fi
paint=(paint --config configs/studies/print-base.toml)
[ -f "$out/paints/random.png" ] || "$pav" "${paint[@]}" --random 0 -o "$out/paints/random.png"
[ -f "$out/paints/rauca.png" ] || "$pav" "${paint[@]}" --texture data:rauca-e2e/RAUCA_E2E.png -o "$out/paints/rauca.png"
[ -f "$out/paints/pav.png" ] || "$pav" "${paint[@]}" --texture "$texture" -o "$out/paints/pav.png"
for fx in none defocus motion-blur noise codec all; do
  case $fx in
    none) list='[]' ;;
    all) list='["defocus", "motion-blur", "noise", "codec"]' ;;
    *) list="[\"$fx\"]" ;;
  esac
  printf 'extends = "%s/%s"\neffects = %s\n' "$here" "$base" "$list" > "$out/rigs/$fx.toml"
done
score() { # dir label
  [ -f "$out/eval/$2/summary.csv" ] || "$rig" evaluate "$1"/videos/*.mp4 --label "$2" --label "$2" \
    -d configs/detectors --no-plots -o "$out/eval/$2" > /dev/null
}
for p in original random rauca pav; do
  tex=(); [ "$p" = original ] || tex=(--texture "$out/paints/$p.png")
  for fx in none defocus motion-blur noise codec all; do
    # Blender: the first variant renders, the others find the views and cut new videos.
    "$pav" views turntable --rig "$out/rigs/$fx.toml" "${tex[@]}" -o "$out/blender/$p" > /dev/null
    score "$out/blender/$p" "blender-$p-$fx"
    "$pav" views turntable --rig "$out/rigs/$fx.toml" --rasterizer "${tex[@]}" -o "$out/raster/$p-$fx" > /dev/null
    score "$out/raster/$p-$fx" "raster-$p-$fx"
  done
done
python3 docs/reports/scripts/rig_table.py "$out" > "$out/tables.md"
echo "tables in $out/tables.md"
