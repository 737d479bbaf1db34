"""The scale-out's exactness on a large volume: a synthetic 25-label tissue split into
chunks, stitched, against the whole-volume solve of the same volume.

    cargo xtask synth-labels --dims 256,256,256 --out target/synth256.npy
    target/ci-venv/bin/python bench/scale/scale_exactness.py target/synth256.npy [--chunk 64] [--halo 24] [param=value ...]

Prints the face and vertex-id comparison (exact), watertightness per label, and the mean
and max vertex deviation (voxels) at the halo, with the wall time of each part.
"""
import argparse
import time

import numpy as np

import voxreg.dask as vd

ap = argparse.ArgumentParser()
ap.add_argument("volume")
ap.add_argument("--chunk", type=int, default=64)
ap.add_argument("--halo", type=int, default=vd.DEFAULT_HALO)
ap.add_argument("params", nargs="*", help="parameters of voxreg.regularize, e.g. tolerance=1e-6")
args = ap.parse_args()
params = {}
for arg in args.params:
    k, v = arg.split("=")
    params[k] = v == "True" if v in ("True", "False") else (int(v) if v.isdigit() else float(v) if v[0].isdigit() else v)

vol = np.load(args.volume)
print(f"volume {vol.shape}, {len(np.unique(vol))} labels, chunks {args.chunk}^3, halo {args.halo}", flush=True)
t = time.perf_counter()
ref = vd.regularize_chunk(vol, (0, 0, 0), [(0, n) for n in vol.shape], vol.shape, threads=0, **params)
print(f"whole volume: {len(ref['quads'])} quads, {time.perf_counter() - t:.1f} s", flush=True)
t = time.perf_counter()
mesh = vd.regularize(vol, chunks=(args.chunk,) * 3, halo=args.halo, scheduler="threads", **params)
print(f"chunked: {len(mesh.quads)} quads, {time.perf_counter() - t:.1f} s", flush=True)


def faces(ids, quads, labels):
    return sorted((tuple(int(v) for v in ids[q]), tuple(int(x) for x in lab)) for q, lab in zip(quads, labels))


same_ids = np.array_equal(np.sort(mesh.vertex_ids), np.sort(ref["vertex_ids"]))
same_faces = faces(mesh.vertex_ids, mesh.quads, mesh.labels) == faces(ref["vertex_ids"], ref["quads"], ref["labels"])
print(f"vertex ids identical: {same_ids}; faces identical: {same_faces}", flush=True)
leaky = []
for label in np.unique(vol):
    if label == 0:
        continue
    q = vd.region_mesh(mesh, int(label)).quads
    edges = np.sort(np.stack([q, np.roll(q, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if not (len(q) and np.all(counts % 2 == 0)):
        leaky.append(int(label))
print(f"labels not watertight: {leaky}", flush=True)
order = np.argsort(ref["vertex_ids"])
d = np.linalg.norm(mesh.vertices - ref["positions"][order], axis=1)
print(f"deviation: mean {d.mean():.2e}, max {d.max():.2e}, 99.9th percentile {np.quantile(d, 0.999):.2e}")

# Where the deviations sit: against the distance of each vertex's lattice corner to the
# nearest chunk border (a plane between two chunks; the volume's own border excluded).
dims = np.array(vol.shape)
ids = np.sort(ref["vertex_ids"])
corner = np.stack([ids % (dims[0] + 1), (ids // (dims[0] + 1)) % (dims[1] + 1),
                   ids // ((dims[0] + 1) * (dims[1] + 1))], axis=1)
to_border = np.full(len(ids), np.inf)
for k in range(3):
    c = corner[:, k]
    planes = np.arange(args.chunk, dims[k], args.chunk)
    if len(planes):
        to_border = np.minimum(to_border, np.abs(c[:, None] - planes[None, :]).min(axis=1))
for lo, hi in ((0, 2), (2, 8), (8, 16), (16, 32), (32, 1e9)):
    sel = (to_border >= lo) & (to_border < hi)
    if sel.any():
        print(f"corners {lo:>2}-{hi:<4} voxels from a chunk border: {sel.sum():8d} vertices, "
              f"mean {d[sel].mean():.2e}, max {d[sel].max():.2e}, above 1e-2: {(d[sel] > 1e-2).sum()}")
