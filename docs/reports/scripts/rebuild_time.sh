#!/usr/bin/env bash
# Incremental rebuild time of the release binaries after touching one leaf file of the library, at
# a base revision and at the working tree, alternating, in one target directory so that both
# reuse the same dependency builds. The leaves, MODULE/FILE (default: image/resize.rs, the base
# layer under everything, and eval/report.rs, a job under the binaries only), are found at any
# layout the workspace has had: src/<module>/ in one crate, crates/pav-core/src/<module>/ or
# crates/pav-<module>/src/ in the workspace, and a module that was one file of pav-core
# (crates/pav-core/src/<module>.rs) or is a crate's root (<module>/lib.rs). Writes
# round,tree,leaf,seconds to stdout.
# usage: docs/reports/scripts/rebuild_time.sh BASE_REV [ROUNDS] [LEAF...]
set -euo pipefail
base=$1
rounds=${2:-2}
shift $(($# < 2 ? $# : 2))
leaves=("$@")
[ ${#leaves[@]} -gt 0 ] || leaves=(image/resize.rs eval/report.rs)
repo=$(cd "$(dirname "$0")/../../.." && pwd)
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$repo/target}
wt=$(mktemp -d)/base
git -C "$repo" worktree add -f "$wt" "$base" >/dev/null 2>&1
trap 'git -C "$repo" worktree remove --force "$wt"' EXIT
# The leaf's file in a tree of either layout.
leaf() {
  local dir=$1 module=$2 file=$3
  local p
  for p in "src/$module/$file" "crates/pav-core/src/$module/$file" "crates/pav-$module/src/$file" \
    "crates/pav-core/src/$module.rs"; do
    [ "$p" = "crates/pav-core/src/$module.rs" ] && [ "$file" != lib.rs ] && continue
    [ -f "$dir/$p" ] && { echo "$dir/$p"; return; }
  done
  echo "no $module/$file in $dir" >&2
  exit 1
}
(cd "$wt" && cargo build --release >/dev/null 2>&1)
(cd "$repo" && cargo build --release >/dev/null 2>&1)
echo "round,tree,leaf,seconds"
for r in $(seq 1 "$rounds"); do
  for l in "${leaves[@]}"; do
    for tree in base working; do
      dir=$wt
      [ "$tree" = working ] && dir=$repo
      touch "$(leaf "$dir" "${l%%/*}" "${l#*/}")"
      s=$(date +%s.%N)
      (cd "$dir" && cargo build --release >/dev/null 2>&1)
      e=$(date +%s.%N)
      echo "$r,$tree,$l,$(echo "$e - $s" | bc)"
    done
  done
done
