"""A synthetic tissue-like label volume written to a Zarr store chunk by chunk.

    target/pyvenv/bin/python bench/scale/synth_zarr.py OUT.zarr [--dims X,Y,Z] [--chunks C]
        [--processes N]

The labels are those of ``cargo xtask synth-labels`` for the same dimensions, voxel for
voxel (``uint8``, indexed ``[x, y, z]``): background 0 around an ellipsoidal body filling
the box, a skin shell (label 1) about 4 voxels thick, and inside 23 organs (labels 2..24),
the cells of a power diagram of seeds drawn by the same fixed-seed SplitMix64 generator.
Each store chunk is evaluated from the function alone (the label of a voxel depends on its
index, not on its neighbours), so no process ever holds more than one chunk, whatever the
volume's size; chunks holding only background are not written (Zarr's fill value).

Also counts the surfels (voxel faces between different labels, the outside counting as
background 0) and the voxels per label, chunk by chunk: the regularized mesh has exactly
that many quads. Prints one JSON line with them, and writes it to ``OUT.zarr.json``.
"""
from __future__ import annotations

import argparse
import itertools
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Dict, List, Sequence, Tuple

import numpy as np

_MASK = (1 << 64) - 1


class SplitMix:
    """SplitMix64, as in ``xtask/src/synth.rs``."""

    def __init__(self, state: int) -> None:
        self.state = state

    def next(self) -> int:
        self.state = (self.state + 0x9E3779B97F4A7C15) & _MASK
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
        return z ^ (z >> 31)

    def unit(self) -> float:
        return float(self.next() >> 11) / float(1 << 53)


def seeds(dims: Sequence[int]) -> List[Tuple[Tuple[float, float, float], float]]:
    """The 23 organ seeds ``(position, weight)`` of ``cargo xtask synth-labels``."""
    rng = SplitMix(0x766F78726567)
    c = [0.5 * (d - 1.0) for d in dims]
    r = [0.5 * d - 2.0 for d in dims]
    out = []
    while len(out) < 23:
        q = [2.0 * rng.unit() - 1.0 for _ in range(3)]
        if (q[0] * q[0] + q[1] * q[1]) + q[2] * q[2] > 0.8:
            continue
        s = tuple(c[k] + q[k] * r[k] for k in range(3))
        cell = float(np.cbrt(r[0] * r[1] * r[2] / 23.0))
        out.append((s, rng.unit() * 0.25 * cell * cell))
    return out


def labels_block(dims: Sequence[int], lo: Sequence[int], hi: Sequence[int],
                 seed_list=None) -> np.ndarray:
    """The labels of voxels ``lo .. hi`` (half-open, any range, even outside the volume),
    the same floating-point operations in the same order as the Rust generator's."""
    seed_list = seeds(dims) if seed_list is None else seed_list
    axes = [np.arange(lo[k], hi[k], dtype=np.float64) for k in range(3)]
    c = [0.5 * (d - 1.0) for d in dims]
    r = [0.5 * d - 2.0 for d in dims]
    q = [(axes[k] - c[k]) / r[k] for k in range(3)]
    rho = np.sqrt((q[0][:, None, None] ** 2 + q[1][None, :, None] ** 2) + q[2][None, None, :] ** 2)
    out = np.zeros(rho.shape, np.uint8)
    skin = 1.0 - 4.0 / min(r)
    out[(rho <= 1.0) & (rho > skin)] = 1
    inside = rho <= skin
    if not inside.any():
        return out
    # Only the voxels inside the skin: their power-diagram cell.
    idx = np.nonzero(inside)
    best = np.full(len(idx[0]), np.inf)
    arg = np.zeros(len(idx[0]), np.uint8)
    for i, (s, w) in enumerate(seed_list):
        d2 = [(axes[k] - s[k]) ** 2 for k in range(3)]
        d = ((d2[0][idx[0]] + d2[1][idx[1]]) + d2[2][idx[2]]) - w
        better = d < best
        best[better] = d[better]
        arg[better] = i
    out[idx] = 2 + arg
    return out


def _faces(dims: Sequence[int], lo: Sequence[int], hi: Sequence[int], block: np.ndarray,
           seed_list) -> int:
    """The faces between different labels whose lower voxel is in the block (and, on the
    volume's near sides, the faces against the outside)."""
    n = 0
    for k in range(3):
        ext_hi = list(hi)
        ext_hi[k] = hi[k] + 1
        ext_lo = list(lo)
        ext_lo[k] = hi[k]
        # The next plane along k (outside the volume: background 0).
        if hi[k] < dims[k]:
            plane = labels_block(dims, ext_lo, ext_hi, seed_list)
        else:
            plane = np.zeros([1 if j == k else hi[j] - lo[j] for j in range(3)], np.uint8)
        ext = np.concatenate([block, plane], axis=k)
        n += int(np.count_nonzero(np.diff(ext.astype(np.int16), axis=k)))
        if lo[k] == 0:
            first = np.take(block, [0], axis=k)
            n += int(np.count_nonzero(first))
    return n


def _chunk_job(args) -> Tuple[int, np.ndarray]:
    path, dims, lo, hi = args
    import zarr

    seed_list = seeds(dims)
    block = labels_block(dims, lo, hi, seed_list)
    if block.any():
        z = zarr.open_array(path, mode="r+")
        z[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = block
    counts = np.bincount(block.ravel(), minlength=256)
    return _faces(dims, lo, hi, block, seed_list), counts


def write(path: str, dims: Sequence[int], chunks: Sequence[int], processes: int = 1) -> Dict:
    """Writes the volume to a new Zarr array at ``path``, chunk by chunk; returns its
    surfel count and voxels per label."""
    import zarr

    dims = tuple(int(d) for d in dims)
    if len(dims) != 3 or min(dims) < 8:
        raise ValueError(f"dims must be three integers of at least 8, got {dims}")
    chunks = tuple(int(c) for c in chunks)
    zarr.create_array(path, shape=dims, chunks=chunks, dtype="u1", fill_value=0, overwrite=True)
    jobs = []
    for index in itertools.product(*(range(0, n, c) for n, c in zip(dims, chunks))):
        lo = list(index)
        hi = [min(lo[k] + chunks[k], dims[k]) for k in range(3)]
        jobs.append((path, dims, lo, hi))
    if processes > 1:
        with ProcessPoolExecutor(processes) as pool:
            results = list(pool.map(_chunk_job, jobs, chunksize=4))
    else:
        results = [_chunk_job(j) for j in jobs]
    surfels = sum(f for f, _ in results)
    counts = sum(c for _, c in results)
    return {"dims": list(dims), "chunks": list(chunks), "surfels": surfels,
            "voxels_per_label": {int(l): int(n) for l, n in enumerate(counts) if n}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--dims", default="2048,2048,512")
    ap.add_argument("--chunks", default="64", help="the store's chunk, C or X,Y,Z")
    ap.add_argument("--processes", type=int, default=1)
    a = ap.parse_args()
    dims = [int(v) for v in a.dims.split(",")]
    chunks = [int(v) for v in a.chunks.split(",")]
    chunks = chunks * 3 if len(chunks) == 1 else chunks
    t = time.perf_counter()
    info = write(a.out, dims, chunks, a.processes)
    info["seconds"] = round(time.perf_counter() - t, 1)
    with open(a.out.rstrip("/") + ".json", "w") as f:
        json.dump(info, f)
    print(json.dumps(info))


if __name__ == "__main__":
    main()
