#!/usr/bin/env bash
# The paper's car with the e-tron's recipe (docs/reports/impala.md): the Impala's adjusted layout
# and navy paint, its Blender training and held-out views (impala-train.toml, impala-test.toml:
# no light map, distance, elevation or azimuth shared), configs/optimize/impala.toml trained
# at seeds 0–3, and the four textures scored on the held-out views beside the original paint and
# three seeds of each random kind, once per seed and once pooled.
# usage: docs/reports/scripts/impala_recipe.sh OUT   (from the repository root; about 45 min)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
[ -f out/uv_adjusted/adjusted.obj ] || "$pav" uv adjust -o out/uv_adjusted
mkdir -p "$out"
# A solid image of the Impala's body colour, RGB (67, 74, 114), painted over half.png's region.
[ -f "$out/navy.png" ] || ffmpeg -loglevel error -f lavfi -i color=c=0x434a72:s=16x16 -frames:v 1 "$out/navy.png"
[ -f out/impala_paint.png ] || "$pav" paint --config configs/optimize/impala-half.toml --texture "$out/navy.png" \
  --base data:pav-camou/half.png -o out/impala_paint.png
"$pav" views render configs/views/impala-train.toml --texture out/impala_paint.png -o out/views_impala_train
"$pav" views render configs/views/impala-test.toml --texture out/impala_paint.png -o out/views_impala_test
[ -f "$out/seed3/texture.png" ] || "$pav" optimize --config configs/optimize/impala.toml --seeds 0,1,2,3 --resume -o "$out"
t=(); for s in 0 1 2 3; do t+=(-t "$out/seed$s/texture.png"); done
"$pav" eval-digital --config configs/optimize/impala-half.toml "${t[@]}" --random-seeds 3 -o "$out/digital"
"$pav" eval-digital --config configs/optimize/impala-half.toml -t "$out" --random-seeds 3 -o "$out/pooled"
