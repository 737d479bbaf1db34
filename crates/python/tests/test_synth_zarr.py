"""bench/scale/synth_zarr.py: the tissue volume of `cargo xtask synth-labels`, chunk by chunk."""

import hashlib
import os
import sys

import numpy as np
import pytest

import voxreg

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "..", "bench", "scale"))
synth = pytest.importorskip("synth_zarr")

DIMS = (64, 60, 40)
#: sha256 of the voxels (C order, uint8) of `cargo xtask synth-labels --dims 64,60,40`.
XTASK_SHA256 = "f6289f72f70150a7ccf9aa9b5f00c17ae8bcf02aa5461627099e283e95c6ae49"


def surfels(labels):
    """Faces between different labels, the outside counting as background 0."""
    padded = np.pad(labels.astype(np.int16), 1)
    return sum(int(np.count_nonzero(np.diff(padded, axis=k))) for k in range(3))


def test_the_labels_are_those_of_the_rust_generator():
    labels = synth.labels_block(DIMS, (0, 0, 0), DIMS)
    assert labels.dtype == np.uint8 and labels.shape == DIMS
    assert hashlib.sha256(labels.tobytes()).hexdigest() == XTASK_SHA256
    assert set(np.unique(labels)) == set(range(25))


def test_the_store_written_chunk_by_chunk_is_the_volume_and_counts_its_surfels(tmp_path):
    zarr = pytest.importorskip("zarr")
    whole = synth.labels_block(DIMS, (0, 0, 0), DIMS)
    info = synth.write(str(tmp_path / "t.zarr"), DIMS, (16, 16, 16))
    stored = zarr.open_array(str(tmp_path / "t.zarr"), mode="r")[:]
    assert np.array_equal(stored, whole)
    assert info["surfels"] == surfels(whole)
    assert info["voxels_per_label"] == {int(l): int(n) for l, n in zip(*np.unique(whole, return_counts=True))}
    # The digital surface has one quad per surfel.
    assert len(voxreg.regularize(whole, background=0, refine=0).quads) == info["surfels"]
