"""Interfaces and regions as meshes of their own: closed, outward, meeting exactly."""

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
