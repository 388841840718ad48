#!/usr/bin/env python3
"""Paired comparisons of the adversarial-training study (docs/reports/defences.md): textures
trained against the tuned head (adaptive: beside the three white boxes; alone: as the only one)
against the control trained against the plain YOLOX-Nano, each pair a (seed, held-out photo),
scored by the plain and by the tuned head. usage: advtrain_table.py OUT (advtrain_study.sh's)."""
import csv
import re
import sys

from paired_stats import bootstrap


out = sys.argv[1]
scores = {}  # (kind, seed, view) -> (before, after)
with open(f"{out}/scored/advtrain.csv") as f:
    for r in csv.DictReader(f):
        m = re.search(r"seed(\d+)/texture\.png", r["file"])
        if m:
            scores[(r["texture"], int(m.group(1)), r["view"])] = (float(r["before"]), float(r["after"]))
print("| texture − control | pairs | scored by yolox_nano | scored by yolox_nano+advtrain |")
print("|---|---:|---:|---:|")
for kind in ["adaptive", "alone", "pav"]:
    keys = [k for k in scores if k[0] == kind and ("control",) + k[1:] in scores]
    if not keys:
        continue
    cells = []
    for col in (0, 1):
        d = [scores[k][col] - scores[("control",) + k[1:]][col] for k in sorted(keys)]
        m, lo, hi = bootstrap(d)
        cells.append(f"{m:+.3f} [{lo:+.3f}, {hi:+.3f}]")
    print(f"| {kind} | {len(keys)} | {cells[0]} | {cells[1]} |")
