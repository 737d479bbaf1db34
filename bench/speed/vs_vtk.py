#!/usr/bin/env python3
"""voxreg against VTK's SurfaceNets3D on the same label volumes, in one process tree.

For each input, runs in turn (interleaved, --runs times each):

* ``voxreg regularize`` (the release CLI, default options), in a child process;
* ``vtkSurfaceNets3D`` with its default smoothing, and with smoothing off, each in a
  child process running this script with ``--child``.

and prints, per tool, the median wall time of the child process, its compute time
(voxreg: the sum of the report's stages, reading and writing excluded; SurfaceNets: the
filter's ``Update()`` alone, reading and the numpy-to-VTK copy excluded), its peak memory
(the child's maximum resident set, from ``wait4``), and voxreg's ratios to each.

Needs a Python with numpy and pip's ``vtk`` (9.4 or later). Example:

    python bench/speed/vs_vtk.py                 # tissue, channels, bunny-128; 3 runs each
    python bench/speed/vs_vtk.py --quick         # bunny-128 and a small tissue, 1 run
    python bench/speed/vs_vtk.py --set-aside     # inputs kept out of tuning: torus, tissue seed 2
    python bench/speed/vs_vtk.py --before target/voxreg-before --json ab.json   # and an older build
    python bench/speed/vs_vtk.py --voxreg-args "--preset fast"   # voxreg's fast preset

The tissue volumes are made with ``cargo xtask synth-labels`` and the torus with the
``digitize`` example when missing (under target/bench/).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WORK = os.path.join(ROOT, "target", "bench")


def read_vol(path):
    """A DGtal .vol file (text header, then u8 samples, x fastest) as an (X, Y, Z) array."""
    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"\n.\n") + 3
    header = dict(
        line.split(": ", 1) for line in data[: end - 3].decode("ascii").splitlines() if ": " in line
    )
    dims = [int(header[k]) for k in ("X", "Y", "Z")]
    body = data[end:]
    if len(body) < dims[0] * dims[1] * dims[2]:
        body = zlib.decompress(body)  # DGtal writes compressed .vol files too
    a = np.frombuffer(body, dtype=np.uint8, count=dims[0] * dims[1] * dims[2])
    return a.reshape(dims[::-1]).transpose(2, 1, 0)


def read_vti(path):
    """A VTK image data file's scalars (point data, else cell data: one label per voxel) as an
    (X, Y, Z) array, with its spacing and origin."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLImageDataReader

    r = vtkXMLImageDataReader()
    r.SetFileName(path)
    r.Update()
    img = r.GetOutput()
    dims = img.GetDimensions()
    scalars = img.GetPointData().GetScalars()
    if scalars is None:
        scalars = img.GetCellData().GetScalars()
        dims = tuple(max(d - 1, 1) for d in dims)
    a = vtk_to_numpy(scalars)
    return a.reshape(dims[::-1]).transpose(2, 1, 0), img.GetSpacing(), img.GetOrigin()


def load_labels(path):
    """The volume as an (X, Y, Z) integer array and its background label (None: none)."""
    import numpy as np

    if path.endswith(".npy"):
        return np.load(path), 0
    if path.endswith(".vol"):
        return read_vol(path), 0
    if path.endswith(".vti"):
        return read_vti(path)[0], None
    raise SystemExit(f"{path}: unsupported input for the SurfaceNets side")


def surface_nets_filter(labels, background, iterations=None, spacing=(1, 1, 1), origin=(0, 0, 0)):
    """vtkSurfaceNets3D set up on `labels` (an (X, Y, Z) array), not yet run: every label but
    `background` a material (with `background` None, every label, and the background a label
    above them); `iterations` None keeps VTK's default smoothing, 0 turns it off."""
    import numpy as np
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData
    from vtkmodules.vtkFiltersCore import vtkSurfaceNets3D

    image = vtkImageData()
    image.SetDimensions(*labels.shape)
    image.SetSpacing(*[float(s) for s in spacing])
    image.SetOrigin(*[float(o) for o in origin])
    flat = np.ascontiguousarray(labels.ravel(order="F")).astype(np.int32)
    image.GetPointData().SetScalars(numpy_to_vtk(flat, deep=1))
    nets = vtkSurfaceNets3D()
    nets.SetInputData(image)
    values = np.unique(labels)
    if background is None:
        nets.SetBackgroundLabel(float(values.max()) + 1.0)
        materials = values
    else:
        nets.SetBackgroundLabel(float(background))
        materials = values[values != background]
    nets.SetNumberOfLabels(len(materials))
    for i, v in enumerate(materials):
        nets.SetLabel(i, float(v))
    if iterations == 0:
        nets.SmoothingOff()
    elif iterations is not None:
        nets.SmoothingOn()
        nets.SetNumberOfIterations(iterations)
    return nets


def child(path, smooth, no_background):
    """Runs SurfaceNets3D on `path` and prints its filter time and output size as JSON."""
    labels, background = load_labels(path)
    if no_background:
        background = None
    f = surface_nets_filter(labels, background, iterations=None if smooth else 0)
    t = time.perf_counter()
    f.Update()
    seconds = time.perf_counter() - t
    out = f.GetOutput()
    print(json.dumps({"compute": seconds, "faces": out.GetNumberOfCells()}))


def run_measured(cmd):
    """Runs `cmd` in a child process: (wall seconds, peak RSS MiB, stdout)."""
    t = time.perf_counter()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(r)
        os.dup2(w, 1)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        try:
            os.execvp(cmd[0], cmd)
        finally:
            os._exit(127)
    os.close(w)
    chunks = []
    while True:
        b = os.read(r, 65536)
        if not b:
            break
        chunks.append(b)
    os.close(r)
    _, status, usage = os.wait4(pid, 0)
    wall = time.perf_counter() - t
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(cmd)} failed (exit {os.waitstatus_to_exitcode(status)})")
    return wall, usage.ru_maxrss / 1024.0, b"".join(chunks).decode()


def voxreg_run(exe, inp, no_background, tmp, extra=()):
    report = os.path.join(tmp, "report.json")
    cmd = [exe, "regularize", inp, "-o", os.path.join(tmp, "out.ply"), "-q", "--report", report]
    if no_background:
        cmd.append("--no-background")
    cmd += list(extra)
    wall, peak, _ = run_measured(cmd)
    with open(report) as f:
        rep = json.load(f)
    stages = rep["stages"]
    compute = sum(v for k, v in stages.items() if k not in ("read", "write"))
    return {"wall": wall, "compute": compute, "peak": peak, "faces": rep["counts"]["surfels"], "stages": stages}


def vtk_run(inp, smooth, no_background):
    cmd = [sys.executable, os.path.abspath(__file__), "--child", inp]
    if smooth:
        cmd.append("--smooth")
    if no_background:
        cmd.append("--no-background")
    wall, peak, out = run_measured(cmd)
    d = json.loads(out.strip().splitlines()[-1])
    return {"wall": wall, "compute": d["compute"], "peak": peak, "faces": d["faces"]}


def ensure(path, make):
    if not os.path.exists(path):
        os.makedirs(os.path.dirname(path), exist_ok=True)
        print(f"making {os.path.relpath(path, ROOT)}: {' '.join(make)}", file=sys.stderr)
        subprocess.run(make, cwd=ROOT, check=True)
    return path


def tissue(dims):
    name = "tissue.npy" if dims is None else f"tissue-{dims.replace(',', 'x')}.npy"
    path = os.path.join(WORK, name)
    make = ["cargo", "xtask", "synth-labels", "--out", path]
    if dims is not None:
        make += ["--dims", dims]
    return ensure(path, make)


def torus(step):
    path = os.path.join(WORK, f"torus-{step}.vol")
    return ensure(path, ["cargo", "run", "--release", "-q", "--example", "digitize", "--", "torus", step, path])


def inputs(args):
    if args.quick:
        return [("tissue 250x235x68", tissue("250,235,68"), False), ("bunny-128", "data/bunny-128.vol", False)]
    if args.set_aside:
        return [
            ("tissue 400x380x110 (set aside)", tissue("400,380,110"), False),
            ("torus (set aside)", torus(args.torus_step), False),
        ]
    if args.tissue:
        return [(os.path.basename(args.tissue), args.tissue, False)]
    return [
        ("tissue (synth-labels)", tissue(None), False),
        ("channels.vti", os.path.join(ROOT, "data/channels.vti"), True),
        ("bunny-128", os.path.join(ROOT, "data/bunny-128.vol"), False),
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--voxreg", default=os.path.join(ROOT, "target", "release", "voxreg"))
    ap.add_argument("--before", help="another voxreg binary (an earlier build) run interleaved too, with the same --voxreg-args")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="bunny-128 and a small tissue, 1 run")
    ap.add_argument("--set-aside", action="store_true", help="the inputs kept out of tuning")
    ap.add_argument("--torus-step", default="0.05", help="grid step of the set-aside torus")
    ap.add_argument("--json", help="also write the medians to this file")
    ap.add_argument("--voxreg-args", default="", help="extra arguments of voxreg regularize, e.g. '--preset fast'")
    ap.add_argument("--only", nargs="*", help="only the inputs whose name contains one of these")
    ap.add_argument("--tissue", help="this .npy volume instead of the synth-labels tissue (e.g. another --seed)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--smooth", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--no-background", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.child, args.smooth, args.no_background)
    if args.quick:
        args.runs = 1
    exe = os.path.abspath(args.voxreg)
    if not os.path.exists(exe):
        raise SystemExit(f"{exe}: no such binary (cargo build --release -p voxreg-cli)")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path, nobg in inputs(args):
            if args.only and not any(o in name for o in args.only):
                continue
            rows = {"voxreg": [], "SurfaceNets3D + smoothing": [], "SurfaceNets3D, no smoothing": []}
            if args.before:
                rows["voxreg before"] = []
            extra = args.voxreg_args.split()
            for _ in range(args.runs):  # interleaved: A B C A B C ...
                rows["voxreg"].append(voxreg_run(exe, path, nobg, tmp, extra))
                if args.before:
                    rows["voxreg before"].append(voxreg_run(os.path.abspath(args.before), path, nobg, tmp, extra))
                rows["SurfaceNets3D + smoothing"].append(vtk_run(path, True, nobg))
                rows["SurfaceNets3D, no smoothing"].append(vtk_run(path, False, nobg))
            med = {
                tool: {k: statistics.median(r[k] for r in rs) for k in ("wall", "compute", "peak", "faces")}
                for tool, rs in rows.items()
            }
            for tool in ("voxreg", "voxreg before"):
                if tool in rows:
                    med[tool]["stages"] = {
                        k: statistics.median(r["stages"].get(k, 0.0) for r in rows[tool])
                        for k in rows[tool][0]["stages"]
                    }
            if args.before:
                # Per interleaved pair, so that the machine's drift cancels.
                med["voxreg"]["vs_before"] = {
                    k: statistics.median(a[k] / b[k] for a, b in zip(rows["voxreg"], rows["voxreg before"]))
                    for k in ("wall", "compute", "peak")
                }
            results[name] = med
            v = med["voxreg"]
            print(f"\n{name}  ({v['faces']:.0f} surfels; medians of {args.runs} interleaved runs)")
            print(f"  {'tool':30} {'wall s':>8} {'compute s':>10} {'peak MiB':>9} {'B/surfel':>9}")
            for tool, m in med.items():
                print(
                    f"  {tool:30} {m['wall']:8.2f} {m['compute']:10.2f} {m['peak']:9.0f}"
                    f" {m['peak'] * 2**20 / v['faces']:9.0f}"
                )
            for tool in [t for t in med if t.startswith("SurfaceNets")]:
                m = med[tool]
                print(
                    f"  voxreg / {tool:21} wall {v['wall'] / m['wall']:6.1f}x  compute"
                    f" {v['compute'] / m['compute']:6.1f}x  peak {v['peak'] / m['peak']:5.2f}x"
                )
            if args.before:
                vb = v["vs_before"]
                print(
                    f"  voxreg / voxreg before (per pair)   wall {vb['wall']:6.2f}x  compute"
                    f" {vb['compute']:6.2f}x  peak {vb['peak']:5.2f}x"
                )
            for tool in ("voxreg", "voxreg before"):
                if tool in med:
                    stages = med[tool]["stages"]
                    print(f"  {tool} stages (s): " + ", ".join(f"{k} {s:.2f}" for k, s in stages.items()))
            sys.stdout.flush()
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
