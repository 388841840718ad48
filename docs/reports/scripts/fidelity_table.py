#!/usr/bin/env python3
"""The fidelity study's table (docs/reports/fidelity.md) from the folders fidelity.sh writes: per
level of training-view fidelity, its cost (the median seconds a view takes to draw, from the
benchmark fidelity_cost.sh writes, bench/fidelity_cost.csv) and how many of its views the arm kept to train on (those whose unpainted
car some white box finds), beside each held-out family's `pav lofo` rows (the trained texture against
RAUCA-E2E's and random blocks on the held-out set), for the levels whose scoring has finished.
usage: fidelity_table.py OUT [COST_CSV] > OUT/fidelity.csv  (standard library only)"""
import csv, os, re, statistics, sys

out = sys.argv[1]
costs = {}
for r in csv.DictReader(open(sys.argv[2] if len(sys.argv) > 2 else "bench/fidelity_cost.csv")):
    costs.setdefault(r["level"], []).append(float(r["seconds"]))
LEVELS = ["rasterizer", "cycles4", "cycles16", "cycles64", "cycles16-208"]
w = csv.writer(sys.stdout, lineterminator="\n")
head = None
for level in LEVELS:
    lofo = os.path.join(out, level, "lofo.csv")
    manifest = os.path.join(out, level, "views", "manifest.csv")
    if not (os.path.exists(lofo) and os.path.exists(manifest)):
        continue
    views = list(csv.DictReader(open(manifest)))
    seconds = statistics.median(costs[level])
    renderer = "rasterizer" if views[0]["samples"] == "0" else "cycles"
    rows = list(csv.DictReader(open(lofo)))
    if head is None:
        head = ["level", "renderer", "samples", "size", "views", "s_per_view", "kept"] + list(rows[0].keys())
        w.writerow(head)
    for r in rows:
        record = open(os.path.join(out, level, f"without-{r['held_out']}", "seed0", "run.toml")).read()
        kept = re.search(r'pbr_kept = "kept (\d+) of', record)
        cells = [level, renderer, views[0]["samples"], views[0]["size"], len(views), f"{seconds:.4f}"]
        w.writerow(cells + [kept.group(1) if kept else ""] + list(r.values()))
