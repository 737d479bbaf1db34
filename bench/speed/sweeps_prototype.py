#!/usr/bin/env python3
"""Prototype (outside the library): a few damped block-Jacobi sweeps from the staircase.

The energy is the library's (``crates/regularize``'s ``Energy``, alpha 1e-2, beta 1,
gamma 0.1):

    E(x) = alpha sum_i |x_i - p_i|^2 + beta sum_f sum_{e in f} (e . n_f)^2
         + gamma sum_i |x_i - mean of x_j over i's neighbours|^2

on the digital surface of a Gauss-digitized analytic shape (built here, one quad per
boundary voxel face, vertices merged by position), with integral-invariant normals
(covariance of the ball of radius r intersected with the solid, the eigenvector of the
smallest eigenvalue, oriented outward; r as voxreg's default rule: 3 h^(1/3) physical,
kept within 3 to 12 voxels). From the staircase x = p it runs damped block-Jacobi
sweeps (the 3x3 vertex blocks of the Hessian, weight 0.7), each one product with the
Hessian, and prints the error against the true surface after 0, 1, 2, 4, ... sweeps next
to the exact minimizer's (sparse direct solve). Then, as a cheap refinement, the normals
re-estimated from the swept positions (area-weighted mean of the quad normals within 3
voxels of each quad) and more sweeps from there. ``--cheap``: no ii at all, rounds of
sweeps and re-estimates from the trivial normals.

Errors: vertex distance in voxels (mean / max), area-weighted mean angle of the quads to
the true normal at their centroid's nearest point (degrees, orientation ignored).

    python bench/speed/sweeps_prototype.py            # sphere R = 20 at h = 1, torus at h = 0.25
    python bench/speed/sweeps_prototype.py --cheap    # no ii: trivial normals, sweeps, re-estimates
    python bench/speed/sweeps_prototype.py --cheap --goursat   # the same on goursat, h = 0.5 and 0.25
"""

import sys
import os
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.spatial import cKDTree

sys.dont_write_bytecode = True  # importing frontier.py leaves no __pycache__ in bench/
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from frontier import Sphere, Torus, Goursat, digitize, face_geometry  # noqa: E402

ALPHA, BETA, GAMMA, OMEGA = 1e-2, 1.0, 0.1, 0.7


def digital_surface(labels):
    """Vertices (voxel coordinates, corners at half-integers) and quads (M, 4), vertices merged by position."""
    inside = labels > 0
    corners, quads_axis = [], []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        lo = np.take(inside, range(inside.shape[a] - 1), axis=a)
        hi = np.take(inside, range(1, inside.shape[a]), axis=a)
        idx = np.argwhere(lo != hi).astype(float)
        centre = idx.copy()
        centre[:, a] += 0.5
        quad = []
        for db, dc in ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)):
            q = centre.copy()
            q[:, b] += db
            q[:, c] += dc
            quad.append(q)
        corners.append(np.stack(quad, 1))
        quads_axis.append(np.full(len(idx), a))
    corners = np.concatenate(corners)
    key = np.round(corners.reshape(-1, 3) * 2).astype(np.int64)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    return uniq / 2.0, inv.reshape(-1, 4)


def ii_normals(labels, centres, radius):
    """Integral-invariant normals at `centres` (voxel coordinates) with a ball of `radius` voxels."""
    r = int(np.ceil(radius)) + 1
    g = np.arange(-r, r + 1)
    off = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    pad = r + 2
    vol = np.pad(labels > 0, pad)
    normals = np.zeros_like(centres)
    for start in range(0, len(centres), 2000):
        c = centres[start : start + 2000]
        base = np.floor(c).astype(int)
        pts = base[:, None, :] + off[None, :, :]  # candidate voxels
        rel = pts - c[:, None, :]
        inball = (rel**2).sum(-1) <= radius**2
        ins = vol[pts[..., 0] + pad, pts[..., 1] + pad, pts[..., 2] + pad] & inball
        w = ins.astype(float)
        n = w.sum(1)[:, None]
        mean = (w[..., None] * rel).sum(1) / n
        d = rel - mean[:, None, :]
        cov = np.einsum("mk,mki,mkj->mij", w, d, d)
        _, vec = np.linalg.eigh(cov)
        nn = vec[:, :, 0]
        nn *= np.where((nn * mean).sum(1) > 0, -1, 1)[:, None]  # outward: away from the solid
        normals[start : start + 2000] = nn
    return normals


def hessian(x0, quads, normals):
    """The energy's matrix A (3n x 3n, CSR) with E = x'Ax - 2 b'x + const."""
    n = len(x0)
    rows, cols, vals = [], [], []

    def add_block(i, j, blocks):
        for a in range(3):
            for b in range(3):
                rows.append(3 * i + a)
                cols.append(3 * j + b)
                vals.append(blocks[:, a, b])

    nnT = BETA * normals[:, :, None] * normals[:, None, :]
    for k in range(4):
        i, j = quads[:, k], quads[:, (k + 1) % 4]
        add_block(i, i, nnT)
        add_block(j, j, nnT)
        add_block(i, j, -nnT)
        add_block(j, i, -nnT)
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))
    # Fairness: gamma |L x|^2 with L = I - W (W: neighbour means over the quads' edges).
    e = np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)])
    e = np.unique(np.sort(e, 1), axis=0)
    adj = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n)).tocsr()
    deg = np.asarray(adj.sum(1)).ravel()
    L = sp.identity(n) - sp.diags(1 / deg) @ adj
    F = GAMMA * (L.T @ L)
    A = A + sp.kron(F, sp.identity(3)) + ALPHA * sp.identity(3 * n)
    return A.tocsr()


def block_diag_inv(A, n):
    D = np.zeros((n, 3, 3))
    Acoo = A.tocoo()
    m = (Acoo.row // 3) == (Acoo.col // 3)
    np.add.at(D, (Acoo.row[m] // 3, Acoo.row[m] % 3, Acoo.col[m] % 3), Acoo.data[m])
    return np.linalg.inv(D)


def measure(shape, x_vox, quads, pmin, h):
    phys = (x_vox + pmin) * h
    d = np.linalg.norm(phys - shape.project(phys), axis=1) / h
    area, cen = face_geometry(phys, quads)
    al = np.linalg.norm(area, axis=1)
    tn = shape.normal(shape.project(cen))
    ang = np.degrees(np.arccos(np.abs((area / al[:, None] * tn).sum(1)).clip(0, 1)))
    return d.mean(), d.max(), (ang * al).sum() / al.sum()


def refined_normals(x, quads, radius):
    area, cen = face_geometry(x, quads)
    tree = cKDTree(cen)
    out = np.zeros_like(area)
    for i, nb in enumerate(tree.query_ball_point(cen, radius)):
        a = area[nb]
        a = a * np.sign(a @ area[i])[:, None]
        out[i] = a.sum(0)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def run(name, shape, h, sweeps=(0, 1, 2, 4, 8, 16, 32, 64)):
    labels, origin = digitize(shape, (h, h, h))
    pmin = origin / h
    verts, quads = digital_surface(labels)
    centres = verts[quads].mean(1)
    radius = min(max(3 * h ** (1 / 3) / h, 3.0), 12.0)
    t = time.perf_counter()
    normals = ii_normals(labels, centres, radius)
    t_ii = time.perf_counter() - t
    tn = shape.normal(shape.project((centres + pmin) * h))
    field = np.degrees(np.arccos(np.abs((normals * tn).sum(1)).clip(0, 1))).mean()
    n = len(verts)
    print(f"\n{name}: {n} vertices, {len(quads)} quads; ii r = {radius:.2f} voxels, field error {field:.2f} deg")
    A = hessian(verts, quads, normals)
    b = ALPHA * verts.ravel()
    t = time.perf_counter()
    exact = spla.spsolve(A.tocsc(), b).reshape(-1, 3)
    t_exact = time.perf_counter() - t
    m = measure(shape, exact, quads, pmin, h)
    print(f"  exact minimizer            distance {m[0]:.3f} / {m[1]:.3f}  normals {m[2]:.2f}  ({t_exact:.1f} s direct)")
    Dinv = block_diag_inv(A, n)
    rows = []

    def sweep_from(x, A, Dinv, count):
        r = b - A @ x.ravel()
        return x + OMEGA * np.einsum("nij,nj->ni", Dinv, r.reshape(-1, 3))

    x = verts.copy()
    done = 0
    t = time.perf_counter()
    for k in sweeps:
        while done < k:
            x = sweep_from(x, A, Dinv, 1)
            done += 1
        m = measure(shape, x, quads, pmin, h)
        rows.append((k, m))
        print(f"  {k:3d} sweeps                 distance {m[0]:.3f} / {m[1]:.3f}  normals {m[2]:.2f}")
    t_sweeps = time.perf_counter() - t
    # One cheap refinement: normals from the positions after 8 sweeps, 8 and 16 more.
    x8 = verts.copy()
    for _ in range(8):
        x8 = sweep_from(x8, A, Dinv, 1)
    n2 = refined_normals(x8, quads, 3.0)
    f2 = np.degrees(np.arccos(np.abs((n2 * tn).sum(1)).clip(0, 1))).mean()
    A2 = hessian(verts, quads, n2)
    D2 = block_diag_inv(A2, n)
    ex2 = spla.spsolve(A2.tocsc(), b).reshape(-1, 3)
    m = measure(shape, ex2, quads, pmin, h)
    print(f"  refined field (from 8 sweeps): error {f2:.2f} deg; its exact minimizer distance {m[0]:.3f} / {m[1]:.3f}  normals {m[2]:.2f}")
    x = x8.copy()
    done = 0
    for k in (4, 8, 16):
        while done < k:
            x = sweep_from(x, A2, D2, 1)
            done += 1
        m = measure(shape, x, quads, pmin, h)
        print(f"  8 + {k:2d} sweeps (refined)    distance {m[0]:.3f} / {m[1]:.3f}  normals {m[2]:.2f}")
    print(f"  (python: ii {t_ii:.2f} s, {sweeps[-1]} sweeps {t_sweeps:.2f} s including the measurements)")
    return rows


def run_cheap(name, shape, h, rounds=3, per_round=8, radius=3.0):
    """No ii: from the trivial normals (each quad's axis: the sweeps then only smooth, by
    the fairness term, as SurfaceNets3D's smoothing does), `rounds` times: normals
    re-estimated from the swept quads (area-weighted mean within `radius` voxels), then
    `per_round` more sweeps."""
    labels, origin = digitize(shape, (h, h, h))
    pmin = origin / h
    verts, quads = digital_surface(labels)
    n = len(verts)
    b = ALPHA * verts.ravel()
    area, _ = face_geometry(verts, quads)
    normals = area / np.linalg.norm(area, axis=1, keepdims=True)  # trivial: the quads' axes
    cen = verts[quads].mean(1)
    tn = shape.normal(shape.project((cen + pmin) * h))
    print(f"\n{name}, no ii: trivial normals, then re-estimates within {radius} voxels; {per_round} sweeps a round")
    x = verts.copy()
    for rnd in range(rounds + 1):
        field = np.degrees(np.arccos(np.abs((normals * tn).sum(1)).clip(0, 1))).mean()
        A = hessian(verts, quads, normals)
        Dinv = block_diag_inv(A, n)
        for k in range(per_round):
            r = b - A @ x.ravel()
            x = x + OMEGA * np.einsum("nij,nj->ni", Dinv, r.reshape(-1, 3))
        m = measure(shape, x, quads, pmin, h)
        print(f"  round {rnd}: field {field:.2f} deg -> {per_round * (rnd + 1):3d} sweeps in all: distance {m[0]:.3f} / {m[1]:.3f}  normals {m[2]:.2f}")
        normals = refined_normals(x, quads, radius)


def main():
    if "--cheap" in sys.argv:
        if "--goursat" in sys.argv:
            for h in (0.5, 0.25):
                run_cheap(f"goursat h = {h}", Goursat(), h, per_round=8)
            return
        for per_round in (4, 8):
            run_cheap("sphere R = 20, h = 1", Sphere(20.0), 1.0, per_round=per_round)
            run_cheap("torus R = 6, r = 2, h = 0.25", Torus(6.0, 2.0), 0.25, per_round=per_round)
        return
    run("sphere R = 20, h = 1", Sphere(20.0), 1.0)
    run("torus R = 6, r = 2, h = 0.25", Torus(6.0, 2.0), 0.25)
    if "--goursat" in sys.argv:
        run("goursat h = 0.5", Goursat(), 0.5)


if __name__ == "__main__":
    main()
