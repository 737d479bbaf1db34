"""Mesh helpers: triangles, pyvista and trimesh round trips, meshes from arrays, check."""

import numpy as np
import pytest

import voxreg
from conftest import ball_labels


@pytest.fixture(scope="module")
def mesh():
    return voxreg.regularize(ball_labels())


def test_triangles(mesh):
    t = mesh.triangles()
    assert np.array_equal(t[0], mesh.quads[0, [0, 1, 2]]) and np.array_equal(t[1], mesh.quads[0, [0, 2, 3]])


def test_pyvista_round_trip(mesh):
    pv = pytest.importorskip("pyvista")
    poly = mesh.to_pyvista()
    assert isinstance(poly, pv.PolyData)
    assert poly.n_cells == len(mesh.quads) and poly.n_points == len(mesh.vertices)
    assert np.array_equal(np.asarray(poly.points), mesh.vertices)
    faces = np.asarray(poly.faces).reshape(-1, 5)
    assert (faces[:, 0] == 4).all() and np.array_equal(faces[:, 1:], mesh.quads)
    assert np.array_equal(poly.cell_data["labels"], mesh.labels)


def test_trimesh_round_trip(mesh):
    trimesh = pytest.importorskip("trimesh")
    tm = mesh.to_trimesh()
    assert isinstance(tm, trimesh.Trimesh)
    assert np.array_equal(tm.vertices, mesh.vertices) and np.array_equal(tm.faces, mesh.triangles())
    region = mesh.region(1).to_trimesh()
    assert region.is_watertight and region.volume > 0


def test_trimesh_colors(data):
    pytest.importorskip("trimesh")
    labels, info = voxreg.read(data / "chr_army1.vox")
    m = voxreg.regularize(labels, **info)
    tm = m.to_trimesh()
    assert np.array_equal(tm.visual.face_colors[0::2], m.colors)


def test_mesh_from_arrays_saves(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    m = voxreg.Mesh(v, [[0, 1, 2, 3]], [[1, 0]], colors=[[255, 0, 0, 255]])
    assert m.interfaces() == [(1, 0)]
    for ext in ("obj", "ply", "glb", "gltf"):
        m.save(tmp_path / f"q.{ext}")
        assert (tmp_path / f"q.{ext}").stat().st_size > 0
    assert voxreg.check(m) == voxreg.check((v, [[0, 1, 2, 3]]))


def test_check_counts_a_fold():
    # A bow-tie quad: its two triangles face opposite ways.
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    r = voxreg.check((v, [[0, 1, 2, 3]]))
    assert r["faces"] == 1 and not r["clean"]


def test_check_gives_the_mean_angle_between_adjacent_quads():
    # Two unit quads sharing the edge (0, 1): flat, then bent to a right angle.
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [1, -1, 0], [0, -1, 0]], dtype=float)
    quads = [[0, 1, 2, 3], [1, 0, 5, 4]]
    assert voxreg.check((v, quads))["mean_angle_deg"] == 0.0
    v[4:, 1], v[4:, 2] = 0.0, -1.0
    assert abs(voxreg.check((v, quads))["mean_angle_deg"] - 90.0) < 1e-9
