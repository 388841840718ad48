#!/usr/bin/env python3
"""What each lever does to transfer, measured against a base `pav lofo` run on the same held-out
views and seeds: for every family both runs left out, the lever arm's best car score minus the
base arm's at the same seed, view by view, with the 95 % interval of a two-level bootstrap over
seeds and views. Below zero: the lever hides the car from the family it never trained on better
than the base recipe does. Rows follow the arguments; families in neither order are skipped.
usage: levers.py BASE_OUT NAME=LOFO_OUT... > levers.csv
  e.g. levers.py out/lofo whole-body=out/lofo-full-pilot scale=out/scale"""
import csv
import glob
import os
import sys

from paired_stats import arm_scores, paired_arms

base_out = sys.argv[1]
w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["lever", "held_out", "score", "base", "diff", "lo", "hi", "half_width", "seeds", "views"])
for arg in sys.argv[2:]:
    if "=" not in arg:
        sys.exit(f"levers.py: {arg!r} is not NAME=LOFO_OUT")
    name, out = arg.split("=", 1)
    arms = sorted(glob.glob(os.path.join(out, "without-*", "heldout", "digital_views.csv")))
    if not arms:
        sys.exit(f"levers.py: {out} holds no scored arm (without-*/heldout/digital_views.csv)")
    for path in arms:
        family = path.split(os.sep)[-3][len("without-"):]
        if not os.path.exists(os.path.join(base_out, f"without-{family}", "heldout", "digital_views.csv")):
            continue
        own, other, mean, lo, hi, seeds, views = paired_arms(arm_scores(out, family), arm_scores(base_out, family))
        w.writerow([name, family, f"{own:.4f}", f"{other:.4f}", f"{mean:.4f}", f"{lo:.4f}", f"{hi:.4f}",
                    f"{(hi - lo) / 2:.4f}", seeds, views])
