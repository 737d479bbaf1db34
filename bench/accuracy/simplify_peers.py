"""Simplification against its peers, same run, same face count: voxreg's simplifier (the
whole partition at once) against per-label `pyfqmr` (the decimator of zmesh and igneous;
`fast-simplification` wraps the same code and gave the same meshes) and per-label VTK
`vtkQuadricDecimation`, all applied to voxreg's own full-resolution regions.

For each input: voxreg regularizes it, simplifies the whole mesh to RATIO of its
triangles within half a voxel, then every region's surface (the region's closed,
outward, 2-manifold mesh) is decimated by each peer to the number of triangles that
region has in voxreg's output. Measured on the regions' meshes of each method:

- shared: the share of vertex positions used by more than one label (a wall between two
  labels is one surface only if its vertices are the same on both sides);
- open: edges of a region's mesh not matched by an opposite edge (holes), summed;
- crossing: intersecting triangle pairs of all regions' meshes together (voxreg's exact
  test, `voxreg.check`; vertices merged by position, a triangle both sides of a wall
  have counted once): the input's own (thin walls) plus those simplification adds;
- Hausdorff per region: the largest distance from a full-resolution region's vertex to
  that region's simplified mesh and back, over all regions (VTK's cell locator), in
  voxels;
- to the whole: the largest distance from a full-resolution vertex to the union of all
  regions' simplified meshes, in voxels (what voxreg's bound tracks);
- time: the simplification's CPU seconds (voxreg: the whole mesh; peers: every region;
  CPU time, since this machine is shared).

    target/venv/bin/python bench/accuracy/simplify_peers.py [--ratio 0.1] \
        [--tissue tissue.npy] [--vox data/chr_army1.vox ...]

Needs the package, numpy, pip `pyfqmr` and `vtk`. Prints a
Markdown table (docs/accuracy.md, "Simplification: against the peers").
"""

import argparse
import pathlib
import sys
import time
from collections import Counter

import numpy as np

import voxreg

ROOT = pathlib.Path(__file__).resolve().parents[2]


def triangles_of(quads):
    """Quads (triangles repeating their last vertex) as triangles."""
    q = np.asarray(quads, np.int64)
    t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    ok = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])
    return t[ok]


def region_meshes(mesh, background):
    """Per label (not the background): its region's triangles, oriented outward, over the
    vertices they use: {label: (vertices, triangles)}."""
    out = {}
    for label in np.unique(mesh.labels):
        label = int(label)
        if label == background:
            continue
        inner, outer = mesh.labels[:, 0] == label, mesh.labels[:, 1] == label
        keep = inner | outer
        # Split first, then turn the triangles: both regions of a wall keep its diagonal.
        q = mesh.quads[keep]
        flip = np.concatenate([outer[keep], outer[keep]])
        t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
        t[flip] = t[flip][:, ::-1]
        t = t[(t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])]
        used, local = np.unique(t, return_inverse=True)
        out[label] = (mesh.vertices[used], local.reshape(-1, 3))
    return out


def shared_fraction(regions):
    """The share of distinct vertex positions used by more than one label."""
    count = Counter()
    for v, _ in regions.values():
        for key in {row.tobytes() for row in np.ascontiguousarray(v)}:
            count[key] += 1
    return sum(1 for n in count.values() if n > 1) / max(len(count), 1)


def open_edges(regions):
    total = 0
    for _, t in regions.values():
        e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        fw = Counter(map(tuple, e.tolist()))
        total += sum(1 for (a, b), n in fw.items() if fw.get((b, a), 0) != n)
    return total


def crossings(regions):
    """Intersecting triangle pairs over all regions together, vertices merged by
    position and each triangle present in two regions (a shared wall) kept once."""
    all_v = np.concatenate([v for v, _ in regions.values()])
    uniq, inv = np.unique(all_v, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    tris, base = [], 0
    for v, t in regions.values():
        tris.append(inv[t + base])
        base += len(v)
    t = np.concatenate(tris)
    key = np.sort(t, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    t = t[np.sort(first)]
    quads = np.concatenate([t, t[:, 2:3]], axis=1)
    return voxreg.check((uniq, quads))["intersecting_pairs"]


def polydata(v, t):
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray

    pts = vtk.vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(v, dtype=np.float64), deep=True))
    cells = vtk.vtkCellArray()
    offsets = np.arange(0, 3 * len(t) + 1, 3, dtype=np.int64)
    cells.SetData(numpy_to_vtkIdTypeArray(offsets, deep=True),
                  numpy_to_vtkIdTypeArray(np.ascontiguousarray(t, dtype=np.int64).ravel(), deep=True))
    poly = vtk.vtkPolyData()
    poly.SetPoints(pts)
    poly.SetPolys(cells)
    return poly


def one_sided(points, v, t):
    """The largest distance from ``points`` to the triangles (v, t)."""
    import vtk

    locator = vtk.vtkStaticCellLocator()
    locator.SetDataSet(polydata(v, t))
    locator.BuildLocator()
    closest = [0.0, 0.0, 0.0]
    cell, sub, d2 = vtk.reference(0), vtk.reference(0), vtk.reference(0.0)
    worst = 0.0
    for p in points:
        locator.FindClosestPoint(p, closest, cell, sub, d2)
        worst = max(worst, float(d2))
    return worst ** 0.5


def hausdorff(full, simple):
    worst = 0.0
    for label, (v, t) in full.items():
        sv, st = simple[label]
        worst = max(worst, one_sided(v, sv, st), one_sided(sv, v, t))
    return worst


def to_whole(full, simple):
    """The largest distance from a full-resolution vertex to the union of every region's
    simplified mesh (the bound voxreg's simplifier tracks)."""
    points = np.concatenate([v for v, _ in full.values()])
    vs, ts, base = [], [], 0
    for v, t in simple.values():
        vs.append(v)
        ts.append(t + base)
        base += len(v)
    return one_sided(points, np.concatenate(vs), np.concatenate(ts))


def by_pyfqmr(v, t, target):
    import pyfqmr

    s = pyfqmr.Simplify()
    s.setMesh(v, t)
    s.simplify_mesh(target_count=int(target), aggressiveness=7, preserve_border=True, verbose=False)
    out_v, out_t, _ = s.getMesh()
    return np.asarray(out_v, np.float64), np.asarray(out_t, np.int64)


def by_vtk(v, t, target):
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    dec = vtk.vtkQuadricDecimation()
    dec.SetInputData(polydata(v, t))
    dec.SetTargetReduction(1.0 - target / len(t))
    dec.VolumePreservationOn()
    dec.Update()
    out = dec.GetOutput()
    ov = vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    conn = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).astype(np.int64).reshape(-1, 3)
    return ov, conn


PEERS = [("pyfqmr, per label", by_pyfqmr), ("VTK vtkQuadricDecimation, per label", by_vtk)]


def measure(name, regions, full, seconds, voxel):
    tris = sum(len(t) for _, t in regions.values())
    return {"method": name, "triangles": tris, "shared": shared_fraction(regions), "open": open_edges(regions),
            "crossing": crossings(regions), "hausdorff": hausdorff(full, regions) / voxel,
            "whole": to_whole(full, regions) / voxel, "time": seconds}


def compare(title, mesh, background, ratio, voxel):
    full = region_meshes(mesh, background)
    rows = [measure("full resolution", full, full, 0.0, voxel)]
    start = time.process_time()
    simple = mesh.simplify(ratio=ratio)
    seconds = time.process_time() - start
    ours = region_meshes(simple, background)
    rows.append(measure("voxreg, whole partition", ours, full, seconds, voxel))
    for name, peer in PEERS:
        out, start = {}, time.process_time()
        for label, (v, t) in full.items():
            out[label] = peer(v, t, len(ours[label][1]))
        seconds = time.process_time() - start
        rows.append(measure(name, out, full, seconds, voxel))
    print(f"\n{title}: {len(mesh)} faces, {len(full)} labels, ratio {ratio}\n")
    print("| method | region triangles | shared vertices | open edges | crossing pairs | Hausdorff per region | to the whole | CPU (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['method']} | {r['triangles']} | {100 * r['shared']:.1f}% | {r['open']} | {r['crossing']} | "
              f"{r['hausdorff']:.3f} | {r['whole']:.3f} | {r['time']:.2f} |")
    sys.stdout.flush()
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ratio", type=float, default=0.1)
    ap.add_argument("--tissue", help="a .npy label volume (cargo xtask synth-labels)")
    ap.add_argument("--vox", nargs="*", default=[str(ROOT / "data" / "veh_fire.vox")])
    args = ap.parse_args()
    if args.tissue:
        labels = np.load(args.tissue)
        mesh = voxreg.regularize(labels)
        compare(f"tissue {pathlib.Path(args.tissue).name} {labels.shape}", mesh, 0, args.ratio, 1.0)
    for path in args.vox:
        labels, info = voxreg.read(path)
        # Each colour its own region: a partition for every method to keep.
        info = dict(info, regions="label")
        mesh = voxreg.regularize(labels, **info)
        compare(f"{pathlib.Path(path).name} {labels.shape} (a region per colour)", mesh,
                info.get("background") or 0, args.ratio, float(min(info["spacing"])))


if __name__ == "__main__":
    main()
