#!/usr/bin/env python3
"""Tables of the rig study (rig_study.sh): A_physical per back-end, paint and detector without
camera effects, and each effect's change to it.
usage: rig_table.py OUT"""
import csv
import math
import sys
from pathlib import Path

out = Path(sys.argv[1])
PAINTS = ["original", "random", "rauca", "pav"]
EFFECTS = ["defocus", "motion-blur", "noise", "codec", "all"]
BACKENDS = ["blender", "raster"]
NAMES = {"blender": "Blender", "raster": "rasterizer"}


def read(label):
    rows = {}
    with open(out / "eval" / label / "summary.csv") as f:
        for r in csv.DictReader(f):
            rows[r["detector"]] = (int(r["detected"]), int(r["frames"]))
    return rows


def wilson(k, n, z=1.96):
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def newcombe(k1, n1, k0, n0):
    """95 % interval of p1 - p0 (Newcombe's hybrid score)."""
    p1, p0 = k1 / n1, k0 / n0
    l1, u1 = wilson(k1, n1)
    l0, u0 = wilson(k0, n0)
    d = p1 - p0
    return d - math.sqrt((p1 - l1) ** 2 + (u0 - p0) ** 2), d + math.sqrt((u1 - p1) ** 2 + (p0 - l0) ** 2)


base = {(b, p): read(f"{b}-{p}-none") for b in BACKENDS for p in PAINTS}
detectors = sorted(next(iter(base.values())).keys())
print("A_physical in % [Wilson 95 %], no camera effects, 44 frames per cell\n")
print("| back-end | paint | " + " | ".join(detectors) + " |")
print("|---|---|" + "---:|" * len(detectors))
for b in BACKENDS:
    for p in PAINTS:
        cells = []
        for d in detectors:
            k, n = base[(b, p)][d]
            lo, hi = wilson(k, n)
            cells.append(f"{100 * k / n:.1f} [{100 * lo:.0f}, {100 * hi:.0f}]")
        print(f"| {NAMES[b]} | {p} | " + " | ".join(cells) + " |")

print("\nChange in A_physical by each camera effect, percentage points, the four detectors pooled")
print("(176 frames per paint) [Newcombe 95 %]\n")
print("| effect | back-end | " + " | ".join(PAINTS) + " |")
print("|---|---|" + "---:|" * len(PAINTS))
for e in EFFECTS:
    for b in BACKENDS:
        cells = []
        for p in PAINTS:
            fx = read(f"{b}-{p}-{e}")
            k1 = sum(fx[d][0] for d in detectors)
            k0 = sum(base[(b, p)][d][0] for d in detectors)
            n = sum(fx[d][1] for d in detectors)
            lo, hi = newcombe(k1, n, k0, n)
            cells.append(f"{100 * (k1 - k0) / n:+.1f} [{100 * lo:+.0f}, {100 * hi:+.0f}]")
        print(f"| {e} | {NAMES[b]} | " + " | ".join(cells) + " |")

print("\nBack-ends side by side: Blender minus rasterizer, percentage points, no effects [Newcombe 95 %]\n")
print("| paint | " + " | ".join(detectors) + " |")
print("|---|" + "---:|" * len(detectors))
for p in PAINTS:
    cells = []
    for d in detectors:
        (k1, n1), (k0, n0) = base[("blender", p)][d], base[("raster", p)][d]
        lo, hi = newcombe(k1, n1, k0, n0)
        mark = "" if lo <= 0 <= hi else " *"
        cells.append(f"{100 * (k1 / n1 - k0 / n0):+.1f} [{100 * lo:+.0f}, {100 * hi:+.0f}]{mark}")
    print(f"| {p} | " + " | ".join(cells) + " |")
print("\n* the interval excludes 0: the back-ends disagree")

print("\nThe unpainted model by camera position: A_physical in % per polar angle (22 frames each)\n")
print("| back-end | polar angle | " + " | ".join(detectors) + " |")
print("|---|---:|" + "---:|" * len(detectors))
for b in BACKENDS:
    with open(out / "eval" / f"{b}-original-none" / "frames.csv") as f:
        rows = list(csv.DictReader(f))
    for e in ["0", "20"]:
        cells = []
        for d in detectors:
            sel = [r for r in rows if r["detector"] == d and r["file"].endswith(f"_e{e}.mp4")]
            k = sum(r["detected"] == "true" for r in sel)
            cells.append(f"{100 * k / len(sel):.1f}")
        print(f"| {NAMES[b]} | {e}° | " + " | ".join(cells) + " |")
