"""voxreg.dask end to end on a Zarr store, through a dask.distributed LocalCluster.

    target/pyvenv/bin/python bench/scale/synth_zarr.py target/ooc/tissue.zarr --dims 2048,2048,512
    target/pyvenv/bin/python bench/scale/scale_ooc.py target/ooc/tissue.zarr --out target/ooc/meshes \\
        [--workers 2] [--memory 2GB] [--chunk 256] [--halo 24] [param=value ...]

Workers have one thread each and the given memory limit (the nanny restarts a worker past
95 % of it). Each task resets its process's peak resident set (Linux VmHWM) when it
starts and reads it when its fragment is written: the peak of that worker process over
the task (the worker's own footprint included). The merge, in this process, reads its own
peak the same way. Prints one JSON line: wall times (compute and merge), CPU time summed
over the tasks, the largest task peak per worker process, the worker processes seen (more
than ``--workers``: one was restarted), quads against the generator's surfel count
(``OUT.zarr.json``), labels closed, and throughput per core (voxels and surfels per CPU
second of the tasks).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from typing import Any, Dict

import voxreg.dask as vd


def _param(text: str) -> Any:
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"True": True, "False": False}.get(text, text)


def run(store: str, out: str, workers: int = 2, memory: str = "2GB", chunk: int = 256,
        halo: int = vd.DEFAULT_HALO, formats=("ply", "precomputed"), **params: Any) -> Dict[str, Any]:
    """One regularization of ``store`` into ``out`` (emptied first) on a fresh cluster."""
    from dask.distributed import Client, LocalCluster

    if os.path.exists(out):
        shutil.rmtree(out)
    with LocalCluster(n_workers=workers, threads_per_worker=1, memory_limit=memory,
                      processes=True, dashboard_address=None) as cluster, Client(cluster) as client:
        client.wait_for_workers(workers)
        t = time.perf_counter()
        vd.regularize(store, chunks=(chunk,) * 3, halo=halo, out=out, formats=formats, **params)
        wall = time.perf_counter() - t
    with open(os.path.join(out, "summary.json")) as f:
        summary = json.load(f)
    tasks = summary["tasks"]
    peaks: Dict[int, int] = {}
    for task in tasks:
        peaks[task["pid"]] = max(peaks.get(task["pid"], 0), task["peak_rss_bytes"] or 0)
    cpu = sum(t["cpu_s"] for t in tasks)
    quads = sum(t["quads"] for t in tasks)
    info_path = store.rstrip("/") + ".json"
    synth = json.load(open(info_path)) if os.path.exists(info_path) else {}
    voxels = 1
    for n in synth.get("dims", [0]):
        voxels *= n
    merge = summary["merge"]
    labels = summary["labels"]
    return {
        "workers": workers, "chunk": chunk, "halo": halo, "tasks": len(tasks),
        "wall_s": round(wall, 1), "compute_s": round(wall - merge["wall_s"], 1),
        "merge_s": round(merge["wall_s"], 1), "task_cpu_s": round(cpu, 1),
        "task_wall_s": round(sum(t["wall_s"] for t in tasks), 1),
        "max_task_cpu_s": round(max(t["cpu_s"] for t in tasks), 1),
        "worker_pids": len(peaks), "worker_peak_gb": sorted(round(p / 1e9, 3) for p in peaks.values()),
        "peaks_reset_per_task": all(t["peak_since_task_start"] for t in tasks),
        "merge_peak_gb": round((merge["peak_rss_bytes"] or 0) / 1e9, 3),
        "client_peak_gb": round((summary["client"]["peak_rss_bytes_before_merge"] or 0) / 1e9, 3),
        "border_vertices": merge["border_vertices"],
        "quads": quads, "surfels_expected": synth.get("surfels"),
        "labels": len(labels), "labels_closed": sum(1 for v in labels.values() if v["closed"]),
        "voxels_per_cpu_s": round(voxels / cpu) if voxels > 1 else None,
        "surfels_per_cpu_s": round(quads / cpu),
        "us_per_surfel_cpu": round(1e6 * cpu / max(quads, 1), 1),
        "load": os.getloadavg(),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("store")
    ap.add_argument("--out", required=True)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--memory", default="2GB")
    ap.add_argument("--chunk", type=int, default=256)
    ap.add_argument("--halo", type=int, default=vd.DEFAULT_HALO)
    ap.add_argument("--formats", default="ply,precomputed")
    ap.add_argument("params", nargs="*", help="param=value, passed to voxreg.dask.regularize")
    a = ap.parse_args()
    params = dict((k, _param(v)) for k, v in (p.split("=", 1) for p in a.params))
    result = run(a.store, a.out, a.workers, a.memory, a.chunk, a.halo, tuple(a.formats.split(",")), **params)
    print(json.dumps(result), flush=True)
    sys.exit(0 if result["labels_closed"] == result["labels"] else 1)


if __name__ == "__main__":
    main()
