"""``Mesh``: the regularized quad mesh as plain numpy arrays."""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import numpy.typing as npt

from . import _voxreg
from ._errors import InputError, ParameterError, VoxregError


class Mesh:
    """A quad mesh: one quad per voxel face of the input, at regularized positions.

    Attributes
    ----------
    vertices : ndarray, (n, 3) float64
        Vertex positions in physical units (the input's ``spacing`` and ``origin``: the
        centre of voxel ``[x, y, z]`` lies at ``origin + [x, y, z] * spacing``).
    quads : ndarray, (m, 4) int64
        Four vertex indices per quad, counter-clockwise seen from the side its normal
        points to.
    labels : ndarray, (m, 2) uint32
        Per quad, the ``[inner, outer]`` labels: the normal points from the inner label's
        voxel to the outer one's (the PLY files' face labels).
    colors : ndarray, (m, 4) uint8, or None
        Per quad, the RGBA colour of its solid voxel, when the input had a palette
        (MagicaVoxel files); else None.
    label_names : dict of int to str
        The names the input gives the labels of this mesh's quads (3D Slicer
        ``.seg.nrrd`` segments, named ``.vox`` materials), as written in the file; empty
        when it names none.
    report : dict
        What the run did (the CLI's ``--report`` JSON ``run`` object): parameters, cell
        counts, seconds per stage, energies before and after, every solve's report.
        Sub-meshes share their parent's.
    """

    vertices: npt.NDArray[np.float64]
    quads: npt.NDArray[np.int64]
    labels: npt.NDArray[np.uint32]
    colors: Optional[npt.NDArray[np.uint8]]
    report: Dict[str, Any]
    label_names: Dict[int, str]

    def __init__(
        self,
        vertices: npt.ArrayLike,
        quads: npt.ArrayLike,
        labels: npt.ArrayLike,
        colors: Optional[npt.ArrayLike] = None,
        report: Optional[Dict[str, Any]] = None,
        *,
        _surface: Any = None,
        _part: Optional[Tuple[str, int, bool]] = None,
        _groups: Optional[List[Tuple[str, np.ndarray]]] = None,
        _summary: Optional[str] = None,
        label_names: Optional[Dict[int, str]] = None,
    ) -> None:
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.quads = np.asarray(quads, dtype=np.int64)
        self.labels = np.asarray(labels, dtype=np.uint32)
        self.colors = None if colors is None else np.asarray(colors, dtype=np.uint8)
        self.report = {} if report is None else report
        self.label_names = dict(label_names or {})
        self._surface = _surface
        self._part = _part
        self._groups = _groups or []
        self._summary = _summary
        self._spacing: Optional[Tuple[float, float, float]] = None

    @classmethod
    def _from_core(cls, d: Dict[str, Any], report: Dict[str, Any], surface: Any,
                   part: Optional[Tuple[str, int, bool]], summary: Optional[str] = None) -> "Mesh":
        return cls(d["vertices"], d["quads"], d["labels"], d["colors"], report,
                   _surface=surface, _part=part, _groups=d["groups"], _summary=summary,
                   label_names={int(k): str(v) for k, v in d.get("label_names", {}).items()})

    def __repr__(self) -> str:
        colored = ", colored" if self.colors is not None else ""
        return f"<voxreg.Mesh: {len(self.quads)} quads, {len(self.vertices)} vertices{colored}>"

    def __len__(self) -> int:
        return len(self.quads)

    @property
    def summary(self) -> str:
        """The CLI's summary line: quads, vertices, energy before -> after, relative
        gradient of the last solve."""
        if self._summary is not None:
            return self._summary
        return f"{len(self.quads)} quads, {len(self.vertices)} vertices"

    # Parts -----------------------------------------------------------------------------

    def _need_surface(self, what: str) -> Any:
        if self._surface is None or self._part is not None:
            raise VoxregError(f"{what} needs the whole mesh returned by voxreg.regularize")
        return self._surface

    def interfaces(self) -> List[Tuple[int, int]]:
        """The interfaces present, as ``(a, b)`` label pairs: the smallest labels of the two
        regions (materials) the interface separates, the lower region first; in interface
        order. For a mesh built from arrays: the distinct ``labels`` rows, in order of
        first appearance."""
        if self._surface is not None:
            names = {name: pair for name, pair, _ in self._surface.interfaces()}
            return [(int(names[name][0]), int(names[name][1])) for name, _ in self._groups]
        _, first = np.unique(self.labels, axis=0, return_index=True)
        return [(int(self.labels[i][0]), int(self.labels[i][1])) for i in sorted(first)]

    def interface(self, a: int, b: int, manifold: bool = False) -> "Mesh":
        """The interface between the regions of labels ``a`` and ``b`` (either order), as
        a mesh of its own, oriented from its lower region to its higher one (see
        ``labels``). Its vertices copy the whole mesh's bit for bit, so interfaces and
        regions meet exactly along junctions.

        ``manifold=True`` duplicates the vertices and edges where the interface pinches
        (two voxels touching only along an edge or at a corner), so the mesh is 2-manifold
        (``voxreg regularize --split interfaces --manifold``); the copies keep their
        position bit for bit."""
        s = self._need_surface("interface()")
        ra, rb = s.region_of(int(a)), s.region_of(int(b))
        for i, (_, _, regions) in enumerate(s.interfaces()):
            if ra is not None and rb is not None and set(regions) == {ra, rb}:
                part = ("interface", i, bool(manifold))
                sub = Mesh._from_core(s.mesh(part), self.report, s, part)
                sub._spacing = self._spacing
                return sub
        raise InputError(f"no interface between labels {a} and {b}")

    def region(self, label: int, manifold: bool = True) -> "Mesh":
        """The surface of the region (material) holding ``label``, closed and oriented
        outward (open along the volume border when the volume has no background). Its
        vertices copy the whole mesh's bit for bit.

        ``manifold=True`` (the default) duplicates the vertices and edges where the region
        pinches (two of its voxels touching only along an edge or at a corner), so every
        edge has exactly two quads and a closed region is watertight for trimesh and
        pyvista; the copies keep their position bit for bit. It is the mesh of
        ``voxreg regularize --split regions --manifold``; ``manifold=False`` keeps the
        pinches (``--split regions``)."""
        s = self._need_surface("region()")
        r = s.region_of(int(label))
        if r is None:
            raise InputError(f"no voxel has label {label}")
        part = ("region", r, bool(manifold))
        sub = Mesh._from_core(s.mesh(part), self.report, s, part)
        sub._spacing = self._spacing
        return sub

    def regions(self) -> List[int]:
        """The smallest label of every region but the background, in region order."""
        s = self._need_surface("regions()")
        bg = s.background_region()
        return [labels[0] for r, labels in enumerate(s.region_labels()) if r != bg and labels]

    # Simplification --------------------------------------------------------------------

    def _default_error(self) -> float:
        """Half a voxel: of the smallest spacing when known, else of the median edge
        length of the quads (a voxel's edge for voxreg's unsimplified output)."""
        spacing = getattr(self, "_spacing", None)
        if spacing is not None:
            return 0.5 * float(min(spacing))
        if len(self.quads) == 0:
            return 0.0
        q = self.quads
        edges = np.linalg.norm(self.vertices[q[:, 1]] - self.vertices[q[:, 0]], axis=1)
        return 0.5 * float(np.median(edges))

    def _simplified(self, targets: List[Tuple[Optional[float], float]],
                    progress: Optional[Callable[[str, float], Any]] = None) -> List["Mesh"]:
        if progress is not None and not callable(progress):
            raise ParameterError(f"progress must be callable(stage, fraction) or None, got {progress!r}")
        if self._surface is not None:
            levels = _voxreg.simplify_surface(self._surface, targets, self._part, progress)
        else:
            colors = None if self.colors is None else np.ascontiguousarray(self.colors, dtype=np.uint8)
            groups = None
            if self._groups:
                groups = np.full(len(self.quads), -1, dtype=np.int64)
                for i, (_, faces) in enumerate(self._groups):
                    groups[np.asarray(faces, dtype=np.int64)] = i
            levels = _voxreg.simplify_arrays(
                np.ascontiguousarray(self.vertices, dtype=np.float64),
                np.ascontiguousarray(self.quads, dtype=np.int64),
                np.ascontiguousarray(self.labels, dtype=np.uint32), targets, groups, colors, progress)
        out = []
        for d, stats in levels:
            report = dict(self.report)
            report["simplify"] = stats
            names = dict(self.label_names)
            names.update({int(k): str(v) for k, v in d.get("label_names", {}).items()})
            mesh = Mesh(d["vertices"], d["quads"], d["labels"], d["colors"], report,
                        _groups=d["groups"], label_names=names)
            mesh._spacing = getattr(self, "_spacing", None)
            out.append(mesh)
        return out

    def simplify(self, ratio: Optional[float] = None, max_error: Optional[float] = None,
                 progress: Optional[Callable[[str, float], Any]] = None) -> "Mesh":
        """A simplified copy that keeps the partition (``voxreg regularize --simplify``):
        each interface simplified once and shared by its two regions, junction lines
        simplified once, their corners kept, each region closed with its Euler
        characteristic; quads where pairs of triangles make good ones, triangles written
        as quads repeating their last vertex.

        Parameters
        ----------
        ratio : float in (0, 1], default None
            Keep about this fraction of the faces (None: as far as ``max_error`` allows).
        max_error : float >= 0, default None (half a voxel)
            The largest distance allowed from any vertex of this mesh to the simplified
            one, in the mesh's units. Collapses that would break it are refused, so the
            ratio may not be reached. Default: half the smallest voxel spacing for a
            regularized mesh, else half the median edge length.
        progress : callable(stage: str, fraction: float), default None
            Called with the stage ("setup", "collapses", "flips", "pairing", then
            "done") and the fraction of the work done, in [0, 1], at most every 50 ms
            and at every stage change, with the GIL held, as in :func:`voxreg.regularize`.
            An exception it raises stops the simplification and propagates.

        Returns
        -------
        Mesh
            Built from arrays (no sub-meshes); its ``report["simplify"]`` gives the input
            and output face counts, the quads among them and ``error_bound``, the largest
            distance reached.

        Raises
        ------
        ParameterError
            A ratio outside (0, 1], a negative, infinite or NaN ``max_error``.
        InputError
            A mesh the simplifier cannot read (an index out of range, a degenerate face).
        """
        ratio = _number("ratio", ratio)
        if ratio is not None and not 0.0 < ratio <= 1.0:
            raise ParameterError(f"ratio must be in (0, 1], got {ratio!r}")
        error = self._error(max_error)
        return self._simplified([(ratio, error)], progress)[0]

    def levels(self, n: int, factor: float = 4.0, max_error: Optional[float] = None,
               progress: Optional[Callable[[str, float], Any]] = None) -> List["Mesh"]:
        """Levels of detail (``voxreg regularize --lod N``): ``n`` meshes, level ``k``
        keeping ``factor**-k`` of the faces within ``max_error * 2**(k - 1)`` of every
        vertex of this mesh (level 0 is this mesh). One collapse sequence: each level
        is a simplification of the one before, and every level keeps the partition (see
        :meth:`simplify`).

        Parameters
        ----------
        n : int, 1 to 12
        factor : float > 1, default 4
        max_error : float >= 0, default None (half a voxel, as in :meth:`simplify`)
        progress : callable(stage: str, fraction: float), default None
            As in :meth:`simplify`; the stages of each level are named
            "level K/N: collapses" and so on.

        Raises
        ------
        ParameterError
            ``n`` outside 1..12, ``factor`` not above 1, a bad ``max_error``.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= int(n) <= 12:
            raise ParameterError(f"n must be an integer from 1 to 12 levels, got {n!r}")
        f = _number("factor", factor)
        if f is None or not f > 1.0 or not np.isfinite(f):
            raise ParameterError(f"factor must be a number above 1, got {factor!r}")
        return self._simplified(_voxreg.pyramid_targets(int(n), f, self._error(max_error)), progress)

    def _error(self, max_error: Optional[float]) -> float:
        e = _number("max_error", max_error)
        if e is None:
            return self._default_error()
        if not (e >= 0.0 and np.isfinite(e)):
            raise ParameterError(f"max_error must be a non-negative number, got {max_error!r}")
        return e

    # Conversions -----------------------------------------------------------------------

    def triangles(self) -> npt.NDArray[np.int64]:
        """The quads split along their first diagonal: (2m, 3) int64, quad ``i`` giving
        triangles ``2i`` (vertices 0, 1, 2) and ``2i + 1`` (0, 2, 3)."""
        q = self.quads
        t = np.empty((2 * len(q), 3), dtype=np.int64)
        t[0::2] = q[:, [0, 1, 2]]
        t[1::2] = q[:, [0, 2, 3]]
        return t

    def to_pyvista(self) -> Any:
        """A ``pyvista.PolyData`` of the quads, with cell data ``labels`` ((m, 2)), and
        ``colors`` ((m, 4) uint8) when the mesh has colours. Needs pyvista."""
        try:
            import pyvista as pv
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Mesh.to_pyvista needs pyvista (pip install pyvista)") from e
        faces = np.hstack([np.full((len(self.quads), 1), 4, dtype=np.int64), self.quads]).ravel()
        poly = pv.PolyData(self.vertices.copy(), faces)
        poly.cell_data["labels"] = self.labels
        if self.colors is not None:
            poly.cell_data["colors"] = self.colors
        return poly

    def to_trimesh(self) -> Any:
        """A ``trimesh.Trimesh`` of ``triangles()`` (not processed: vertices and faces as
        here), with per-triangle face attribute ``labels`` and face colours when the mesh
        has colours. Needs trimesh."""
        try:
            import trimesh
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("Mesh.to_trimesh needs trimesh (pip install trimesh)") from e
        kwargs: Dict[str, Any] = {}
        if self.colors is not None:
            kwargs["face_colors"] = np.repeat(self.colors, 2, axis=0)
        m = trimesh.Trimesh(self.vertices, self.triangles(), process=False, **kwargs)
        m.face_attributes["labels"] = np.repeat(self.labels, 2, axis=0)
        return m

    def save(self, path: "str | os.PathLike[str]") -> None:
        """Writes the mesh with voxreg's writers, chosen by extension: ``.obj`` (quads, one
        group per interface, an ``.mtl`` for coloured meshes), ``.ply`` (binary, face
        labels and colours), ``.glb`` or ``.gltf`` (glTF 2.0, triangulated, one material
        per colour), ``.stl`` (binary, triangulated) or ``.vtp`` (VTK PolyData, labels and
        colours as cell data). The same bytes as the CLI's for the same mesh. A mesh built from
        arrays is written without interface groups, one material per distinct colour."""
        path = os.fspath(path)
        if self._surface is not None:
            self._surface.save(path, self._part)
        else:
            colors = None if self.colors is None else np.ascontiguousarray(self.colors, dtype=np.uint8)
            _voxreg.write_arrays(path, np.ascontiguousarray(self.vertices), np.ascontiguousarray(self.quads),
                                 np.ascontiguousarray(self.labels), colors)


def _number(name: str, value: Any) -> Optional[float]:
    """``value`` as a float, None kept; else a ``ParameterError`` naming ``name``."""
    if value is None:
        return None
    if isinstance(value, bool):
        raise ParameterError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number, got {value!r}") from None


def _report(d: Dict[str, Any]) -> Dict[str, Any]:
    return json.loads(d["report_json"])
