#!/usr/bin/env bash
# How a crossval's wall time divides over Slurm array tasks (docs/cluster.md): one crossval
# (3 folds x 2 seeds over 6 of FCA's photos, 3 epochs) run once in one process, then on a
# single-node Slurm (scripts/cluster/local-slurm.sh) as arrays of 1 task x 2 CPUs and of 2, 3 and
# 6 tasks x 1 CPU, each with its merge job; wall time from submission to the merge's end. Every
# merged result is compared with the one-process one (timings aside). Writes OUT/scaling.csv.
# usage: docs/reports/scripts/cluster_scaling.sh OUT (run from the repository root, as root)
set -euo pipefail
out=$(mkdir -p "$1" && cd "$1" && pwd)
pav=${PAV:-$(pwd)/target/release/pav}
studies=$(cd configs/studies && pwd)
cat > "$out/config.toml" <<CONF
extends = "$studies/half.toml"
[views]
train = ["data:fca/carla_dataset/test/data12501.npz", "data:fca/carla_dataset/test/data12502.npz", "data:fca/carla_dataset/test/data12503.npz", "data:fca/carla_dataset/test/data12504.npz"]
test = ["data:fca/carla_dataset/test/data12505.npz", "data:fca/carla_dataset/test/data12506.npz"]
[optimizer]
epochs = 3
CONF
job=(crossval --config "$out/config.toml" --folds 3 --seeds 0,1 --random-seeds 1 -d configs/detectors/yolov3-tiny.toml -d configs/detectors/yolox_nano.toml)
echo "tasks,cpus_per_task,wall_s,fold_s_sum,same_as_one_process" > "$out/scaling.csv"
fold_sum() { python3 -c "import json,glob,sys; print(round(sum(json.load(open(f))['seconds'] for f in glob.glob(sys.argv[1]+'/seed*/fold*/scores.json')),1))" "$1"; }
same() { diff -rq "$out/one" "$1" -x run.toml -x 'shard-*' -x loss.csv -x loss_detectors.csv -x checkpoint.bin -x scores.json -x crossval.md >/dev/null && echo yes || echo no; }
rm -rf "$out/one"
t0=$(date +%s.%N)
"$pav" "${job[@]}" -o "$out/one" > "$out/one.log" 2>&1
t1=$(date +%s.%N)
echo "0,2,$(python3 -c "print(round($t1-$t0,1))"),$(fold_sum "$out/one"),yes" >> "$out/scaling.csv"
slurm=$out/slurm
bash scripts/cluster/local-slurm.sh start "$slurm" > /dev/null
trap 'bash scripts/cluster/local-slurm.sh stop "$slurm"' EXIT
export SLURM_CONF=$slurm/slurm.conf
for spec in 1:2 2:1 3:1 6:1; do
  n=${spec%:*}; c=${spec#*:}
  dir=$out/array-$n-x$c
  rm -rf "$dir"
  "$pav" cluster slurm --tasks "$n" --cpus-per-task "$c" --mem 4G -o "$dir/jobs" -- "$pav" "${job[@]}" -o "$dir/cv" 2>/dev/null
  t0=$(date +%s.%N)
  bash "$dir/jobs/submit.sh" > /dev/null
  while [ -n "$(squeue -h)" ]; do sleep 0.5; done
  t1=$(date +%s.%N)
  [ -f "$dir/cv/seed1/crossval.csv" ] || { echo "array $spec: no merged result; logs in $dir/jobs/logs" >&2; exit 1; }
  echo "$n,$c,$(python3 -c "print(round($t1-$t0,1))"),$(fold_sum "$dir/cv"),$(same "$dir/cv")" >> "$out/scaling.csv"
done
cat "$out/scaling.csv"
