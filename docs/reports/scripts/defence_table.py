#!/usr/bin/env python3
"""The defence study's tables (docs/reports/defences.md) from the crossval runs that
defence_study.sh writes: per detector and defence, the held-out mean best car score and the
share of held-out photos whose car is found (score >= 0.5) for each texture, pooled over seeds;
paired differences by (seed, photo) with 95 % bootstrap intervals; and Xu et al.'s feature
squeezing detector (the largest change of the car score under bit depth 4 or a 3x3 median,
flagged above the 95th percentile of legitimate photos: the original paint and random blocks).
usage: defence_table.py OUT  (the folder defence_study.sh wrote; standard library only)"""
import csv, glob, os, random, re, statistics, sys

out = sys.argv[1]
DET = ["yolov3-tiny", "deimv2_atto_int8", "yolox_nano"]
DEFENCES = [("none", ""), ("median 3×3", "+median3"), ("bit depth 4", "+bits4"), ("JPEG q75", "+jpeg75"),
            ("cutout 2×60²", "+cutout2x60"), ("noise σ 8", "+noise8"), ("clipping 2×", "+clip2")]
TEXTURES = [("original", "plain", "original"), ("random", "plain", "random"), ("RAUCA-E2E", "plain", "RAUCA_E2E"),
            ("pav", "plain", "optimized"), ("pav through median", "median", "optimized"),
            ("pav through clipping", "clip", "optimized")]


def collect(cond, texture):
    """{(detector, seed, photo): score} over every seed of a condition (its -clipped rescoring included)."""
    rows = {}
    for run in sorted(glob.glob(os.path.join(out, f"{cond}-s*"))):
        m = re.search(r"-s(\d+)(-clipped)?$", run)
        path = os.path.join(run, "crossval_views.csv")
        if not m or not os.path.exists(path):
            continue
        seen = {}
        for r in csv.DictReader(open(path)):
            if r["role"] == "held-out" and r["texture"] == texture:
                seen.setdefault((r["detector"], int(m.group(1)), r["view"]), []).append(float(r["score"]))
        rows.update({k: statistics.mean(v) for k, v in seen.items()})
    return rows


def ci(diffs, n=4000):
    rng = random.Random(0)
    means = sorted(statistics.mean(rng.choices(diffs, k=len(diffs))) for _ in range(n))
    return statistics.mean(diffs), means[int(0.025 * n)], means[int(0.975 * n)]


def paired(a, da, b, db):
    """Mean [interval] of a on detector da − b on detector db, paired by (seed, photo)."""
    keys = sorted((k[1], k[2]) for k in a if k[0] == da and (db, k[1], k[2]) in b)
    if not keys:
        return "–"
    m, lo, hi = ci([a[(da, s, v)] - b[(db, s, v)] for s, v in keys])
    return f"{m:+.3f} [{lo:+.3f}, {hi:+.3f}]"


data = {name: collect(cond, tex) for name, cond, tex in TEXTURES}
# The photo tables, where defence_study.sh ran (defence_turntable.sh alone writes none).
if data["pav"]:
    seeds = sorted({k[1] for k in data["pav"]})
    print(f"seeds {seeds}; held-out photos per seed: {len({k[2] for k in data['pav']})}\n")
    for d in DET:
        print(f"\n### {d}: mean best car score / photos with the car found\n")
        print("| defence | " + " | ".join(t for t, _, _ in TEXTURES) + " |")
        print("|---|" + "---:|" * len(TEXTURES))
        for label, suffix in DEFENCES:
            cells = []
            for t, _, _ in TEXTURES:
                v = [s for k, s in data[t].items() if k[0] == d + suffix]
                cells.append(f"{statistics.mean(v):.3f} / {100 * sum(x >= 0.5 for x in v) / len(v):.0f} %" if v else "–")
            print(f"| {label} | " + " | ".join(cells) + " |")

    print("\n### Paired differences of the mean best car score, pairs = (seed, held-out photo)\n")
    print("Clean cost: the original paint behind the defence − without it (negative: the defence loses the car). "
          "Effect: pav's texture behind the defence − without it (positive: the defence finds the car again). "
          "Adapted: the texture trained through the defence − pav's, both scored behind it (negative: adapting wins it back).\n")
    print("| defence | detector | clean cost | effect on pav | effect on RAUCA-E2E | adapted (median) | adapted (clipping) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for label, suffix in DEFENCES[1:]:
        for d in DET:
            dd = d + suffix
            print(f"| {label} | {d} | {paired(data['original'], dd, data['original'], d)} | "
                  f"{paired(data['pav'], dd, data['pav'], d)} | {paired(data['RAUCA-E2E'], dd, data['RAUCA-E2E'], d)} | "
                  f"{paired(data['pav through median'], dd, data['pav'], dd) if suffix == '+median3' else '–'} | "
                  f"{paired(data['pav through clipping'], dd, data['pav'], dd) if suffix == '+clip2' else '–'} |")

    print("\n### Feature squeezing as an attack detector (Xu et al.)\n")
    print("A photo is flagged when bit depth 4 or a 3×3 median moves its best car score by more than the threshold "
          "that flags 5 % of legitimate photos (original paint and random blocks).\n")
    print("| detector | threshold | " + " | ".join(f"{t} flagged" for t, _, _ in TEXTURES) + " |")
    print("|---|---:|" + "---:|" * len(TEXTURES))
    for d in DET:
        def squeeze(t):
            return [max(abs(data[t][(d, s, v)] - data[t][(d + q, s, v)]) for q in ("+bits4", "+median3"))
                    for (dk, s, v) in data[t] if dk == d and all((d + q, s, v) in data[t] for q in ("+bits4", "+median3"))]
        legit = sorted(squeeze("original") + squeeze("random"))
        thr = legit[min(len(legit) - 1, int(0.95 * len(legit)))]
        cells = []
        for t, _, _ in TEXTURES:
            f = squeeze(t)
            cells.append(f"{100 * sum(x > thr for x in f) / len(f):.0f} % of {len(f)}" if f else "–")
        print(f"| {d} | {thr:.3f} | " + " | ".join(cells) + " |")

# The simulated turntable (defence_turntable.sh): A_physical per detector and defence, one column per paint.
rows = {}
for name in ("eval", "eval-clipped"):
    path = os.path.join(out, "turntable", name, "summary.csv")
    if os.path.exists(path):
        for r in csv.DictReader(open(path)):
            rows[(r["video"], r["detector"])] = (int(r["detected"]), int(r["frames"]))
if rows:
    PAINTS = [("original", "original"), ("rauca", "RAUCA-E2E"), ("plain", "pav"), ("median", "pav through median"),
              ("clip", "pav through clipping")]
    print("\n### Simulated turntable: A_physical % (frames with the car found / frames scored)\n")
    print("| detector | defence | " + " | ".join(p for _, p in PAINTS) + " |")
    print("|---|---|" + "---:|" * len(PAINTS))
    for d in DET:
        for label, suffix in DEFENCES:
            cells = [f"{100 * rows[(v, d + suffix)][0] / rows[(v, d + suffix)][1]:.1f}" if (v, d + suffix) in rows else "–"
                     for v, _ in PAINTS]
            print(f"| {d} | {label} | " + " | ".join(cells) + " |")
