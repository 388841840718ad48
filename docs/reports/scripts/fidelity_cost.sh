#!/usr/bin/env bash
# What a training view costs at each level of the fidelity study (docs/reports/fidelity.md):
# every 11th view of each configs/views/fidelity/LEVEL.toml (9 views: one photo's plate at every
# turn) drawn afresh into a scratch folder, the seconds of each view from its manifest (Blender's
# own time per view, or the rasterizer's). Run it with nothing else on the machine.
# Writes bench/fidelity_cost.csv (level,renderer,samples,size,view,seconds).
# usage: docs/reports/scripts/fidelity_cost.sh   (needs `blender` and a release build)
set -euo pipefail
pav=${PAV:-target/release/pav}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p bench
echo "level,renderer,samples,size,view,seconds" > bench/fidelity_cost.csv
for level in rasterizer cycles4 cycles16 cycles64 cycles16-208; do
  "$pav" views render "configs/views/fidelity/$level.toml" --shard 1/11 -o "$work/$level" > "$work/$level.log" 2>&1
  awk -F, -v level="$level" 'NR==1 {for (i=1;i<=NF;i++) c[$i]=i; next}
    {printf "%s,%s,%s,%s,%s,%s\n", level, ($c["samples"]=="0" ? "rasterizer" : "cycles"), $c["samples"], $c["size"], $c["name"], $c["seconds"]}' \
    "$work/$level/shard-1-of-11/manifest.csv" >> bench/fidelity_cost.csv
done
cat bench/fidelity_cost.csv
