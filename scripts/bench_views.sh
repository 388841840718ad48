#!/usr/bin/env bash
# What accuracy costs in time for the Blender back-end of the simulated turntable: seconds
# per view against Cycles samples and resolution, and how far the simulated A_physical and each
# detector's mean best car score move with them. Each setting films configs/views/turntable.toml's
# car and room, 8 frames a turn at polar 0° and 20° (16 frames), and scores them with every
# detector in configs/detectors. Settings resume where they stopped (the per-view seconds come
# from the manifest, so a resumed setting is timed like a fresh one).
# Writes bench/views_cost.csv and bench/views_cost.svg.
# Usage: scripts/bench_views.sh [texture.png]   (needs `blender` and a release build)
set -euo pipefail
cd "$(dirname "$0")/.."
tex=()
[ $# -ge 1 ] && tex=(--texture "$1")
work=out/bench_views
mkdir -p "$work" bench
echo "size,samples,frames,seconds_per_view,detector,a_physical,mean_best_score" > bench/views_cost.csv
# Appends one row per detector: A_physical and mean best car score over $dir/eval.
score() {
  local dir=$1 size=$2 samples=$3 secs=$4
  awk -F, -v size="$size" -v samples="$samples" -v secs="$secs" '
    FNR==1 {next}
    FILENAME ~ /frames.csv$/ {best[$5]+=$7; cnt[$5]++; next}
    {ap[$2]=$8; fr[$2]=$6}
    END {for (d in ap) printf "%s,%s,%s,%s,%s,%s,%.4f\n", size, samples, fr[d], secs, d, ap[d], best[d]/cnt[d]}' \
    "$dir/eval/frames.csv" "$dir/eval/summary.csv" | sort -t, -k5 >> bench/views_cost.csv
}
for setting in 208:16 416:4 416:16 416:64; do
  size=${setting%:*}; samples=${setting#*:}
  dir="$work/s${size}_n${samples}"
  cfg="$work/s${size}_n${samples}.toml"
  sed -e "s/^size = .*/size = $size/" -e "s/^samples = .*/samples = $samples/" \
      -e "s/^azimuth_step = .*/azimuth_step = 45/" configs/views/turntable.toml > "$cfg"
  target/release/pav views turntable "$cfg" "${tex[@]}" -o "$dir" > "$dir.log" 2>&1
  target/release/pav-rig evaluate "$dir"/videos/*.mp4 --label s --label s -d configs/detectors \
      --no-plots -o "$dir/eval" > "$dir/eval.log" 2>&1
  secs=$(awk -F, 'NR==1 {for (i=1;i<=NF;i++) if ($i=="seconds") c=i} NR>1 {s+=$c; n++} END {printf "%.2f", s/n}' "$dir/manifest.csv")
  score "$dir" "$size" "$samples" "$secs"
done
# pav's rasterizer (the live back-end) on the same car at 416²: a 3.5 s turn (--time-scale 8)
# with the camera asked for 100 fps, so it draws as fast as it can; seconds per view is the
# turn over the frames it recorded (an upper bound: encoding is included). 8 frames of each of
# the two polar angles are scored, like the Cycles settings.
dir="$work/raster_416"
mkdir -p "$dir"
frames=0
for e in 0 20; do
  target/release/pav-rig capture --port sim --time-scale 8 --camera sim --car configs/views/turntable.toml "${tex[@]}" \
      --elevation "$e" --width 416 --height 416 --fps 100 -o "$dir/e$e.mp4" > "$dir/e$e.log" 2>&1
  n=$(sed -n 's/^recorded \([0-9]*\) frames.*/\1/p' "$dir/e$e.log")
  frames=$((frames + n))
done
secs=$(awk -v f="$frames" 'BEGIN {printf "%.4f", 2 * 3.5 / f}')
target/release/pav-rig evaluate "$dir/e0.mp4" "$dir/e20.mp4" --label s --label s --sample 8 -d configs/detectors \
    --no-plots -o "$dir/eval" > "$dir/eval.log" 2>&1
score "$dir" 416 raster "$secs"
python3 scripts/plot_views_cost.py bench/views_cost.csv bench/views_cost.svg
cat bench/views_cost.csv
