#!/usr/bin/env bash
# Times `pav-rig evaluate` against the plain Python loop a user would write instead
# (scripts/python_loop.py: OpenCV + onnxruntime), as whole processes on the same video, in
# alternating runs in one sitting. Writes bench/vs_python.csv (or $CSV; tool, detector, run, wall_s,
# frames) and prints pav's wall time over the loop's per detector. With BEFORE=1 it also times
# `evaluate --lanes 1` (one frame at a time, ONNX Runtime's threads), tool `pav-lanes1`.
#   scripts/bench_vs_python.sh [VIDEO] [RUNS]
# VIDEO defaults to the turntable fixture looped to 836 frames. The loop runs in .venv-bench
# (onnxruntime and opencv-python-headless from PyPI, made on first use); without it the
# benchmark says so and stops.
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${2:-3}
VIDEO=${1:-out/bench/turntable836.mp4}
[ -n "${1:-}" ] || scripts/loop_video.sh "$VIDEO" 19 fixtures/turntable.mp4
PY=.venv-bench/bin/python
if [ ! -x "$PY" ]; then
  python3 -m venv .venv-bench && $PY -m pip install -q onnxruntime==1.31.1 opencv-python-headless numpy \
    || { echo "bench_vs_python: no Python loop to compare with (could not make .venv-bench)" >&2; exit 1; }
fi
cargo build --release --bin pav-rig -q
YOLOX=$(target/release/pav data path models-yolox/yolox_nano.onnx)
TINY=.deps/models/yolov3-tiny/yolov3-tiny.onnx
CSV=${CSV:-bench/vs_python.csv}
echo "tool,detector,run,wall_s,frames" > "$CSV"
now() { date +%s%N; }
secs() { printf "%d.%03d" $((($2 - $1) / 1000000000)) $(((($2 - $1) / 1000000) % 1000)); }
# Each tool as NAME:OPTIONS of `pav-rig evaluate`.
tools=("pav:")
[ "${BEFORE:-0}" != 1 ] || tools+=("pav-lanes1:--lanes 1")
for run in $(seq 1 "$RUNS"); do
  for det in yolox_nano:yolox:$YOLOX yolov3-tiny:darknet:$TINY; do
    IFS=: read -r name layout model <<< "$det"
    t0=$(now); out=$($PY scripts/python_loop.py "$layout" "$model" "$VIDEO"); t1=$(now)
    echo "python,$name,$run,$(secs "$t0" "$t1"),${out%% *}" >> "$CSV"
    for tool in "${tools[@]}"; do
      t0=$(now)
      # shellcheck disable=SC2086  # the tool's options split into words
      target/release/pav-rig evaluate "$VIDEO" -d "configs/detectors/$name.toml" ${tool#*:} -o "out/bench/vs_python_$name" 2> /dev/null > /dev/null
      t1=$(now)
      frames=$(($(wc -l < "out/bench/vs_python_$name/frames.csv") - 1))
      echo "${tool%%:*},$name,$run,$(secs "$t0" "$t1"),$frames" >> "$CSV"
    done
  done
done
python3 - "$CSV" <<'PY'
import csv, collections, sys
t = collections.defaultdict(list)
for r in csv.DictReader(open(sys.argv[1])):
    t[(r["detector"], r["tool"])].append(float(r["wall_s"]))
for d in sorted({k[0] for k in t}):
    q = min(t[(d, "python")])
    for tool in sorted({k[1] for k in t if k[0] == d and k[1] != "python"}):
        p = min(t[(d, tool)])
        print(f"{d}: {tool} {p:.2f} s, python loop {q:.2f} s (fastest of {len(t[(d, tool)])}): {tool} / python = {p / q:.2f}")
PY
