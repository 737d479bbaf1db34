"""Neuroglancer's multi-resolution precomputed meshes (``neuroglancer_multilod_draco``).

:func:`write_multilod` writes a voxreg mesh (every label's surface, sharing its
interfaces) as one multi-resolution mesh per label: an octree of fragments, level of
detail ``k`` cut into cubes of ``chunk * 2**k`` voxels, each fragment Draco-encoded with
integer positions quantized to the cube (the format of
``neuroglancer/src/datasource/precomputed/meshes.md``). Every level keeps the partition:
all labels are simplified together (``voxreg`` simplification), so two labels that
touch share the same simplified wall.

Chunk borders do not crack between levels. The mesh is cut along the planes of the
finest cubes first (new vertices where an edge crosses a plane, shared by both sides).
Level ``k``'s faces are grouped by their cube of level ``k - 1``, so that each fragment
splits into the 2x2x2 children Neuroglancer draws separately and no triangle crosses
them; and the faces touching a plane of level ``k``'s cubes never change, so the curve
where the surface crosses such a plane is the full-resolution curve at every level that
can meet there (the planes of coarser cubes are planes of every finer level). Two cubes
drawn side by side, at the same level or not, meet along the same vertices (up to the
quantization of the coarser one: ``chunk * 2**k / (2**bits - 1)`` voxel). See
``docs/design/neuroglancer-lod.md``.

Draco encoding uses ``DracoPy`` (pip), Google's encoder: the positions are quantized
here to the cube, then passed to Draco as integers with a quantization that keeps
them unchanged.
"""

from __future__ import annotations

import json
import os
import struct
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import _voxreg
from ._errors import ParameterError, label_argument

#: Vertices closer than this to a cutting plane (in voxels) are moved onto it.
_SNAP = 1e-6


def _triangles(quads: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The quads split along their first diagonal, degenerate halves (triangles written as
    quads repeating a vertex) dropped: triangles and the quad of each."""
    q = np.asarray(quads, dtype=np.int64)
    t = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    owner = np.concatenate([np.arange(len(q)), np.arange(len(q))])
    ok = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])
    order = np.argsort(owner[ok], kind="stable")
    return t[ok][order], owner[ok][order]


def _cut(u: np.ndarray, tris: np.ndarray, owner: np.ndarray, chunk: int):
    """Cuts a triangle mesh (positions ``u`` in voxels) along the planes ``x = k chunk``
    (and y, z): a new vertex where an edge crosses a plane, shared by the triangles on
    both sides of the edge; orientation kept. Returns positions, triangles and each
    triangle's parent."""
    u = u.copy()
    # Vertices within _SNAP of a plane go onto it, exactly.
    near = np.round(u / chunk) * chunk
    snap = np.abs(u - near) < _SNAP
    u[snap] = near[snap]
    for a in range(3):
        while True:
            ua = u[tris, a]
            lo, hi = ua.min(axis=1), ua.max(axis=1)
            plane = np.ceil(lo / chunk) * chunk
            plane = np.where(plane == lo, plane + chunk, plane)
            cross = plane < hi
            if not cross.any():
                break
            idx = np.nonzero(cross)[0]
            t, p = tris[idx], plane[idx]
            d = u[t, a] - p[:, None]
            s = np.sign(d).astype(np.int64)
            # Rotate each triangle so that its special vertex comes first: the one on the
            # plane (case A), else the one alone on its side (case B).
            zero = s == 0
            case_a = zero.any(axis=1)
            lone = np.where(s.sum(axis=1)[:, None] > 0, s < 0, s > 0)
            first = np.where(case_a, np.argmax(zero, axis=1), np.argmax(lone, axis=1))
            r = (first[:, None] + np.arange(3)[None, :]) % 3
            t = np.take_along_axis(t, r, axis=1)
            # The edges crossed: case A (v1, v2); case B (v0, v1) and (v0, v2).
            e1 = np.where(case_a[:, None], t[:, [1, 2]], t[:, [0, 1]])
            e2 = t[:, [0, 2]]
            edges = np.concatenate([e1, e2[~case_a]])
            planes = np.concatenate([p, p[~case_a]])
            key_lo, key_hi = edges.min(axis=1), edges.max(axis=1)
            keys = np.stack([key_lo, key_hi, planes.view(np.int64)], axis=1)
            uniq, inv = np.unique(keys, axis=0, return_inverse=True)
            inv = inv.reshape(-1)
            i, j = uniq[:, 0], uniq[:, 1]
            pl = np.ascontiguousarray(uniq[:, 2]).view(np.float64)
            w = (pl - u[i, a]) / (u[j, a] - u[i, a])
            new = u[i] + w[:, None] * (u[j] - u[i])
            new[:, a] = pl
            base = len(u)
            u = np.concatenate([u, new])
            n1 = base + inv[:len(idx)]
            n2 = np.full(len(idx), -1, np.int64)
            n2[~case_a] = base + inv[len(idx):]
            v0, v1, v2 = t[:, 0], t[:, 1], t[:, 2]
            pieces_a = np.concatenate([np.stack([v0, v1, n1], 1), np.stack([v0, n1, v2], 1)])[
                np.concatenate([case_a, case_a])]
            b = ~case_a
            pieces_b = np.concatenate([np.stack([v0[b], n1[b], n2[b]], 1), np.stack([n1[b], v1[b], v2[b]], 1),
                                       np.stack([n1[b], v2[b], n2[b]], 1)])
            own_a = np.concatenate([owner[idx][case_a]] * 2)
            own_b = np.concatenate([owner[idx][b]] * 3)
            keep = ~cross
            tris = np.concatenate([tris[keep], pieces_a, pieces_b])
            owner = np.concatenate([owner[keep], own_a, own_b])
            order = np.argsort(owner, kind="stable")
            tris, owner = tris[order], owner[order]
    return u, tris, owner


def _on_planes(u: np.ndarray, size: float) -> np.ndarray:
    """Whether each vertex lies on a plane ``k size`` of some axis."""
    return (np.mod(u, size) == 0).any(axis=1)


def _morton(pos: np.ndarray) -> np.ndarray:
    """Z-order keys of node positions: bit ``i`` of x, y, z at bits ``3i``, ``3i+1``,
    ``3i+2`` (Neuroglancer's order: z most significant at each bit)."""
    key = np.zeros(len(pos), np.uint64)
    p = pos.astype(np.uint64)
    for bit in range(21):
        for axis in range(3):
            key |= ((p[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return key


def _encode(q: np.ndarray, tris: np.ndarray, bits: int) -> bytes:
    """A Draco mesh of integer positions ``q`` (already quantized), kept as they are."""
    try:
        import DracoPy
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("voxreg.neuroglancer needs DracoPy (pip install DracoPy)") from e

    top = float(2 ** bits - 1)
    return DracoPy.encode(q.astype(np.float32), tris.astype(np.uint32), quantization_bits=bits,
                          quantization_range=top, quantization_origin=[0.0, 0.0, 0.0])


def _level_meshes(u: np.ndarray, tris: np.ndarray, labels: np.ndarray, lods: int, chunk: int,
                  spacing: np.ndarray, max_error: float) -> List[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each level's mesh: (positions in voxels, triangles, labels). Level 0 is the cut mesh;
    level k is the cut mesh simplified with faces grouped by their cube of level k - 1
    and the faces touching a plane of level k frozen (a group each)."""
    out = [(u, tris, labels)]
    if lods == 1:
        return out
    phys = u * spacing
    # Exact position lookup of the vertices the simplifier keeps.
    rows = np.ascontiguousarray(phys).view(np.dtype((np.void, 24))).reshape(-1)
    order = np.argsort(rows)
    sorted_rows = rows[order]
    quads = np.concatenate([tris, tris[:, 2:3]], axis=1)
    for k in range(1, lods):
        size, sub = chunk * 2.0 ** k, chunk * 2.0 ** (k - 1)
        frozen = _on_planes(u, size)[tris].any(axis=1)
        cell = np.floor(u[tris].mean(axis=1) / sub).astype(np.int64)
        _, group = np.unique(cell, axis=0, return_inverse=True)
        group = group.reshape(-1).astype(np.int64)
        n_cells = int(group.max()) + 1 if len(group) else 0
        group[frozen] = n_cells + np.arange(int(frozen.sum()))
        ratio = min(1.0, 4.0 ** -k)
        (d, _stats), = _voxreg.simplify_arrays(
            np.ascontiguousarray(phys), np.ascontiguousarray(quads, dtype=np.int64),
            np.ascontiguousarray(labels, dtype=np.uint32), [(ratio, max_error * 2.0 ** (k - 1))], group, None)
        # Vertices the simplifier kept (those on the frozen faces of the cube planes among
        # them) take their input position exactly; interior ones it placed anew (volume
        # preservation) come back in voxels.
        out_vertices = np.ascontiguousarray(d["vertices"], dtype=np.float64)
        out_rows = out_vertices.view(np.dtype((np.void, 24))).reshape(-1)
        at = np.minimum(np.searchsorted(sorted_rows, out_rows), len(rows) - 1)
        kept = sorted_rows[at] == out_rows
        pos = out_vertices / spacing
        pos[kept] = u[order[at[kept]]]
        level_tris, owner = _triangles(d["quads"])
        out.append((pos, level_tris, np.asarray(d["labels"])[owner]))
    return out


def write_multilod(mesh: Any, out: "str | os.PathLike[str]", lods: int = 3, chunk: int = 64,
                   spacing: Sequence[float] = (1.0, 1.0, 1.0), origin: Sequence[float] = (0.0, 0.0, 0.0),
                   background: Optional[int] = 0, quantization_bits: int = 16,
                   max_error: float = 0.5, dims: Optional[Sequence[int]] = None) -> Dict[str, Any]:
    """Writes ``mesh`` (a :class:`voxreg.Mesh`: vertices, quads, ``[inner, outer]`` labels,
    in physical units from ``spacing`` and ``origin``) as Neuroglancer multi-resolution
    meshes under ``out``: ``out/info`` (a segmentation volume's metadata, no voxels, whose
    ``mesh`` is ``mesh``, so that ``cloud-volume`` and Neuroglancer open it as
    ``precomputed://file://out``), ``out/mesh/info`` (``neuroglancer_multilod_draco``),
    and per label ``out/mesh/<label>.index`` (the manifest) and ``out/mesh/<label>`` (the
    fragments, level 0 first).

    Stored model coordinates are voxels from the volume's corner; the ``transform`` scales
    them by ``spacing`` (Neuroglancer's nanometres, the volume's ``resolution``).

    Parameters
    ----------
    lods : int, 1 to 8, default 3
        Levels of detail; level ``k`` keeps about ``4**-k`` of the faces, every vertex of
        the full mesh within ``max_error * 2**(k - 1)`` voxels of it.
    chunk : int >= 2, default 64
        The finest octree cube, in voxels.
    background : int or None, default 0
        The label that gets no mesh.
    quantization_bits : 10 or 16, default 16
    max_error : float > 0, default 0.5
        In voxels (of the smallest spacing).
    dims : three ints, default None
        The volume's size in voxels, for ``out/info`` (default: the mesh's extent).

    Returns
    -------
    dict
        Per label and level: faces and fragments; the levels' face counts.
    """
    if isinstance(lods, bool) or not isinstance(lods, (int, np.integer)) or not 1 <= int(lods) <= 8:
        raise ParameterError(f"lods must be an integer from 1 to 8, got {lods!r}")
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or int(chunk) < 2:
        raise ParameterError(f"chunk must be an integer of at least 2 voxels, got {chunk!r}")
    if quantization_bits not in (10, 16):
        raise ParameterError(f"quantization_bits must be 10 or 16, got {quantization_bits!r}")
    if not (isinstance(max_error, (int, float)) and np.isfinite(max_error) and max_error > 0):
        raise ParameterError(f"max_error must be a positive number of voxels, got {max_error!r}")
    background = label_argument("background", background)
    lods, chunk = int(lods), int(chunk)
    sp = np.asarray(spacing, dtype=np.float64)
    org = np.asarray(origin, dtype=np.float64)
    out = os.fspath(out)
    mesh_dir = os.path.join(out, "mesh")
    os.makedirs(mesh_dir, exist_ok=True)

    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    u = (vertices - org) / sp + 0.5
    tris, owner = _triangles(mesh.quads)
    u, tris, owner = _cut(u, tris, owner, chunk)
    labels = np.asarray(mesh.labels, dtype=np.uint32)[owner]
    levels = _level_meshes(u, tris, labels, lods, chunk, sp, float(max_error) * float(sp.min()))

    bits = int(quantization_bits)
    top = 2 ** bits - 1
    summary: Dict[str, Any] = {"levels": [int(len(t)) for _, t, _ in levels], "labels": {}}
    all_labels = np.unique(labels)
    for label in all_labels:
        label = int(label)
        if background is not None and label == background:
            continue
        per_lod_nodes: List[np.ndarray] = []
        per_lod_frags: List[List[bytes]] = []
        child_nodes = np.zeros((0, 3), np.int64)
        faces_per_lod = []
        for k, (pos, t, lab) in enumerate(levels):
            size = chunk * 2 ** k
            inner, outer = lab[:, 0] == label, lab[:, 1] == label
            sel = t[inner | outer].copy()
            flip = outer[inner | outer]
            sel[flip] = sel[flip][:, ::-1]
            faces_per_lod.append(int(len(sel)))
            node = np.floor(pos[sel].mean(axis=1) / size).astype(np.int64)
            parents = child_nodes >> 1
            nodes = np.unique(np.concatenate([node, parents]), axis=0)
            nodes = nodes[np.argsort(_morton(nodes), kind="stable")]
            frags = []
            node_key = {tuple(n): i for i, n in enumerate(nodes.tolist())}
            which = np.array([node_key[tuple(n)] for n in node.tolist()], np.int64) if len(node) else np.zeros(0, np.int64)
            order = np.argsort(which, kind="stable")
            bounds = np.searchsorted(which[order], np.arange(len(nodes) + 1))
            for i in range(len(nodes)):
                ft = sel[order[bounds[i]:bounds[i + 1]]]
                if len(ft) == 0:
                    frags.append(b"")
                    continue
                used, local = np.unique(ft, return_inverse=True)
                q = (pos[used] - nodes[i] * size) / size * top
                # Vertices on a cube's mid-plane go to Neuroglancer's partition point, so
                # they belong to both halves.
                mid = (pos[used] - nodes[i] * size) == size / 2
                q = np.rint(q)
                q[mid] = 2 ** (bits - 1)
                q = np.clip(q, 0, top)
                frags.append(_encode(q, local.reshape(-1, 3), bits))
            per_lod_nodes.append(nodes)
            per_lod_frags.append(frags)
            child_nodes = nodes
        manifest = [struct.pack("<3f", chunk, chunk, chunk), struct.pack("<3f", 0.0, 0.0, 0.0),
                    struct.pack("<I", lods), struct.pack(f"<{lods}f", *[2.0 ** k for k in range(lods)]),
                    np.zeros((lods, 3), "<f4").tobytes(),
                    struct.pack(f"<{lods}I", *[len(n) for n in per_lod_nodes])]
        for nodes, frags in zip(per_lod_nodes, per_lod_frags):
            manifest.append(np.ascontiguousarray(nodes.T, dtype="<u4").tobytes())
            manifest.append(np.asarray([len(f) for f in frags], "<u4").tobytes())
        _atomic(os.path.join(mesh_dir, f"{label}.index"), b"".join(manifest))
        _atomic(os.path.join(mesh_dir, str(label)), b"".join(b"".join(f) for f in per_lod_frags))
        summary["labels"][str(label)] = {"faces": faces_per_lod,
                                         "fragments": [len(n) for n in per_lod_nodes]}
    transform = [float(sp[0]), 0.0, 0.0, 0.0, 0.0, float(sp[1]), 0.0, 0.0, 0.0, 0.0, float(sp[2]), 0.0]
    _atomic(os.path.join(mesh_dir, "info"), json.dumps({
        "@type": "neuroglancer_multilod_draco", "vertex_quantization_bits": bits,
        "transform": transform, "lod_scale_multiplier": 1.0}).encode())
    if dims is None:
        dims = [int(np.ceil(x)) for x in u.max(axis=0)] if len(u) else [1, 1, 1]
    _atomic(os.path.join(out, "info"), json.dumps({
        "@type": "neuroglancer_multiscale_volume", "type": "segmentation", "data_type": "uint32",
        "num_channels": 1, "mesh": "mesh",
        "scales": [{"key": "1_1_1", "size": [int(d) for d in dims], "resolution": [float(s) for s in sp],
                    "voxel_offset": [0, 0, 0], "chunk_sizes": [[chunk, chunk, chunk]], "encoding": "raw"}],
    }).encode())
    return summary


def _atomic(path: str, data: bytes) -> None:
    tmp = path + f".tmp-{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)
