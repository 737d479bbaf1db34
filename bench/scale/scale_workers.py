"""Throughput of voxreg.dask on 1 worker against 2, interleaved on the same Zarr volume.

    target/pyvenv/bin/python bench/scale/synth_zarr.py target/ooc/t512.zarr --dims 512,512,512
    target/pyvenv/bin/python bench/scale/scale_workers.py target/ooc/t512.zarr [--pairs 2]
        [--chunk 128] [--halo H (default: voxreg.dask's)] [--workers 2] [param=value ...]

Runs 1-worker and N-worker clusters in turn (1, N, 1, N, ...; each a fresh LocalCluster,
one thread per worker, output to a scratch directory), and prints per run one JSON line
(``bench/scale/scale_ooc.py``'s figures), then per pair the speed-up of the compute phase (the
tasks, without the serial merge) and of the whole run. On a machine with other load the
speed-up is bounded by the cores actually free: run it on an idle machine with at least
N cores, and quote the load it prints.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(__file__))
from scale_ooc import _param, run  # noqa: E402

import voxreg.dask as vd  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("store")
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=128)
    ap.add_argument("--halo", type=int, default=vd.DEFAULT_HALO)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--memory", default="2GB")
    ap.add_argument("params", nargs="*")
    a = ap.parse_args()
    params = dict((k, _param(v)) for k, v in (p.split("=", 1) for p in a.params))
    scratch = tempfile.mkdtemp(prefix="voxreg-scale-")
    rows = []
    for pair in range(a.pairs):
        one = run(a.store, os.path.join(scratch, "out"), 1, a.memory, a.chunk, a.halo, ("ply",), **params)
        print(json.dumps(one), flush=True)
        many = run(a.store, os.path.join(scratch, "out"), a.workers, a.memory, a.chunk, a.halo, ("ply",), **params)
        print(json.dumps(many), flush=True)
        rows.append((one, many))
        print(json.dumps({
            "pair": pair, "compute_speedup": round(one["compute_s"] / many["compute_s"], 3),
            "wall_speedup": round(one["wall_s"] / many["wall_s"], 3),
            "task_cpu_ratio": round(many["task_cpu_s"] / one["task_cpu_s"], 3),
            "load": os.getloadavg(),
        }), flush=True)


if __name__ == "__main__":
    main()
