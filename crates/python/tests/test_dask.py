"""voxreg.dask: chunked regularization stitched by vertex id, against the whole volume."""

import os

import numpy as np
import pytest

import voxreg

dask = pytest.importorskip("dask")
da = pytest.importorskip("dask.array")
distributed = pytest.importorskip("distributed")
import voxreg.dask as vd  # noqa: E402


def tissue(n=64, seed=3):
    """Five labelled balls, some touching each other and the border, in background 0."""
    rng = np.random.default_rng(seed)
    x, y, z = np.meshgrid(*(np.arange(n),) * 3, indexing="ij")
    labels = np.zeros((n, n, n), np.uint32)
    for label in range(1, 6):
        c = rng.uniform(0, n, 3)
        r = rng.uniform(n / 8, n / 4)
        labels[(x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 < r * r] = label
    return labels


def whole(labels, **params):
    """The whole-volume solve, as one chunk owning everything."""
    dims = labels.shape
    return vd.regularize_chunk(labels, (0, 0, 0), [(0, n) for n in dims], dims, threads=0, **params)


def faces(ids, quads, labels):
    return sorted((tuple(int(v) for v in ids[q]), tuple(int(l) for l in lab)) for q, lab in zip(quads, labels))


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as c:
        yield c


@pytest.fixture(scope="module")
def volume():
    return tissue()


@pytest.fixture(scope="module")
def reference(volume):
    return whole(volume)


def test_stitched_chunks_are_the_whole_volume_mesh(client, volume, reference):
    mesh = vd.regularize(da.from_array(volume, chunks=32))
    ref_ids = reference["vertex_ids"]
    assert sorted(mesh.vertex_ids.tolist()) == sorted(ref_ids.tolist())
    assert faces(mesh.vertex_ids, mesh.quads, mesh.labels) == faces(ref_ids, reference["quads"], reference["labels"])
    order = np.argsort(ref_ids)
    deviation = np.linalg.norm(mesh.vertices - reference["positions"][order], axis=1)
    assert deviation.max() < 1e-2 and deviation.mean() < 1e-3, (deviation.mean(), deviation.max())


def test_every_label_is_watertight_after_stitching(client, volume):
    mesh = vd.regularize(volume, chunks=(32, 32, 32), halo=4)
    for label in range(1, 6):
        part = vd.region_mesh(mesh, label)
        q = part.quads
        edges = np.sort(np.stack([q, np.roll(q, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert len(q) and np.all(counts % 2 == 0), label


def test_a_zarr_store_to_ply_and_precomputed_files(client, volume, tmp_path):
    zarr = pytest.importorskip("zarr")
    store = str(tmp_path / "labels.zarr")
    z = zarr.open_array(store, mode="w", shape=volume.shape, chunks=(32, 32, 32), dtype="u4")
    z[:] = volume
    out = tmp_path / "meshes"
    assert vd.regularize(store, out=str(out), formats=("ply", "precomputed"), halo=4) == str(out)
    for label in range(1, 6):
        assert (out / f"label_{label}.ply").stat().st_size > 0
        manifest = (out / "precomputed" / f"{label}:0").read_text()
        names = __import__("json").loads(manifest)["fragments"]
        assert names
        v, t = vd.read_precomputed_fragment(out / "precomputed" / names[0])
        assert v.shape[1] == 3 and t.shape[1] == 3 and t.max() < len(v)
    assert (out / "precomputed" / "info").read_text() == '{"@type": "neuroglancer_legacy_mesh"}'
    assert len(os.listdir(out / "fragments")) == 8


def test_bad_chunking_is_refused(volume):
    with pytest.raises(voxreg.ParameterError, match="halo"):
        vd.regularize(volume, chunks=(32, 32, 32), halo=1)
    with pytest.raises(voxreg.ParameterError, match="chunks"):
        vd.regularize(volume, chunks=(32, 0, 32))
