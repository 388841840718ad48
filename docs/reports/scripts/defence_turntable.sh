#!/usr/bin/env bash
# The defence study on the simulated rig (docs/reports/defences.md): one texture per recipe of
# defence_study.sh at seed 0 (trained on its six training photos), painted on the e-tron model
# and filmed by Blender on the paper's rig (configs/rig/phone-etron.toml, polar angles 0° and
# 20°, 44 frames a turn each), beside the original paint and RAUCA-E2E's texture; every video
# scored by YOLOv3-tiny, DEIMv2 and YOLOX-Nano, plain, behind the five input defences and clipped.
# usage: docs/reports/scripts/defence_turntable.sh OUT (run from the repository root)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
here=$(pwd)
source "$(dirname "$0")/defence_configs.sh"
defence_configs "$out" 0
# The clipping level: the unpainted model of the turntable fixture, each model clipped after its
# three backbone stages at 1, 1.5 and 2 times the mean feature norm.
clip_levels() { # name config layers
  [ -f "$out/clip-levels/$1/summary.csv" ] || "$rig" evaluate fixtures/turntable.mp4 -d "$2" \
    --defence "clip:layers=$3,level=1" --defence "clip:layers=$3,level=1.5" --defence "clip:layers=$3,level=2" \
    --no-plots -o "$out/clip-levels/$1"
}
clip_levels yolov3-tiny configs/detectors/yolov3-tiny.toml "['l6','l8','l12']"
clip_levels yolox_nano configs/detectors/yolox_nano.toml "['781','841','886']"
s=/backbone/stages
deim="['$s.0/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0','$s.1/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0','$s.2/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0']"
clip_levels deimv2 configs/detectors/deimv2_atto_int8.toml "$deim"
mkdir -p "$out/turntable"
printf 'extends = "%s/configs/rig/phone-etron.toml"\n\n[render]\nframes = 44\n' "$here" > "$out/turntable/rig.toml"
paint() { # name texture
  [ -f "$out/turntable/$1.png" ] || "$pav" paint --config configs/studies/print-base.toml --texture "$2" -o "$out/turntable/$1.png"
}
for r in plain median clip; do
  [ -f "$out/turntable/$r/texture.png" ] || "$pav" optimize --config "$out/configs/$r-s0.toml" -o "$out/turntable/$r"
  paint "$r" "$out/turntable/$r/texture.png"
done
paint rauca data:rauca-e2e/RAUCA_E2E.png
videos=(); labels=()
for p in original rauca plain median clip; do
  tex=(); [ "$p" = original ] || tex=(--texture "$out/turntable/$p.png")
  "$pav" views turntable --rig "$out/turntable/rig.toml" "${tex[@]}" -o "$out/turntable/film/$p" > /dev/null
  for v in "$out/turntable/film/$p"/videos/*.mp4; do videos+=("$v"); labels+=(--label "$p"); done
done
[ -f "$out/turntable/eval/summary.csv" ] || "$rig" evaluate "${videos[@]}" "${labels[@]}" \
  -d configs/detectors/yolov3-tiny.toml -d configs/detectors/deimv2_atto_int8.toml -d configs/detectors/yolox_nano.toml \
  --defence median:k=3 --defence bits:b=4 --defence jpeg:q=75 --defence cutout:n=2,s=60 --defence noise:sigma=8 \
  -o "$out/turntable/eval"
[ -f "$out/turntable/eval-clipped/summary.csv" ] || "$rig" evaluate "${videos[@]}" "${labels[@]}" -d configs/defences \
  -o "$out/turntable/eval-clipped"
# DEIMv2's float surrogate (clipping at an infinite level rewrites nothing else) against the int8
# model, unclipped and clipped at 2, on FCA's 11 photos and on the rig's unpainted model.
[ -f "$out/surrogate/digital.csv" ] || "$pav" eval-digital --config configs/optimize/paper.toml \
  -d configs/detectors/deimv2_atto_int8.toml --defence "clip:layers=$deim,level=inf" --defence "clip:layers=$deim,level=2" \
  --random-seeds 1 -o "$out/surrogate"
[ -f "$out/turntable/eval-surrogate/summary.csv" ] || "$rig" evaluate "$out/turntable/film/original"/videos/*.mp4 \
  --label original --label original -d configs/detectors/deimv2_atto_int8.toml \
  --defence "clip:layers=$deim,level=inf" --defence "clip:layers=$deim,level=2" --no-plots -o "$out/turntable/eval-surrogate"
