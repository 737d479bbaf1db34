"""How much the refinement rounds still move a volume's surface, and how much the output
depends on the solver's tolerance.

    target/ci-venv/bin/python bench/accuracy/refine_stability.py target/channels.npy

Regularizes a label volume (`.npy`, indexed [x, y, z]) with the default parameters and
`refine` = 1, 2, 3, 4, then once more at half the default tolerance. Prints, between
consecutive round counts, each vertex's motion across the surface (projected on the vertex
normal of the later mesh: the sum of its quads' vector areas) and in all; then the default
run against the half-tolerance run. Distances in voxels. The same surface every run, so
vertices compare by index.
"""
import sys

import numpy as np

import voxreg


def vertex_normals(v, quads):
    q = v[quads]
    n = np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])
    out = np.zeros_like(v)
    for k in range(4):
        np.add.at(out, quads[:, k], n)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def describe(d):
    return (f"mean {d.mean():.3e}, 99th {np.quantile(d, 0.99):.3f}, max {d.max():.3f}, "
            f"past 1e-2 {(d > 1e-2).sum()}, past 0.1 {(d > 0.1).sum()}, past 0.5 {(d > 0.5).sum()}")


labels = np.load(sys.argv[1])
runs = {k: voxreg.regularize(labels, refine=k) for k in (1, 2, 3, 4)}
quads = runs[3].quads
for k in (1, 2, 3):
    a, b = runs[k].vertices, runs[k + 1].vertices
    across = np.abs(np.sum((b - a) * vertex_normals(b, quads), axis=1))
    print(f"rounds {k} -> {k + 1}, across: {describe(across)}")
    print(f"rounds {k} -> {k + 1}, in all:  {describe(np.linalg.norm(b - a, axis=1))}")
half = voxreg.regularize(labels, tolerance=5e-4).vertices
print(f"default against tolerance 5e-4: {describe(np.linalg.norm(half - runs[3].vertices, axis=1))}")
