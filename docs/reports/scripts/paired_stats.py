"""The paired bootstrap the report scripts share."""
import random


def bootstrap(d, n=10000, seed=0):
    """Mean of the paired differences `d` and its 95 % percentile bootstrap interval over `n`
    resamples, drawn from `seed` so that a rerun prints the same numbers."""
    rng = random.Random(seed)
    means = sorted(sum(rng.choice(d) for _ in d) / len(d) for _ in range(n))
    return sum(d) / len(d), means[int(0.025 * n)], means[int(0.975 * n) - 1]
