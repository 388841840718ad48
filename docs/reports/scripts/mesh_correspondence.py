#!/usr/bin/env python3
"""Do two OBJ meshes of one car correspond face by face, and is one a mirror of the other?

    python3 docs/reports/scripts/mesh_correspondence.py $(pav data path fca/audi_et_te.obj) \
        $(pav data path rauca-e2e/pytorch3d_Etron.obj)

Fits the scale between the two meshes' face centroids (faces taken in file order). It then
reports, for the identity and for a mirror in each horizontal axis, the median distance between
corresponding centroids and the share of faces within 2 cm, after centring. Needs numpy.
"""
import sys

import numpy as np


def load(path):
    v, f = [], []
    for line in open(path, errors="ignore"):
        if line.startswith("v "):
            v.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            f.append([int(t.split("/")[0]) for t in line.split()[1:4]])
    return np.array(v), np.array(f) - 1


def main(a_path, b_path):
    va, fa = load(a_path)
    vb, fb = load(b_path)
    if len(fa) != len(fb):
        sys.exit(f"{len(fa)} and {len(fb)} faces: no face-by-face correspondence to test")
    ca, cb = va[fa].mean(1), vb[fb].mean(1)
    scale = np.ptp(cb, axis=0).max() / np.ptp(ca, axis=0).max()
    print(f"{len(fa)} faces; scale {scale:.5f} (B per unit of A)")
    for name, flip in [("identity", (1, 1, 1)), ("mirror y", (1, -1, 1)), ("mirror x", (-1, 1, 1))]:
        a = ca * scale * np.array(flip)
        a = a - a.mean(0) + cb.mean(0)
        d = np.linalg.norm(a - cb, axis=1)
        print(f"{name:9} median {np.median(d):.4f}, within 2 cm {(d < 0.02).mean():.3f}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
