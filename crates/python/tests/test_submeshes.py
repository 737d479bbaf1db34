"""Interfaces and regions as meshes of their own: closed, outward, meeting exactly."""

import os
from collections import Counter

import numpy as np
import pytest

import voxreg
from conftest import three_labels


@pytest.fixture(scope="module")
def mesh():
    return voxreg.regularize(three_labels())


def directed_edges(quads):
    return [(int(q[i]), int(q[(i + 1) % 4])) for q in quads for i in range(4)]


def bits(vertices):
    return {tuple(v) for v in np.ascontiguousarray(vertices).view(np.uint64)}


def test_interfaces(mesh):
    pairs = mesh.interfaces()
    assert sorted(tuple(sorted(p)) for p in pairs) == [(0, 1), (0, 2), (1, 2), (1, 3), (2, 3)]
    total = sum(len(mesh.interface(a, b)) for a, b in pairs)
    assert total == len(mesh)
    assert len(mesh.interface(1, 2)) == len(mesh.interface(2, 1))
    with pytest.raises(voxreg.InputError, match="no interface between labels 0 and 3"):
        mesh.interface(0, 3)


@pytest.mark.parametrize("label", [1, 2, 3])
def test_regions_closed_and_oriented(mesh, label):
    region = mesh.region(label)
    edges = directed_edges(region.quads)
    undirected = Counter(tuple(sorted(e)) for e in edges)
    assert all(n % 2 == 0 for n in undirected.values())
    directed = Counter(edges)
    assert all(directed[(a, b)] == directed[(b, a)] for a, b in directed)
    # Outward: the signed volume (divergence theorem over the triangles) is positive.
    v, t = region.vertices, region.triangles()
    volume = np.einsum("ij,ij->i", v[t[:, 0]], np.cross(v[t[:, 1]], v[t[:, 2]])).sum() / 6
    assert volume > 0
    # The region is the inner side of every quad.
    assert (region.labels[:, 0] == label).all()


def test_junction_vertices_identical(mesh):
    whole = bits(mesh.vertices)
    r1, r2, r3 = (bits(mesh.region(l).vertices) for l in (1, 2, 3))
    assert r1 <= whole and r2 <= whole and r3 <= whole
    i12 = bits(mesh.interface(1, 2).vertices)
    assert i12 <= r1 and i12 <= r2
    junction = r1 & r2 & r3
    assert junction, "the three regions meet along junction curves"


def test_sub_meshes_save_and_report(mesh, tmp_path):
    sub = mesh.region(3)
    assert sub.report is mesh.report
    sub.save(tmp_path / "r3.obj")
    assert sum(1 for l in (tmp_path / "r3.obj").read_text().splitlines() if l.startswith("f ")) == len(sub)
    with pytest.raises(voxreg.VoxregError):
        sub.region(1)
    assert mesh.regions() == [1, 2, 3]


def pinched_labels():
    """Label 1: two cubes touching along an edge and a third touching at a corner, so its
    surface pinches at an edge and at a vertex."""
    labels = np.zeros((10, 10, 10), dtype=np.uint8)
    labels[2:4, 2:4, 2:4] = 1
    labels[4:6, 4:6, 2:4] = 1  # shares the edge x = y = 4, z in [2, 4]
    labels[6:8, 6:8, 4:6] = 1  # shares the corner (6, 6, 4)
    return labels


def assert_watertight(region):
    """Closed, consistently oriented outward, 2-manifold: for trimesh and for pyvista."""
    tm = region.to_trimesh()
    assert tm.is_watertight and tm.is_winding_consistent
    assert tm.volume > 0
    poly = region.to_pyvista()
    assert poly.n_open_edges == 0
    edges = poly.extract_feature_edges(boundary_edges=False, feature_edges=False,
                                       manifold_edges=False, non_manifold_edges=True)
    assert edges.n_cells == 0


def test_manifold_regions_split_pinches():
    pytest.importorskip("trimesh")
    pytest.importorskip("pyvista")
    mesh = voxreg.regularize(pinched_labels(), preset="papers")
    kept = mesh.region(1, manifold=False)
    assert not kept.to_trimesh().is_watertight  # the pinched edge has four quads
    split = mesh.region(1)
    assert_watertight(split)
    assert len(split) == len(kept) and len(split.vertices) > len(kept.vertices)
    # The copies keep the whole mesh's positions bit for bit.
    assert bits(split.vertices) == bits(kept.vertices) <= bits(mesh.vertices)


@pytest.fixture(scope="module")
def tissue():
    from conftest import synth_tissue

    labels = synth_tissue()
    return labels, voxreg.regularize(labels, refine=1)


def test_synthetic_tissue_matches_the_xtask(tmp_path):
    import pathlib
    import subprocess

    from conftest import ROOT, synth_tissue

    xtask = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "release" / "xtask"
    if not xtask.is_file():
        pytest.skip("xtask is not built (cargo build --release -p xtask)")
    out = tmp_path / "t.npy"
    subprocess.run([str(xtask), "synth-labels", "--dims", "64,60,32", "--out", str(out)], check=True,
                   capture_output=True)
    assert np.array_equal(np.load(out), synth_tissue())


def test_tissue_regions_watertight(tissue):
    pytest.importorskip("trimesh")
    pytest.importorskip("pyvista")
    labels, mesh = tissue
    assert mesh.regions() == list(range(1, 25))
    for label in mesh.regions():
        region = mesh.region(label)
        assert_watertight(region)
        assert (region.labels[:, 0] == label).all()
        # One quad per voxel face between the label and another, counted on the voxels.
        padded = np.pad(labels, 1)
        faces = 0
        for axis in range(3):
            a = np.moveaxis(padded, axis, 0)
            lo, hi = a[:-1], a[1:]
            faces += int(((lo != hi) & ((lo == label) | (hi == label))).sum())
        assert len(region) == faces


@pytest.mark.parametrize("name", ["cat10.vol", "chr_army1.vox"])
def test_bundled_regions_watertight_and_cli(cli, data, tmp_path, name):
    pytest.importorskip("trimesh")
    pytest.importorskip("pyvista")
    labels, info = voxreg.read(data / name)
    mesh = voxreg.regularize(labels, **info)
    r = cli("regularize", data / name, "-o", tmp_path / "split", "--split", "regions", "--manifold", "-q")
    assert r.returncode == 0, r.stderr
    for label in mesh.regions():
        region = mesh.region(label)
        assert_watertight(region)
        region.save(tmp_path / f"py_{label}.ply")
        cli_file = tmp_path / "split" / f"region_{label}.ply"
        assert cli_file.read_bytes() == (tmp_path / f"py_{label}.ply").read_bytes()
