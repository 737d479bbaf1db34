"""Mean angle (degrees) between the normals (vector areas) of edge-adjacent quads of OBJ
meshes: `voxreg_quality::mean_adjacent_angle_deg`, through the Python package
(`voxreg.check(...)["mean_angle_deg"]`; `pip install ./crates/python`), for outputs of any
options.

    python3 bench/accuracy/mean_angle.py out.obj [more.obj ...]

Also the OBJ loader and the adjacent pairs that bench/accuracy/angle_bound.py builds its
objective from.
"""
import sys

import numpy as np


def load(p):
    """The vertices (n, 3) and faces (lists of 0-based indices) of an OBJ file."""
    V = []
    F = []
    for line in open(p):
        if line.startswith("v "):
            V.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("f "):
            F.append([int(x.split("/")[0]) - 1 for x in line.split()[1:]])
    return np.array(V), F


def adjacent_pairs(F):
    """The pairs of faces sharing an edge that no other face shares."""
    E = {}
    for fi, f in enumerate(F):
        for i in range(len(f)):
            e = tuple(sorted((f[i], f[(i + 1) % len(f)])))
            E.setdefault(e, []).append(fi)
    return [fs for fs in E.values() if len(fs) == 2]


def mean_angle(V, F):
    """The library's mean angle between adjacent quads of the quad mesh (V, F)."""
    import voxreg

    return voxreg.check((V, np.asarray(F, dtype=np.int64)))["mean_angle_deg"]


if __name__ == "__main__":
    for p in sys.argv[1:]:
        V, F = load(p)
        print(p, round(mean_angle(V, F), 2))
