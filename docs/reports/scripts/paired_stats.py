"""The paired bootstrap the report scripts share, and the readers of the per-view scores of
eval-digital and the per-frame scores of `pav-rig evaluate` they pair."""
import csv
import random
from collections import defaultdict


def bootstrap(d, n=10000, seed=0):
    """Mean of the paired differences `d` and its 95 % percentile bootstrap interval over `n`
    resamples, drawn from `seed` so that a rerun prints the same numbers."""
    rng = random.Random(seed)
    means = sorted(sum(rng.choice(d) for _ in d) / len(d) for _ in range(n))
    return sum(d) / len(d), means[int(0.025 * n)], means[int(0.975 * n) - 1]


def two_level_bootstrap(d, n=10000, seed=0):
    """Mean of `d[seed][unit]` (paired differences per seed and per view or frame, every seed
    over the same units) and its 95 % percentile interval from `n` resamples that draw seeds and
    units with replacement, as `pav lofo` does: the interval carries the spread between seeds
    as well as between units."""
    rng = random.Random(seed)
    s, v = len(d), len(d[0])
    means = []
    for _ in range(n):
        seeds = [rng.randrange(s) for _ in range(s)]
        units = [rng.randrange(v) for _ in range(v)]
        means.append(sum(d[k][u] for k in seeds for u in units) / (s * v))
    means.sort()
    mean = sum(sum(r) for r in d) / (s * v)
    return mean, means[int(0.025 * n)], means[int(0.975 * n) - 1]


def heldout_scores(path, detector):
    """`digital_views.csv` at `path` as {(texture, seed): {view: best car score}}, over the
    held-out views that `detector` scored."""
    out = defaultdict(dict)
    with open(path) as f:
        for r in csv.DictReader(f):
            if r["role"] == "held-out" and r["detector"] == detector:
                out[(r["texture"], r["seed"])][r["view"]] = float(r["score"])
    return out


def rig_frames(path):
    """`pav-rig evaluate`'s `frames.csv` at `path` as (detector, {video label: {(shot file,
    frame index): (turntable angle, best car score)}})."""
    out = defaultdict(dict)
    detector = None
    with open(path) as f:
        for r in csv.DictReader(f):
            out[r["video"]][(r["file"], int(r["frame"]))] = (r["angle_deg"], float(r["max_score"]))
            detector = r["detector"]
    return detector, out


def arm_scores(lofo_out, family):
    """{seed: {view: best car score}} of the textures of the arm of the `pav lofo` run at
    `lofo_out` that left `family` out, on the held-out views that family scored."""
    arm = f"without-{family}"
    every = heldout_scores(f"{lofo_out}/{arm}/heldout/digital_views.csv", family)
    return {seed: views for (texture, seed), views in every.items() if texture == arm}


def paired_arms(mine, base):
    """Two arms' scores (as `arm_scores` gives them) paired on the seeds and views they share:
    (mean score of `mine`, of `base`, mean difference, 95 % interval low, high, seeds, views),
    the interval from `two_level_bootstrap`. ValueError when they share no seed or no view."""
    seeds = sorted(set(mine) & set(base))
    if not seeds:
        raise ValueError("the two arms share no seed")
    views = sorted(set.intersection(*(set(mine[s]) & set(base[s]) for s in seeds)))
    if not views:
        raise ValueError("the two arms share no view or frame (another held-out set or rig config?)")
    d = [[mine[s][v] - base[s][v] for v in views] for s in seeds]
    mean, lo, hi = two_level_bootstrap(d)
    n = len(seeds) * len(views)
    own = sum(mine[s][v] for s in seeds for v in views) / n
    other = sum(base[s][v] for s in seeds for v in views) / n
    return own, other, mean, lo, hi, len(seeds), len(views)
