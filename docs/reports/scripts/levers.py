#!/usr/bin/env python3
"""What each lever does to transfer, measured against a base `pav lofo` run on the same held-out
views and seeds: for every family both runs left out, the lever arm's best car score minus the
base arm's at the same seed, view by view, with the 95 % interval of a two-level bootstrap over
seeds and views. Below zero: the lever hides the car from the family it never trained on better
than the base recipe does. Rows follow the arguments; a family the base did not leave out is
skipped. With --rig the runs are lofo_rig.sh outputs filmed on one rig config, paired frame by
frame (shot and turntable angle), on screen and as printed.
usage: levers.py [--rig] BASE_OUT NAME=OUT... > levers.csv
  e.g. levers.py out/lofo whole-body=out/lofo-full-pilot scale=out/scale
       levers.py --rig out/lofo-rig-dense scale=out/scale/rig"""
import csv
import glob
import os
import sys
import tomllib

from paired_stats import arm_scores, paired_arms, rig_frames


def rig_scores(rig_out, mode, arm):
    """{seed: {(shot, angle): best car score}} of an arm's textures in a lofo_rig.sh output, or
    None where it filmed no such arm."""
    path = os.path.join(rig_out, mode, "eval", arm, "frames.csv")
    if not os.path.exists(path):
        return None
    _, frames = rig_frames(path)
    return {label[len(arm) + 2:]: {(shot, angle): s for (shot, _), (angle, s) in f.items()}
            for label, f in frames.items() if label.startswith(f"{arm}-s")}


def printed(out):
    """Whether a `pav lofo` run scored its held-out set through a printer: the config its
    `--heldout` names (in its run.toml's command) has a [print] table."""
    with open(os.path.join(out, "run.toml"), "rb") as f:
        command = tomllib.load(f)["command"]
    if "--heldout" not in command:
        return False
    with open(command[command.index("--heldout") + 1], "rb") as f:
        return "print" in tomllib.load(f)


def pairs(out, rig):
    """(where, family, lever scores) of every arm a run holds; the base's come from `base`."""
    if rig:
        found = sorted(glob.glob(os.path.join(out, "*", "eval", "without-*", "frames.csv")))
        for path in found:
            mode, arm = path.split(os.sep)[-4], path.split(os.sep)[-2]
            yield f"rig, {mode}", arm[len("without-"):], rig_scores(out, mode, arm), lambda b, m=mode, a=arm: rig_scores(b, m, a)
    else:
        found = sorted(glob.glob(os.path.join(out, "without-*", "heldout", "digital_views.csv")))
        on = "held-out set, printed" if printed(out) else "held-out set"
        for path in found:
            family = path.split(os.sep)[-3][len("without-"):]
            has = os.path.exists(os.path.join(base_out, f"without-{family}", "heldout", "digital_views.csv"))
            yield on, family, arm_scores(out, family), lambda b, f=family, h=has: arm_scores(b, f) if h else None
    if not found:
        sys.exit(f"levers.py: {out} holds no scored arm")


args = sys.argv[1:]
rig = args[:1] == ["--rig"]
if rig:
    args = args[1:]
base_out = args[0]
w = csv.writer(sys.stdout, lineterminator="\n")
w.writerow(["lever", "on", "held_out", "score", "base", "diff", "lo", "hi", "half_width", "seeds", "units"])
for arg in args[1:]:
    if "=" not in arg:
        sys.exit(f"levers.py: {arg!r} is not NAME=OUT")
    name, out = arg.split("=", 1)
    for on, family, mine, base_of in pairs(out, rig):
        base = base_of(base_out)
        if base is None:
            continue
        try:
            own, other, mean, lo, hi, seeds, units = paired_arms(mine, base)
        except ValueError as e:
            sys.exit(f"levers.py: {name} against the base for {family} ({on}): {e}")
        w.writerow([name, on, family, f"{own:.4f}", f"{other:.4f}", f"{mean:.4f}", f"{lo:.4f}", f"{hi:.4f}",
                    f"{(hi - lo) / 2:.4f}", seeds, units])
