#!/usr/bin/env bash
# The "views of the model on the rig" lever (docs/reports/transfer.md): recipes trained at the
# seeds SEEDS (default 0), painted, filmed on the test shot (configs/rig/phone-etron.toml: 0.5 m,
# 0° and 20°, the interior map, 44 frames a turn), beside the original paint and RAUCA-E2E's
# texture, scored by YOLOv3-tiny, YOLOv8n, DEIMv2, YOLOX-Nano, NanoDet-m and PP-PicoDet-XS, and
# compared frame by frame (pairs: seed, elevation, frame) against each label of AGAINST.
# VARIANTS names the recipes as LABEL=CONFIG; by default the recipe of the rig comparison
# (configs/studies/print-base.toml, trained on its six training photos and their turns) against
# the same recipe with Blender views of the 1:20 model on a turntable as training views
# (configs/studies/rig-views.toml, rendered from configs/rig/train-etron-near.toml and -far.toml
# into out/views_rig_near and out/views_rig_far: 144 views at 0.4 and 0.65 m, 10° and 30°, the
# studio and courtyard maps). EVAL names the scoring folder; the paired comparisons go to
# paired-LABEL (with EVAL=eval-X: paired-X-LABEL). RIGVIEWS names the rig view sets to render
# first (default "near far"). PRINT=1 sticks every texture on as printed (`pav paint --print`:
# Ghostscript's CMYK profile, relative colorimetric), RAUCA-E2E's included; the original paint
# is not printed. TEXTURES names the folder that holds (or gets) the optimized textures
# (default OUT), so that one set of textures can be filmed both ways. Resumes: finished
# textures, paints, films and views are kept.
# usage: [SEEDS="0 1 2 3"] [VARIANTS="A=CONFIG B=CONFIG"] [AGAINST="rauca A"] [EVAL=eval] [RIGVIEWS="near far"]
#        [PRINT=1] [TEXTURES=DIR] docs/reports/scripts/lever_rig_views.sh OUT   (from the repository root)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
here=$(pwd)
seeds=${SEEDS:-0}
variants=${VARIANTS:-plain=configs/studies/print-base.toml rig=configs/studies/rig-views.toml}
against=${AGAINST:-rauca plain}
eval_dir=${EVAL:-eval}
textures=${TEXTURES:-$out}
print=(); [ -z "${PRINT:-}" ] || print=(--print)
# The rig views the variants train on: configs/rig/train-etron-NAME.toml into out/views_rig_NAME
# (NAME with - as _), for each NAME of RIGVIEWS.
for n in ${RIGVIEWS:-near far}; do
  "$pav" views turntable --rig "configs/rig/train-etron-$n.toml" -o "out/views_rig_${n//-/_}" > /dev/null
done
mkdir -p "$out/configs" "$out/paint"
printf 'extends = "%s/configs/rig/phone-etron.toml"\n\n[render]\nframes = 44\n' "$here" > "$out/rig.toml"
for s in $seeds; do
  for v in $variants; do
    c=${v%%=*} cfg=${v#*=}
    case $cfg in /*) ;; *) cfg="$here/$cfg" ;; esac
    printf 'extends = "%s"\n\n[optimizer]\nseed = %s\n' "$cfg" "$s" > "$out/configs/$c-s$s.toml"
    [ -f "$textures/$c-s$s/texture.png" ] || "$pav" optimize --config "$out/configs/$c-s$s.toml" -o "$textures/$c-s$s"
    [ -f "$out/paint/$c-s$s.png" ] || "$pav" paint --config configs/studies/print-base.toml --texture "$textures/$c-s$s/texture.png" "${print[@]}" -o "$out/paint/$c-s$s.png"
    "$pav" views turntable --rig "$out/rig.toml" --texture "$out/paint/$c-s$s.png" -o "$out/film/$c-s$s" > /dev/null
  done
done
[ -f "$out/paint/rauca.png" ] || "$pav" paint --config configs/studies/print-base.toml --texture data:rauca-e2e/RAUCA_E2E.png "${print[@]}" -o "$out/paint/rauca.png"
"$pav" views turntable --rig "$out/rig.toml" --texture "$out/paint/rauca.png" -o "$out/film/rauca" > /dev/null
"$pav" views turntable --rig "$out/rig.toml" -o "$out/film/original" > /dev/null
# The two fixed paints once per seed, as links, so that each of their frames pairs with the
# same frame of every seed's textures.
names=""
for v in $variants; do names+=" ${v%%=*}"; done
videos=(); labels=()
for p in original rauca $names; do
  for s in $seeds; do
    case $p in
      original|rauca) mkdir -p "$out/film/$p/seed$s"
        for v in "$out/film/$p"/videos/*; do ln -sf "$(realpath "$v")" "$out/film/$p/seed$s/"; done
        dir="$out/film/$p/seed$s" ;;
      *) dir="$out/film/$p-s$s/videos" ;;
    esac
    for v in "$dir"/*.mp4; do videos+=("$v"); labels+=(--label "$p"); done
  done
done
"$rig" evaluate "${videos[@]}" "${labels[@]}" -d configs/detectors -d configs/detectors-wide -o "$out/$eval_dir"
for a in $against; do
  "$rig" paired "$out/$eval_dir" --against "$a" -o "$out/${eval_dir/eval/paired}-$a"
done
