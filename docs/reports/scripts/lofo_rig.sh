#!/usr/bin/env bash
# Leave-one-family-out on the simulated rig: every arm's textures of a `pav lofo` run, RAUCA-E2E's
# texture and random blocks, each stuck on the e-tron on screen and as printed through the
# default CMYK profile (`pav paint --print`), filmed on the phone rig by pav's rasterizer (two
# camera heights, 22 frames a turn), and scored frame by frame by the family each arm left out.
# Every step skips what is already there, so a rerun goes on where it stopped. Then the table,
# paired frame by frame against each reference with intervals over seeds and frames.
# usage: docs/reports/scripts/lofo_rig.sh OUT LOFO_OUT ARM.toml...   (from the repository root)
#   e.g. docs/reports/scripts/lofo_rig.sh out/lofo-rig out/lofo configs/studies/lofo/without-*.toml
set -euo pipefail
out=$1
lofo=$2
shift 2
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
rig_config=${RIG_CONFIG:-configs/rig/phone-etron.toml}
seeds=${SEEDS:-0 1 2 3}
randoms=${RANDOMS:-1 2 3 4}
# The arms share the car and its region, so any of them paints every texture.
first=$1
detector_of() { # NAME: the detector config a family's name comes from
  ls configs/detectors/"$1".toml configs/detectors-wide/"$1".toml 2>/dev/null | head -n 1
}
film() { # MODE LABEL TEXTURE-ARGS...: paint, then film with the rasterizer
  local mode=$1 label=$2
  shift 2
  local print=()
  [ "$mode" = printed ] && print=(--print)
  local paint="$out/$mode/paints/$label.png" films="$out/$mode/films/$label"
  mkdir -p "$out/$mode/paints"
  [ -f "$paint" ] || "$pav" paint --config "$first" "${print[@]}" "$@" -o "$paint" > /dev/null
  [ -f "$films/done" ] || {
    "$pav" views turntable --rig "$rig_config" --rasterizer --texture "$paint" -o "$films" > /dev/null
    touch "$films/done"
  }
}
for mode in screen printed; do
  film "$mode" rauca --texture data:rauca-e2e/RAUCA_E2E.png
  for r in $randoms; do film "$mode" "random$r" --random "$r"; done
  for arm in "$@"; do
    name=$(basename "$arm" .toml)
    held=${name#without-}
    for s in $seeds; do film "$mode" "$name-s$s" --texture "$lofo/$name/seed$s/texture.png"; done
    eval_dir="$out/$mode/eval/$name"
    every="rauca $(printf 'random%s ' $randoms)$(printf "$name-s%s " $seeds)"
    # The summary is written last and names every video it scored, so a stopped evaluation runs
    # again, as does one of other seeds.
    [ -f "$eval_dir/summary.csv" ] && [ "$(tail -n +2 "$eval_dir/summary.csv" | cut -d, -f1 | tr '\n' ' ')" = "$every" ] && continue
    videos=() labels=()
    for label in $every; do
      for v in "$out/$mode/films/$label"/videos/*.mp4; do videos+=("$v"); labels+=(--label "$label"); done
    done
    "$rig" evaluate "${videos[@]}" "${labels[@]}" -d "$(detector_of "$held")" --no-plots -o "$eval_dir" > /dev/null
  done
done
python3 "$(dirname "$0")/lofo_rig_table.py" "$out" $seeds > "$out/lofo_rig.csv"
echo "table in $out/lofo_rig.csv"
