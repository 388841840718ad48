#!/usr/bin/env python3
"""Two `pav optimize` runs of one config and seed (same views, same EoT draws), step by step:
the loss terms and each white box's best detection score, A and B, and B − A with a 95 %
paired-bootstrap interval over steps. Usage: paired_loss.py RUN_A RUN_B (docs/reports/transfer.md, "Where the miss sits")."""
import csv
import random
import sys


def load(d):
    return list(csv.DictReader(open(d + '/loss.csv'))), list(csv.DictReader(open(d + '/loss_detectors.csv')))


def interval(d):
    rng = random.Random(1)
    n = len(d)
    bs = sorted(sum(rng.choice(d) for _ in range(n)) / n for _ in range(10000))
    return sum(d) / n, bs[250], bs[9750]


def main(a_dir, b_dir):
    (a, ad), (b, bd) = load(a_dir), load(b_dir)
    if [r['view'] for r in a] != [r['view'] for r in b]:
        sys.exit('the runs visit different views: same config and optimizer seed needed')
    print('| per step (%d), mean | A | B | B − A |\n|---|---:|---:|---:|' % len(a))

    def row(name, x, y):
        m, lo, hi = interval([v - u for u, v in zip(x, y)])
        print('| %s | %.3f | %.3f | %+.3f [%+.3f, %+.3f] |' % (name, sum(x) / len(x), sum(y) / len(y), m, lo, hi))

    for k in ['l1', 'l2', 'total']:
        row(k, [float(r[k]) for r in a], [float(r[k]) for r in b])
    for det in sorted(set(r['detector'] for r in ad)):
        for k in ['l1', 'l2', 'max_score']:
            of = lambda rows: [float(r[k]) for r in rows if r['detector'] == det]
            row('%s %s' % (det, k), of(ad), of(bd))


if __name__ == '__main__':
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
