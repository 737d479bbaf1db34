#!/usr/bin/env python3
"""The speed/accuracy frontier: voxreg's settings against VTK's SurfaceNets3D, in one run.

For each analytic shape (Gauss-digitized as the test kit does: voxel ``p`` inside iff
``f(spacing * p) <= 0``, a margin of one voxel):

* sphere R = 20 at h = 1; torus R = 6, r = 2 at h = 0.25; goursat at h = 0.25 and 0.5;
* the split ball (R = 20, cut z = 0.5, labels 1 below and 2 above, background 0) and its
  junction circle;
* the sphere R = 20 sampled at spacing (1, 1, 2.5),

it runs, interleaved (every setting once, then again, ``--runs`` times), each voxreg
setting of ``VOXREG`` below (the release CLI in a child process) and SurfaceNets3D at 0
(smoothing off), 16 (its default), 32 and 64 smoothing iterations (in this process), and
reports per setting the median compute time and the error against the true surface:
mean / max vertex distance in voxels (of the finest spacing), the area-weighted mean
angle between each face and the true normal at its centroid's nearest surface point
(orientation ignored), and on the split ball the mean / max distance of the junction
vertices (where labels 0, 1 and 2 meet) to the true circle.

Compute time is defined as in ``bench/vs_vtk.py``: voxreg, the sum of the report's stages
(reading and writing excluded); SurfaceNets3D, the filter's ``Update()`` alone. It also
times (no ground truth) the 25-label tissue (``cargo xtask synth-labels``) and
``data/channels.vti`` with fewer settings (``VOLUME_SETTINGS``).

Writes a Markdown report (tables, the frontier questions answered from the numbers) and a
PNG (x: compute time relative to SurfaceNets3D's default, log; y: mean distance, log; one
curve per tool, one panel per shape), and the raw samples as JSON (``--json``; re-render
with ``--from-json`` without running anything).

Needs numpy, matplotlib and pip's ``vtk`` (9.4 or later). Example:

    python bench/speed/frontier.py --voxreg target/release/voxreg --runs 3 \
        --md docs/frontier.md --png docs/figures/frontier.png --json target/frontier.json
    python bench/speed/frontier.py --quick          # two shapes, a few settings, 1 run
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from vs_vtk import read_vti, surface_nets_filter  # noqa: E402  (the same SurfaceNets3D set-up and reader)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
WORK = os.path.join(ROOT, "target", "bench")

# --- analytic shapes (numpy twins of crates/testkit) -------------------------------------


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n == 0, 1, n)


class Sphere:
    def __init__(self, radius):
        self.r = radius
        self.bounds = (np.full(3, -radius), np.full(3, radius))

    def label(self, p):
        return (np.linalg.norm(p, axis=-1) <= self.r).astype(np.uint8)

    def project(self, p):
        return _unit(p) * self.r

    def normal(self, q):
        return _unit(q)


class Torus:
    def __init__(self, major, minor):
        self.R, self.r = major, minor
        e = major + minor
        self.bounds = (np.array([-e, -e, -minor]), np.array([e, e, minor]))

    def _centre(self, p):
        xy = p.copy()
        xy[..., 2] = 0
        n = np.linalg.norm(xy, axis=-1, keepdims=True)
        xy = np.where(n == 0, np.array([1.0, 0, 0]), xy / np.where(n == 0, 1, n))
        return xy * self.R

    def label(self, p):
        return (np.linalg.norm(p - self._centre(p), axis=-1) <= self.r).astype(np.uint8)

    def project(self, p):
        c = self._centre(p)
        return c + _unit(p - c) * self.r

    def normal(self, q):
        return _unit(q - self._centre(q))


class Goursat:
    """DGtal's goursat: -(8 - 0.03 sum x^4 + 2 sum x^2) <= 0."""

    bounds = (np.full(3, -9.7), np.full(3, 9.7))

    @staticmethod
    def value(p):
        q = p * p
        return -(8.0 - 0.03 * (q * q).sum(-1) + 2.0 * q.sum(-1))

    @staticmethod
    def gradient(p):
        return 0.12 * p**3 - 4.0 * p

    def label(self, p):
        return (self.value(p) <= 0).astype(np.uint8)

    def project(self, p):
        # The test kit's Shape::project: Newton steps along the gradient.
        q = p.copy()
        for _ in range(30):
            g = self.gradient(q)
            g2 = (g * g).sum(-1, keepdims=True)
            step = self.value(q)[..., None] / np.where(g2 == 0, 1, g2) * g
            q = q - step
            if np.abs(step).max() < 1e-13:
                break
        return q

    def normal(self, q):
        return _unit(self.gradient(q))


class SplitBall:
    """testkit's SplitBall: label 1 below z = cut, 2 above, inside radius R; 0 outside."""

    def __init__(self, radius, cut):
        self.r, self.cut = radius, cut
        self.bounds = (np.full(3, -radius), np.full(3, radius))
        self.rc = np.sqrt(radius**2 - cut**2)

    def label(self, p):
        inside = np.linalg.norm(p, axis=-1) <= self.r
        return np.where(inside, np.where(p[..., 2] < self.cut, 1, 2), 0).astype(np.uint8)

    def circle(self, p):
        q = p.copy()
        q[..., 2] = 0
        q = _unit(q) * self.rc
        q[..., 2] = self.cut
        return q

    def nearest(self, labels, p):
        """Nearest point of the part named by each point's label set (a 3-bit mask of
        labels 0, 1, 2), and the true unit normal there."""
        q = _unit(p) * self.r
        wrong = ((labels == 0b011) & (q[:, 2] >= self.cut)) | ((labels == 0b101) & (q[:, 2] < self.cut))
        q = np.where(wrong[:, None], self.circle(p), q)
        n = _unit(q)
        plane = labels == 0b110
        disc = p.copy()
        disc[:, 2] = self.cut
        out = np.hypot(disc[:, 0], disc[:, 1]) > self.rc
        disc = np.where(out[:, None], self.circle(p), disc)
        q = np.where(plane[:, None], disc, q)
        n = np.where(plane[:, None], np.array([0, 0, 1.0]), n)
        junction = labels == 0b111
        q = np.where(junction[:, None], self.circle(p), q)
        return q, n


def digitize(shape, spacing):
    """(labels (X, Y, Z) uint8, origin): voxel [i, j, k] is centred at origin + spacing [i, j, k]."""
    spacing = np.asarray(spacing, float)
    lo, hi = shape.bounds
    pmin = np.floor(lo / spacing) - 1
    pmax = np.ceil(hi / spacing) + 1
    dims = (pmax - pmin + 1).astype(int)
    idx = np.stack(np.meshgrid(*[np.arange(d) for d in dims], indexing="ij"), -1).reshape(-1, 3)
    labels = shape.label((pmin + idx) * spacing).reshape(tuple(dims))
    return labels, pmin * spacing


SHAPES = {
    "sphere R=20, h=1": (lambda: Sphere(20.0), (1, 1, 1)),
    "torus h=0.25": (lambda: Torus(6.0, 2.0), (0.25,) * 3),
    "goursat h=0.25": (lambda: Goursat(), (0.25,) * 3),
    "goursat h=0.5": (lambda: Goursat(), (0.5,) * 3),
    "split ball R=20": (lambda: SplitBall(20.0, 0.5), (1, 1, 1)),
    "sphere R=20, (1,1,2.5)": (lambda: Sphere(20.0), (1, 1, 2.5)),
}
# --set-aside: shapes kept out of the frontier and of tuning, to confirm a setting on.
SET_ASIDE = {
    "split ball R=17 (set aside)": (lambda: SplitBall(17.0, 0.5), (1, 1, 1)),
    "split ball R=20, cut 6.5 (set aside)": (lambda: SplitBall(20.0, 6.5), (1, 1, 1)),
}

# --- settings ----------------------------------------------------------------------------

# name -> extra CLI arguments ("{r5}" is replaced by 5 voxels of the finest spacing).
VOXREG = {
    "default (3 rounds)": [],
    "default, tol 1e-2": ["--tolerance", "1e-2"],
    "2 rounds": ["--refine", "2"],
    "1 round": ["--refine", "1"],
    "1 round, tol 1e-2": ["--refine", "1", "--tolerance", "1e-2"],
    "0 rounds": ["--refine", "0"],
    "0 rounds, tol 1e-2": ["--refine", "0", "--tolerance", "1e-2"],
    "0 rounds, tol 5e-2": ["--refine", "0", "--tolerance", "5e-2"],
    "0 rounds, ii r=5": ["--refine", "0", "--radius", "{r5}"],
    "0 rounds, convolved": ["--refine", "0", "--normals", "convolved"],
    "0 rounds, trivial": ["--refine", "0", "--normals", "trivial"],
    "papers": ["--preset", "papers"],
    "fast": ["--preset", "fast"],
    "fast, 1 round": ["--preset", "fast", "--refine", "1"],
    "diffused, 8 sweeps": ["--solver", "sweeps", "--normals", "diffused", "--refine", "0"],
}
SNETS = [0, 16, 32, 64]
VOLUME_SETTINGS = ["default (3 rounds)", "1 round, tol 1e-2", "0 rounds", "0 rounds, tol 5e-2", "0 rounds, trivial", "fast", "fast, 1 round"]
# --volume-settings short: the default, one solve and one solve from the trivial normals.
SHORT_VOLUME_SETTINGS = ["default (3 rounds)", "0 rounds", "0 rounds, trivial", "fast", "fast, 1 round"]
QUICK_SETTINGS = ["default (3 rounds)", "0 rounds", "0 rounds, trivial", "fast"]

# --- running -----------------------------------------------------------------------------


def read_ply(path):
    """voxreg's binary PLY: positions (N, 3), quads (M, 4), face labels (M, 2)."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    nv = nf = 0
    for line in header:
        if line.startswith("element vertex"):
            nv = int(line.split()[-1])
        elif line.startswith("element face"):
            nf = int(line.split()[-1])
    if any("red" in line for line in header):
        raise SystemExit(f"{path}: unexpected coloured PLY")
    v = np.frombuffer(data, dtype="<f4", count=3 * nv, offset=end).reshape(nv, 3).astype(np.float64)
    ft = np.dtype([("n", "u1"), ("v", "<i4", (4,)), ("a", "<i4"), ("b", "<i4")])
    f = np.frombuffer(data, dtype=ft, count=nf, offset=end + 12 * nv)
    if nf and not (f["n"] == 4).all():
        raise SystemExit(f"{path}: not all faces are quads")
    return v, f["v"].astype(np.int64), np.stack([f["a"], f["b"]], 1)


def voxreg_run(exe, vol, spacing, extra, tmp, no_background=False):
    out, report = os.path.join(tmp, "out.ply"), os.path.join(tmp, "report.json")
    cmd = [exe, "regularize", vol, "-o", out, "-q", "--report", report]
    if spacing is not None:
        cmd += ["--spacing", ",".join(f"{s:g}" for s in spacing)]
    if no_background:
        cmd.append("--no-background")
    cmd += extra
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed: {r.stderr.strip()}")
    with open(report) as f:
        rep = json.load(f)
    stages = rep["stages"]
    return {
        "compute": sum(stages.values()),
        "stages": stages,
        "iterations": [s.get("iterations", 0) for s in rep.get("solves", [])],
        "faces": rep["counts"]["surfels"],
    }, out


def surface_nets(labels, spacing, origin, iterations, background=0):
    """SurfaceNets3D on `labels` (X, Y, Z): (seconds of Update(), points, triangles, boundary labels)."""
    from vtkmodules.util import numpy_support

    nets = surface_nets_filter(labels, background, iterations, spacing, origin)
    t = time.perf_counter()
    nets.Update()
    seconds = time.perf_counter() - t
    out = nets.GetOutput()
    points = numpy_support.vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    # Triangles with smoothing, quads without (VTK's default output mesh type).
    conn = numpy_support.vtk_to_numpy(out.GetPolys().GetConnectivityArray()).astype(np.int64)
    sizes = np.unique(np.diff(numpy_support.vtk_to_numpy(out.GetPolys().GetOffsetsArray())))
    if len(sizes) != 1:
        raise SystemExit(f"SurfaceNets3D: mixed polygon sizes {sizes}")
    tris = conn.reshape(-1, int(sizes[0]))
    bl = numpy_support.vtk_to_numpy(out.GetCellData().GetArray("BoundaryLabels")).reshape(-1, 2)
    return seconds, points, tris, bl


# --- errors against the truth ------------------------------------------------------------


def face_geometry(points, faces):
    """Vector areas and centroids of polygons (M, k), as voxreg-baselines' Mesh computes them."""
    c = points[faces].mean(1)
    a = np.zeros_like(c)
    k = faces.shape[1]
    for i in range(k):
        a += np.cross(points[faces[:, i]] - c, points[faces[:, (i + 1) % k]] - c)
    return a / 2, c


def vertex_label_masks(n, faces, face_labels):
    """For each vertex, a bit mask of the labels (0, 1, 2) of the faces around it."""
    mask = np.zeros(n, np.int64)
    for j in range(2):
        bits = np.left_shift(1, np.clip(face_labels[:, j], 0, 62))
        for i in range(faces.shape[1]):
            np.bitwise_or.at(mask, faces[:, i], bits)
    return mask


def errors(shape, points, faces, face_labels, unit):
    """Distances in voxels (`unit`: the finest spacing) and normal errors in degrees."""
    used = np.zeros(len(points), bool)
    used[faces.ravel()] = True
    area, centroid = face_geometry(points, faces)
    alen = np.linalg.norm(area, axis=1)
    ok = alen > 0
    out = {}
    if isinstance(shape, SplitBall):
        vmask = vertex_label_masks(len(points), faces, face_labels)
        q, _ = shape.nearest(vmask, points)
        d = np.linalg.norm(points - q, axis=1) / unit
        junction = used & (vmask == 0b111)
        out["junction_mean"] = float(d[junction].mean())
        out["junction_max"] = float(d[junction].max())
        out["junction_count"] = int(junction.sum())
        fmask = np.left_shift(1, face_labels[:, 0]) | np.left_shift(1, face_labels[:, 1])
        _, tn = shape.nearest(fmask, centroid)
        d = d[used]
    else:
        p = points[used]
        d = np.linalg.norm(p - shape.project(p), axis=1) / unit
        tn = shape.normal(shape.project(centroid))
    cos = np.abs((area[ok] / alen[ok, None] * tn[ok]).sum(1)).clip(0, 1)
    ang = np.degrees(np.arccos(cos))
    out.update(
        mean=float(d.mean()),
        max=float(d.max()),
        normal_mean=float((ang * alen[ok]).sum() / alen[ok].sum()),
        normal_max=float(ang.max()),
    )
    return out


# --- the volumes -------------------------------------------------------------------------


def tissue():
    path = os.path.join(WORK, "tissue.npy")
    if not os.path.exists(path):
        os.makedirs(WORK, exist_ok=True)
        print(f"making {os.path.relpath(path, ROOT)} (cargo xtask synth-labels)", file=sys.stderr)
        subprocess.run(["cargo", "xtask", "synth-labels", "--out", path], cwd=ROOT, check=True)
    return path


def load_volume(path):
    """(labels (X, Y, Z), spacing, origin) of a .npy or .vti volume."""
    if path.endswith(".npy"):
        return np.load(path), (1, 1, 1), (0, 0, 0)
    return read_vti(path)


# --- the run -----------------------------------------------------------------------------


def run_shapes(args, exe, tmp, settings, samples):
    shapes = {**SHAPES, **SET_ASIDE} if args.set_aside else SHAPES
    for name, (make, spacing) in shapes.items():
        if args.shapes and not any(s in name for s in args.shapes):
            continue
        shape = make()
        labels, origin = digitize(shape, spacing)
        vol = os.path.join(tmp, "shape.npy")
        np.save(vol, labels)
        unit = min(spacing)
        r5 = f"{5 * unit:g}"
        entry = samples.setdefault(name, {})
        errs = {}
        for rep in range(args.runs):
            for s in settings:
                extra = [a.replace("{r5}", r5) for a in VOXREG[s]]
                res, out = voxreg_run(exe, vol, spacing, extra, tmp)
                if rep == 0:  # deterministic: measure the error once
                    pts, quads, fl = read_ply(out)
                    errs[s] = errors(shape, pts + origin, quads, fl, unit)
                entry.setdefault("voxreg " + s, {"runs": []})["runs"].append(res)
            for it in SNETS:
                sec, pts, tris, bl = surface_nets(labels, spacing, origin, it)
                if rep == 0:
                    errs[f"snets {it}"] = errors(shape, pts, tris, bl.astype(np.int64), unit)
                entry.setdefault(f"SurfaceNets3D {it}", {"runs": []})["runs"].append({"compute": sec, "faces": len(tris), "polygon": tris.shape[1]})
            print(f"{name}: run {rep + 1}/{args.runs} done", file=sys.stderr, flush=True)
        for s in settings:
            entry["voxreg " + s]["error"] = errs[s]
        for it in SNETS:
            entry[f"SurfaceNets3D {it}"]["error"] = errs[f"snets {it}"]
        save(args, samples)


def run_volumes(args, exe, tmp, settings, samples):
    vols = [("tissue (synth-labels)", tissue, False), ("channels.vti", lambda: os.path.join(ROOT, "data/channels.vti"), True)]
    for name, path, nobg in vols:
        if args.volumes and not any(v in name for v in args.volumes):
            continue
        path = path()
        labels, spacing, origin = load_volume(path)
        entry = samples.setdefault(name, {})
        for rep in range(args.volume_runs):
            for s in settings:
                res, _ = voxreg_run(exe, path, None, VOXREG[s], tmp, no_background=nobg)
                entry.setdefault("voxreg " + s, {"runs": []})["runs"].append(res)
            for it in SNETS:
                sec, _, tris, _ = surface_nets(labels, spacing, origin, it, background=None if nobg else 0)
                entry.setdefault(f"SurfaceNets3D {it}", {"runs": []})["runs"].append({"compute": sec, "faces": len(tris), "polygon": tris.shape[1]})
            print(f"{name}: run {rep + 1}/{args.volume_runs} done", file=sys.stderr, flush=True)
            save(args, samples)


def save(args, results, meta=None):
    """Writes the samples so far to --json (after each input: a long run keeps what it measured)."""
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump({"meta": meta or {}, "results": results}, f, indent=1)


# --- the report --------------------------------------------------------------------------


def med(entry, key="compute"):
    return statistics.median(r[key] for r in entry["runs"])


def med_stages(entry):
    keys = entry["runs"][0]["stages"].keys()
    return {k: statistics.median(r["stages"].get(k, 0.0) for r in entry["runs"]) for k in keys}


def fmt_t(s):
    return f"{s * 1000:.0f} ms" if s < 10 else f"{s:.1f} s"


def analysis(results):
    """The frontier questions, answered from the medians: a list of Markdown lines."""
    shapes = [s for s in results if "error" in next(iter(results[s].values()))]
    lines = []
    if not shapes:
        return ["(no analytic shape in these samples)"]
    vox = [k for k in results[shapes[0]] if k.startswith("voxreg")]
    for it in SNETS:
        sn = f"SurfaceNets3D {it}"
        winners = []
        for v in vox:
            if all(
                v in results[s]
                and med(results[s][v]) <= med(results[s][sn])
                and results[s][v]["error"]["mean"] <= 0.5 * results[s][sn]["error"]["mean"]
                for s in shapes
            ):
                winners.append(v[len("voxreg ") :])
        per_shape = []
        for s in shapes:
            ok = [
                v
                for v in vox
                if med(results[s][v]) <= med(results[s][sn])
                and results[s][v]["error"]["mean"] <= 0.5 * results[s][sn]["error"]["mean"]
            ]
            per_shape.append(f"{s}: {len(ok)}")
        lines.append(
            f"- **{sn} iterations**: "
            + (f"yes: {', '.join(winners)}" if winners else "**no** voxreg setting on every shape")
            + f" (settings that qualify, per shape: {'; '.join(per_shape)})"
        )
    lines.append("")
    lines.append(
        "The gap, per shape and SurfaceNets3D setting: the cheapest voxreg setting with at most half its mean"
        " distance (time as a multiple of that SurfaceNets3D setting's), and the most accurate voxreg setting"
        " no slower than it."
    )
    lines.append("")
    lines.append("| shape | SurfaceNets3D | its mean distance | cheapest voxreg at half the error | most accurate voxreg no slower |")
    lines.append("|---|---|---|---|---|")
    for s in shapes:
        for it in SNETS:
            sn = results[s][f"SurfaceNets3D {it}"]
            ts, es = med(sn), sn["error"]["mean"]
            half = [(med(results[s][v]) / ts, v) for v in vox if results[s][v]["error"]["mean"] <= 0.5 * es]
            cheap = min(half) if half else None
            fast = [(results[s][v]["error"]["mean"], v) for v in vox if med(results[s][v]) <= ts]
            best = min(fast) if fast else None
            acc = min((results[s][v]["error"]["mean"], v) for v in vox)
            lines.append(
                f"| {s} | {it} | {es:.3f} | "
                + (f"{cheap[1][7:]}: {cheap[0]:.1f}x" if cheap else f"none (the best, {acc[1][7:]}: {acc[0]:.3f}, {acc[0] / es:.2f} of it)")
                + " | "
                + (f"{best[1][7:]}: {best[0]:.3f} ({best[0] / es:.2f} of it)" if best else "none")
                + " |"
            )
    return lines


def markdown(results, args, meta):
    out = [
        "# The speed/accuracy frontier: voxreg against SurfaceNets3D",
        "",
        f"Made by {meta['command']} on {meta['date']} ({meta['machine']}; VTK {meta['vtk']}).",
        "",
        f"Conditions: {meta['conditions']} Every setting ran once per round, rounds"
        f" repeated ({meta['runs']} on the shapes, {meta['volume_runs']} on the volumes); times are medians."
        " Compute time as in `bench/vs_vtk.py`: voxreg, the sum of its report's stages (reading and writing"
        " excluded; the release CLI in a child process); SurfaceNets3D, the filter's `Update()` alone (in the"
        " script's process, labels already in a `vtkImageData`). Ratios are to SurfaceNets3D's default (16"
        " smoothing iterations) on the same input in the same runs.",
        "",
        "Errors against the analytic surface (the shapes digitized as `crates/testkit` does): vertex distance in"
        " voxels of the finest spacing (mean / max), the area-weighted mean (and max) angle between each face and"
        " the true normal at its centroid's nearest surface point, in degrees, orientation ignored; on the split"
        " ball also the distance of the junction vertices (labels 0, 1 and 2 meet) to the true circle.",
        "",
        "voxreg's settings: `N rounds` is `--refine N` (the default preset has 3), `tol` `--tolerance` (default"
        " 1e-3 voxel), `ii r=5` `--radius` of 5 voxels (the default rule gives 3 voxels at unit spacing, 7.6 at"
        " h = 0.25), `convolved` and `trivial` `--normals` (default `ii`), `papers` `--preset papers`, `fast`"
        " `--preset fast` (`fast, 1 round` with `--refine 1`), `diffused, 8 sweeps` `--solver sweeps --normals"
        " diffused --refine 0` (the fast preset's first field and 8 sweeps instead of 20); the rest is"
        " the default preset. SurfaceNets3D: `SmoothingOff()` for 0, else `SetNumberOfIterations`, every other"
        f" option VTK {meta['vtk']}'s default (relaxation factor 0.5, its default constraint; triangles when smoothed,"
        " quads not).",
        "",
        "![frontier](figures/frontier.png)",
        "",
        "## Can voxreg beat each SurfaceNets3D setting today?",
        "",
        "For each SurfaceNets3D setting: the voxreg settings (among those measured) that are no slower and have"
        " at most half its mean distance on every shape.",
        "",
    ]
    out += analysis(results)
    out += ["", "## Per shape", ""]
    for s, entry in results.items():
        if "error" not in next(iter(entry.values())):
            continue
        ref = med(entry["SurfaceNets3D 16"])
        junction = "junction_mean" in next(iter(entry.values()))["error"]
        faces = next(iter(entry.values()))["runs"][0]["faces"]
        out.append(f"### {s} ({faces} voxreg quads)")
        out.append("")
        head = "| tool, setting | compute | vs SNets 16 | distance mean / max | normals mean / max |"
        sep = "|---|---|---|---|---|"
        if junction:
            head += " junction mean / max |"
            sep += "---|"
        out += [head, sep]
        for k, e in sorted(entry.items(), key=lambda kv: med(kv[1])):
            err = e["error"]
            row = (
                f"| {k} | {fmt_t(med(e))} | {med(e) / ref:.2f}x | {err['mean']:.3f} / {err['max']:.3f} |"
                f" {err['normal_mean']:.2f} / {err['normal_max']:.1f} |"
            )
            if junction:
                row += f" {err['junction_mean']:.3f} / {err['junction_max']:.3f} |"
            out.append(row)
        out.append("")
    out += ["## Stages against SurfaceNets3D", ""]
    out.append(
        "voxreg's stages (medians, seconds) against SurfaceNets3D without smoothing (its extraction) and with"
        " its default smoothing: `surface` is the digital surface's extraction, `normals` the estimator,"
        " `assemble` + `solve` every solve (all rounds together), `refine` the normal re-estimates and re-centring"
        " between solves."
    )
    out.append("")
    out.append("| input | setting | surface / SNets 0 | normals / SNets 16 | assemble + solve / SNets 16 | refine / SNets 16 | total / SNets 16 |")
    out.append("|---|---|---|---|---|---|---|")
    for s, entry in results.items():
        s0, s16 = med(entry["SurfaceNets3D 0"]), med(entry["SurfaceNets3D 16"])
        for k in ("voxreg default (3 rounds)", "voxreg 1 round, tol 1e-2", "voxreg 0 rounds", "voxreg 0 rounds, tol 5e-2", "voxreg 0 rounds, trivial"):
            if k not in entry:
                continue
            st = med_stages(entry[k])
            out.append(
                f"| {s} | {k[7:]} | {st.get('surface', 0) / s0:.2f}x | {st.get('normals', 0) / s16:.2f}x |"
                f" {(st.get('assemble', 0) + st.get('solve', 0)) / s16:.2f}x | {st.get('refine', 0) / s16:.2f}x |"
                f" {med(entry[k]) / s16:.2f}x |"
            )
    out.append("")
    vols = [s for s in results if "error" not in next(iter(results[s].values()))]
    if vols:
        out += ["## Volumes (time only)", ""]
        out.append("| input | tool, setting | faces (quads; SurfaceNets3D: triangles when smoothed) | compute | vs SNets 16 | stages (s) |")
        out.append("|---|---|---|---|---|---|")
        for s in vols:
            entry = results[s]
            ref = med(entry["SurfaceNets3D 16"])
            for k, e in sorted(entry.items(), key=lambda kv: med(kv[1])):
                st = ", ".join(f"{a} {b:.2f}" for a, b in med_stages(e).items()) if "stages" in e["runs"][0] else ""
                out.append(f"| {s} | {k} | {e['runs'][0]['faces']} | {fmt_t(med(e))} | {med(e) / ref:.2f}x | {st} |")
        out.append("")
    return "\n".join(out) + "\n"


def pareto(points):
    """The points (t, e) not beaten on both time and error, sorted by time."""
    pts = sorted(points)
    front, best = [], float("inf")
    for t, e in pts:
        if e < best:
            front.append((t, e))
            best = e
    return front


def plot(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shapes = [s for s in results if "error" in next(iter(results[s].values()))]
    cols = 3
    rows = (len(shapes) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.2 * rows), squeeze=False)
    for ax, s in zip(axes.ravel(), shapes):
        entry = results[s]
        ref = med(entry["SurfaceNets3D 16"])
        sn = [(med(entry[f"SurfaceNets3D {it}"]) / ref, entry[f"SurfaceNets3D {it}"]["error"]["mean"], it) for it in SNETS]
        ax.plot([p[0] for p in sn], [p[1] for p in sn], "o-", color="tab:red", label="SurfaceNets3D (0/16/32/64 it.)")
        for t, e, it in sn:
            ax.annotate(str(it), (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7, color="tab:red")
        vx = [(med(v) / ref, v["error"]["mean"], k[7:]) for k, v in entry.items() if k.startswith("voxreg")]
        ax.scatter([p[0] for p in vx], [p[1] for p in vx], s=14, color="tab:blue", alpha=0.5)
        front = pareto([(t, e) for t, e, _ in vx])
        ax.plot([p[0] for p in front], [p[1] for p in front], "s-", color="tab:blue", label="voxreg (Pareto front of its settings)")
        last = None
        for t, e, k in sorted(vx):
            # Label the front's points, skipping those too close to the last labelled one.
            if (t, e) in front and (last is None or t > 1.25 * last[0] or abs(np.log(e / last[1])) > 0.2):
                ax.annotate(k, (t, e), textcoords="offset points", xytext=(4, -9), fontsize=6, color="tab:blue")
                last = (t, e)
        half = [(t, 0.5 * e) for t, e, _ in sn]
        ax.plot([p[0] for p in half], [p[1] for p in half], ":", color="tab:red", alpha=0.6, label="half SurfaceNets3D's error")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_title(s, fontsize=10)
        ax.set_xlabel("compute time / SurfaceNets3D default (16 it.)")
        ax.set_ylabel("mean vertex distance (voxels)")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(shapes) :]:
        ax.axis("off")
    handles, names = axes.ravel()[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=3, fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    os.makedirs(os.path.dirname(path), exist_ok=True)
    fig.savefig(path, dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--voxreg", default=os.path.join(ROOT, "target", "release", "voxreg"))
    ap.add_argument("--runs", type=int, default=3, help="rounds on the analytic shapes")
    ap.add_argument("--volume-runs", type=int, default=3, help="rounds on the tissue and channels.vti")
    ap.add_argument("--shapes", nargs="*", help="only the shapes whose name contains one of these")
    ap.add_argument("--volumes", nargs="*", help="only the volumes whose name contains one of these")
    ap.add_argument("--volume-settings", choices=["all", "short"], default="all", help="voxreg settings on the volumes")
    ap.add_argument("--no-volumes", action="store_true", help="skip the tissue and channels.vti")
    ap.add_argument("--settings", nargs="*", help="only these voxreg settings (names of VOXREG, e.g. fast)")
    ap.add_argument("--quick", action="store_true", help="sphere and torus, three settings, one run, no volumes")
    ap.add_argument("--conditions", default="", help="a sentence on the machine's load, for the report")
    ap.add_argument("--json", help="write the raw samples here")
    ap.add_argument("--add-to", help="start from the samples of this JSON file (inputs measured earlier)")
    ap.add_argument("--no-shapes", action="store_true", help="skip the analytic shapes")
    ap.add_argument("--set-aside", action="store_true", help="also the shapes set aside (SET_ASIDE: split balls of another radius and cut)")
    ap.add_argument("--from-json", nargs="+", help="render the report from these samples (pooled) instead of running")
    ap.add_argument("--command-note", help="with --from-json: the commands that made the samples, for the report")
    ap.add_argument("--md", help="write the Markdown report here (default: print it)")
    ap.add_argument("--png", help="write the plot here")
    args = ap.parse_args()
    if args.from_json:
        # Several files: their samples pooled per input and setting (rounds of separate runs,
        # each interleaved), the first file's description kept.
        results, meta = {}, None
        for path in args.from_json:
            with open(path) as f:
                saved = json.load(f)
            meta = meta or saved["meta"]
            for name, entry in saved["results"].items():
                for setting, e in entry.items():
                    into = results.setdefault(name, {}).setdefault(setting, {"runs": []})
                    into["runs"] += e["runs"]
                    if "error" in e:
                        into["error"] = e["error"]
        if args.command_note:
            meta["command"] = args.command_note
        meta["runs"] = max((len(e["runs"]) for n, x in results.items() for e in x.values() if "error" in e), default=0)
        meta["volume_runs"] = max((len(e["runs"]) for n, x in results.items() for e in x.values() if "error" not in e), default=0)
        if args.conditions:
            meta["conditions"] = args.conditions
    else:
        import platform

        import vtkmodules.vtkCommonCore as vcore

        exe = os.path.abspath(args.voxreg)
        if not os.path.exists(exe):
            raise SystemExit(f"{exe}: no such binary (cargo build --release -p voxreg-cli)")
        settings = list(VOXREG)
        if args.settings:
            unknown = [s for s in args.settings if s not in VOXREG]
            if unknown:
                raise SystemExit(f"unknown settings {unknown}: one of {list(VOXREG)}")
            settings = args.settings
        if args.quick:
            args.runs, args.no_volumes = 1, True
            args.shapes = args.shapes or ["sphere R=20, h", "torus"]
            settings = QUICK_SETTINGS
        results = {}
        if args.add_to:  # earlier inputs' samples, kept (each input's settings ran interleaved)
            with open(args.add_to) as f:
                results = json.load(f)["results"]
        with tempfile.TemporaryDirectory() as tmp:
            if not args.no_shapes:
                run_shapes(args, exe, tmp, settings, results)
            if not args.no_volumes:
                vs = SHORT_VOLUME_SETTINGS if args.volume_settings == "short" else VOLUME_SETTINGS
                run_volumes(args, exe, tmp, [s for s in vs if s in settings], results)
        meta = {
            "command": "`python bench/speed/frontier.py " + " ".join(sys.argv[1:]) + "`",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "machine": f"{os.cpu_count()} cores, {platform.machine()}, load average {os.getloadavg()[0]:.1f} at the end",
            "vtk": vcore.vtkVersion.GetVTKVersion(),
            "conditions": args.conditions,
            "runs": args.runs,
            "volume_runs": 0 if args.no_volumes else args.volume_runs,
        }
        save(args, results, meta)
    text = markdown(results, args, meta)
    if args.md:
        with open(args.md, "w") as f:
            f.write(text)
    else:
        print(text)
    if args.png:
        plot(results, args.png)


if __name__ == "__main__":
    main()
