#!/usr/bin/env python3
"""The table of lofo_rig.sh: per way of sticking on (screen, printed), per family left out, the
arm's mean best car score over its seeds' frames against RAUCA-E2E's texture and against random
blocks (each frame's mean over the random seeds), paired frame by frame (shot file and frame
index), with the 95 % interval of a two-level bootstrap over seeds and frames.
usage: lofo_rig_table.py OUT SEED..."""
import csv
import sys
from pathlib import Path

from paired_stats import rig_frames, two_level_bootstrap

out = Path(sys.argv[1])
seeds = sys.argv[2:]
w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["mode", "held_out", "against", "score", "other", "diff", "lo", "hi", "half_width", "seeds", "frames"])
for mode in ["screen", "printed"]:
    for frames_csv in sorted((out / mode / "eval").glob("without-*/frames.csv")):
        arm = frames_csv.parent.name
        held, frames = rig_frames(frames_csv)
        score = {label: {k: s for k, (_, s) in f.items()} for label, f in frames.items()}
        keys = sorted(score["rauca"])
        randoms = [l for l in score if l.startswith("random")]
        mine = [score[f"{arm}-s{s}"] for s in seeds]
        refs = {
            "rauca-e2e": {k: score["rauca"][k] for k in keys},
            "random": {k: sum(score[l][k] for l in randoms) / len(randoms) for k in keys},
        }
        for against, ref in refs.items():
            d = [[m[k] - ref[k] for k in keys] for m in mine]
            mean, lo, hi = two_level_bootstrap(d)
            own = sum(sum(m[k] for k in keys) for m in mine) / (len(mine) * len(keys))
            other = sum(ref.values()) / len(keys)
            w.writerow([mode, held, against, f"{own:.4f}", f"{other:.4f}", f"{mean:.4f}", f"{lo:.4f}", f"{hi:.4f}",
                        f"{(hi - lo) / 2:.4f}", len(mine), len(keys)])
