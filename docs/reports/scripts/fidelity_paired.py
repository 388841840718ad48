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

from paired_stats import heldout_scores, two_level_bootstrap

out = sys.argv[1]
BASE = "cycles16"
LEVELS = ["rasterizer", "cycles4", "cycles64", "cycles16-208"]
FAMILIES = ["yolox_nano", "nanodet_m_416"]


def scores(level, family):
    """seed -> view -> best car score of the arm's textures on the held-out views."""
    arm = f"without-{family}"
    every = heldout_scores(os.path.join(out, level, arm, "heldout", "digital_views.csv"), family)
    return {seed: views for (texture, seed), views in every.items() if texture == arm}


w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["level", "held_out", "against", "score", "other", "diff", "lo", "hi", "half_width", "seeds", "views"])
for family in FAMILIES:
    base = scores(BASE, family)
    for level in LEVELS:
        mine = scores(level, family)
        seeds = sorted(set(mine) & set(base))
        views = sorted(set.intersection(*(set(mine[s]) & set(base[s]) for s in seeds)))
        d = [[mine[s][v] - base[s][v] for v in views] for s in seeds]
        mean, lo, hi = two_level_bootstrap(d)
        n = len(seeds) * len(views)
        own = sum(mine[s][v] for s in seeds for v in views) / n
        other = sum(base[s][v] for s in seeds for v in views) / n
        w.writerow([level, family, BASE, f"{own:.4f}", f"{other:.4f}", f"{mean:.4f}", f"{lo:.4f}", f"{hi:.4f}",
                    f"{(hi - lo) / 2:.4f}", len(seeds), len(views)])
