"""The Python package makes the CLI's meshes: same preset choice, same bytes on disk."""

import numpy as np
import pytest

import voxreg


def same_files(a, b):
    return a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize("name", ["cat10.vol", "chr_army1.vox", "formats/organs.seg.nrrd"])
@pytest.mark.parametrize("ext", ["obj", "ply", "glb"])
def test_save_matches_cli(cli, data, tmp_path, name, ext):
    # Same file names in two directories: an OBJ names its .mtl.
    (tmp_path / "cli").mkdir(), (tmp_path / "py").mkdir()
    out_cli = tmp_path / "cli" / f"mesh.{ext}"
    r = cli("regularize", data / name, "-o", out_cli, "-q")
    assert r.returncode == 0, r.stderr
    labels, info = voxreg.read(data / name)
    mesh = voxreg.regularize(labels, **info)
    out_py = tmp_path / "py" / f"mesh.{ext}"
    mesh.save(out_py)
    assert same_files(out_cli, out_py)
    if ext == "obj" and info["palette"] is not None:
        assert same_files(out_cli.with_suffix(".mtl"), out_py.with_suffix(".mtl"))


def test_obj_positions_bit_identical(cli, data, tmp_path):
    """OBJ prints f64 round-trip exactly: the CLI's positions are the arrays' bit for bit."""
    out = tmp_path / "cli.obj"
    assert cli("regularize", data / "cat10.vol", "-o", out, "-q", "--preset", "papers").returncode == 0
    labels, info = voxreg.read(data / "cat10.vol")
    mesh = voxreg.regularize(labels, **dict(info, preset="papers"))
    v = [line.split()[1:] for line in out.read_text().splitlines() if line.startswith("v ")]
    assert np.array_equal(np.array(v, dtype=np.float64), mesh.vertices)
    f = [line.split()[1:] for line in out.read_text().splitlines() if line.startswith("f ")]
    assert np.array_equal(np.array(f, dtype=np.int64) - 1, mesh.quads)


def test_options_match_cli(cli, data, tmp_path):
    out = tmp_path / "cli.ply"
    args = ["--alpha", "0.02", "--normals", "convolved", "--radius", "2.5", "--refine", "1",
            "--solver", "cg", "--tolerance", "1e-4", "--no-preserve-size", "--regions", "solid"]
    assert cli("regularize", data / "cat10.vol", "-o", out, "-q", *args).returncode == 0
    labels, info = voxreg.read(data / "cat10.vol")
    mesh = voxreg.regularize(labels, **info, alpha=0.02, normals="convolved", radius=2.5, refine=1,
                             solver="cg", tolerance=1e-4, preserve_size=False, regions="solid")
    mesh.save(tmp_path / "py.ply")
    assert same_files(out, tmp_path / "py.ply")


def test_split_regions_match_cli(cli, tmp_path):
    from conftest import three_labels

    labels = three_labels()
    np.save(tmp_path / "v.npy", labels.astype(np.uint32))
    assert cli("regularize", tmp_path / "v.npy", "-o", tmp_path / "split", "--split", "regions", "-q").returncode == 0
    a, info = voxreg.read(tmp_path / "v.npy")
    mesh = voxreg.regularize(a, **info)
    for label in (1, 2, 3):
        mesh.region(label, manifold=False).save(tmp_path / f"py_{label}.ply")
        assert same_files(tmp_path / "split" / f"region_{label}.ply", tmp_path / f"py_{label}.ply")


def test_cli_report_equals_python_report(cli, data, tmp_path):
    import json

    assert cli("regularize", data / "cat10.vol", "-o", tmp_path / "o.obj", "-q", "--report", tmp_path / "r.json").returncode == 0
    run = json.loads((tmp_path / "r.json").read_text())
    for key in ("input", "output", "io"):
        del run[key]
    labels, info = voxreg.read(data / "cat10.vol")
    report = voxreg.regularize(labels, **info).report
    for key in ("params", "counts", "normals"):
        assert run[key] == report[key]
    # Energies are parallel sums: equal to rounding.
    for when in ("before", "after"):
        assert run["energy"][when] == pytest.approx(report["energy"][when], rel=1e-12)
    assert len(run["solves"]) == len(report["solves"])


def test_smoothness_matches_cli(cli, data, tmp_path):
    labels, info = voxreg.read(data / "chr_army1.vox")
    plain = voxreg.regularize(labels, **info)
    for s in (0.3, 1.0):
        # Same file names in two directories: an OBJ names its .mtl.
        (tmp_path / f"cli{s}").mkdir(), (tmp_path / f"py{s}").mkdir()
        out = tmp_path / f"cli{s}" / "mesh.obj"
        assert cli("regularize", data / "chr_army1.vox", "-o", out, "-q", "--smoothness", s).returncode == 0
        mesh = voxreg.regularize(labels, **info, smoothness=s)
        v = [line.split()[1:] for line in out.read_text().splitlines() if line.startswith("v ")]
        assert np.array_equal(np.array(v, dtype=np.float64), mesh.vertices)
        mesh.save(tmp_path / f"py{s}" / "mesh.obj")
        assert same_files(out, tmp_path / f"py{s}" / "mesh.obj")
    # Blockier: every vertex nearer its lattice corner than the preset lets it go.
    def from_corners(m):
        c = (m.vertices - np.asarray(info["origin"])) / np.asarray(info["spacing"]) + 0.5
        return np.abs(c - np.round(c)).max()

    low = voxreg.regularize(labels, **info, smoothness=0.3)
    assert from_corners(low) < from_corners(plain)


@pytest.mark.parametrize("kwargs, message", [
    ({"smoothness": 0.0}, r"smoothness must be in \(0, 1\], got 0"),
    ({"smoothness": 1.5}, r"smoothness must be in \(0, 1\], got 1.5"),
    ({"smoothness": 0.5, "clamp": True}, "smoothness and clamp exclude each other"),
])
def test_smoothness_errors(kwargs, message):
    from conftest import ball_labels

    with pytest.raises(voxreg.ParameterError, match=message):
        voxreg.regularize(ball_labels(), **kwargs)


def cli_flag(name):
    """The command line's flag of an option (an `Overrides` field)."""
    return {"preserve_size": "--no-preserve-size"}.get(name, "--" + name.replace("_", "-"))


def test_every_option_reaches_the_cli_and_python(cli):
    """One mapping: every library option is a keyword of voxreg.regularize and a flag."""
    import inspect

    names = voxreg._voxreg.option_names()
    assert "alpha" in names and "clamp" in names
    keywords = inspect.signature(voxreg.regularize).parameters
    help_text = cli("regularize", "--help").stdout
    for name in names:
        assert name in keywords, name
        assert cli_flag(name) in help_text, name
    assert "--no-clamp" in help_text


@pytest.mark.parametrize("args, kwargs", [
    (["--beta", "0.5", "--gamma", "0.2", "--texture-aware"], dict(beta=0.5, gamma=0.2, texture_aware=True)),
    (["--normals", "at", "--sharpen", "3", "--sharpen-threshold", "0.3", "--refine", "1"],
     dict(normals="at", sharpen=3, sharpen_threshold=0.3, refine=1)),
    (["--refine", "2", "--intermediate-tolerance", "3"], dict(refine=2, intermediate_tolerance=3)),
    (["--clamp", "--refine", "0"], dict(clamp=True, refine=0)),
    (["--clamp", "0.2", "--refine", "0"], dict(clamp=0.2, refine=0)),
    (["--smoothness", "0.4", "--preset", "voxel-art"], dict(smoothness=0.4, preset="voxel_art")),
    (["--preset", "voxel-art", "--no-clamp"], dict(preset="voxel_art", clamp=False)),
    (["--preset", "papers", "--solver", "direct"], dict(preset="papers", solver="direct")),
    (["--preset", "fast"], dict(preset="fast")),
    (["--preset", "fast", "--refine", "1"], dict(preset="fast", refine=1)),
])
def test_options_resolve_to_the_same_params(cli, data, tmp_path, args, kwargs):
    import json

    report = tmp_path / "r.json"
    r = cli("regularize", data / "cat10.vol", "-o", tmp_path / "o.obj", "-q", "--report", report, *args)
    assert r.returncode == 0, r.stderr
    labels, info = voxreg.read(data / "cat10.vol")
    mesh = voxreg.regularize(labels, **dict(info, **kwargs))
    assert json.loads(report.read_text())["params"] == mesh.report["params"]


@pytest.mark.parametrize("args, kwargs, message", [
    (["--alpha=0"], dict(alpha=0), "alpha must be finite and positive, got 0"),
    (["--refine", "1000000000"], dict(refine=10**9), "refinement rounds must be at most 100"),
    (["--clamp", "2"], dict(clamp=2.0), r"clamp must be a margin in \(0, 1\) voxel, got 2"),
    (["--intermediate-tolerance", "0.5"], dict(intermediate_tolerance=0.5), "intermediate tolerance"),
])
def test_the_same_options_are_refused_with_the_same_message(cli, data, tmp_path, args, kwargs, message):
    import re

    r = cli("regularize", data / "cat10.vol", "-o", tmp_path / "o.obj", *args)
    assert r.returncode == 1 and re.search(message, r.stderr), r.stderr
    assert not (tmp_path / "o.obj").exists()
    with pytest.raises(voxreg.ParameterError, match=message):
        voxreg.regularize(voxreg.read(data / "cat10.vol")[0], **kwargs)


def test_threads_are_bounded():
    from conftest import ball_labels

    with pytest.raises(voxreg.ParameterError, match="threads must be at most 1024"):
        voxreg.regularize(ball_labels(), threads=10**9)
