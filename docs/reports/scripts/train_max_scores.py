#!/usr/bin/env python3
"""Mean of each white box's best car score (unweighted) over the training steps of `pav crossval`
runs, from a given step on, all folds of all runs pooled: how well the white boxes fit their
training views. Usage: train_max_scores.py [--from-step N] CROSSVAL_DIR... (default N: 150)."""
import argparse
import collections
import csv
import glob
import os

ap = argparse.ArgumentParser(description=__doc__)
ap.add_argument("--from-step", type=int, default=150)
ap.add_argument("runs", nargs="+", help="crossval output folders (each with fold*/loss_detectors.csv)")
a = ap.parse_args()
agg = collections.defaultdict(list)
for run in a.runs:
    folds = sorted(glob.glob(os.path.join(run, "fold*", "loss_detectors.csv")))
    if not folds:
        raise SystemExit(f"{run}: no fold*/loss_detectors.csv (not a crossval folder?)")
    for path in folds:
        for r in csv.DictReader(open(path)):
            if int(r["step"]) >= a.from_step:
                agg[r["detector"]].append(float(r["max_score"]))
print({k: round(sum(v) / len(v), 3) for k, v in agg.items()}, "steps", {k: len(v) for k, v in agg.items()})
