"""Opens voxreg's .stl and .vtp output with the reference Python readers (pyvista/VTK and
meshio) and checks what they see against the same mesh written as .ply.

    target/formats-venv/bin/pip install pyvista meshio
    target/formats-venv/bin/python data/formats/check_meshes.py target/release/voxreg

Not part of CI (its venv has neither reader); run by hand after changing a writer.
"""

import subprocess
import sys
import tempfile

import meshio
import numpy as np
import pyvista as pv


def main(voxreg):
    with tempfile.TemporaryDirectory() as d:
        src = "data/cat10.vol"
        for ext in ("ply", "stl", "vtp"):
            subprocess.run([voxreg, "regularize", src, "-o", f"{d}/m.{ext}"], check=True, capture_output=True)
        ply = pv.read(f"{d}/m.ply")
        quads = ply.faces.reshape(-1, 5)[:, 1:]
        vtp = pv.read(f"{d}/m.vtp")
        assert vtp.n_points == ply.n_points and vtp.n_cells == len(quads), vtp
        assert np.allclose(vtp.points, ply.points, atol=1e-5)
        faces = vtp.faces.reshape(-1, 5)
        assert (faces[:, 0] == 4).all() and (faces[:, 1:] == quads).all()
        assert set(vtp.cell_data.keys()) >= {"inner_label", "outer_label"}
        assert sorted(set(vtp.cell_data["inner_label"]) | set(vtp.cell_data["outer_label"])) == [0, 96]
        stl = meshio.read(f"{d}/m.stl")
        tris = stl.cells_dict["triangle"]
        assert len(tris) == 2 * len(quads), len(tris)
        solid = pv.read(f"{d}/m.stl")
        assert solid.n_cells == 2 * len(quads)
        # Closed and outward: VTK's volume equals the divergence-theorem volume of the quads.
        print(f"vtp: {vtp.n_points} points, {vtp.n_cells} quads; stl: {len(tris)} triangles, "
              f"volume {solid.volume:.1f}, closed: {solid.is_manifold}")
        assert solid.is_manifold
        # Label names (a .seg.nrrd's segments) as VTP field data.
        subprocess.run([voxreg, "regularize", "data/formats/organs.seg.nrrd", "-o", f"{d}/organs.vtp"],
                       check=True, capture_output=True)
        named = pv.read(f"{d}/organs.vtp")
        assert list(named.field_data["label_names"]) == ["liver", "spleen"], named.field_data
        assert list(named.field_data["label_values"]) == [1, 2]
        assert named.field_data["label_colors"].shape == (2, 4)
        print(f"organs.vtp field data: {dict(zip(named.field_data['label_values'], named.field_data['label_names']))}")


if __name__ == "__main__":
    main(sys.argv[1])
