#!/usr/bin/env bash
# Adversarial training of YOLOX-Nano's head (docs/reports/defences.md, "Adversarial training"):
# pav's texture at four seeds, the tuned head rebuilt from its recipe, textures optimized with the
# tuned head as a fourth white box (adaptive) and with the plain one (control), all scored on the
# held-out photos, their car painted out, and the rig study's Blender videos.
# usage: docs/reports/scripts/advtrain_study.sh OUT   (from the repository root; about 15 min)
#        python3 docs/reports/scripts/advtrain_table.py OUT   (the paired comparisons)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
rig=${RIG:-target/release/pav-rig}
base=configs/studies/print-base.toml
seeds=0,1,2,3
# pav's texture: the print-base recipe, which never trains against YOLOX-Nano.
[ -f "$out/pav/seed3/texture.png" ] || "$pav" optimize --config $base --seeds $seeds -o "$out/pav"
# The tuned head from the recipe (its sha256 is checked).
[ -f "$out/recipe/yolox_nano_advtrain.onnx" ] || "$pav" adv-train configs/advtrain/yolox_nano.toml -o "$out/recipe"
tuned=$(realpath "$out/recipe/yolox_nano_advtrain.toml")
# The attacker who knows the defence: the tuned head as a fourth white box (adaptive); the
# control trains against the plain YOLOX-Nano instead, so the difference is the defence's, not
# the family's; and the tuned head as the only white box (alone).
mkdir -p "$out/configs"
d=$(realpath configs/detectors)
for kind in adaptive control alone; do
  yolox=$([ $kind = control ] && echo "$d/yolox_nano.toml" || echo "$tuned")
  boxes="  { detector = \"$d/yolov3-tiny.toml\" },
  { detector = \"$d/yolov8n_int8.toml\", surrogate = true },
  { detector = \"$d/deimv2_atto_int8.toml\", surrogate = true },
"
  [ $kind = alone ] && boxes=""
  cat > "$out/configs/$kind.toml" <<TOML
extends = "$(realpath $base)"
white_box = [
$boxes  { detector = "$yolox" },
]
TOML
  [ -f "$out/$kind/seed3/texture.png" ] || "$pav" optimize --config "$out/configs/$kind.toml" --seeds $seeds -o "$out/$kind"
done
# Held-out photos, before and after, every texture's four seeds pooled (the model is rebuilt).
tests=()
for kind in pav adaptive control alone; do
  for s in 0 1 2 3; do tests+=(--test-texture "$kind=$out/$kind/seed$s/texture.png"); done
done
[ -f "$out/scored/advtrain.csv" ] || "$pav" adv-train configs/advtrain/yolox_nano.toml "${tests[@]}" -o "$out/scored"
# P@0.5 on the held-out photos (boxes against FCA's labels).
textures=(--texture data:rauca-e2e/RAUCA_E2E.png)
for s in 0 1 2 3; do textures+=(--texture "$out/pav/seed$s/texture.png"); done
[ -f "$out/digital/digital.csv" ] || "$pav" eval-digital --config $base -d configs/detectors/yolox_nano.toml -d "$tuned" \
  "${textures[@]}" --random-seeds 2 -o "$out/digital"
# The rig study's Blender videos (docs/reports/rig.md): the model on the phone rig, 44 frames a paint.
v=out/rig_study/blender
[ -f "$out/rig/summary.csv" ] || "$rig" evaluate $v/original/videos/*.mp4 $v/random/videos/*.mp4 $v/rauca/videos/*.mp4 \
  $v/pav/videos/*.mp4 --label original --label original --label random --label random --label rauca --label rauca \
  --label pav --label pav -d configs/detectors/yolox_nano.toml -d "$tuned" --no-plots -o "$out/rig"
