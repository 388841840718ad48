#!/usr/bin/env python3
"""Per-seed spread of a paired turntable comparison: for an `evaluate` run whose labels hold one
video per (seed, shot), each video's path naming its seed (`…s<K>/…` or `…/seed<K>/…`), prints
per detector the mean best car score difference of LABEL − AGAINST for each seed (frames paired
by shot and index, as `pav-rig paired` pairs them) and their range.
usage: rig_seed_spread.py EVAL/frames.csv LABEL AGAINST"""
import csv
import re
import sys
from collections import defaultdict

frames, label, against = sys.argv[1:4]
seed_re = re.compile(r"(?:-s|/seed)(\d+)/")
score = {}  # (label, detector, seed, shot, frame) -> score
for r in csv.DictReader(open(frames)):
    m = seed_re.search(r["file"])
    if not m:
        continue
    shot = r["file"].rsplit("/", 1)[-1]
    score[(r["video"], r["detector"], int(m.group(1)), shot, int(r["frame"]))] = float(r["max_score"])
diffs = defaultdict(lambda: defaultdict(list))
for (v, det, seed, shot, frame), s in score.items():
    if v != label:
        continue
    t = score.get((against, det, seed, shot, frame))
    if t is not None:
        diffs[det][seed].append(s - t)
print(f"{label} − {against}, mean best car score per seed")
for det, per in diffs.items():
    means = {k: sum(d) / len(d) for k, d in sorted(per.items())}
    cells = "  ".join(f"s{k} {m:+.3f}" for k, m in means.items())
    print(f"{det:18} {cells}  range [{min(means.values()):+.3f}, {max(means.values()):+.3f}]")
