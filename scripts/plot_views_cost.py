#!/usr/bin/env python3
"""Plot bench/views_cost.csv (scripts/bench_views.sh) as an SVG with the standard library only:
seconds per view (log axis) against the simulated A_physical and the mean best car score, one
line per detector, each point labelled with its size/samples."""
import csv
import math
import sys

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]


def main(src, dst):
    rows = list(csv.DictReader(open(src)))
    if not rows:
        sys.exit(f"{src}: no rows")
    dets = sorted({r["detector"] for r in rows})
    secs = [float(r["seconds_per_view"]) for r in rows]
    lo, hi = math.log10(min(secs)) - 0.1, math.log10(max(secs)) + 0.1
    w, h, m = 420, 300, 50
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * w + 130}" height="{h + 40}" font-family="sans-serif" font-size="11">',
           f'<rect width="{2 * w + 130}" height="{h + 40}" fill="white"/>']
    for p, (key, title) in enumerate([("a_physical", "simulated A_physical"), ("mean_best_score", "mean best car score")]):
        x0 = p * w
        X = lambda s: x0 + m + (math.log10(s) - lo) / (hi - lo) * (w - 2 * m)
        Y = lambda v: h - m + 20 - v * (h - 2 * m)
        out.append(f'<text x="{x0 + w / 2}" y="16" text-anchor="middle" font-size="13">{title} vs seconds per view</text>')
        out.append(f'<line x1="{x0 + m}" y1="{Y(0)}" x2="{x0 + w - m}" y2="{Y(0)}" stroke="black"/>')
        out.append(f'<line x1="{x0 + m}" y1="{Y(0)}" x2="{x0 + m}" y2="{Y(1)}" stroke="black"/>')
        for v in (0, 0.25, 0.5, 0.75, 1):
            out.append(f'<text x="{x0 + m - 4}" y="{Y(v) + 4}" text-anchor="end">{v:g}</text>')
            out.append(f'<line x1="{x0 + m}" y1="{Y(v)}" x2="{x0 + w - m}" y2="{Y(v)}" stroke="#ddd"/>')
        for e in range(math.floor(lo), math.ceil(hi) + 1):
            for k in (1, 2, 5):
                s = k * 10 ** e
                if lo <= math.log10(s) <= hi:
                    out.append(f'<text x="{X(s)}" y="{Y(0) + 14}" text-anchor="middle">{s:g}</text>')
        out.append(f'<text x="{x0 + w / 2}" y="{Y(0) + 30}" text-anchor="middle">seconds per view (log)</text>')
        for i, d in enumerate(dets):
            c = COLOURS[i % len(COLOURS)]
            pts = sorted((float(r["seconds_per_view"]), float(r[key]), f'{r["size"]}/{r["samples"]}')
                         for r in rows if r["detector"] == d)
            out.append('<polyline fill="none" stroke="%s" points="%s"/>' % (c, " ".join(f"{X(s):.1f},{Y(v):.1f}" for s, v, _ in pts)))
            for s, v, lab in pts:
                out.append(f'<circle cx="{X(s):.1f}" cy="{Y(v):.1f}" r="3" fill="{c}"/>')
                if i == 0:
                    out.append(f'<text x="{X(s):.1f}" y="{Y(1) - 4}" text-anchor="middle" fill="#555">{lab}</text>')
            if p == 1:
                out.append(f'<text x="{x0 + w - m + 4}" y="{Y(1) + 14 * i + 10}" fill="{c}">{d}</text>')
    out.append("</svg>")
    open(dst, "w").write("\n".join(out))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: plot_views_cost.py views_cost.csv out.svg")
    main(sys.argv[1], sys.argv[2])
