#!/usr/bin/env python3
"""Paired bootstrap of two `pav crossval` runs over the same held-out views.

    python3 scripts/paired_runs.py A/crossval_views.csv B/crossval_views.csv

For each detector: the mean over held-out views of B's optimized score minus A's, with a 95 %
interval from 10,000 resamples of the views (seed 0). Below zero: B leaves the car lower scores.
"""
import csv
import random
import sys


def held_out(path):
    d = {}
    for r in csv.DictReader(open(path)):
        if r["role"] == "held-out" and r["texture"] == "optimized":
            d[(r["view"], r["detector"])] = float(r["score"])
    return d


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
