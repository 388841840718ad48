#!/usr/bin/env bash
# Why a result moves between machines (docs/reports/lofo.md, "Between machines"). On one machine:
# the quick recipe at seed 0 twice, at one ONNX Runtime thread, with its learning rate one
# float unit higher, and at seed 1, then all five textures scored on the held-out set by the six
# families; and paper.toml for one epoch natively and under qemu-user as a CPU without AVX-512
# (Haswell), to see whether the instruction set changes the floats.
# usage: docs/reports/scripts/between_machines.sh OUT   (needs out/views_heldout and qemu-user)
set -euo pipefail
out=$1
pav=${PAV:-target/release/pav}
mkdir -p "$out"
train() { # NAME CONFIG [ARGS…]
  local name=$1 cfg=$2; shift 2
  find "$out/$name" -name texture.png 2>/dev/null | grep -q . || "$pav" optimize --config "$cfg" -o "$out/$name" "$@" > "$out/$name.log" 2>&1
}
train s0 configs/optimize/quick.toml
train s0again configs/optimize/quick.toml
train s0t1 configs/studies/recommended-threads1.toml
train s0ulp configs/studies/recommended-lr-ulp.toml
train seed1 configs/optimize/quick.toml --seeds 1
for t in s0again s0t1 s0ulp; do
  if cmp -s "$out/s0/texture.png" "$out/$t/texture.png"; then echo "$t: the same bytes as s0"; else echo "$t: another texture than s0"; fi
done
"$pav" eval-digital --config configs/studies/lofo/heldout.toml -d configs/detectors -d configs/detectors-wide \
  -t "$out/s0/texture.png" -t "$out/s0ulp/texture.png" -t "$out/seed1/seed1/texture.png" --random-seeds 1 \
  -o "$out/heldout" > "$out/heldout.log" 2>&1
train isa-native configs/optimize/paper.toml --epochs 1
[ -f "$out/isa-haswell/texture.png" ] || qemu-x86_64 -cpu Haswell "$pav" optimize --config configs/optimize/paper.toml \
  --epochs 1 -o "$out/isa-haswell" > "$out/isa-haswell.log" 2>&1
if cmp -s "$out/isa-native/loss.csv" "$out/isa-haswell/loss.csv"; then
  echo "without AVX-512: the same losses"
else
  echo "without AVX-512: other losses from the first step:"
  paste -d' ' <(cut -d, -f4 "$out/isa-native/loss.csv" | head -3) <(cut -d, -f4 "$out/isa-haswell/loss.csv" | head -3)
fi
