"""The stitched mesh of voxreg.dask against the whole-volume solve, per halo width.

    target/ci-venv/bin/python bench/scale/halo.py [param=value ...]   # e.g. refine=0

Prints the mean and max vertex deviation (voxels) on the pytest suite's 64^3 five-label
volume in 32^3 chunks.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "crates", "python", "tests"))
from test_dask import tissue, whole  # noqa: E402

import voxreg.dask as vd  # noqa: E402

vol = tissue()
params = {}
for arg in sys.argv[1:]:
    k, v = arg.split("=")
    params[k] = int(v) if v.isdigit() else (v == "True" if v in ("True", "False") else v)
ref = whole(vol, **params)
order = np.argsort(ref["vertex_ids"])
for halo in (8, 12, 16, 24):
    m = vd.regularize(vol, chunks=(32, 32, 32), halo=halo, scheduler="threads", **params)
    d = np.linalg.norm(m.vertices - ref["positions"][order], axis=1)
    print(f"halo {halo:2d}: mean {d.mean():.2e}, max {d.max():.2e}", flush=True)
