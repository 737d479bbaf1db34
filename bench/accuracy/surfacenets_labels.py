#!/usr/bin/env python3
"""VTK's SurfaceNets3D on the label volumes of `cargo xtask compare --labels --surfacenets`.

The xtask writes each case's digitized volume to FOLDER/case_K.npy (labels, shape
(X, Y, Z)) with FOLDER/case_K.json (spacing and origin: voxel [x, y, z] is centred at
origin + [x, y, z] * spacing, as in voxreg), runs this script on FOLDER, and measures the
meshes it writes with the metric of its other rows. For each volume this writes
FOLDER/case_K.snets: a line `N M`, then N lines `x y z` (the vertices), then M lines
`i j k a b` (a triangle and the two labels on either side of it, VTK's BoundaryLabels).

vtkSurfaceNets3D runs with its defaults but the labels: every label present but the
background 0 is listed for extraction (by default it extracts one), its constrained
smoothing on (16 iterations, relaxation 0.5, constraint distance and
scale as VTK sets them), triangles. The settings used are printed.

Needs numpy and pip's `vtk` (9.4 or later, which has vtkSurfaceNets3D):

    python3 bench/accuracy/surfacenets_labels.py target/xtask/compare/volumes
"""

import json
import pathlib
import sys

import numpy as np
import vtk
from vtk.util import numpy_support


def surface_nets(labels, spacing, origin):
    """The SurfaceNets3D mesh of `labels`: vertices (N, 3), triangles (M, 3), labels (M, 2)."""
    image = vtk.vtkImageData()
    image.SetDimensions(*labels.shape)
    image.SetSpacing(*spacing)
    image.SetOrigin(*origin)
    # VTK's point order is x fastest.
    scalars = numpy_support.numpy_to_vtk(np.ascontiguousarray(labels.ravel(order="F")), deep=1)
    image.GetPointData().SetScalars(scalars)
    nets = vtk.vtkSurfaceNets3D()
    nets.SetInputData(image)
    nets.SetBackgroundLabel(0)
    # Without a list, VTK extracts one label only: list every label present.
    present = [int(l) for l in np.unique(labels) if l != 0]
    nets.SetNumberOfLabels(len(present))
    for i, label in enumerate(present):
        nets.SetLabel(i, label)
    nets.Update()
    out = nets.GetOutput()
    points = numpy_support.vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64)
    polys = numpy_support.vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    boundary = numpy_support.vtk_to_numpy(out.GetCellData().GetArray("BoundaryLabels")).reshape(-1, 2)
    settings = (
        f"smoothing {bool(nets.GetSmoothing())}, {nets.GetNumberOfIterations()} iterations, "
        f"relaxation {nets.GetRelaxationFactor()}, constraint distance {nets.GetConstraintDistance()}, "
        f"output mesh type {nets.GetOutputMeshType()}"
    )
    return points, polys, boundary, settings


def main(folder):
    volumes = sorted(folder.glob("case_*.npy"))
    if not volumes:
        sys.exit(f"{folder}: no case_*.npy volumes (cargo xtask compare --labels --surfacenets writes them)")
    for path in volumes:
        meta = json.loads(path.with_suffix(".json").read_text())
        labels = np.load(path)
        points, polys, boundary, settings = surface_nets(labels, meta["spacing"], meta["origin"])
        with open(path.with_suffix(".snets"), "w") as f:
            f.write(f"{len(points)} {len(polys)}\n")
            np.savetxt(f, points, fmt="%.17g")
            np.savetxt(f, np.hstack([polys, boundary]).astype(np.int64), fmt="%d")
        print(f"{path.name}: {len(points)} vertices, {len(polys)} triangles ({settings}; VTK {vtk.vtkVersion.GetVTKVersion()})")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(pathlib.Path(sys.argv[1]))
