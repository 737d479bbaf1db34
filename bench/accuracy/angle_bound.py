"""How low can the mean angle between adjacent quads go while the voxel-art guarantees hold?

Minimizes `voxreg_quality::mean_adjacent_angle_deg`'s quantity itself (the mean over
edge-adjacent quads of the angle between their vector areas) over the vertex positions,
from the preset's output and from random points, with L-BFGS-B:

- every vertex in its clamping box, as `clamping.rs` builds it: `[-0.495, 0.495]` voxel
  around its lattice corner, capped at `0.5 - thin_depth` towards each thin voxel whose
  face on the vertex's side is a surfel (`--thin-depth`, the preset's 0.3);
- or, with `--uniform-depth D`, the uniform boxes only and the thickness target itself as
  a penalty: every solid thin voxel's centre at least D from the mesh (sampled on a
  barycentric grid of each triangle, so `voxreg check --voxels` must confirm it);
- folds penalized with a margin (triangles of a quad at least 78 degrees from folding,
  adjacent quads at most 110 degrees apart), so that the minima keep clear of folding;
- optionally `--attach L`: plus L times the mean squared distance to the preset's output.

A local search, so its value bounds the reachable minimum from above, not below; the
random starts sample the rest. Confirm the written mesh with `voxreg check --voxels`.

    voxreg regularize data/metal-material.vox -o mm.obj -q
    python3 bench/accuracy/angle_bound.py mm.obj --starts 30 --out mm-bound.obj
    voxreg check mm-bound.obj --voxels data/metal-material.vox

Needs numpy, scipy and autograd (`pip install numpy scipy autograd`). The input must be
a clamped voxel-art output (each vertex within half a voxel of its corner, unit spacing):
the corners are the rounded positions.
"""
import argparse
import os
import sys

import autograd.numpy as anp
import numpy as np
from autograd import value_and_grad
from scipy.optimize import minimize

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from mean_angle import adjacent_pairs, load  # noqa: E402

HALF = 0.495


def write_obj(path, verts, quads):
    with open(path, "w") as out:
        for p in verts:
            out.write("v %.17g %.17g %.17g\n" % tuple(p))
        for q in quads:
            out.write("f %d %d %d %d\n" % tuple(q + 1))


def surfels(corners, quads):
    """Each quad's axis and cell (its lowest corner): the face between voxels cell - e_axis
    and cell, and the voxel on its solid side (behind its outward vector area)."""
    p = corners[quads]
    axis = np.argmin(p.max(1) - p.min(1), axis=1)
    cell = p.min(1).astype(int)
    area = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    behind = cell.copy()
    outward = area[np.arange(len(quads)), axis] > 0
    behind[np.arange(len(quads)), axis] -= outward.astype(int)
    return axis, [tuple(c) for c in cell], [tuple(c) for c in behind]


def thin_voxels(axis, cells):
    keys = set(zip(axis.tolist(), cells))
    thin = set()
    for a, c in keys:
        up = list(c)
        up[a] += 1
        if (a, tuple(up)) in keys:
            thin.add(c)  # voxel c has both faces along a
    return thin


def clamp_boxes(corners, quads, axis, cells, thin, cap):
    lo = np.full(corners.shape, -HALF)
    hi = np.full(corners.shape, HALF)
    faces_of = {}
    for f, q in enumerate(quads):
        for v in q:
            faces_of.setdefault(v, set()).add((int(axis[f]), cells[f]))
    for v, k in enumerate(corners.astype(int)):
        for o in range(8):
            off = np.array([o & 1, (o >> 1) & 1, (o >> 2) & 1])
            voxel = tuple(k - off)
            if voxel not in thin:
                continue
            for a in range(3):
                cell = list(voxel)
                cell[a] += off[a]
                if (a, tuple(cell)) not in faces_of[v]:
                    continue
                if off[a] == 0:
                    hi[v, a] = min(hi[v, a], cap)
                else:
                    lo[v, a] = max(lo[v, a], -cap)
    return lo, hi


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("--thin-depth", type=float, default=0.3)
    ap.add_argument("--uniform-depth", type=float)
    ap.add_argument("--attach", type=float, default=0.0)
    ap.add_argument("--starts", type=int, default=1, help="the output, then random points")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out")
    args = ap.parse_args()

    start, quads = load(args.mesh)
    quads = np.array(quads)
    corners = np.round(start)
    axis, cells, behind = surfels(corners, quads)
    thin = thin_voxels(axis, cells)
    if args.uniform_depth is None:
        lo, hi = clamp_boxes(corners, quads, axis, cells, thin, min(0.5 - args.thin_depth, HALF))
    else:
        lo, hi = np.full(corners.shape, -HALF), np.full(corners.shape, HALF)
    d0 = start - corners
    if (d0 < lo - 1e-9).any() or (d0 > hi + 1e-9).any():
        raise SystemExit(f"{args.mesh}: a vertex lies outside its box: not this preset's output")
    pairs = np.array(adjacent_pairs(quads.tolist()))
    centres = np.array(sorted(thin & set(behind)), float) + 0.5
    k = 8
    bary = np.array([(i / k, j / k, 1 - (i + j) / k) for i in range(k + 1) for j in range(k + 1 - i)])

    def energy(d):
        x = corners + anp.reshape(d, (-1, 3))
        p = x[quads]
        n = anp.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
        u = n / (anp.sqrt(anp.sum(n * n, 1)) + 1e-30)[:, None]
        c = anp.clip(anp.sum(u[pairs[:, 0]] * u[pairs[:, 1]], 1), -1 + 1e-9, 1 - 1e-9)
        value = anp.mean(anp.arccos(c)) * 180 / np.pi
        t1 = anp.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        t2 = anp.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])
        tc = anp.sum(t1 * t2, 1) / (anp.sqrt(anp.sum(t1 * t1, 1) * anp.sum(t2 * t2, 1)) + 1e-30)
        penalty = anp.sum(anp.maximum(0.0, 0.2 - tc) ** 2) + anp.sum(anp.maximum(0.0, -0.35 - c) ** 2)
        if args.uniform_depth is not None and len(centres):
            pts = []
            for t in [(0, 1, 2), (0, 2, 3)]:
                a, b, cc = p[:, t[0]], p[:, t[1]], p[:, t[2]]
                pts.append(bary[None, :, 0:1] * a[:, None] + bary[None, :, 1:2] * b[:, None] + bary[None, :, 2:3] * cc[:, None])
            s = anp.reshape(anp.concatenate(pts, axis=1), (-1, 3))
            dist = anp.sqrt(anp.sum((s[None] - centres[:, None]) ** 2, 2) + 1e-12)
            penalty = penalty + anp.sum(anp.maximum(0.0, args.uniform_depth - dist) ** 2)
        attach = args.attach * anp.mean(anp.sum((anp.reshape(d, (-1, 3)) - d0) ** 2, 1))
        return value + 1e3 * penalty + attach

    grad = value_and_grad(energy)
    bounds = list(zip(lo.ravel(), hi.ravel()))
    rng = np.random.default_rng(args.seed)
    best = None
    for s in range(args.starts):
        x0 = d0.ravel() if s == 0 else rng.uniform(lo.ravel(), hi.ravel())
        r = minimize(grad, x0, jac=True, method="L-BFGS-B", bounds=bounds, options=dict(maxiter=20000, maxfun=40000))
        if best is None or r.fun < best.fun:
            best = r
        print(f"start {s}: {r.fun:.2f} (best {best.fun:.2f})", flush=True)
    moved = np.linalg.norm(best.x.reshape(-1, 3) - d0, axis=1)
    print(
        f"{args.mesh}: {len(thin)} thin voxels, {int((lo > -HALF).sum() + (hi < HALF).sum())} capped coordinates; "
        f"objective {best.fun:.2f}, moved from the input mesh: mean {moved.mean():.3f}, max {moved.max():.3f} voxel"
    )
    if args.out:
        write_obj(args.out, corners + best.x.reshape(-1, 3), quads)


if __name__ == "__main__":
    main()
