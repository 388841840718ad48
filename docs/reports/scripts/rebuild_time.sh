#!/usr/bin/env bash
# Incremental rebuild time after touching one leaf file of the library (src/image/resize.rs), at a
# base revision and at the working tree, alternating, in one target directory so that both reuse
# the same dependency builds. Writes round,tree,seconds to stdout.
# usage: docs/reports/scripts/rebuild_time.sh BASE_REV [ROUNDS]
set -euo pipefail
base=$1
rounds=${2:-2}
repo=$(cd "$(dirname "$0")/../../.." && pwd)
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$repo/target}
wt=$(mktemp -d)/base
git -C "$repo" worktree add -f "$wt" "$base" >/dev/null 2>&1
trap 'git -C "$repo" worktree remove --force "$wt"' EXIT
(cd "$wt" && cargo build --release >/dev/null 2>&1)
(cd "$repo" && cargo build --release >/dev/null 2>&1)
echo "round,tree,seconds"
for r in $(seq 1 "$rounds"); do
  for tree in base working; do
    dir=$wt
    [ "$tree" = working ] && dir=$repo
    touch "$dir/src/image/resize.rs"
    s=$(date +%s.%N)
    (cd "$dir" && cargo build --release >/dev/null 2>&1)
    e=$(date +%s.%N)
    echo "$r,$tree,$(echo "$e - $s" | bc)"
  done
done
