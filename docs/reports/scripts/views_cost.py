#!/usr/bin/env python3
"""What a rendered view set cost on this machine, from the seconds `pav views render` records per
view in its manifest: per set and kind of view (a view on a street photo, or a pose in an
environment map), the count, the median seconds a view and the hours the set takes at that
median. The median, not the sum: a render paused or sharing the cores records longer views, and
the sum would charge those to Blender.
usage: views_cost.py VIEWS_OUT... > cost.csv"""
import csv
import os
import statistics
import sys
from collections import defaultdict

w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["views_out", "kind", "views", "median_s", "hours"])
for out in sys.argv[1:]:
    seconds = defaultdict(list)
    with open(os.path.join(out, "manifest.csv")) as f:
        for r in csv.DictReader(f):
            seconds["plate" if r["plate"] else "pose"].append(float(r["seconds"]))
    every = [s for kind in seconds.values() for s in kind]
    for kind, s in sorted(seconds.items()) + [("all", every)]:
        median = statistics.median(s)
        w.writerow([os.path.basename(out.rstrip("/")), kind, len(s), f"{median:.2f}", f"{median * len(s) / 3600:.2f}"])
