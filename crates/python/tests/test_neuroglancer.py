"""Neuroglancer multi-resolution meshes (voxreg.neuroglancer, voxreg.dask's "multilod"):
read back by cloud-volume and by an independent reader of the format (meshes.md), every
fragment decoded by Google's Draco decoder (DracoPy); every level closed per label, no
triangle across a child cube, and the same vertices on the cubes' planes at every level
(no crack where two levels meet)."""

import json
import struct

import numpy as np
import pytest

import voxreg
from conftest import synth_tissue

DracoPy = pytest.importorskip("DracoPy")
from voxreg.neuroglancer import write_multilod  # noqa: E402

LODS, CHUNK, BITS = 3, 8, 16
DIMS = (40, 36, 24)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    labels = synth_tissue(DIMS)
    mesh = voxreg.regularize(labels, refine=0)
    out = tmp_path_factory.mktemp("multilod")
    summary = write_multilod(mesh, out, lods=LODS, chunk=CHUNK, dims=DIMS)
    return out, summary, sorted(int(x) for x in np.unique(labels) if x != 0)


def read_manifest(data):
    """The manifest, as meshes.md specifies it."""
    chunk = np.frombuffer(data, "<f4", 3, 0)
    origin = np.frombuffer(data, "<f4", 3, 12)
    (lods,) = struct.unpack_from("<I", data, 24)
    at = 28
    scales = np.frombuffer(data, "<f4", lods, at)
    at += 4 * lods
    offsets = np.frombuffer(data, "<f4", 3 * lods, at).reshape(lods, 3)
    at += 12 * lods
    counts = np.frombuffer(data, "<u4", lods, at)
    at += 4 * lods
    positions, sizes = [], []
    for n in counts:
        positions.append(np.frombuffer(data, "<u4", 3 * n, at).reshape(3, n).T.astype(np.int64))
        at += 12 * int(n)
        sizes.append(np.frombuffer(data, "<u4", n, at).astype(np.int64))
        at += 4 * int(n)
    assert at == len(data)
    return chunk, origin, scales, offsets, positions, sizes


def fragments(out, label):
    """Per level, per fragment: (node position, decoded integer positions, triangles)."""
    chunk, origin, _, offsets, positions, sizes = read_manifest((out / "mesh" / f"{label}.index").read_bytes())
    assert (chunk == CHUNK).all() and (origin == 0).all() and (offsets == 0).all()
    data = (out / "mesh" / str(label)).read_bytes()
    assert len(data) == sum(int(s.sum()) for s in sizes)
    at, levels = 0, []
    for pos, size in zip(positions, sizes):
        level = []
        for p, n in zip(pos, size):
            if n:
                m = DracoPy.decode(data[at:at + n])
                level.append((p, np.asarray(m.points, np.float64), np.asarray(m.faces, np.int64).reshape(-1, 3)))
            at += int(n)
        levels.append(level)
    return levels


def z_order_sorted(pos):
    def key(p):
        k = 0
        for bit in range(21):
            for axis in range(3):
                k |= ((int(p[axis]) >> bit) & 1) << (3 * bit + axis)
        return k
    keys = [key(p) for p in pos]
    return keys == sorted(keys)


def test_info_files(written):
    out, _, _ = written
    info = json.loads((out / "mesh" / "info").read_text())
    assert info["@type"] == "neuroglancer_multilod_draco"
    assert info["vertex_quantization_bits"] == BITS and len(info["transform"]) == 12
    volume = json.loads((out / "info").read_text())
    assert volume["mesh"] == "mesh" and volume["type"] == "segmentation"


def stored(p, q, k):
    """Stored model coordinates (voxels) of decoded positions ``q`` of node ``p``, level ``k``."""
    return CHUNK * 2.0 ** k * (p + q / (2.0 ** BITS - 1))


def test_fragments_decode_nest_and_close(written):
    out, summary, labels = written
    faces = summary["levels"]
    assert faces[0] > faces[1] > faces[2], faces
    top = 2 ** BITS - 1
    for label in labels:
        chunk, _, _, _, positions, _ = read_manifest((out / "mesh" / f"{label}.index").read_bytes())
        for k, pos in enumerate(positions):
            assert z_order_sorted(pos), (label, k)
            if k > 0:
                # Every node's children are listed under it (an octree).
                parents = {tuple(p) for p in pos.tolist()}
                assert {tuple(p >> 1) for p in positions[k - 1]} <= parents
        for k, level in enumerate(fragments(out, label)):
            assert level, (label, k)
            edges = {}
            for p, q, t in level:
                assert (q == np.round(q)).all() and q.min() >= 0 and q.max() <= top
                if k > 0:
                    # Neuroglancer's partition of a fragment into its 8 children: each
                    # triangle wholly on one side of each mid-plane.
                    half = 2 ** (BITS - 1)
                    side = np.where(q[t] < half, -1, np.where(q[t] > half, 1, 0))
                    assert not ((side.min(axis=1) < 0) & (side.max(axis=1) > 0)).any(), (label, k)
                v = stored(p, q, k)
                for tri in t:
                    key = [tuple(v[i]) for i in tri]
                    for i in range(3):
                        e = (key[i], key[(i + 1) % 3])
                        edges[e] = edges.get(e, 0) + 1
            unmatched = [e for e, n in edges.items() if edges.get((e[1], e[0]), 0) != n and e[0] != e[1]]
            assert not unmatched, (label, k, len(unmatched))


def plane_groups(v, size):
    """The points of ``v`` on each plane ``axis = j size``, by (axis, value)."""
    groups = {}
    for a in range(3):
        on = np.mod(v[:, a], size) == 0
        for value in np.unique(v[on, a]):
            groups[(a, float(value))] = v[on & (v[:, a] == value)]
    return groups


def test_no_crack_between_levels(written):
    """The vertices on the planes of level m's cubes are the same at every level up to m
    (within the coarser level's quantum): where cubes of two levels meet, their meshes
    meet along the same curve."""
    out, _, labels = written
    compared = 0
    for label in labels:
        levels = fragments(out, label)
        points = [np.concatenate([stored(p, q, k) for p, q, _ in level]) for k, level in enumerate(levels)]
        for m in range(1, LODS):
            size = CHUNK * 2 ** m
            ref = plane_groups(points[0], size)
            for k in range(1, m + 1):
                quantum = CHUNK * 2 ** k / (2 ** BITS - 1)
                groups = plane_groups(points[k], size)
                assert groups.keys() == ref.keys(), (label, m, k)
                for key, a in ref.items():
                    b = groups[key]
                    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
                    assert d.min(axis=1).max() <= quantum and d.min(axis=0).max() <= quantum, (label, m, k, key)
                    compared += len(a)
    assert compared > 100


def test_walls_are_shared_between_labels(written):
    """At every level two touching labels carry the same triangles on their wall, in
    opposite orientations (the partition kept)."""
    out, _, labels = written
    for k in range(LODS):
        seen = {}
        for label in labels:
            for p, q, t in fragments(out, label)[k]:
                v = stored(p, q, k)
                for tri in t:
                    key = tuple(sorted(tuple(v[i]) for i in tri))
                    seen.setdefault(key, []).append(label)
        twice = sum(1 for ls in seen.values() if len(ls) == 2)
        assert twice > 0 and all(len(ls) <= 2 for ls in seen.values()), k


def test_cloud_volume_reads_every_level(written):
    cloudvolume = pytest.importorskip("cloudvolume")
    out, summary, labels = written
    cv = cloudvolume.CloudVolume(f"file://{out}", progress=False)
    for k in range(LODS):
        meshes = cv.mesh.get(labels[:3], lod=k)
        for label in labels[:3]:
            m = meshes[label]
            assert len(m.faces) == sum(len(t) for _, _, t in fragments(out, label)[k]) > 0
            assert m.vertices.min() >= -1e-3 and (m.vertices.max(axis=0) <= np.array(DIMS) + 1e-3).all()


def test_dask_writes_multilod(tmp_path):
    pytest.importorskip("dask")
    import voxreg.dask as vd

    labels = synth_tissue((32, 28, 20))
    out = vd.regularize(labels, chunks=16, halo=4, out=tmp_path, formats=("multilod",), lods=2,
                        refine=0, scheduler="synchronous")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["multilod"]["levels"][1] < summary["multilod"]["levels"][0]
    assert (tmp_path / "multilod" / "mesh" / "info").exists()
    assert str(out) == str(tmp_path)


def test_bad_arguments(tmp_path):
    mesh = voxreg.Mesh(np.zeros((3, 3)), np.zeros((0, 4), np.int64), np.zeros((0, 2), np.uint32))
    for kwargs, message in ((dict(lods=0), "lods must be"), (dict(chunk=1), "chunk must be"),
                            (dict(quantization_bits=12), "quantization_bits must be"),
                            (dict(max_error=0), "max_error must be")):
        with pytest.raises(voxreg.ParameterError, match=message):
            write_multilod(mesh, tmp_path, **kwargs)
