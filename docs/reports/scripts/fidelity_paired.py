#!/usr/bin/env python3
"""Each fidelity level against Cycles at 16 samples, paired on the same held-out views and seeds
(docs/reports/fidelity.md): per family left out, the level's textures' best car score minus
those of the Cycles-16 arm at the same seed, view by view, with the 95 % interval of a two-level
bootstrap over seeds and views. Below zero: the level's views trained a texture that hides the
car better than Cycles 16's.
usage: fidelity_paired.py OUT > OUT/fidelity_paired.csv   (OUT as fidelity.sh wrote it)"""
import csv
import os
import sys

from paired_stats import arm_scores, paired_arms

out = sys.argv[1]
BASE = "cycles16"
LEVELS = ["rasterizer", "cycles4", "cycles64", "cycles16-208"]
FAMILIES = ["yolox_nano", "nanodet_m_416"]

w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["level", "held_out", "against", "score", "other", "diff", "lo", "hi", "half_width", "seeds", "views"])
for family in FAMILIES:
    base = arm_scores(os.path.join(out, BASE), family)
    for level in LEVELS:
        own, other, mean, lo, hi, seeds, views = paired_arms(arm_scores(os.path.join(out, level), family), base)
        w.writerow([level, family, BASE, f"{own:.4f}", f"{other:.4f}", f"{mean:.4f}", f"{lo:.4f}", f"{hi:.4f}",
                    f"{(hi - lo) / 2:.4f}", seeds, views])
