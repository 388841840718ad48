#!/usr/bin/env python3
"""Paired bootstrap of `pav crossval` runs over the same held-out views.

    python3 scripts/paired_runs.py A B
    python3 scripts/paired_runs.py A1,A2 B1,B2          # seeds averaged per view
    python3 scripts/paired_runs.py A1,A2@RAUCA_E2E B1,B2  # another texture of the same runs

Each side is one or more `crossval_views.csv` files (comma-separated: runs of one config with
different seeds) and optionally `@TEXTURE` (default `optimized`; `RAUCA_E2E`, `random`, ...).
A view's score on a side is the mean over its files and over that texture's seeds, so several
seeds of a config compare as the method rather than as one draw of it.

For each detector: the mean over held-out views of B minus A, with a 95 % interval from 10,000
resamples of the views (seed 0). Below zero: B leaves the car lower scores.
"""
import csv
import random
import sys
from collections import defaultdict


def held_out(side):
    paths, _, texture = side.partition("@")
    texture = texture or "optimized"
    sums = defaultdict(lambda: [0.0, 0])
    for path in paths.split(","):
        for r in csv.DictReader(open(path)):
            if r["role"] == "held-out" and r["texture"] == texture:
                s = sums[(r["view"], r["detector"])]
                s[0] += float(r["score"])
                s[1] += 1
    if not sums:
        sys.exit(f"{side}: no held-out rows for texture {texture!r}")
    return {k: total / n for k, (total, n) in sums.items()}


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    a, b = held_out(sys.argv[1]), held_out(sys.argv[2])
    random.seed(0)
    for det in sorted({k[1] for k in a}):
        views = sorted(v for (v, d) in a if d == det and (v, d) in b)
        if not views:
            continue
        diff = [b[(v, det)] - a[(v, det)] for v in views]
        m = sum(diff) / len(diff)
        boots = sorted(sum(random.choice(diff) for _ in diff) / len(diff) for _ in range(10000))
        print(f"{det}: {len(views)} views, B - A {m:+.3f} [{boots[249]:+.3f}, {boots[9749]:+.3f}]")


main()
