"""Mesh.simplify and Mesh.levels: fewer faces, the partition kept (every region closed,
each interface shared by its two regions), errors on bad arguments."""

from collections import Counter

import numpy as np
import pytest

import voxreg
from conftest import synth_tissue, three_labels


@pytest.fixture(scope="module")
def tissue():
    return voxreg.regularize(synth_tissue((40, 36, 24)), refine=1)


@pytest.fixture(scope="module")
def small():
    return voxreg.regularize(three_labels())


def polygon(q):
    """A face's distinct vertices in order (a triangle repeats its last vertex)."""
    return [int(v) for i, v in enumerate(q) if v != q[i - 1]]


def directed_edges(quads, labels, label):
    """The directed edges of ``label``'s region: each face around it, turned out of it."""
    edges = Counter()
    for q, (inner, outer) in zip(quads, labels):
        if label not in (inner, outer):
            continue
        p = polygon(q)
        if outer == label:
            p = p[::-1]
        for i in range(len(p)):
            edges[(p[i], p[(i + 1) % len(p)])] += 1
    return edges


def assert_partition(mesh):
    """Every region closed and consistently oriented; the two sides of each interface are
    the same faces (one face per wall, its labels naming both regions)."""
    labels = sorted({int(x) for x in np.unique(mesh.labels)})
    for label in labels:
        if label == 0:
            continue
        edges = directed_edges(mesh.quads, mesh.labels, label)
        assert edges, label
        open_edges = [e for e, n in edges.items() if edges[(e[1], e[0])] != n]
        assert not open_edges, (label, open_edges[:5])
    # No wall is written twice (two faces on the same vertices would be a crack or an
    # overlap between two regions' copies).
    keys = Counter(tuple(sorted(polygon(q))) for q in mesh.quads)
    assert max(keys.values()) == 1


def euler(mesh, label):
    faces = [polygon(q) for q, l in zip(mesh.quads, mesh.labels) if label in l]
    verts = {v for p in faces for v in p}
    edges = {tuple(sorted((p[i], p[(i + 1) % len(p)]))) for p in faces for i in range(len(p))}
    return len(verts) - len(edges) + len(faces)


def test_simplify_keeps_the_partition_at_a_tenth(tissue):
    simple = tissue.simplify(ratio=0.1)
    assert isinstance(simple, voxreg.Mesh)
    assert len(simple) < 0.2 * len(tissue), (len(simple), len(tissue))
    assert_partition(tissue)
    assert_partition(simple)
    for label in (1, 2, 7, 13):
        assert euler(simple, label) == euler(tissue, label), label
    stats = simple.report["simplify"]
    assert stats["input_faces"] == len(tissue) and stats["faces"] == len(simple)
    assert 0 < stats["error_bound"] <= 0.5 + 1e-12
    assert 0 < stats["quads"] <= stats["faces"]
    # The same interfaces, now simplified once each.
    assert {tuple(sorted(p)) for p in map(tuple, simple.labels.tolist())} == \
        {tuple(sorted(p)) for p in map(tuple, tissue.labels.tolist())}
    # No intersection added (this small tissue's input has some, in its thinnest walls).
    assert voxreg.check(simple)["intersecting_pairs"] <= voxreg.check(tissue)["intersecting_pairs"]


def test_max_error_bounds_the_distance(small):
    loose = small.simplify(max_error=0.5)
    tight = small.simplify(max_error=0.05)
    assert len(loose) < len(tight) <= len(small)
    assert tight.report["simplify"]["error_bound"] <= 0.05 + 1e-12
    assert_partition(loose)
    assert_partition(tight)


def test_levels_are_nested_and_keep_the_partition(tissue):
    levels = tissue.levels(3)
    assert len(levels) == 3
    counts = [len(m) for m in levels]
    assert counts[0] == len(tissue) and counts[0] > counts[1] > counts[2], counts
    for k, level in enumerate(levels):
        assert_partition(level)
        assert level.report["simplify"]["error_bound"] <= 0.5 * 2 ** max(k - 1, 0) + 1e-12
    # Nested: snapshots of one collapse sequence, so each level has fewer vertices than the
    # one before and a bound no smaller (interior vertices are placed anew to keep the
    # volumes, so a level's vertices need not be the finer level's).
    for a, b in zip(levels, levels[1:]):
        assert len(b.vertices) < len(a.vertices)
        assert b.report["simplify"]["error_bound"] >= a.report.get("simplify", {"error_bound": 0.0})["error_bound"]


def test_a_mesh_from_arrays_and_a_part_simplify(small):
    arrays = voxreg.Mesh(small.vertices, small.quads, small.labels)
    simple = arrays.simplify(ratio=0.3)
    assert len(simple) < len(small)
    assert_partition(simple)
    region = small.region(1, manifold=False).simplify(ratio=0.5)
    assert (region.labels[:, 0] == 1).all() and len(region) < len(small.region(1, manifold=False))


@pytest.mark.parametrize("kwargs, message", [
    (dict(ratio=0), "ratio must be in"),
    (dict(ratio=1.5), "ratio must be in"),
    (dict(ratio=float("nan")), "ratio must be in"),
    (dict(ratio="half"), "ratio must be a number"),
    (dict(max_error=-1), "max_error must be a non-negative number"),
    (dict(max_error=float("inf")), "max_error must be a non-negative number"),
])
def test_bad_arguments_raise(small, kwargs, message):
    with pytest.raises(voxreg.ParameterError, match=message) as e:
        small.simplify(**kwargs)
    assert isinstance(e.value, voxreg.VoxregError)


@pytest.mark.parametrize("args, message", [
    ((0,), "n must be an integer from 1 to 12"),
    ((13,), "n must be an integer from 1 to 12"),
    ((2.5,), "n must be an integer from 1 to 12"),
    ((3, 1.0), "factor must be a number above 1"),
])
def test_bad_levels_raise(small, args, message):
    with pytest.raises(voxreg.VoxregError, match=message):
        small.levels(*args)


def test_a_broken_mesh_raises_input_error():
    mesh = voxreg.Mesh(np.zeros((4, 3)), [[0, 1, 1, 1]], [[1, 0]])
    with pytest.raises(voxreg.InputError, match="fewer than three distinct vertices"):
        mesh.simplify(ratio=0.5)


def test_ctrl_c_stops_a_simplification_which_releases_the_gil():
    import os
    import signal
    import threading
    import time

    big = voxreg.regularize(synth_tissue((96, 84, 44)), preset="fast")
    ticks = []
    done = threading.Event()

    def count():
        while not done.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.002)

    counter = threading.Thread(target=count)
    sigint = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    counter.start()
    start = time.monotonic()
    sigint.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            big.levels(4)
        stopped = time.monotonic() - start
    finally:
        done.set()
        counter.join()
        sigint.cancel()
    # The signal comes 0.5 s in; the levels take seconds (6 s uninterrupted on the shared
    # 2-core machine); a stopped run returns within the 50 ms signal poll and a collapse
    # or a pass over the triangles.
    assert stopped < 0.5 + 1.0, stopped
    # Another Python thread ran meanwhile: the GIL was released.
    during = [t for t in ticks if start + 0.05 < t < start + 0.45]
    assert len(during) > 20, len(during)


def test_progress_reports_the_stages_in_order_and_ends_done(tissue):
    calls = []
    levels = tissue.levels(3, progress=lambda stage, fraction: calls.append((stage, fraction)))
    assert [len(m) for m in levels] == [len(m) for m in tissue.levels(3)]
    stages = [s for s, _ in calls]
    assert stages[0] == "setup" and calls[-1] == ("done", 1.0), calls
    assert "level 2/3: collapses" in stages and "level 3/3: pairing" in stages, stages
    fractions = [f for _, f in calls]
    assert all(0.0 <= f <= 1.0 for f in fractions)
    assert fractions == sorted(fractions), calls

    one = []
    tissue.simplify(ratio=0.2, progress=lambda s, f: one.append(s))
    assert one[0] == "setup" and "collapses" in one and "pairing" in one and one[-1] == "done", one


def test_an_exception_in_progress_stops_the_simplification(tissue):
    class Stop(Exception):
        pass

    def stop(stage, fraction):
        if stage.endswith("collapses"):
            raise Stop(stage)

    with pytest.raises(Stop, match="collapses"):
        tissue.levels(3, progress=stop)
    with pytest.raises(voxreg.ParameterError, match="progress must be callable"):
        tissue.simplify(ratio=0.5, progress=3)
