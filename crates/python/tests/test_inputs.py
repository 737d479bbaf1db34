"""Label arrays of every integer dtype and memory order, the embedding, the background."""

import numpy as np
import pytest

import voxreg
from conftest import ball_labels


@pytest.fixture(scope="module")
def reference():
    return voxreg.regularize(ball_labels().astype(np.uint32), preset="papers")


DTYPES = [np.uint8, np.uint16, np.uint32, np.uint64, np.int8, np.int16, np.int32, np.int64]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("order", ["C", "F", "strided"])
def test_every_dtype_and_order_same_mesh(reference, dtype, order):
    labels = ball_labels().astype(dtype)
    if order == "F":
        labels = np.asfortranarray(labels)
    elif order == "strided":
        big = np.zeros((40, 20, 20), dtype=dtype)
        big[::2] = labels
        labels = big[::2]
        assert not labels.flags.c_contiguous and not labels.flags.f_contiguous
    mesh = voxreg.regularize(labels, preset="papers")
    assert np.array_equal(mesh.vertices, reference.vertices)
    assert np.array_equal(mesh.quads, reference.quads)
    assert np.array_equal(mesh.labels, reference.labels)


def test_bool_big_endian_and_lists():
    ball = ball_labels(split=False)
    ref = voxreg.regularize(ball, preset="papers")
    for labels in (ball.astype(bool), ball.astype(">u4"), ball.tolist()):
        assert np.array_equal(voxreg.regularize(labels, preset="papers").vertices, ref.vertices)


def test_dtypes_of_results(reference):
    m = reference
    assert m.vertices.dtype == np.float64 and m.vertices.shape[1] == 3
    assert m.quads.dtype == np.int64 and m.quads.shape[1] == 4
    assert m.labels.shape == (len(m.quads), 2)
    assert m.colors is None
    assert m.report["counts"]["surfels"] == len(m.quads)
    assert m.triangles().shape == (2 * len(m.quads), 3)


def test_large_labels_fit_u32():
    labels = ball_labels(split=False).astype(np.uint64) * np.uint64(4_000_000_000)
    mesh = voxreg.regularize(labels, preset="papers")
    assert set(mesh.labels.ravel().tolist()) == {0, 4_000_000_000}


def test_origin_translates_and_spacing_scales(reference):
    labels = ball_labels()
    moved = voxreg.regularize(labels, preset="papers", origin=(10.0, -5.0, 2.5))
    assert np.allclose(moved.vertices, reference.vertices + [10.0, -5.0, 2.5], atol=1e-9)
    # Uniform spacing s scales every energy term by s^2: the minimizer scales by s.
    scaled = voxreg.regularize(labels, preset="papers", spacing=(2.0, 2.0, 2.0), radius=6.0)
    unit = voxreg.regularize(labels, preset="papers", radius=3.0)
    assert np.allclose(scaled.vertices, 2.0 * unit.vertices, atol=1e-3)


def test_anisotropic_spacing_bounds():
    labels = ball_labels(split=False)
    mesh = voxreg.regularize(labels, spacing=(0.5, 1.0, 2.0), origin=(1.0, 2.0, 3.0))
    lo = np.array([1.0, 2.0, 3.0]) + (np.argwhere(labels).min(0) - 0.5) * [0.5, 1.0, 2.0]
    hi = np.array([1.0, 2.0, 3.0]) + (np.argwhere(labels).max(0) + 0.5) * [0.5, 1.0, 2.0]
    # Vertices move less than a voxel from the staircase, whose corners lie within [lo, hi].
    assert (mesh.vertices >= lo - [0.5, 1.0, 2.0]).all() and (mesh.vertices <= hi + [0.5, 1.0, 2.0]).all()
    assert mesh.vertices[:, 2].max() - mesh.vertices[:, 2].min() > 2.0 * (np.ptp(np.argwhere(labels)[:, 2]) - 1)
    assert mesh.report["normals"]["radius"] == pytest.approx(3.0 * 2.0 ** (1 / 3))


def test_no_background_leaves_interfaces_open():
    labels = np.ones((6, 6, 6), dtype=np.uint8)
    labels[3:] = 2
    closed = voxreg.regularize(labels, preset="papers")
    open_ = voxreg.regularize(labels, background=None, preset="papers")
    assert open_.interfaces() == [(1, 2)]
    assert len(open_.quads) == 36  # the 6 x 6 plane between the halves, nothing on the border
    assert (1, 0) in closed.interfaces() or (0, 1) in closed.interfaces()
    assert len(closed.quads) == 36 + 6 * 36


def test_regions_groups_and_presets():
    labels = ball_labels()
    assert voxreg.regularize(labels, regions="solid").interfaces() == [(1, 0)]
    assert voxreg.regularize(labels, regions=[[1, 2]]).interfaces() == [(1, 0)]
    assert voxreg.regularize(labels, regions="1,2").interfaces() == [(1, 0)]
    assert len(voxreg.regularize(labels, regions="label").interfaces()) == 3
    art = voxreg.regularize(labels, preset="voxel_art")
    assert art.report["params"]["mode"]["clamped"]["margin"] == 0.01
    assert voxreg.check(art)["intersecting_pairs"] == 0


def test_read_every_format(data, tmp_path):
    for name, shape in [("cat10.vol", (40, 40, 40)), ("cat10.pgm3d", (40, 40, 40)), ("test.longvol", (16, 16, 16)),
                        ("chr_army1.vox", (8, 7, 12)), ("channels.vti", (250, 250, 100))]:
        labels, info = voxreg.read(data / name)
        assert labels.shape == shape and labels.dtype == np.uint32, name
    labels, info = voxreg.read(data / "lobsterCroped2.nii.gz", threshold=30)
    assert labels.shape == (101, 101, 41) and set(np.unique(labels)) == {0, 1}
    np.save(tmp_path / "grey.npy", np.linspace(0, 1, 27).reshape(3, 3, 3))
    with pytest.raises(voxreg.InputError, match="grey-level data needs threshold=T"):
        voxreg.read(tmp_path / "grey.npy")
    labels, _ = voxreg.read(tmp_path / "grey.npy", threshold=0.5)
    assert labels.sum() == 13
    ball = ball_labels().astype(np.uint16)
    np.save(tmp_path / "b.npy", ball)
    labels, info = voxreg.read(tmp_path / "b.npy")
    assert np.array_equal(labels, ball) and info["preset"] == "default" and info["palette"] is None
    ball.ravel(order="F").tofile(tmp_path / "b.raw")  # raw data: x fastest
    labels, _ = voxreg.read(tmp_path / "b.raw", dims=ball.shape, dtype="u16", spacing=(1, 2, 3))
    assert np.array_equal(labels, ball)
    with pytest.raises(voxreg.InputError, match="raw data have no header"):
        voxreg.read(tmp_path / "b.raw")
    labels, info = voxreg.read(tmp_path / "b.npy", keep_labels=[2], background=5)
    assert set(np.unique(labels)) == {2, 5} and info["background"] == 5


def test_read_vox_palette_and_preset(data):
    labels, info = voxreg.read(data / "chr_army1.vox")
    assert info["preset"] == "voxel_art"
    assert info["palette"]["colors"].shape == (256, 4) and len(info["palette"]["materials"]) == 256
    mesh = voxreg.regularize(labels, **info)
    assert mesh.colors.shape == (len(mesh.quads), 4) and mesh.colors.dtype == np.uint8
    assert voxreg.check(mesh)["intersecting_pairs"] == 0  # clamped: never self-intersecting


def test_seg_nrrd_label_names(data):
    """3D Slicer segment names: in read's palette, on the mesh and its sub-meshes."""
    labels, info = voxreg.read(data / "formats" / "organs.seg.nrrd")
    assert info["palette"]["names"] == {1: "liver", 2: "spleen"}
    mesh = voxreg.regularize(labels, **info)
    assert mesh.label_names == {1: "liver", 2: "spleen"}
    assert mesh.interface(1, 0).label_names == {1: "liver"}
    assert mesh.region(1).label_names == {1: "liver", 2: "spleen"}  # it borders the spleen
    assert voxreg.regularize(labels).label_names == {}
