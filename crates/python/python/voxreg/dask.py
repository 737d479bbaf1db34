"""Regularize volumes larger than one machine, chunk by chunk, with Dask.

Each chunk is regularized with a halo of voxels around it and returns only what it owns:
the quads whose voxel face lies in the chunk (half-open ranges; the volume's far border
belongs to the last chunk) and the vertices whose first quad it owns. Every vertex of a
digital surface is a lattice corner, so the chunks' meshes glue into the whole-volume mesh
by vertex id, exactly: the same quads, the same vertices, no gap and no duplicate. Inside
a chunk, positions match the whole-volume solve to within a tolerance that shrinks with
the halo (see ``docs/scale.md``).

A task reads only its chunk and halo: from a Zarr store it opens the store itself, from a
dask array it depends on that slice alone.

Example (a laptop; on a cluster, create a ``dask.distributed.Client`` for it first)::

    import voxreg.dask
    mesh = voxreg.dask.regularize("labels.zarr", chunks=(128, 128, 128))
    voxreg.dask.regularize("labels.zarr", out="meshes/", formats=("ply", "precomputed"))
"""

from __future__ import annotations

import itertools
import json
import os
import struct
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _voxreg
from ._errors import ParameterError
from ._mesh import Mesh

#: The halo's default width in voxels: the narrowest of those measured whose stitched mesh
#: stays within 1e-2 voxel of the whole-volume solve with the default pipeline (the table
#: of ``docs/scale.md``). The cut sides of a chunk's sub-volume close its surfaces, and the
#: default attachment is weak, so the difference decays over about ten voxels.
DEFAULT_HALO = 24

_PARAMS = (
    "regions", "preset", "normals", "radius", "alpha", "beta", "gamma", "refine",
    "preserve_size", "texture_aware", "solver", "clamp", "tolerance",
)


def _open(array: Any) -> Any:
    """A Zarr path opened read-only (zarr-python 3); anything else as given."""
    if isinstance(array, (str, os.PathLike)):
        import zarr

        return zarr.open_array(os.fspath(array), mode="r")
    return array


def _grid(dims: Sequence[int], chunks: Sequence[int]) -> List[List[Tuple[int, int]]]:
    return [[(lo, min(lo + c, n)) for lo in range(0, n, c)] for n, c in zip(dims, chunks)]


def _chunks_of(array: Any, chunks: Optional[Sequence[int]]) -> Tuple[int, int, int]:
    if chunks is None:
        size = getattr(array, "chunksize", None) or getattr(array, "chunks", None)
        if isinstance(size, tuple) and len(size) == 3 and all(isinstance(c, int) for c in size):
            chunks = size
        else:
            chunks = (64, 64, 64)
    if len(chunks) != 3 or any(int(c) < 1 for c in chunks):
        raise ParameterError(f"chunks must be three positive integers, got {chunks!r}")
    return tuple(int(c) for c in chunks)  # type: ignore[return-value]


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
    p = {k: params.get(k) for k in _PARAMS}
    p["preset"] = p["preset"] or "default"
    sp = np.asarray(spacing, dtype=np.float64)
    chunk_origin = np.asarray(origin, dtype=np.float64) + np.asarray(start) * sp
    labels = np.asarray(labels)
    return _voxreg.regularize_block(
        labels, tuple(sp), tuple(chunk_origin), background, tuple(int(s) for s in start),
        tuple(tuple(int(x) for x in o) for o in owned), tuple(int(n) for n in global_dims),
        p["regions"], p["preset"], p["normals"], p["radius"], p["alpha"], p["beta"], p["gamma"],
        p["refine"], p["preserve_size"], p["texture_aware"], p["solver"], p["clamp"],
        p["tolerance"], threads,
    )


def _task(source: Any, sliced: bool, index: Tuple[int, int, int], start: Sequence[int],
          end: Sequence[int], owned: Sequence[Sequence[int]], global_dims: Sequence[int],
          out: Optional[str], kwargs: Dict[str, Any]) -> Any:
    """One chunk: read its voxels (``sliced``: ``source`` is already the chunk and halo;
    else a Zarr path or array, opened and sliced here, in the worker), regularize, and
    return the fragment or write it under ``out`` and return its path."""
    if sliced:
        labels = np.asarray(source)
    else:
        labels = np.asarray(_open(source)[start[0]:end[0], start[1]:end[1], start[2]:end[2]])
    d = regularize_chunk(labels, start, owned, global_dims, **kwargs)
    fragment = {k: d[k] for k in ("vertex_ids", "positions", "owns_vertex", "quads", "labels")}
    fragment["index"] = np.asarray(index)
    if out is None:
        return fragment
    path = os.path.join(out, "fragments", "chunk_{}_{}_{}.npz".format(*index))
    tmp = path + ".tmp.npz"
    np.savez(tmp, **fragment)
    os.replace(tmp, path)
    return path


def regularize(array: Any, chunks: Optional[Sequence[int]] = None, halo: int = DEFAULT_HALO,
               out: "Optional[str | os.PathLike[str]]" = None,
               formats: Iterable[str] = ("ply",), scheduler: Any = None,
               spacing: Sequence[float] = (1.0, 1.0, 1.0), origin: Sequence[float] = (0.0, 0.0, 0.0),
               background: Optional[int] = 0, threads: int = 1, **params: Any) -> Union[Mesh, str]:
    """Regularizes a label volume chunk by chunk through Dask, and stitches the chunks.

    Parameters
    ----------
    array : dask array, Zarr array, numpy array, or str (a Zarr array's path)
        The labels, indexed ``[x, y, z]``, any integer dtype.
    chunks : three ints, default None
        The chunk each task owns, in voxels: by default the array's own chunks (dask or
        Zarr), else 64.
    halo : int >= 2, default DEFAULT_HALO (24)
        Voxels read around each chunk. The stitched mesh has the whole-volume mesh's
        quads and vertex ids at any halo; its positions approach the whole-volume solve
        as the halo grows.
    out : str or path-like, default None
        A directory: fragments are written to ``out/fragments/`` by the tasks, then
        stitched into ``out/label_<L>.ply`` (each label's closed, outward surface) and/or
        Neuroglancer's precomputed legacy meshes in ``out/precomputed/`` (``formats``).
        None: the stitched mesh is returned (it must fit in memory).
    formats : iterable of {"ply", "glb", "precomputed"}, default ("ply",)
        What ``out`` receives.
    scheduler : default None
        Passed to ``dask.compute`` (None: the current one, e.g. a distributed Client's).
    spacing, origin, background : as in ``voxreg.regularize``
    threads : int, default 1
        Threads per task (dask runs several tasks at once).
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
    if int(halo) < 2:
        raise ParameterError(f"halo must be at least 2 voxels, got {halo}")
    formats = tuple(formats)
    bad = set(formats) - {"ply", "glb", "precomputed"}
    if bad:
        raise ParameterError(f"unknown formats: {', '.join(sorted(bad))}")
    out_dir = None if out is None else os.fspath(out)
    if out_dir is not None:
        os.makedirs(os.path.join(out_dir, "fragments"), exist_ok=True)
    kwargs = dict(params, spacing=spacing, origin=origin, background=background, threads=threads)
    # A Zarr path travels as the path (each worker opens it); a dask array as its slices.
    is_dask = hasattr(source, "dask")
    by_path = isinstance(array, (str, os.PathLike))
    tasks = []
    grid = _grid(dims, chunks)
    for index in itertools.product(*(range(len(g)) for g in grid)):
        owned = [grid[k][index[k]] for k in range(3)]
        start = [max(lo - halo, 0) for lo, _ in owned]
        end = [min(hi + halo, n) for (_, hi), n in zip(owned, dims)]
        if by_path:
            src: Any = os.fspath(array)
        elif is_dask:
            src = source[start[0]:end[0], start[1]:end[1], start[2]:end[2]]
        else:
            src = np.asarray(source[start[0]:end[0], start[1]:end[1], start[2]:end[2]])
        tasks.append(dask.delayed(_task, pure=True)(src, not by_path, index, start, end, owned, dims,
                                                     out_dir, kwargs))
    results = dask.compute(*tasks, scheduler=scheduler)
    fragments = [dict(np.load(r)) if isinstance(r, str) else r for r in results]
    mesh, chunk_of_quad = stitch(fragments)
    if out_dir is None:
        return mesh
    background_label = background
    for label in np.unique(mesh.labels):
        if background_label is not None and label == background_label:
            continue
        part = region_mesh(mesh, int(label))
        for f in formats:
            if f in ("ply", "glb"):
                part.save(os.path.join(out_dir, f"label_{int(label)}.{f}"))
    if "precomputed" in formats:
        write_precomputed(os.path.join(out_dir, "precomputed"), mesh, chunk_of_quad, background_label)
    return out_dir


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


def write_precomputed(path: str, mesh: Mesh, chunk_of_quad: np.ndarray, background: Optional[int]) -> None:
    """Neuroglancer's precomputed legacy mesh format under ``path``: ``info``, per label a
    manifest ``<label>:0`` listing its fragments, and one fragment per chunk per label
    (uint32 vertex count, float32 positions, uint32 triangle indices, little-endian)."""
    os.makedirs(path, exist_ok=True)
    with open(os.path.join(path, "info"), "w") as f:
        json.dump({"@type": "neuroglancer_legacy_mesh"}, f)
    for label in np.unique(mesh.labels):
        if background is not None and label == background:
            continue
        label = int(label)
        in_label = (mesh.labels[:, 0] == label) | (mesh.labels[:, 1] == label)
        names = []
        for chunk in np.unique(chunk_of_quad[in_label]):
            keep = in_label & (chunk_of_quad == chunk)
            sub = region_mesh(Mesh(mesh.vertices, mesh.quads[keep], mesh.labels[keep]), label)
            name = f"{label}:0:{int(chunk)}"
            tris = sub.triangles().astype("<u4")
            with open(os.path.join(path, name), "wb") as f:
                f.write(struct.pack("<I", len(sub.vertices)))
                f.write(sub.vertices.astype("<f4").tobytes())
                f.write(tris.tobytes())
            names.append(name)
        with open(os.path.join(path, f"{label}:0"), "w") as f:
            json.dump({"fragments": names}, f)


def read_precomputed_fragment(path: "str | os.PathLike[str]") -> Tuple[np.ndarray, np.ndarray]:
    """Reads one legacy fragment: (vertices (n, 3) float32, triangles (m, 3) uint32)."""
    data = open(path, "rb").read()
    (n,) = struct.unpack_from("<I", data, 0)
    vertices = np.frombuffer(data, "<f4", 3 * n, 4).reshape(n, 3)
    triangles = np.frombuffer(data, "<u4", offset=4 + 12 * n).reshape(-1, 3)
    return vertices, triangles
