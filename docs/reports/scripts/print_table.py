#!/usr/bin/env python3
"""The print-channel study's table (docs/reports/print.md) from the crossval runs that
print_study.sh writes: per condition and detector, the held-out mean best car score and the share
of held-out photos whose car is found (score >= 0.5), pooled over seeds; each condition against
a baseline, paired by (seed, photo), with a 95 % bootstrap interval.
usage: print_table.py OUT  (the folder print_study.sh wrote; standard library only)"""
import csv, glob, os, random, re, statistics, sys

out = sys.argv[1]
DET = ["yolov3-tiny", "yolov8n_int8", "deimv2_atto_int8", "yolox_nano"]


def held_out(run, texture):
    """{(detector, photo): score} of one run's held-out rows for one texture (seed 0 for the
    optimized and reference textures; random textures are pooled by photo)."""
    rows = {}
    for r in csv.DictReader(open(os.path.join(run, "crossval_views.csv"))):
        if r["role"] == "held-out" and r["texture"] == texture:
            rows.setdefault((r["detector"], r["view"]), []).append(float(r["score"]))
    return {k: statistics.mean(v) for k, v in rows.items()}


def collect(cond, texture):
    """{(detector, seed, photo): score} over every seed of a condition."""
    out_rows = {}
    for run in sorted(glob.glob(os.path.join(out, f"{cond}-s*"))):
        seed = int(re.search(r"-s(\d+)$", run).group(1))
        if not os.path.exists(os.path.join(run, "crossval_views.csv")):
            continue
        for (d, v), s in held_out(run, texture).items():
            out_rows[(d, seed, v)] = s
    return out_rows


def ci(diffs, n=4000):
    rng = random.Random(0)
    means = sorted(statistics.mean(rng.choices(diffs, k=len(diffs))) for _ in range(n))
    return statistics.mean(diffs), means[int(0.025 * n)], means[int(0.975 * n)]


CONDITIONS = [
    ("original paint", "base", "original"),
    ("random blocks, as printed", "base-printed", "random"),
    ("RAUCA-E2E, on screen", "base", "RAUCA_E2E"),
    ("RAUCA-E2E, as printed", "base-printed", "RAUCA_E2E"),
    ("no channel, on screen", "base", "optimized"),
    ("no channel, as printed", "base-printed", "optimized"),
    ("channel, as printed", "channel-g0", "optimized"),
    ("channel + gamut 0.03, as printed", "channel-g0.03", "optimized"),
    ("channel + gamut 0.1, as printed", "channel-g0.1", "optimized"),
    ("channel + gamut 0.3, as printed", "channel-g0.3", "optimized"),
]
data = {name: collect(cond, tex) for name, cond, tex in CONDITIONS}
seeds = sorted({k[1] for k in data["no channel, as printed"]})
print(f"seeds {seeds}; held-out photos per seed: {len({k[2] for k in data['no channel, as printed']})}\n")
print("| texture | " + " | ".join(f"{d} score / found" for d in DET) + " |")
print("|---|" + "---|" * len(DET))
for name, _, _ in CONDITIONS:
    cells = []
    for d in DET:
        v = [s for k, s in data[name].items() if k[0] == d]
        cells.append(f"{statistics.mean(v):.3f} / {100 * sum(x >= 0.5 for x in v) / len(v):.0f} %" if v else "–")
    print(f"| {name} | " + " | ".join(cells) + " |")

PAIRS = [
    ("what printing costs (no channel: as printed − on screen)", "no channel, as printed", "no channel, on screen"),
    ("what printing costs RAUCA-E2E (as printed − on screen)", "RAUCA-E2E, as printed", "RAUCA-E2E, on screen"),
    ("channel − no channel, both as printed", "channel, as printed", "no channel, as printed"),
    ("channel + gamut 0.03 − channel", "channel + gamut 0.03, as printed", "channel, as printed"),
    ("channel + gamut 0.1 − channel", "channel + gamut 0.1, as printed", "channel, as printed"),
    ("channel + gamut 0.3 − channel", "channel + gamut 0.3, as printed", "channel, as printed"),
    ("channel − RAUCA-E2E, both as printed", "channel, as printed", "RAUCA-E2E, as printed"),
]
print("\nPaired differences of the mean best car score (negative: the first hides the car better), "
      "pairs = (seed, held-out photo), 95 % bootstrap interval:\n")
print("| comparison | " + " | ".join(DET) + " |")
print("|---|" + "---|" * len(DET))
for label, a, b in PAIRS:
    cells = []
    for d in DET:
        keys = [k for k in data[a] if k[0] == d and k in data[b]]
        if not keys:
            cells.append("–")
            continue
        m, lo, hi = ci([data[a][k] - data[b][k] for k in keys])
        cells.append(f"{m:+.3f} [{lo:+.3f}, {hi:+.3f}]")
    print(f"| {label} | " + " | ".join(cells) + " |")

# How far printing moves each trained texture (pav print proof over the region, every fold and seed).
import subprocess, tempfile
pav = os.environ.get("PAV", "target/release/pav")
config = os.path.join(out, "configs", "base-s0.toml")
print("\nHow far printing moves the textures (ΔE2000 over the region, median over folds and seeds of each texture's median / share above 5):\n")
print("| trained | median ΔE2000 | texels above 5 |")
print("|---|---|---|")
for cond in ["base", "channel-g0", "channel-g0.03", "channel-g0.1", "channel-g0.3"]:
    med, over = [], []
    for tex in sorted(glob.glob(os.path.join(out, f"{cond}-s*", "fold*", "texture.png"))):
        with tempfile.TemporaryDirectory() as t:
            text = subprocess.run([pav, "print", "proof", "--config", config, "--texture", tex, "-o", os.path.join(t, "p.png")],
                                  capture_output=True, text=True, check=True).stdout
        m = re.search(r"median ([\d.]+), p90 [\d.]+; (\d+) %", text)
        med.append(float(m.group(1)))
        over.append(float(m.group(2)))
    if med:
        print(f"| {cond} ({len(med)} textures) | {statistics.median(med):.1f} | {statistics.median(over):.0f} % |")
