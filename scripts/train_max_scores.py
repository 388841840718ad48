#!/usr/bin/env python3
# Usage: scripts/train_max_scores.py RUN_PREFIX... (crossval folders RUN_PREFIX-seed0, -seed1, 11 folds each)
# Mean of each white box's best car score (unweighted) over training steps from step 150, all folds, seeds 0-1.
import csv, collections, sys
for run in sys.argv[1:]:
    agg = collections.defaultdict(list)
    for s in (0, 1):
        for f in range(11):
            for r in csv.DictReader(open(f'{run}-seed{s}/fold{f}of11/loss_detectors.csv')):
                if int(r['step']) >= 150:
                    agg[r['detector']].append(float(r['max_score']))
    print(run, {k: round(sum(v) / len(v), 3) for k, v in agg.items()}, 'steps', {k: len(v) for k, v in agg.items()})
