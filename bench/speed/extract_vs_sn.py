"""The surface extraction alone against vtkSurfaceNets3D without smoothing, interleaved.

Each round runs, per input, every voxreg build given (the `extract_npy` example: one
`DigitalSurface::new` in a fresh process, wall and CPU time of the call) and SurfaceNets3D
(`surface_nets_filter(..., iterations=0)` of vs_vtk.py, its `Update()` in a fresh process,
wall and CPU time). Prints each figure's median over the rounds and the per-round ratios
of the first build to SurfaceNets3D.

    cargo build --release -p voxreg-digisurf --example extract_npy
    python bench/speed/extract_vs_sn.py --build now=target/release/examples/extract_npy \\
        --build before=target/extract-before --rounds 5 \\
        tissue.npy channels.npy:nobg t2.npy

An input `FILE.npy:nobg` has no background (every label a region, as `channels.vti`; save
it x fastest with numpy). Needs numpy and vtk for SurfaceNets3D (the CI venv's python).
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))


def sn_child(path, nobg):
    """Runs SurfaceNets3D once on `path` and prints wall and CPU seconds of Update()."""
    import time

    import numpy as np

    sys.path.insert(0, HERE)
    from vs_vtk import surface_nets_filter

    labels = np.load(path)
    f = surface_nets_filter(labels, None if nobg else 0, iterations=0)
    t, c = time.perf_counter(), time.process_time()
    f.Update()
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    print(json.dumps({"wall": wall, "cpu": cpu, "faces": f.GetOutput().GetNumberOfCells()}))


def run_voxreg(exe, path, nobg):
    env = dict(os.environ, NO_CHECKSUM="1")
    if nobg:
        env["NO_BACKGROUND"] = "1"
    out = subprocess.run([exe, path, "1"], env=env, capture_output=True, text=True, check=True).stdout
    m = re.search(r"(\d+) surfels, best of 1: ([\d.]+) s, cpu ([\d.]+) s", out)
    return {"wall": float(m.group(2)), "cpu": float(m.group(3)), "faces": int(m.group(1))}


def run_sn(path, nobg):
    cmd = [sys.executable, os.path.abspath(__file__), "--child", path] + (["--nobg"] if nobg else [])
    return json.loads(subprocess.run(cmd, capture_output=True, text=True, check=True).stdout)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("inputs", nargs="*", help="FILE.npy, or FILE.npy:nobg")
    ap.add_argument("--build", action="append", default=[], help="NAME=PATH of an extract_npy build")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--nobg", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return sn_child(args.child, args.nobg)
    builds = [b.split("=", 1) for b in args.build]
    for spec in args.inputs:
        path, _, flag = spec.partition(":")
        nobg = flag == "nobg"
        rows = {name: [] for name, _ in builds}
        rows["SurfaceNets3D 0"] = []
        for _ in range(args.rounds):
            for name, exe in builds:
                rows[name].append(run_voxreg(exe, path, nobg))
            rows["SurfaceNets3D 0"].append(run_sn(path, nobg))
        print(f"{os.path.basename(path)}: {rows[builds[0][0]][0]['faces']} surfels, "
              f"SurfaceNets3D {rows['SurfaceNets3D 0'][0]['faces']} quads, {args.rounds} rounds")
        for name, runs in rows.items():
            wall = statistics.median(r["wall"] for r in runs)
            cpu = statistics.median(r["cpu"] for r in runs)
            print(f"  {name:18} wall {wall:.3f} s  cpu {cpu:.3f} s")
        sn = rows["SurfaceNets3D 0"]
        for name, _ in builds:
            wr = sorted(a["wall"] / b["wall"] for a, b in zip(rows[name], sn))
            cr = sorted(a["cpu"] / b["cpu"] for a, b in zip(rows[name], sn))
            print(f"  {name} / SurfaceNets3D per round: wall median {statistics.median(wr):.2f} "
                  f"({wr[0]:.2f} to {wr[-1]:.2f}), cpu median {statistics.median(cr):.2f} "
                  f"({cr[0]:.2f} to {cr[-1]:.2f})")


if __name__ == "__main__":
    main()
