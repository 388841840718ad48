#!/usr/bin/env bash
# The defence study (docs/reports/defences.md): for each seed, cross-validate (3 folds over FCA's
# 11 photos) the photo recipe of configs/studies/print-base.toml trained without defences, and
# trained through median smoothing (each white box behind `median:k=3`, differentiated) and
# through feature norm clipping (YOLOv3-tiny and DEIMv2 white boxes clipped at twice the mean
# feature norm, the clipping differentiated). Every run is scored by YOLOv3-tiny, DEIMv2 and the
# never-trained YOLOX-Nano, each plain and behind five input defences; then once more (its folds
# resume, so the textures are the same) by the clipped detectors of configs/defences.
# usage: docs/reports/scripts/defence_study.sh OUT SEED... (run from the repository root)
set -euo pipefail
out=$1; shift
pav=${PAV:-target/release/pav}
source "$(dirname "$0")/defence_configs.sh"
common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png)
scoring=(-d configs/detectors/yolov3-tiny.toml -d configs/detectors/deimv2_atto_int8.toml -d configs/detectors/yolox_nano.toml
  --defence median:k=3 --defence bits:b=4 --defence jpeg:q=75 --defence cutout:n=2,s=60 --defence noise:sigma=8)
clipped=(-d configs/defences/yolov3-tiny-clip.toml -d configs/defences/deimv2_atto_int8-clip.toml -d configs/defences/yolox_nano-clip.toml)
run() { # name config
  [ -f "$out/$1/crossval.csv" ] || "$pav" crossval --config "$2" "${common[@]}" "${scoring[@]}" -o "$out/$1"
  if [ ! -f "$out/$1-clipped/crossval.csv" ]; then
    mkdir -p "$out/$1-clipped" && cp -r "$out/$1"/fold* "$out/$1-clipped/"
    "$pav" crossval --config "$2" "${common[@]}" "${clipped[@]}" -o "$out/$1-clipped"
  fi
}
for s in "$@"; do
  defence_configs "$out" "$s"
  for r in plain median clip; do run $r-s$s "$out/configs/$r-s$s.toml"; done
done
