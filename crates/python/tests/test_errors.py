"""Errors: the right class, the CLI's message, nothing panics across into Python."""

import numpy as np
import pytest

import voxreg
from conftest import ball_labels


def test_hierarchy():
    assert issubclass(voxreg.InputError, voxreg.VoxregError) and issubclass(voxreg.InputError, ValueError)
    assert issubclass(voxreg.ParameterError, ValueError) and issubclass(voxreg.IoError, OSError)


@pytest.mark.parametrize("labels, message", [
    (np.zeros((4, 4)), r"3-D array indexed \[x, y, z\], got shape \(4, 4\)"),
    (np.zeros((4, 4, 4), dtype=np.float32), "integer array, got dtype float32"),
    (np.full((3, 3, 3), -2, dtype=np.int16), r"voxel \[0, 0, 0\] has label -2, which is negative"),
    (np.full((3, 3, 3), 2**33, dtype=np.int64), "beyond 4294967295"),
    (np.zeros((4, 4, 4), dtype=np.uint8), "labels: no surface to regularize"),
])
def test_input_errors(labels, message):
    with pytest.raises(voxreg.InputError, match=message):
        voxreg.regularize(labels)


@pytest.mark.parametrize("kwargs, message", [
    (dict(preset="quick"), "preset must be one of 'default', 'papers', 'voxel_art', 'fast', got 'quick'"),
    (dict(alpha=0), "alpha must be finite and positive, got 0"),
    (dict(beta=-1), "beta must be finite and non-negative"),
    (dict(radius=float("nan")), "radius must be finite and positive"),
    (dict(normals="pca"), "normals must be one of"),
    (dict(solver="lu"), "solver must be one of"),
    (dict(solver="cg", clamp=0.1), "clamp needs the bounded solver"),
    (dict(clamp=1.5), r"clamp must be a margin in \(0, 1\) voxel, got 1.5"),
    (dict(refine=-1), "refine must be a non-negative integer"),
    (dict(threads=-2), "threads must be a non-negative integer"),
    (dict(spacing=(1, 0, 1)), "spacing: invalid volume: voxel spacing must be finite and positive"),
    (dict(spacing=(1, 1)), "spacing must be three numbers"),
    (dict(regions="1,2;2"), "regions '1,2;2'"),
])
def test_parameter_errors(kwargs, message):
    with pytest.raises(voxreg.ParameterError, match=message):
        voxreg.regularize(ball_labels(8, 3), **kwargs)


def test_io_errors(tmp_path, data):
    with pytest.raises(voxreg.IoError, match="missing.vol"):
        voxreg.read(tmp_path / "missing.vol")
    with pytest.raises(voxreg.IoError, match="unknown file extension"):
        voxreg.read(tmp_path / "x.txt")
    with pytest.raises(voxreg.IoError):
        voxreg.read(data / "not_a.vox")
    mesh = voxreg.regularize(ball_labels(8, 3))
    with pytest.raises(voxreg.IoError, match=r"unsupported output format \(expected .obj, .ply, .glb, .gltf, .stl or .vtp\)"):
        mesh.save(tmp_path / "m.off")
    mesh.save(tmp_path / "m.stl")
    mesh.save(tmp_path / "m.vtp")
    assert (tmp_path / "m.stl").stat().st_size == 84 + 50 * 2 * len(mesh.quads)
    with pytest.raises(voxreg.IoError):
        mesh.save(tmp_path / "no" / "such" / "dir" / "m.ply")
    with pytest.raises(voxreg.ParameterError, match="unknown data type"):
        voxreg.read(tmp_path / "x.raw", dims=(2, 2, 2), dtype="u7")


def test_progress_exception_aborts_and_propagates():
    seen = []

    class Stop(Exception):
        pass

    def progress(stage, fraction):
        seen.append(stage)
        if stage.startswith("solve"):
            raise Stop(stage)

    with pytest.raises(Stop, match="solve 1/4"):
        voxreg.regularize(ball_labels(), progress=progress)
    assert seen == ["normals", "solve 1/4"]
    # The module still works afterwards.
    assert len(voxreg.regularize(ball_labels(8, 3)).quads) > 0


def test_progress_stages_fractions_and_throttle():
    calls = []
    voxreg.regularize(ball_labels(), progress=lambda s, f: calls.append((s, f)))
    stages = [s for s, _ in calls]
    assert stages[0] == "normals" and stages[-1] == "done" and calls[-1][1] == 1.0
    assert {"solve 1/4", "refine 1/3", "solve 4/4"} <= set(stages)
    fractions = [f for _, f in calls]
    assert fractions == sorted(fractions) and all(0.0 <= f <= 1.0 for f in fractions)


def test_docstrings_tell_units_and_defaults():
    doc = voxreg.regularize.__doc__
    for word in ["physical units", "default (1, 1, 1)", "alpha : float > 0, default None (preset: 1e-2",
                 "threads : int, 0 to 1024, default 0", "voxels"]:
        assert word in doc


@pytest.mark.parametrize("background", [-1, 2**32, 1.5, "0", True])
def test_a_bad_background_is_a_parameter_error(background):
    with pytest.raises(voxreg.ParameterError, match="background must be"):
        voxreg.regularize(ball_labels(8, 3), background=background)


@pytest.mark.parametrize("palette, message", [
    ({"materials": []}, "needs 'colors'"),
    ({"colors": np.zeros((4, 3), np.uint8), "materials": [{"name": "a"}]}, "material 0 has no color"),
    ({"colors": np.zeros((4, 3), np.uint8), "materials": [
        {"name": "a", "color": "red", "metallic": 0, "roughness": 0, "emission": 0, "transparency": 0}]},
     "material 0"),
    ({"colors": np.zeros((4, 3), np.uint8), "names": {"one": "a"}}, "'names' must map"),
])
def test_a_bad_palette_is_a_parameter_error(palette, message):
    with pytest.raises(voxreg.ParameterError, match=message):
        voxreg.regularize(ball_labels(8, 3), palette=palette)


def test_check_reports_non_finite_vertices():
    vertices = np.full((4, 3), np.nan)
    report = voxreg.check((vertices, np.array([[0, 1, 2, 3]])))
    assert report["invalid_faces"] == 1 and not report["clean"]


def test_dask_chunks_may_be_one_integer():
    pytest.importorskip("dask")
    import voxreg.dask

    labels = ball_labels(12, 4)
    one = voxreg.dask.regularize(labels, chunks=8, scheduler="synchronous")
    three = voxreg.dask.regularize(labels, chunks=(8, 8, 8), scheduler="synchronous")
    assert np.array_equal(one.quads, three.quads)
    for bad in [0, -3, (8, 8), "8", 2.5]:
        with pytest.raises(voxreg.ParameterError, match="chunks must be"):
            voxreg.dask.regularize(labels, chunks=bad, scheduler="synchronous")
    with pytest.raises(voxreg.ParameterError, match="background must be"):
        voxreg.dask.regularize(labels, chunks=8, background=-1, scheduler="synchronous")


@pytest.mark.parametrize("kwargs, message", [
    (dict(origin=(1e30, 0, 0)), r"spacing and origin: voxel spacing 1 along x is below the precision"),
    (dict(origin=(2e30, 0, 0)), r"spacing and origin: coordinates along x reach .* beyond 1e30"),
    (dict(spacing=(1e-38, 1, 1)), r"spacing and origin: voxel spacing 1e-38 along x is below 1e-30"),
])
def test_coordinates_a_mesh_cannot_store_are_refused(kwargs, message):
    """A flat or collapsed mesh is never returned for an embedding floats cannot resolve."""
    with pytest.raises(voxreg.ParameterError, match=message):
        voxreg.regularize(ball_labels(8, 3), **kwargs)
