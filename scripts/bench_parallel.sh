#!/usr/bin/env bash
# Times `pav-rig evaluate` with every shipped detector on one video, detectors one after another
# (ONNX Runtime's default threads) against side by side (one thread each), as whole processes in
# alternating runs in one sitting; checks that both wrote the same frames.csv. Writes
# bench/evaluate_parallel.csv (mode, run, wall_s) and prints the fastest of each.
#   scripts/bench_parallel.sh [VIDEO] [RUNS]
# VIDEO defaults to the CARLA fixture looped to 810 frames.
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${2:-3}
VIDEO=${1:-out/bench/loop810.mp4}
scripts/loop_video.sh "$VIDEO" 18
cargo build --release --bin pav-rig -q
CSV=bench/evaluate_parallel.csv
echo "mode,run,wall_s" > "$CSV"
now() { date +%s%N; }
secs() { printf "%d.%03d" $((($2 - $1) / 1000000000)) $(((($2 - $1) / 1000000) % 1000)); }
for run in $(seq 1 "$RUNS"); do
  for mode in sequential side_by_side; do
    flag="--parallel 1"
    [ "$mode" = side_by_side ] && flag="--parallel 0"
    s=$(now)
    target/release/pav-rig evaluate "$VIDEO" -d configs/detectors $flag --no-plots -o "out/bench/parallel_$mode" >/dev/null 2>&1
    e=$(now)
    echo "$mode,$run,$(secs "$s" "$e")" | tee -a "$CSV"
  done
done
cmp out/bench/parallel_sequential/frames.csv out/bench/parallel_side_by_side/frames.csv \
  && echo "frames.csv identical in both modes"
for mode in sequential side_by_side; do
  printf '%s fastest: ' "$mode"; grep "^$mode," "$CSV" | cut -d, -f3 | sort -n | head -1
done
