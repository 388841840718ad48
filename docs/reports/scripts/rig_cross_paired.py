#!/usr/bin/env python3
"""A label of one `pav-rig evaluate` run against a label of the same or another run, frame by
frame: the per-seed spread of a comparison within one run, or one set of textures filmed two
ways. Pairs are (detector, seed, shot, frame), the seed read from each video's path (`…-s<K>/…`
or `…/seed<K>/…`) and the shot from its file name, so two runs must have filmed the same shots
at the same seeds. Prints per detector the mean best car score of both, the mean difference
A − B with its 95 % paired-bootstrap interval (10,000 resamples of the pairs, seed 0) and the
per-seed means. SEEDS (comma-separated) keeps only those seeds: a fixed paint is linked once per
seed, so its own comparison takes one.
usage: rig_cross_paired.py A/frames.csv LABEL_A B/frames.csv LABEL_B [SEEDS]"""
import csv
import re
import sys
from collections import defaultdict

from paired_stats import bootstrap

seed_re = re.compile(r"(?:-s|/seed)(\d+)/")


def scores(path, label):
    out = {}
    for r in csv.DictReader(open(path)):
        if r["video"] != label:
            continue
        m = seed_re.search(r["file"])
        if m:
            key = (r["detector"], int(m.group(1)), r["file"].rsplit("/", 1)[-1], int(r["frame"]))
            out[key] = float(r["max_score"])
    return out


a_path, a_label, b_path, b_label = sys.argv[1:5]
keep = {int(k) for k in sys.argv[5].split(",")} if len(sys.argv) > 5 else None
a, b = scores(a_path, a_label), scores(b_path, b_label)
pairs = defaultdict(list)  # detector -> [(seed, a, b)]
for key, s in a.items():
    if key in b and (keep is None or key[1] in keep):
        pairs[key[0]].append((key[1], s, b[key]))
if not pairs:
    sys.exit("no frame pairs: the two runs share no (detector, seed, shot, frame)")
print(f"| detector | pairs | {a_label} (A) | {b_label} (B) | A − B [95 %] | per seed |")
print("|---|---:|---:|---:|---:|---|")
for det, ps in pairs.items():
    d = [x - y for _, x, y in ps]
    n = len(d)
    mean, lo, hi = bootstrap(d)
    per = defaultdict(list)
    for seed, x, y in ps:
        per[seed].append(x - y)
    seeds = ", ".join(f"s{k} {sum(v) / len(v):+.3f}" for k, v in sorted(per.items()))
    print(f"| {det} | {n} | {sum(x for _, x, _ in ps) / n:.3f} | {sum(y for _, _, y in ps) / n:.3f} "
          f"| {mean:+.3f} [{lo:+.3f}, {hi:+.3f}] | {seeds} |")
