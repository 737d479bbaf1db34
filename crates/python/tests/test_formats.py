"""The scientific formats both ways: Zarr stores written by zarr-python read as zarr-python
reads them; the .stl and .vtp that save() writes open in pyvista, the .stl in meshio too
(meshio reads VTK's .vtu and legacy .vtk, not .vtp)."""

import numpy as np
import pytest

import voxreg
from conftest import ball_labels


@pytest.mark.parametrize("name", ["labels_v2.zarr", "labels_v3.zarr", "labels_sharded.zarr", "image.ome.zarr/0",
                                  "image_v3.ome.zarr/1"])
def test_read_zarr_as_zarr_python_does(data, name):
    zarr = pytest.importorskip("zarr")
    expected = zarr.open_array(str(data / "formats" / name), mode="r")[...]  # [z, y, x]
    labels, info = voxreg.read(data / "formats" / name)
    assert np.array_equal(labels, expected.transpose()), name


def test_read_ome_zarr_image_is_level_0(data):
    image, info = voxreg.read(data / "formats" / "image.ome.zarr")
    level0, info0 = voxreg.read(data / "formats" / "image.ome.zarr" / "0")
    assert np.array_equal(image, level0) and tuple(info["spacing"]) == tuple(info0["spacing"]) == (0.5, 0.5, 2.0)
    with pytest.raises(voxreg.IoError, match="missing.zarr"):
        voxreg.read(data / "formats" / "missing.zarr")


@pytest.fixture(scope="module")
def mesh():
    return voxreg.regularize(ball_labels())


def test_stl_and_vtp_open_in_pyvista(mesh, tmp_path):
    pv = pytest.importorskip("pyvista")
    mesh.save(tmp_path / "m.vtp")
    poly = pv.read(tmp_path / "m.vtp")
    assert poly.n_cells == len(mesh.quads) and poly.n_points == len(mesh.vertices)
    assert np.allclose(poly.points, mesh.vertices, atol=1e-5)
    assert np.array_equal(np.asarray(poly.faces).reshape(-1, 5)[:, 1:], mesh.quads)
    mesh.save(tmp_path / "m.stl")
    stl = pv.read(tmp_path / "m.stl")
    assert stl.n_cells == 2 * len(mesh.quads)
    # The STL splits each quad (a, b, c, d) along a-c (pyvista's triangulate() may take the
    # other diagonal, whose area differs on a non-planar quad).
    v, q = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.quads)
    a, b, c, d = (v[q[:, i]] for i in range(4))
    area = 0.5 * (np.linalg.norm(np.cross(b - a, c - a), axis=1) + np.linalg.norm(np.cross(c - a, d - a), axis=1))
    assert np.isclose(stl.area, area.sum(), rtol=1e-5)
    assert np.isclose(stl.area, poly.triangulate().area, rtol=1e-3)


def test_stl_opens_in_meshio(mesh, tmp_path):
    meshio = pytest.importorskip("meshio")
    mesh.save(tmp_path / "m.stl")
    s = meshio.read(tmp_path / "m.stl")
    triangles = np.concatenate([c.data for c in s.cells if c.type == "triangle"])
    assert len(triangles) == 2 * len(mesh.quads)
    # STL has no shared vertices: every triangle corner is one of the mesh's vertices.
    corners = s.points[triangles].reshape(-1, 3)
    dist = np.abs(corners[:, None, :] - mesh.vertices[None, :, :]).max(axis=2).min(axis=1)
    assert dist.max() < 1e-4
