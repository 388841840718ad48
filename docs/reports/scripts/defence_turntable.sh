#!/usr/bin/env bash
# The defence study on the simulated turntable (docs/reports/defences.md): one texture per recipe
# of defence_study.sh at seed 0 (trained on its six training photos), painted on the e-tron and
# filmed by pav's rasterizer at polar angles 0° and 20°, beside the original paint and
# RAUCA-E2E's texture; every video scored by YOLOv3-tiny, DEIMv2 and YOLOX-Nano, plain, behind the
# five input defences and clipped, 44 frames a turn.
# usage: docs/reports/scripts/defence_turntable.sh OUT (run from the repository root, after
# defence_study.sh OUT 0 wrote OUT/configs)
set -euo pipefail
out=$1
# The clipping level: the unpainted car of the turntable fixture, each model clipped after its
# three backbone stages at 1, 1.5 and 2 times the mean feature norm.
clip_levels() { # name config layers
  [ -f "$out/clip-levels/$1/summary.csv" ] || "${RIG:-target/release/pav-rig}" evaluate fixtures/turntable.mp4 -d "$2" \
    --defence "clip:layers=$3,level=1" --defence "clip:layers=$3,level=1.5" --defence "clip:layers=$3,level=2" \
    --no-plots -o "$out/clip-levels/$1"
}
clip_levels yolov3-tiny configs/detectors/yolov3-tiny.toml "['l6','l8','l12']"
clip_levels yolox_nano configs/detectors/yolox_nano.toml "['781','841','886']"
s=/backbone/stages
clip_levels deimv2 configs/detectors/deimv2_atto_int8.toml \
  "['$s.0/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0','$s.1/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0','$s.2/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0']"
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
car=configs/views/turntable.toml
mkdir -p "$out/turntable"
paint() { # name texture
  "$pav" paint --config configs/studies/print-base.toml --texture "$2" -o "$out/turntable/$1.png"
}
for r in plain median clip; do
  [ -f "$out/turntable/$r/texture.png" ] || "$pav" optimize --config "$out/configs/$r-s0.toml" -o "$out/turntable/$r"
  [ -f "$out/turntable/$r.png" ] || paint "$r" "$out/turntable/$r/texture.png"
done
[ -f "$out/turntable/rauca.png" ] || paint rauca data:rauca-e2e/RAUCA_E2E.png
videos=(); labels=()
for p in original rauca plain median clip; do
  for e in 0 20; do
    v="$out/turntable/$p-$e.mp4"
    tex=(); [ "$p" = original ] || tex=(--texture "$out/turntable/$p.png")
    [ -f "$v" ] || "$rig" capture --port sim --camera sim --car "$car" --elevation $e --time-scale 4 \
      --width 640 --height 480 --fps 10 "${tex[@]}" -o "$v"
    videos+=("$v"); labels+=(--label "$p")
  done
done
[ -f "$out/turntable/eval/summary.csv" ] || "$rig" evaluate "${videos[@]}" "${labels[@]}" --sample 44 \
  -d configs/detectors/yolov3-tiny.toml -d configs/detectors/deimv2_atto_int8.toml -d configs/detectors/yolox_nano.toml \
  --defence median:k=3 --defence bits:b=4 --defence jpeg:q=75 --defence cutout:n=2,s=60 --defence noise:sigma=8 \
  -o "$out/turntable/eval"
[ -f "$out/turntable/eval-clipped/summary.csv" ] || "$rig" evaluate "${videos[@]}" "${labels[@]}" --sample 44 -d configs/defences -o "$out/turntable/eval-clipped"
# DEIMv2's float surrogate (clipping at an infinite level rewrites nothing else) against the int8
# model, unclipped and clipped at 2, on FCA's 11 photos and on the turntable's unpainted car.
deim="['$s.0/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0','$s.1/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0','$s.2/blocks/blocks.0/aggregation/aggregation.1/lab/Add_output_0']"
[ -f "$out/surrogate/digital.csv" ] || "$pav" eval-digital --config configs/optimize/paper.toml \
  -d configs/detectors/deimv2_atto_int8.toml --defence "clip:layers=$deim,level=inf" --defence "clip:layers=$deim,level=2" \
  --random-seeds 1 -o "$out/surrogate"
[ -f "$out/turntable/eval-surrogate/summary.csv" ] || "$rig" evaluate "$out/turntable/original-0.mp4" \
  "$out/turntable/original-20.mp4" --label original --label original --sample 44 -d configs/detectors/deimv2_atto_int8.toml \
  --defence "clip:layers=$deim,level=inf" --no-plots -o "$out/turntable/eval-surrogate"
