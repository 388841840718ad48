#!/usr/bin/env python3
"""Each detector's mean best car score per snapshot step, on the folds' training photos and on
their held-out photos, pooled over `pav crossval` runs made with --curve-every (their
crossval_curve.csv; each fold's off-grid last step left out). Usage: curve_means.py CROSSVAL_DIR..."""
import collections
import csv
import sys

if len(sys.argv) < 2:
    sys.exit(__doc__)
acc = collections.defaultdict(list)
for d in sys.argv[1:]:
    for row in csv.DictReader(open(d + '/crossval_curve.csv')):
        if row['last'] == 'false':
            acc[(row['role'], row['detector'], int(row['step']))].append(float(row['score']))
for role in ['train', 'held-out']:
    for det in sorted({k[1] for k in acc}):
        steps = sorted((s, v) for (ro, d, s), v in acc.items() if ro == role and d == det)
        print(role, det, ' '.join('%d:%.3f' % (s, sum(v) / len(v)) for s, v in steps))
