#!/usr/bin/env bash
# Runs the README's main job, a paper.toml optimize and a 3-fold crossval (half.toml, one epoch)
# with two builds of pav on the same inputs, and lists every output file that differs between
# them. The timing columns of loss.csv and loss_stages.csv, a fold's time in its scores.json, the
# run time in crossval.md's title and run.toml (command, start time, commit) are expected to
# differ and are compared with those parts removed.
# usage: docs/reports/scripts/same_outputs.sh BASE_BIN_DIR NEW_BIN_DIR OUT
#        (COMPARE_ONLY=1 compares the outputs already in OUT)
set -euo pipefail
base=$1 new=$2 out=$3
repo=$(cd "$(dirname "$0")/../../.." && pwd)
cd "$repo"
export ORT_DYLIB_PATH=${ORT_DYLIB_PATH:-$repo/.deps/onnxruntime/libonnxruntime.so}
cv=$(mktemp -d)/half-1epoch.toml
printf 'extends = "%s"\n\n[optimizer]\nepochs = 1\n' "$repo/configs/studies/half.toml" > "$cv"
for tree in base new; do
  [ -n "${COMPARE_ONLY:-}" ] && break
  bin=${!tree}
  o=$out/$tree
  rm -rf "$o" && mkdir -p "$o"
  "$bin/pav-rig" evaluate fixtures/turntable.mp4 -d configs/detectors -o "$o/evaluate" >/dev/null 2>&1
  "$bin/pav" optimize --config configs/optimize/paper.toml -o "$o/optimize" >/dev/null 2>&1
  "$bin/pav" crossval --config "$cv" --folds 3 --random-seeds 1 -o "$o/crossval" >/dev/null 2>&1
done
# Drops what is expected to differ: run.toml, the timing columns of loss.csv and loss_stages.csv,
# scores.json's seconds, crossval.md's run time.
normal() {
  case "$1" in
    */run.toml) echo "(run record)" ;;
    */loss.csv | */loss_stages.csv) python3 -c 'import csv,sys
r=list(csv.reader(open(sys.argv[1])))
keep=[i for i,h in enumerate(r[0]) if not h.endswith("_ms")]
[print(",".join(row[i] for i in keep)) for row in r]' "$1" ;;
    */scores.json) python3 -c 'import json,sys
d=json.load(open(sys.argv[1])); d.pop("seconds",None); print(json.dumps(d,sort_keys=True))' "$1" ;;
    */crossval.md) sed -E 's/\([0-9.]+ (s|min|h) of folds\)//' "$1" ;;
    *) cat "$1" ;;
  esac
}
same=0 differ=0
while IFS= read -r f; do
  rel=${f#"$out/base/"}
  if [ ! -f "$out/new/$rel" ]; then echo "only in base: $rel"; differ=$((differ + 1)); continue; fi
  if cmp -s <(normal "$f") <(normal "$out/new/$rel"); then same=$((same + 1)); else echo "differs: $rel"; differ=$((differ + 1)); fi
done < <(find "$out/base" -type f | sort)
echo "identical (expected parts aside): $same files; different: $differ"
