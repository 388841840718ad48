#!/usr/bin/env python3
"""Where on the held-out set an arm of a `pav lofo` run trails or leads RAUCA-E2E's texture and
random blocks: per family left out, the mean difference of best car score (the arm's seeds
against RAUCA-E2E's texture, or against the mean of the random-block seeds, view by view) over
the views of each elevation and over FCA's photos, with the 95 % interval of a two-level
bootstrap over seeds and views.
usage: lofo_by_kind.py LOFO_OUT > LOFO_OUT/lofo_by_kind.csv"""
import csv
import glob
import os
import re
import sys
from collections import defaultdict

from paired_stats import heldout_scores, two_level_bootstrap

out = sys.argv[1]
w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["held_out", "against", "views", "count", "diff", "lo", "hi"])
view_re = re.compile(r"pbr:\w+_d[\d.]+_e(\d+)_a")
for path in sorted(glob.glob(os.path.join(out, "without-*", "heldout", "digital_views.csv"))):
    arm = path.split(os.sep)[-3]
    family = arm[len("without-"):]
    score = heldout_scores(path, family)
    rauca = score[("rauca-e2e", "0")]
    randoms = [views for (t, _), views in score.items() if t == "random"]
    refs = {"rauca-e2e": rauca, "random": {v: sum(r[v] for r in randoms) / len(randoms) for v in rauca}}
    seeds = sorted(s for (t, s) in score if t == arm)
    kinds = defaultdict(list)
    for v in sorted(rauca):
        m = view_re.match(v)
        kinds[f"elevation {m.group(1)}°" if m else "FCA photos"].append(v)
    for against, ref in refs.items():
        for kind, views in sorted(kinds.items()):
            d = [[score[(arm, s)][v] - ref[v] for v in views] for s in seeds]
            mean, lo, hi = two_level_bootstrap(d)
            w.writerow([family, against, kind, len(views), f"{mean:.4f}", f"{lo:.4f}", f"{hi:.4f}"])
