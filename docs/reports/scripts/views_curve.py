#!/usr/bin/env python3
"""Transfer against the number of training views: each `pav lofo` run's rows against RAUCA-E2E's
texture (its lofo.csv), one per family left out, beside the number of views its recipe trained
on, for `pav results plot --x "training views" --log-x`.
usage: views_curve.py VIEWS=LOFO_OUT... > curve.csv
  e.g. views_curve.py 297=out/lofo 3096=out/scale"""
import csv
import os
import sys

w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["views", "held_out", "diff", "lo", "hi", "seeds"])
for arg in sys.argv[1:]:
    views, out = arg.split("=", 1) if "=" in arg else sys.exit(f"views_curve.py: {arg!r} is not VIEWS=LOFO_OUT")
    with open(os.path.join(out, "lofo.csv")) as f:
        for r in csv.DictReader(f):
            if r["against"] == "rauca-e2e":
                w.writerow([views, r["held_out"], r["diff"], r["lo"], r["hi"], r["seeds"]])
