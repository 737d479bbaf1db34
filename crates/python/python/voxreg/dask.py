"""Regularize volumes larger than one machine, chunk by chunk, with Dask.

Each chunk is regularized with a halo of voxels around it and returns only what it owns:
the quads whose voxel face lies in the chunk (half-open ranges; the volume's far border
belongs to the last chunk) and the vertices whose first quad it owns. Every vertex of a
digital surface is a lattice corner, so the chunks' meshes glue into the whole-volume mesh
by vertex id, exactly: the same quads, the same vertices, no gap and no duplicate. Inside
a chunk, positions match the whole-volume solve to within a tolerance that shrinks with
the halo (see ``docs/scale.md``).

A task reads only its chunk and halo: from a Zarr path or array it opens or reads the
store itself (only the store's chunks meeting its range), from a dask array it depends on
that slice alone. With ``out=`` the merge streams the fragments from disk, so neither the
client nor any worker holds the whole mesh.

Example (a laptop; on a cluster, create a ``dask.distributed.Client`` for it first)::

    import voxreg.dask
    mesh = voxreg.dask.regularize("labels.zarr", chunks=(128, 128, 128))
    voxreg.dask.regularize("labels.zarr", out="meshes/", formats=("ply", "precomputed"))
"""

from __future__ import annotations

import itertools
import json
import operator
import os
import struct
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _voxreg
from ._errors import ParameterError, label_argument
from ._mesh import Mesh

#: The halo's default width in voxels for the default pipeline: the narrowest of those
#: measured whose stitched mesh stays within 1e-2 voxel (mean 1e-3) of the whole-volume
#: solve on a 256^3 synthetic tissue (the table of ``docs/scale.md``). The cut sides of a
#: chunk's sub-volume close its surfaces, and the difference reaches far through the
#: refinement rounds and the size preservation. Each preset has its own
#: (:func:`preset_halo`): 32 for ``fast``, whose sweeps reach a bounded distance.
DEFAULT_HALO = 64


def preset_halo(preset: str = "default") -> int:
    """The halo ``regularize`` reads around each chunk by default under ``preset``: 64
    voxels for the default pipeline, 32 for ``fast`` (within 1e-4 voxel of the
    whole-volume solve there; ``docs/scale.md``)."""
    return int(_voxreg.preset_halo(preset))

#: The keyword arguments of a chunk: the preset and the library's options (those of
#: ``voxreg.regularize``).
_PARAMS = ("preset",) + tuple(_voxreg.option_names())


def _open(array: Any) -> Any:
    """A Zarr path opened read-only (zarr-python 3); anything else as given."""
    if isinstance(array, (str, os.PathLike)):
        import zarr

        return zarr.open_array(os.fspath(array), mode="r")
    return array


def _grid(dims: Sequence[int], chunks: Sequence[int]) -> List[List[Tuple[int, int]]]:
    return [[(lo, min(lo + c, n)) for lo in range(0, n, c)] for n, c in zip(dims, chunks)]


def _chunks_of(array: Any, chunks: Union[None, int, Sequence[int]]) -> Tuple[int, int, int]:
    if chunks is None:
        size = getattr(array, "chunksize", None) or getattr(array, "chunks", None)
        if isinstance(size, tuple) and len(size) == 3 and all(isinstance(c, int) for c in size):
            chunks = size
        else:
            chunks = (64, 64, 64)
    # One integer, as dask takes it: the same on every axis.
    if isinstance(chunks, (int, np.integer)) and not isinstance(chunks, bool):
        chunks = (chunks,) * 3
    try:
        parsed = tuple(operator.index(c) for c in chunks)
    except TypeError:
        parsed = ()
    if len(parsed) != 3 or any(c < 1 for c in parsed):
        raise ParameterError(f"chunks must be a positive integer or three, got {chunks!r}")
    return parsed  # type: ignore[return-value]


def regularize_chunk(labels: Any, start: Sequence[int], owned: Sequence[Sequence[int]],
                     global_dims: Sequence[int], spacing: Sequence[float] = (1.0, 1.0, 1.0),
                     origin: Sequence[float] = (0.0, 0.0, 0.0), background: Optional[int] = 0,
                     threads: int = 1, **params: Any) -> Dict[str, Any]:
    """Regularizes one chunk: ``labels`` are the whole volume's voxels from global index
    ``start`` on (the chunk and its halo), ``owned`` the chunk's half-open global ranges.
    Returns the owned quads and their vertices as numpy arrays: ``vertex_ids`` (global
    lattice ids, ``x + (X + 1) (y + (Y + 1) z)`` for corner ``(x, y, z)``), ``positions``,
    ``owns_vertex``, ``quads`` (indices into the vertex arrays), ``labels``."""
    unknown = set(params) - set(_PARAMS)
    if unknown:
        raise ParameterError(f"unknown parameters: {', '.join(sorted(unknown))}")
    preset = params.pop("preset", None) or "default"
    sp = np.asarray(spacing, dtype=np.float64)
    chunk_origin = np.asarray(origin, dtype=np.float64) + np.asarray(start) * sp
    labels = np.asarray(labels)
    return _voxreg.regularize_block(
        labels, tuple(sp), tuple(chunk_origin), label_argument("background", background),
        tuple(int(s) for s in start),
        tuple(tuple(int(x) for x in o) for o in owned), tuple(int(n) for n in global_dims),
        preset, params, threads,
    )


def _peak_rss() -> Optional[int]:
    """This process's peak resident set (VmHWM), in bytes, or None where unknown."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        import resource

        return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
    except (ImportError, OSError):  # pragma: no cover - not Linux
        return None


def _reset_peak_rss() -> bool:
    """Resets VmHWM to the current resident set (Linux), so that the next reading is the
    peak since now; False where the system refuses."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _read(source: Any, start: Sequence[int], end: Sequence[int]) -> np.ndarray:
    """The voxels ``start .. end`` of a Zarr path or array-like, read here."""
    return np.asarray(_open(source)[start[0]:end[0], start[1]:end[1], start[2]:end[2]])


def _task(source: Any, sliced: bool, index: Tuple[int, int, int], start: Sequence[int],
          end: Sequence[int], owned: Sequence[Sequence[int]], global_dims: Sequence[int],
          out: Optional[str], kwargs: Dict[str, Any]) -> Any:
    """One chunk: read its voxels (``sliced``: ``source`` is already the chunk and halo;
    else a Zarr path or array, opened and sliced here, in the worker), regularize, and
    return the fragment, or write it under ``out`` and return its path and the task's
    figures (``stats``: times, voxels read, quads, this process's peak memory)."""
    import time

    reset = _reset_peak_rss()
    wall, cpu = time.perf_counter(), time.process_time()
    labels = np.asarray(source) if sliced else _read(source, start, end)
    read_s = time.perf_counter() - wall
    d = regularize_chunk(labels, start, owned, global_dims, **kwargs)
    fragment = {k: d[k] for k in ("vertex_ids", "positions", "owns_vertex", "quads", "labels")}
    fragment["index"] = np.asarray(index)
    fragment["owned"] = np.asarray(owned, dtype=np.int64)
    fragment["dims"] = np.asarray(global_dims, dtype=np.int64)
    stats = {
        "index": [int(i) for i in index], "voxels_read": int(labels.size),
        "quads": int(len(fragment["quads"])), "read_s": read_s,
        "wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
        "peak_rss_bytes": _peak_rss(), "peak_since_task_start": reset, "pid": os.getpid(),
    }
    del labels, d
    if out is None:
        fragment["stats"] = stats
        return fragment
    path = os.path.join(out, "fragments", "chunk_{}_{}_{}.npz".format(*index))
    tmp = path + ".tmp.npz"
    np.savez(tmp, stats=np.asarray(json.dumps(stats)), **fragment)
    os.replace(tmp, path)
    stats["peak_rss_bytes"] = _peak_rss()
    return {"path": path, "stats": stats}


def regularize(array: Any, chunks: Union[None, int, Sequence[int]] = None, halo: Optional[int] = None,
               out: "Optional[str | os.PathLike[str]]" = None,
               formats: Iterable[str] = ("ply",), scheduler: Any = None,
               spacing: Sequence[float] = (1.0, 1.0, 1.0), origin: Sequence[float] = (0.0, 0.0, 0.0),
               background: Optional[int] = 0, threads: int = 1, lods: int = 3,
               **params: Any) -> Union[Mesh, str]:
    """Regularizes a label volume chunk by chunk through Dask, and stitches the chunks.

    Parameters
    ----------
    array : dask array, Zarr array, numpy array, or str (a Zarr array's path)
        The labels, indexed ``[x, y, z]``, any integer dtype.
    chunks : int or three ints, default None
        The chunk each task owns, in voxels (one int: the same on every axis, as dask
        takes it): by default the array's own chunks (dask or Zarr), else 64.
    halo : int >= 2, default None (the preset's: 64 voxels, 32 for ``preset="fast"``)
        Voxels read around each chunk. The stitched mesh has the whole-volume mesh's
        quads and vertex ids at any halo; its positions approach the whole-volume solve
        as the halo grows (default pipeline at 64: within 1e-2 voxel on a synthetic
        tissue; on a real volume of thin sloping layers, a few hundred vertices in a
        million up to 6e-2; ``fast`` at 32: within 1e-4 on both). A chunk reads
        ``(c + 2 halo)^3`` voxels for the ``c^3`` it owns: at halo 64, chunks of 128 to
        256 keep that within 8 to 3.4 times; a narrower halo is faster and less exact
        (docs/scale.md).
    out : str or path-like, default None
        A directory: fragments are written to ``out/fragments/`` by the tasks, then
        stitched (``merge``, one fragment in memory at a time) into ``out/label_<L>.ply``
        (each label's closed, outward surface) and/or Neuroglancer's precomputed legacy
        meshes in ``out/precomputed/`` (``formats``), and ``out/summary.json``: per label
        its quads, vertices and whether it is closed; per task its chunk, voxels read,
        quads, times and its worker's peak memory; the merge's time and peak memory.
        None: the stitched mesh is returned (it must fit in memory).
    formats : iterable of {"ply", "glb", "precomputed", "multilod"}, default ("ply",)
        What ``out`` receives (``glb`` holds one label's surface in memory at a time).
        ``multilod``: Neuroglancer's multi-resolution meshes in ``out/multilod/``
        (``voxreg.neuroglancer.write_multilod``: ``lods`` levels, the finest octree cube
        the smallest chunk side), every level simplified with the partition kept and no
        crack between levels; the stitched mesh is held in memory for it.
    scheduler : default None
        Passed to ``dask.compute`` (None: the current one, e.g. a distributed Client's).
    spacing, origin, background : as in ``voxreg.regularize``
    threads : int, default 1
        Threads per task (dask runs several tasks at once).
    lods : int, default 3
        Levels of detail of the ``multilod`` format.
    **params
        Any parameter of ``voxreg.regularize`` (preset, normals, alpha, refine, ...).

    Returns
    -------
    Mesh, when ``out`` is None: vertices, quads and labels of the whole volume, the
    vertices in increasing lattice id. Else the ``out`` path.
    """
    import dask

    source = _open(array)
    dims = tuple(int(n) for n in np.shape(source))
    if len(dims) != 3:
        raise ParameterError(f"the labels must be three-dimensional, got shape {dims}")
    chunks = _chunks_of(source, chunks)
    if halo is None:
        halo = preset_halo(params.get("preset") or "default")
    if int(halo) < 2:
        raise ParameterError(f"halo must be at least 2 voxels, got {halo}")
    formats = tuple(formats)
    bad = set(formats) - {"ply", "glb", "precomputed", "multilod"}
    if bad:
        raise ParameterError(f"unknown formats: {', '.join(sorted(bad))}")
    out_dir = None if out is None else os.fspath(out)
    if out_dir is not None:
        os.makedirs(os.path.join(out_dir, "fragments"), exist_ok=True)
    background = label_argument("background", background)
    kwargs = dict(params, spacing=spacing, origin=origin, background=background, threads=threads)
    # A Zarr path travels as the path (each worker opens it), a Zarr array as itself
    # (each worker reads its slice); a dask array as its slices; numpy as its slices.
    is_dask = hasattr(source, "dask")
    by_path = isinstance(array, (str, os.PathLike))
    in_task = by_path or (not is_dask and _is_zarr(source))
    tasks = []
    grid = _grid(dims, chunks)
    for index in itertools.product(*(range(len(g)) for g in grid)):
        owned = [grid[k][index[k]] for k in range(3)]
        start = [max(lo - halo, 0) for lo, _ in owned]
        end = [min(hi + halo, n) for (_, hi), n in zip(owned, dims)]
        if by_path:
            src: Any = os.fspath(array)
        elif in_task:
            src = source
        elif is_dask:
            src = source[start[0]:end[0], start[1]:end[1], start[2]:end[2]]
        else:
            src = np.asarray(source[start[0]:end[0], start[1]:end[1], start[2]:end[2]])
        tasks.append(dask.delayed(_task, pure=True)(src, not in_task, index, start, end, owned, dims,
                                                     out_dir, kwargs))
    results = dask.compute(*tasks, scheduler=scheduler)
    if out_dir is None:
        mesh, _ = stitch(results)
        return mesh
    client_peak = _peak_rss()
    summary = merge(out_dir, [r["path"] for r in results], formats, background)
    summary["client"] = {"peak_rss_bytes_before_merge": client_peak}
    summary["tasks"] = [r["stats"] for r in results]
    if "multilod" in formats:
        from .neuroglancer import write_multilod

        loaded = []
        for r in results:
            with np.load(r["path"]) as f:
                loaded.append({k: f[k] for k in ("vertex_ids", "positions", "owns_vertex", "quads", "labels")})
        mesh, _ = stitch(loaded)
        del loaded
        summary["multilod"] = write_multilod(mesh, os.path.join(out_dir, "multilod"), lods=lods,
                                             chunk=max(2, min(chunks)), spacing=spacing, origin=origin,
                                             background=background, dims=dims)
    _write_json(os.path.join(out_dir, "summary.json"), summary)
    return out_dir


def _is_zarr(array: Any) -> bool:
    return type(array).__module__.split(".")[0] == "zarr"


def _write_json(path: str, value: Any) -> None:
    tmp = path + f".tmp-{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump(value, f, indent=1)
    os.replace(tmp, path)


def stitch(fragments: Sequence[Dict[str, Any]]) -> Tuple[Mesh, np.ndarray]:
    """Glues chunk fragments into one mesh by vertex id: each vertex takes the position of
    the one fragment that owns it. Returns the mesh (vertices in increasing lattice id)
    and, per quad, the index of the fragment it came from."""
    ids = [f["vertex_ids"][f["owns_vertex"].astype(bool)] for f in fragments]
    pos = [f["positions"][f["owns_vertex"].astype(bool)] for f in fragments]
    all_ids = np.concatenate(ids) if ids else np.zeros(0, np.uint64)
    order = np.argsort(all_ids, kind="stable")
    all_ids = all_ids[order]
    if len(all_ids) and np.any(all_ids[1:] == all_ids[:-1]):
        raise ValueError("a vertex is owned by two chunks")
    vertices = (np.concatenate(pos) if pos else np.zeros((0, 3)))[order]
    quads, labels, chunk = [], [], []
    for i, f in enumerate(fragments):
        global_ids = f["vertex_ids"][f["quads"].astype(np.int64)]
        index = np.searchsorted(all_ids, global_ids)
        if np.any(index >= len(all_ids)) or np.any(all_ids[np.minimum(index, len(all_ids) - 1)] != global_ids):
            raise ValueError("a quad uses a vertex no chunk owns")
        quads.append(index)
        labels.append(f["labels"])
        chunk.append(np.full(len(index), i, dtype=np.int64))
    mesh = Mesh(vertices, np.concatenate(quads) if quads else np.zeros((0, 4), np.int64),
                np.concatenate(labels) if labels else np.zeros((0, 2), np.uint32))
    mesh.vertex_ids = all_ids
    return mesh, (np.concatenate(chunk) if chunk else np.zeros(0, np.int64))


def region_mesh(mesh: Mesh, label: int) -> Mesh:
    """The closed surface of ``label`` in a stitched mesh: its quads, each oriented out of
    the label, over the vertices they use."""
    inner = mesh.labels[:, 0] == label
    outer = mesh.labels[:, 1] == label
    keep = inner | outer
    quads = mesh.quads[keep].copy()
    flip = outer[keep]
    quads[flip] = quads[flip][:, ::-1]
    used, local = np.unique(quads, return_inverse=True)
    labels = mesh.labels[keep].copy()
    labels[flip] = labels[flip][:, ::-1]
    return Mesh(mesh.vertices[used], local.reshape(-1, 4), labels)


def read_precomputed_fragment(path: "str | os.PathLike[str]") -> Tuple[np.ndarray, np.ndarray]:
    """Reads one legacy fragment: (vertices (n, 3) float32, triangles (m, 3) uint32)."""
    data = open(path, "rb").read()
    (n,) = struct.unpack_from("<I", data, 0)
    vertices = np.frombuffer(data, "<f4", 3 * n, 4).reshape(n, 3)
    triangles = np.frombuffer(data, "<u4", offset=4 + 12 * n).reshape(-1, 3)
    return vertices, triangles


#: One PLY face record of voxreg's writer: 4, the quad's vertices, its [inner, outer] labels.
_PLY_FACE = np.dtype([("n", "u1"), ("v", "<i4", (4,)), ("l", "<i4", (2,))])

#: Labels whose files a merge sweep keeps open at once.
_LABELS_PER_SWEEP = 128


def _corners(ids: np.ndarray, dims: Sequence[int]) -> np.ndarray:
    """The lattice corners ``(x, y, z)`` of global vertex ids."""
    ids = ids.astype(np.int64)
    x1, y1 = int(dims[0]) + 1, int(dims[1]) + 1
    return np.stack([ids % x1, (ids // x1) % y1, ids // (x1 * y1)], axis=1)


def _inner(ids: np.ndarray, owned: np.ndarray, dims: Sequence[int]) -> np.ndarray:
    """Whether each vertex is inner to the chunk owning ``owned``: every voxel face
    touching its corner is the chunk's (strictly inside the owned range, or on the
    volume's border), so no other chunk's quad uses it."""
    c = _corners(ids, dims)
    inner = np.ones(len(ids), bool)
    for k in range(3):
        lo, hi = int(owned[k][0]), int(owned[k][1])
        inner &= ((c[:, k] > lo) | (lo == 0)) & ((c[:, k] < hi) | (hi == int(dims[k])))
    return inner


def _label_groups(labels: np.ndarray, background: Optional[int]):
    """Per label, its quads (in quad order) and whether each is flipped (the label is
    its outer side): ``(label, quad indices, flipped)``."""
    m = len(labels)
    side = np.concatenate([labels[:, 0], labels[:, 1]]).astype(np.int64)
    quad = np.concatenate([np.arange(m), np.arange(m)])
    flip = np.concatenate([np.zeros(m, bool), np.ones(m, bool)])
    if background is not None:
        keep = side != int(background)
        side, quad, flip = side[keep], quad[keep], flip[keep]
    order = np.lexsort((quad, side))
    side, quad, flip = side[order], quad[order], flip[order]
    values, first = np.unique(side, return_index=True)
    bounds = list(first) + [len(side)]
    for i, label in enumerate(values):
        yield int(label), quad[bounds[i]:bounds[i + 1]], flip[bounds[i]:bounds[i + 1]]


def _oriented(quads: np.ndarray, labels: np.ndarray, flip: np.ndarray):
    """The quads and labels of one label's surface, turned out of the label."""
    q = quads.astype(np.int64)
    lab = labels.astype(np.int64)
    q[flip] = q[flip][:, ::-1]
    lab[flip] = lab[flip][:, ::-1]
    return q, lab


def _balanced(edges_from: np.ndarray, edges_to: np.ndarray, n: int) -> bool:
    """Whether every directed edge ``a -> b`` is matched by as many ``b -> a``: a closed,
    consistently oriented surface (pinched edges included)."""
    forward = np.sort(edges_from * n + edges_to)
    backward = np.sort(edges_to * n + edges_from)
    return bool(np.array_equal(forward, backward))


def _edges(q: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    return q.ravel(), np.roll(q, -1, axis=1).ravel()


def merge(out: "str | os.PathLike[str]", fragments: Sequence[str], formats: Iterable[str] = ("ply",),
          background: Optional[int] = 0) -> Dict[str, Any]:
    """Stitches fragment files (``regularize``'s ``out/fragments/*.npz``, in task order)
    into per-label files under ``out``, streaming: one fragment in memory at a time.

    A vertex inner to its chunk (all the voxel faces at its corner are the chunk's) is used
    by that chunk's quads only, and owned by it; only the vertices on the chunks' borders,
    a two-dimensional set, are kept across fragments (their owners' positions). Each
    label's PLY lists those border vertices first, then each fragment's inner ones, then
    the faces, written at their offsets as the fragments go by; the closure check (every
    directed edge matched by its reverse) is done per fragment for the inner edges and at
    the end for the edges touching the borders. Two passes over the fragments: counts and
    borders, then the files. ``glb`` holds one label's mesh in memory at a time.

    Returns per label its quad and vertex counts and whether its surface is closed, and
    the merge's time and peak memory."""
    import time

    wall, cpu = time.perf_counter(), time.process_time()
    reset = _reset_peak_rss()
    out = os.fspath(out)
    formats = tuple(formats)
    # Pass 1: the owned border vertices, and per label and fragment its counts and the
    # border vertices it uses.
    border_ids, border_pos = [], []
    counts: Dict[int, List[Tuple[int, int, int]]] = {}  # label -> [(fragment, quads, inner vertices)]
    border_used: Dict[int, List[np.ndarray]] = {}
    for i, path in enumerate(fragments):
        with np.load(path) as f:
            ids, owns, quads, labels = f["vertex_ids"], f["owns_vertex"].astype(bool), f["quads"], f["labels"]
            owned, dims = f["owned"], f["dims"]
            if len(ids) == 0:
                continue
            inner = _inner(ids, owned, dims)
            if np.any(inner & ~owns):
                raise ValueError(f"{path}: a vertex inside the chunk is owned by another chunk")
            keep = owns & ~inner
            border_ids.append(ids[keep])
            border_pos.append(f["positions"][keep])
            for label, qi, _ in _label_groups(labels, background):
                used = np.unique(quads[qi])
                n_inner = int(np.count_nonzero(inner[used]))
                counts.setdefault(label, []).append((i, len(qi), n_inner))
                border_used.setdefault(label, []).append(ids[used[~inner[used]]])
    b_ids = np.concatenate(border_ids) if border_ids else np.zeros(0, np.uint64)
    order = np.argsort(b_ids, kind="stable")
    b_ids = b_ids[order]
    b_pos = (np.concatenate(border_pos) if border_pos else np.zeros((0, 3)))[order]
    del border_ids, border_pos
    if len(b_ids) and np.any(b_ids[1:] == b_ids[:-1]):
        raise ValueError("a vertex is owned by two chunks")

    def border_index(table: np.ndarray, wanted: np.ndarray) -> np.ndarray:
        at = np.searchsorted(table, wanted)
        if np.any(at >= len(table)) or np.any(table[np.minimum(at, len(table) - 1)] != wanted):
            raise ValueError("a quad uses a vertex no chunk owns")
        return at

    labels_out = sorted(counts)
    summary: Dict[str, Any] = {"labels": {}}
    write_ply = "ply" in formats or "glb" in formats
    precomputed = os.path.join(out, "precomputed")
    if "precomputed" in formats:
        os.makedirs(precomputed, exist_ok=True)
        _write_json_compact(os.path.join(precomputed, "info"), {"@type": "neuroglancer_legacy_mesh"})
    for sweep in range(0, len(labels_out), _LABELS_PER_SWEEP):
        batch = labels_out[sweep:sweep + _LABELS_PER_SWEEP]
        state = {}
        try:
            for label in batch:
                b_used = np.unique(np.concatenate(border_used.pop(label)))
                at = border_index(b_ids, b_used)
                n_vertices = len(b_used) + sum(c[2] for c in counts[label])
                n_faces = sum(c[1] for c in counts[label])
                st = {"border": b_used, "n_vertices": n_vertices, "n_faces": n_faces,
                      "next_vertex": len(b_used), "next_face": 0, "closed": True,
                      "border_edges": [], "fragments": [], "ply": None}
                if write_ply:
                    # The library's PLY writer, fed in parts; the file appears when finished.
                    name = f"label_{label}.ply" if "ply" in formats else f".label_{label}.ply.tmp-{os.getpid()}"
                    st["path"] = os.path.join(out, name)
                    st["ply"] = _voxreg.PlyParts(st["path"], n_vertices, n_faces)
                    st["ply"].write_vertices(0, np.ascontiguousarray(b_pos[at], dtype=np.float64))
                state[label] = st
            # Pass 2: each fragment's part of each label.
            for i, path in enumerate(fragments):
                with np.load(path) as f:
                    ids = f["vertex_ids"]
                    if len(ids) == 0:
                        continue
                    pos, quads, labels = f["positions"], f["quads"], f["labels"]
                    inner = _inner(ids, f["owned"], f["dims"])
                for label, qi, flip in _label_groups(labels, background):
                    st = state.get(label)
                    if st is None:
                        continue
                    q, lab = _oriented(quads[qi], labels[qi], flip)
                    used, local = np.unique(q, return_inverse=True)
                    by_id = np.argsort(ids[used], kind="stable")
                    used = used[by_id]
                    rank = np.empty(len(used), np.int64)
                    rank[by_id] = np.arange(len(used))
                    local = rank[local.reshape(-1)].reshape(-1, 4)
                    is_inner = inner[used]
                    # Indices in the label's vertex list: inner vertices next in line,
                    # border ones at their rank among the label's border vertices.
                    index = np.empty(len(used), np.int64)
                    n_inner = int(np.count_nonzero(is_inner))
                    index[is_inner] = st["next_vertex"] + np.arange(n_inner)
                    index[~is_inner] = border_index(st["border"], ids[used[~is_inner]])
                    qv = index[local]
                    if write_ply:
                        st["ply"].write_vertices(st["next_vertex"],
                                                 np.ascontiguousarray(pos[used[is_inner]], dtype=np.float64))
                        st["ply"].write_faces(st["next_face"], np.ascontiguousarray(qv, dtype=np.int64),
                                              np.ascontiguousarray(lab, dtype=np.uint32))
                    st["next_vertex"] += n_inner
                    st["next_face"] += len(qv)
                    # Closure: inner edges here, edges touching a border vertex at the end.
                    a, b = _edges(qv)
                    inner_edge = (a >= len(st["border"])) & (b >= len(st["border"]))
                    if not _balanced(a[inner_edge], b[inner_edge], st["n_vertices"]):
                        st["closed"] = False
                    st["border_edges"].append((a[~inner_edge], b[~inner_edge]))
                    if "precomputed" in formats:
                        v = pos[used].copy()
                        outside = ~is_inner
                        v[outside] = b_pos[border_index(b_ids, ids[used[outside]])]
                        name = f"{label}:0:{i}"
                        tris = np.empty((2 * len(local), 3), "<u4")
                        tris[0::2] = local[:, [0, 1, 2]]
                        tris[1::2] = local[:, [0, 2, 3]]
                        with open(os.path.join(precomputed, name), "wb") as fh:
                            fh.write(struct.pack("<I", len(v)))
                            fh.write(v.astype("<f4").tobytes())
                            fh.write(tris.tobytes())
                        st["fragments"].append(name)
            for label in batch:
                st = state[label]
                if st["next_vertex"] != st["n_vertices"] or st["next_face"] != st["n_faces"]:
                    raise ValueError(f"label {label}: the fragments changed during the merge")
                a = np.concatenate([e[0] for e in st["border_edges"]])
                b = np.concatenate([e[1] for e in st["border_edges"]])
                closed = st["closed"] and _balanced(a, b, st["n_vertices"])
                summary["labels"][str(label)] = {"quads": st["n_faces"], "vertices": st["n_vertices"],
                                                 "closed": closed}
                if st["ply"] is not None:
                    st["ply"].finish()
                    st["ply"] = None
                    if "glb" in formats:
                        _ply_to(st["path"], os.path.join(out, f"label_{label}.glb"))
                    if "ply" not in formats:
                        os.remove(st["path"])
                if "precomputed" in formats:
                    _write_json_compact(os.path.join(precomputed, f"{label}:0"), {"fragments": st["fragments"]})
        finally:
            for st in state.values():
                if st.get("ply") is not None:
                    st["ply"].discard()
    summary["merge"] = {"wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
                        "peak_rss_bytes": _peak_rss(), "peak_since_merge_start": reset,
                        "border_vertices": int(len(b_ids))}
    return summary


def _write_json_compact(path: str, value: Any) -> None:
    with open(path, "w") as f:
        json.dump(value, f)


def _ply_to(ply: str, path: str) -> None:
    """Rewrites one of the merge's PLY files with voxreg's writer for ``path``'s format."""
    data = np.fromfile(ply, np.uint8)
    end = data[:4096].tobytes().index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].tobytes().decode()
    n_v = int(header.split("element vertex ")[1].split()[0])
    n_f = int(header.split("element face ")[1].split()[0])
    v = np.frombuffer(data, "<f4", 3 * n_v, end).reshape(n_v, 3).astype(np.float64)
    f = np.frombuffer(data, _PLY_FACE, n_f, end + 12 * n_v)
    _voxreg.write_arrays(path, np.ascontiguousarray(v), np.ascontiguousarray(f["v"], dtype=np.int64),
                         np.ascontiguousarray(f["l"], dtype=np.uint32), None)
