"""How far the refinement rounds move the surface closer to the digitized shape.

    target/ci-venv/bin/python bench/accuracy/refine_rounds.py

Digitizes a sphere (radius 20 voxels) and a torus (radii 24 and 8 voxels), regularizes each
with the default parameters and with `refine=0` and `refine=1`, and prints the distance of
the mesh's vertices to the analytic surface (mean, max, mean signed; voxels). Vertices, not
area: the figures compare the settings with each other, not with docs/accuracy.md's table.
"""
import numpy as np

import voxreg


def run(name, labels, distance):
    for params in ({}, {"refine": 0}, {"refine": 1}):
        mesh = voxreg.regularize(labels.astype(np.uint8), threads=1, **params)
        d = distance(mesh.vertices)
        setting = ", ".join(f"{k}={v}" for k, v in params.items()) or "default"
        print(f"{name}, {setting}: mean {np.abs(d).mean():.4f}, max {np.abs(d).max():.3f}, "
              f"signed {d.mean():+.4f}")


def grid(dims):
    return np.stack(np.meshgrid(*[np.arange(n) for n in dims], indexing="ij"), -1).astype(float)


# Voxel centres at integer coordinates; centres off the lattice's symmetry.
centre = np.array([23.3, 23.6, 23.45])
run("sphere r = 20", np.linalg.norm(grid((48,) * 3) - centre, axis=-1) < 20.0,
    lambda v: np.linalg.norm(v - centre, axis=1) - 20.0)

torus_centre = np.array([36.3, 36.6, 12.45])


def torus(p):
    q = p - torus_centre
    return np.hypot(np.hypot(q[..., 0], q[..., 1]) - 24.0, q[..., 2]) - 8.0


run("torus R = 24, r = 8", torus(grid((74, 74, 26))) < 0, torus)
