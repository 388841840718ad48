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
mkdir -p "$out/configs"
cfgdir=$(cd "$out/configs" && pwd)
repo=$(pwd)
common=(--folds 3 --random-seeds 1 --reference data:rauca-e2e/RAUCA_E2E.png)
scoring=(-d configs/detectors/yolov3-tiny.toml -d configs/detectors/deimv2_atto_int8.toml -d configs/detectors/yolox_nano.toml
  --defence median:k=3 --defence bits:b=4 --defence jpeg:q=75 --defence cutout:n=2,s=60 --defence noise:sigma=8)
clipped=(-d configs/defences/yolov3-tiny-clip.toml -d configs/defences/deimv2_atto_int8-clip.toml -d configs/defences/yolox_nano-clip.toml)
white_boxes() { # defence-toml-or-empty yolov3-config deimv2-config
  for d in "$2" "$repo/configs/detectors/yolov8n_int8.toml" "$3"; do
    printf '\n[[white_box]]\ndetector = "%s"\nweight = 1.0\n' "$d"
    case $d in *int8*) echo 'surrogate = true' ;; esac
    [ -n "$1" ] && echo "defence = [$1]"
  done
}
config() { # name seed white-box-lines...
  { echo "extends = \"$repo/configs/studies/print-base.toml\""; printf '\n[optimizer]\nseed = %s\n' "$2"; echo "$3"; } > "$cfgdir/$1.toml"
  echo "$cfgdir/$1.toml"
}
run() { # name config
  [ -f "$out/$1/crossval.csv" ] || "$pav" crossval --config "$2" "${common[@]}" "${scoring[@]}" -o "$out/$1"
  if [ ! -f "$out/$1-clipped/crossval.csv" ]; then
    mkdir -p "$out/$1-clipped" && cp -r "$out/$1"/fold* "$out/$1-clipped/"
    "$pav" crossval --config "$2" "${common[@]}" "${clipped[@]}" -o "$out/$1-clipped"
  fi
}
for s in "$@"; do
  run plain-s$s "$(config plain-s$s $s "$(white_boxes "" "$repo/configs/detectors/yolov3-tiny.toml" "$repo/configs/detectors/deimv2_atto_int8.toml")")"
  run median-s$s "$(config median-s$s $s "$(white_boxes '{ kind = "median", k = 3 }' "$repo/configs/detectors/yolov3-tiny.toml" "$repo/configs/detectors/deimv2_atto_int8.toml")")"
  run clip-s$s "$(config clip-s$s $s "$(white_boxes "" "$repo/configs/defences/yolov3-tiny-clip.toml" "$repo/configs/defences/deimv2_atto_int8-clip.toml")")"
done
