#!/usr/bin/env bash
# A headline unit from a fresh clone (docs/reports/lofo.md, "From a fresh clone"): clone the
# repository beside ../shared, set it up with its own data store, draw the quick recipe's
# training views and the held-out set, train the leave-one-family-out unit that leaves YOLOX-Nano
# out at seed 0 (shard 6 of the 24 units of the six-arm command), score it on the held-out set,
# and compare every file and score with those of this checkout. Each step skips what is there.
# usage: docs/reports/scripts/fresh_clone.sh DIR   (from the repository root; needs out/lofo,
#   out/views_etron_plates_wide and out/views_heldout here, and ffmpeg)
set -euo pipefail
dir=$1
here=$(pwd)
mkdir -p "$dir"
ln -sfn "$(cd .. && pwd)/shared" "$dir/shared"
stamp() { echo "$1,$(date +%s)" >> "$dir/steps.csv"; }
[ -f "$dir/steps.csv" ] || echo "step,unix_s" > "$dir/steps.csv"
stamp start
[ -d "$dir/pav" ] || git clone -q "$here" "$dir/pav"
cd "$dir/pav"
export PAV_DATA="$dir/data"
pav=./target/release/pav
bash scripts/setup.sh > ../setup.log 2>&1
stamp setup
"$pav" views render configs/views/etron-plates-wide.toml -o out/views_etron_plates_wide > ../views.log 2>&1
stamp training-views
"$pav" views render configs/views/heldout.toml -o out/views_heldout > ../heldout.log 2>&1
stamp held-out-views
"$pav" lofo configs/studies/lofo/without-*.toml --seeds 0,1,2,3 -o out/lofo --shard 6/24 > ../lofo.log 2>&1
stamp unit
unit=out/lofo/shard-6-of-24/without-yolox_nano/seed0
"$pav" eval-digital --config configs/studies/lofo/heldout.toml -t "$unit/texture.png" \
  -d configs/detectors/yolox_nano.toml -o out/eval-s0 > ../eval.log 2>&1
stamp scores
# Files: bytes, or where Blender wrote them with a date inside, decoded pixels.
pixels() { ffmpeg -v error -i "$1" -f rawvideo -pix_fmt rgba - | sha256sum; }
compare() { # WHAT FOLDER_THERE FOLDER_HERE FILE...: each FILE (relative) in both folders
  local what=$1 there=$2 mine=$3 bytes=0 pix=0 differ=0 n=0
  shift 3
  for f in "$@"; do
    n=$((n + 1))
    if cmp -s "$there/$f" "$mine/$f"; then bytes=$((bytes + 1))
    elif [ "$(pixels "$there/$f")" = "$(pixels "$mine/$f")" ]; then pix=$((pix + 1))
    else differ=$((differ + 1)); fi
  done
  echo "$what,$n,$bytes,$pix,$differ"
}
listed() { (cd "$1" && ls views/*.png); }
{
  echo "what,compared,same_bytes,same_pixels,differ"
  compare "training views" out/views_etron_plates_wide "$here/out/views_etron_plates_wide" \
    $(listed out/views_etron_plates_wide)
  compare "held-out views" out/views_heldout "$here/out/views_heldout" $(listed out/views_heldout)
  compare "trained texture and checkpoint" "$unit" "$here/out/lofo/without-yolox_nano/seed0" texture.png checkpoint.bin
  python3 - "$here" <<'PY'
import sys
here = sys.argv[1]
sys.path.insert(0, f"{here}/docs/reports/scripts")
from paired_stats import heldout_scores
fresh = heldout_scores("out/eval-s0/digital_views.csv", "yolox_nano")
there = heldout_scores(f"{here}/out/lofo/without-yolox_nano/heldout/digital_views.csv", "yolox_nano")
# The clone's texture is named by its folder, seed0; this checkout's by its arm.
pairs = [(views[v], there.get(("without-yolox_nano" if t == "seed0" else t, s), {}).get(v))
         for (t, s), views in fresh.items() for v in views]
same = sum(1 for a, b in pairs if a == b)
print(f"held-out scores by YOLOX-Nano,{len(pairs)},{same},0,{len(pairs) - same}")
PY
} > ../fresh_clone.csv
stamp compared
cat ../fresh_clone.csv
