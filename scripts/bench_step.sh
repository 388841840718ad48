#!/usr/bin/env bash
# pav's white-box step against PyTorch's on this machine, in one run: the same YOLOv3-tiny darknet
# weights, batch 1, input gradient only, on THREADS threads. Rounds alternate the two so both see
# the same machine; each row is one round's median. Writes bench/step.csv (every round) and
# bench/step_vs_torch.csv (the best round of each, and the ratios).
# PyTorch is optional: with no TORCH_PYTHON (default .venv-torch/bin/python) importing torch, only
# pav is timed. To make one:
#   python3 -m venv .venv-torch && .venv-torch/bin/pip install torch==2.15.0 numpy
set -euo pipefail
cd "$(dirname "$0")/.."
SIZES=${SIZES:-416,608}
REPEATS=${REPEATS:-20}
ROUNDS=${ROUNDS:-3}
THREADS=${THREADS:-2}
PY=${TORCH_PYTHON:-.venv-torch/bin/python}
MODEL=.deps/models/yolov3-tiny
cargo build --release --features optimize --bin pav
torch=1
if ! "$PY" -c 'import torch' 2>/dev/null; then
  echo "PyTorch not importable from $PY: timing pav only (see the comment at the top of this script)" >&2
  torch=0
fi
mkdir -p bench
out=bench/step.csv
tmp=$(mktemp)
for r in $(seq "$ROUNDS"); do
  echo "round $r of $ROUNDS" >&2
  target/release/pav bench-step --sizes "$SIZES" --threads "$THREADS" --repeats "$REPEATS" -o "$tmp"
  if [ "$r" = 1 ]; then head -n1 "$tmp" > "$out"; fi
  tail -n +2 "$tmp" >> "$out"
  if [ "$torch" = 1 ]; then
    "$PY" scripts/torch_step.py "$MODEL/yolov3-tiny.cfg" "$MODEL/yolov3-tiny.weights" \
      --sizes "$SIZES" --threads "$THREADS" --repeats "$REPEATS" >> "$out"
  fi
done
rm -f "$tmp"
python3 - "$out" bench/step_vs_torch.csv <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
best = {}
for r in rows:
    key = (r['backend'].startswith('pav'), int(r['size']))
    if key not in best or float(r['forward_backward_ms']) < float(best[key]['forward_backward_ms']):
        best[key] = r
with open(sys.argv[2], 'w', newline='') as f:
    w = csv.writer(f)
    w.writerow(['size', 'threads', 'pav_forward_ms', 'pav_forward_backward_ms', 'torch_backend',
                'torch_forward_ms', 'torch_forward_backward_ms', 'forward_ratio', 'forward_backward_ratio'])
    for size in sorted({k[1] for k in best}):
        p, t = best.get((True, size)), best.get((False, size))
        ratio = lambda a, b: f'{float(a) / float(b):.3f}' if b else ''
        w.writerow([size, p['threads'], p['forward_ms'], p['forward_backward_ms'],
                    t['backend'] if t else '', t['forward_ms'] if t else '', t['forward_backward_ms'] if t else '',
                    ratio(p['forward_ms'], t['forward_ms']) if t else '',
                    ratio(p['forward_backward_ms'], t['forward_backward_ms']) if t else ''])
print(open(sys.argv[2]).read())
PY
