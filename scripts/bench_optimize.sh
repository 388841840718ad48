#!/usr/bin/env bash
# What accuracy costs in time for `pav optimize`: render size × epochs against the white-box
# ASR / P@0.5 / mean car score on all views (evaluated at 416² for every run), plus the mean
# time per step split by stage. Writes bench/optimize_tradeoff.csv and bench/optimize_step.csv.
# Usage: scripts/bench_optimize.sh [config] (needs a build with --features optimize).
set -euo pipefail
cd "$(dirname "$0")/.."
cfg=${1:-configs/optimize/paper.toml}
pav=target/release/pav
work=out/bench_optimize
rm -rf "$work"; mkdir -p "$work" bench
echo "size,epochs,steps,optimize_s,step_ms,asr,p50,mean_score" > bench/optimize_tradeoff.csv
for size in 416 608; do
  start=$(date +%s.%N)
  for epochs in 1 5 20; do
    resume=""; [ -f "$work/$size/checkpoint.bin" ] && resume="--resume"
    "$pav" optimize --config "$cfg" -o "$work/$size" --size "$size" --epochs "$epochs" $resume > "$work/$size-$epochs.log" 2>&1
    secs=$(echo "$(date +%s.%N) - $start" | bc)
    cp "$work/$size/texture.png" "$work/$size/texture-$epochs.png"
    mkdir -p "$work/eval-$size-$epochs/s$size-e$epochs"
    cp "$work/$size/texture.png" "$work/eval-$size-$epochs/s$size-e$epochs/texture.png"
    "$pav" eval-digital --config "$cfg" -d configs/detectors/yolov3-tiny.toml \
      -t "$work/eval-$size-$epochs/s$size-e$epochs/texture.png" -o "$work/eval-$size-$epochs" > /dev/null 2>&1
    steps=$(($(wc -l < "$work/$size/loss.csv") - 1))
    step_ms=$(awk -F, 'NR>1 {s += $12+$13+$14+$15+$16+$17; n++} END {printf "%.1f", s/n}' "$work/$size/loss.csv")
    row=$(awk -F, -v t="s$size-e$epochs" '$3==t && $4=="all" {print $6","$7","$8}' "$work/eval-$size-$epochs/digital.csv")
    echo "$size,$epochs,$steps,$secs,$step_ms,$row" >> bench/optimize_tradeoff.csv
    # Not timed: the evaluation runs between the timed optimization segments.
    start=$(echo "$(date +%s.%N) - $secs" | bc)
  done
  awk -F, -v size="$size" 'NR>1 {for (i=12;i<=17;i++) s[i]+=$i; n++} END {
      printf "%s,%d,%.2f,%.2f,%.1f,%.1f,%.2f,%.2f\n", size, n, s[12]/n, s[13]/n, s[14]/n, s[15]/n, s[16]/n, s[17]/n}' \
    "$work/$size/loss.csv" >> "$work/steps.csv"
done
{ echo "size,steps,render_ms,eot_ms,forward_ms,backward_ms,adjoint_ms,optimizer_ms"; cat "$work/steps.csv"; } > bench/optimize_step.csv
cat bench/optimize_tradeoff.csv bench/optimize_step.csv
