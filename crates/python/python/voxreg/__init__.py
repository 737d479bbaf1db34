"""voxreg: regularize voxel label volumes into smooth, faithful quad meshes.

One quad per voxel face between two labels, at positions that minimize the papers'
quadratic energy (attachment to the voxels, alignment with estimated normals, fairness)::

    import numpy as np, voxreg
    x, y, z = np.mgrid[:32, :32, :32]
    labels = ((x - 16) ** 2 + (y - 16) ** 2 + (z - 16) ** 2 <= 100).astype(np.uint8)
    mesh = voxreg.regularize(labels, spacing=(0.5, 0.5, 0.5))
    print(mesh.summary, mesh.vertices.shape, mesh.quads.shape)
    mesh.save("ball.ply")

- :func:`regularize`: a numpy label array in, a :class:`Mesh` out.
- :func:`read`: every voxel format the ``voxreg`` command reads, as an array and a dict
  (``regularize(labels, **info)`` regularizes it as the command does).
- :func:`check`: self-intersections and folds of a mesh (``voxreg check``).
- :class:`Mesh`: vertices, quads, labels, colours and report; sub-meshes per interface and
  per region, triangles, pyvista and trimesh conversions, ``save``.
- Errors: :class:`VoxregError` and its subclasses :class:`InputError`,
  :class:`ParameterError` (both also ``ValueError``) and :class:`IoError` (also ``OSError``).
"""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Optional, Sequence, Tuple, TypedDict, Union, cast

import numpy as np
import numpy.typing as npt

from . import _voxreg
from ._errors import InputError, IoError, ParameterError, VoxregError, label_argument
from ._mesh import Mesh, _report

__all__ = [
    "regularize",
    "read",
    "check",
    "Mesh",
    "VoxregError",
    "InputError",
    "ParameterError",
    "IoError",
    "__version__",
]

__version__: str = _voxreg.__version__


class MeshReport(TypedDict):
    """What :func:`check` counts (see there)."""

    faces: int
    intersecting_pairs: int
    invalid_faces: int
    folded_quads: int
    folded_pairs: int
    first_intersection: Optional[Tuple[int, int]]
    clean: bool
    mean_angle_deg: float


def _triple(name: str, value: Any) -> Tuple[float, float, float]:
    try:
        t = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be three numbers (x, y, z), got {value!r}") from None
    if len(t) != 3:
        raise ParameterError(f"{name} must be three numbers (x, y, z), got {value!r}")
    return t  # type: ignore[return-value]


def _palette(palette: Any) -> Tuple[Optional[np.ndarray], Optional[list], Optional[Dict[int, str]]]:
    """The palette as the core takes it: (n, 4) uint8 colours, material tuples, label names."""
    if palette is None:
        return None, None, None
    materials = None
    names = None
    if isinstance(palette, dict):
        if "colors" not in palette:
            raise ParameterError("palette: a dict palette needs 'colors' (an (n, 3) or (n, 4) array)")
        colors = palette["colors"]
        if palette.get("names"):
            try:
                names = {int(k): str(v) for k, v in palette["names"].items()}
            except (AttributeError, TypeError, ValueError):
                raise ParameterError("palette: 'names' must map integer labels to names") from None
        if palette.get("materials") is not None:
            keys = ("name", "color", "metallic", "roughness", "emission", "transparency")
            materials = []
            for i, m in enumerate(palette["materials"]):
                missing = [k for k in keys if not isinstance(m, dict) or k not in m]
                if missing:
                    raise ParameterError(f"palette: material {i} has no {', '.join(missing)} (each needs {', '.join(keys)})")
                try:
                    materials.append((str(m["name"]), tuple(int(c) for c in m["color"]), float(m["metallic"]),
                                      float(m["roughness"]), float(m["emission"]), float(m["transparency"])))
                except (TypeError, ValueError) as e:
                    raise ParameterError(f"palette: material {i}: {e}") from None
    else:
        colors = palette
    colors = np.asarray(colors)
    if colors.ndim != 2 or colors.shape[1] not in (3, 4):
        raise ParameterError(f"palette colours must be an (n, 3) or (n, 4) array, got shape {colors.shape}")
    if colors.shape[1] == 3:
        colors = np.hstack([colors, np.full((len(colors), 1), 255)])
    return np.ascontiguousarray(colors, dtype=np.uint8), materials, names


def _labels(labels: Any) -> np.ndarray:
    a = np.asarray(labels)
    if a.dtype.kind in "biu" and not a.dtype.isnative:
        a = a.astype(a.dtype.newbyteorder("="))  # the core reads native byte order only
    return a


def regularize(
    labels: npt.ArrayLike,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    background: Optional[int] = 0,
    regions: Union[None, str, Sequence[Sequence[int]]] = None,
    preset: str = "default",
    normals: Optional[str] = None,
    radius: Optional[float] = None,
    alpha: Optional[float] = None,
    beta: Optional[float] = None,
    gamma: Optional[float] = None,
    refine: Optional[int] = None,
    preserve_size: Optional[bool] = None,
    texture_aware: Optional[bool] = None,
    solver: Optional[str] = None,
    clamp: Union[None, bool, float] = None,
    smoothness: Optional[float] = None,
    tolerance: Optional[float] = None,
    sharpen: Optional[int] = None,
    sharpen_threshold: Optional[float] = None,
    intermediate_tolerance: Optional[float] = None,
    threads: int = 0,
    progress: Optional[Callable[[str, float], Any]] = None,
    palette: Any = None,
    max_memory: Union[None, int, str] = None,
) -> Mesh:
    """Regularizes the surfaces between the labels of a volume into a quad mesh.

    Every parameter left at ``None`` takes the preset's value; the others apply over it,
    exactly as the ``voxreg regularize`` options do.

    Parameters
    ----------
    labels : array_like of int, shape (X, Y, Z)
        The label of each voxel, indexed ``[x, y, z]``: any integer or bool dtype (uint8,
        uint16, uint32, uint64, int8 ... int64), C or Fortran order, or a strided view.
        Values must fit an unsigned 32-bit integer; negative labels are refused
        (``InputError``). A uint32 array (any order or strides) is read in place, not
        copied: do not write to it from another thread while the call runs. Other
        dtypes are converted once into uint32 (a checked conversion, with the GIL held,
        memory order kept). At most 2^31 voxels.
    spacing : three floats, default (1, 1, 1)
        Size of a voxel along x, y and z, in physical units (finite, positive).
    origin : three floats, default (0, 0, 0)
        Position of the centre of voxel [0, 0, 0], in physical units.
    background : int or None, default 0
        The background label: empty space, which also fills the outside of the volume,
        so objects touching the border get closed surfaces. ``None``: no background;
        every label is a material and interfaces reaching the border end there, open.
    regions : None, "label", "solid", str or list of lists of int, default None
        How labels form regions (materials): "label" (each label its own), "solid" (all
        non-background labels one), a spec such as "1,2,3;7", or groups such as
        ``[[1, 2, 3], [7]]``. None: the preset's ("solid" for voxel_art, else "label").
    preset : {"default", "papers", "voxel_art", "fast"}, default "default"
        "default": the fidelity pipeline (ii normals, alpha 1e-2, 3 refinement rounds,
        re-centring); "papers": the papers' single solve (alpha 1e-3, no refinement);
        "voxel_art": one solve clamped to the voxels' boxes (never self-intersecting),
        all colours one solid (what the CLI uses for .vox files); "fast": about the
        cost of surface nets (diffused normals, one batch of 20 block-Jacobi sweeps).
    normals : {"trivial", "convolved", "ii", "at", "diffused"}, default None (preset: "ii"; fast "diffused")
        Normal estimator driving the alignment term: each face's axis, axes averaged
        within the radius, integral invariants, Ambrosio-Tortorelli (keeps sharp
        features), or axes diffused over the surface within the radius (cheap).
    radius : float, default None (preset: 3 h^(1/3), h the largest spacing, 3 at unit spacing; voxel_art 2 voxels)
        Radius of the ii, convolved, at and diffused estimators, in physical units
        (diffused: 8 voxels of the finest axis by default).
    alpha : float > 0, default None (preset: 1e-2; papers 1e-3)
        Attachment weight.
    beta : float >= 0, default None (preset: 1)
        Alignment weight.
    gamma : float >= 0, default None (preset: 0.1; voxel_art 1)
        Fairness weight.
    refine : int >= 0, default None (preset: 3; papers, voxel_art and fast 0)
        Normal refinement rounds: re-estimate the normals from the result and solve again.
    preserve_size : bool, default None (preset: True; papers False)
        Re-centre the attachment targets between refinement rounds (cancels the shrinking
        of thin curved shapes).
    texture_aware : bool, default None (preset: False)
        Texture-aware fairness: quad edges follow label boundaries (paper, sec. 4.5).
    solver : {"auto", "direct", "cg", "bounded", "sweeps"}, default None (preset: "auto"; fast "sweeps")
        "auto": exact factorization for small surfaces, else cg; "direct": sparse
        Cholesky; "cg": multigrid conjugate gradient; "bounded": conjugate gradient in
        per-vertex boxes (the only one that clamps; "gd" is its former name); "sweeps":
        a fixed count of damped block-Jacobi sweeps, no tolerance (the fast preset's).
    clamp : bool or float, default None (preset: off; voxel_art 0.01)
        Keep every vertex within (1 - eps) voxel of its input, which rules out
        self-intersections. A float is eps in voxels, in (0, 1); True is the preset's
        margin (0.01); False
        turns the preset's clamping off. Implies solver="bounded".
    smoothness : float in (0, 1], default None (off)
        Voxel art: how rounded, from blocky (near 0: edges only softened) to rounded (1):
        each vertex moves at most ``smoothness`` times half a voxel from its voxel
        corner; thin parts keep their thickness and no face folds. The CLI's
        ``--smoothness``; excludes ``clamp``; implies solver="bounded".
    tolerance : float > 0, default None (preset: 1e-3)
        Iterative solvers stop when every vertex is estimated within this many voxels of
        the exact minimizer.
    sharpen : int >= 0, default None (preset: 10)
        With normals="at": most alternations of the sharpening stage (0 turns it off).
    sharpen_threshold : float > 0, default None (preset: 0.4)
        With normals="at": the sharpening stage's threshold on the feature field.
    intermediate_tolerance : float >= 1, default None (preset: 2)
        The solves before the last refinement round stop at this factor times
        ``tolerance``.
    threads : int, 0 to 1024, default 0
        Threads of the private thread pool the run uses (0: every core, or
        RAYON_NUM_THREADS). The GIL is released during the computation.
    progress : callable(stage: str, fraction: float), default None
        Called with the stage ("normals", "solve 1/4", "refine 1/3", ... then "done")
        and the fraction of the run done, in [0, 1], at most every 50 ms and at every
        stage change, with the GIL held (a tqdm bar can follow it). An exception it
        raises aborts the run and propagates. With tqdm::

            with tqdm(total=100, unit="%") as bar:
                def progress(stage, fraction):
                    bar.set_description(stage)
                    bar.update(100 * fraction - bar.n)
                mesh = voxreg.regularize(labels, progress=progress)
    palette : dict or (n, 3 | 4) uint8 array, default None
        Colours (and materials, and label names) indexed by label, as ``read`` returns
        them: the mesh's ``colors`` and ``label_names``, and the materials and names of
        saved files.
    max_memory : int or str, default None (half the physical memory)
        Memory budget in bytes, or a size such as "4G" or "512M" (the CLI's
        ``--max-memory``), never above what ``ulimit -v`` and the cgroup's memory limit
        leave. A conversion of the labels to uint32, or a run whose estimated
        peak (about 1.6 kB per surfel) exceeds it, is refused with ``VoxregError``
        before anything is allocated for it.

    Returns
    -------
    Mesh
        Vertices, quads, labels, colours (with a palette) and the run's report.

    Raises
    ------
    InputError
        Labels of the wrong shape or dtype, a negative or too large label, more than
        2^31 voxels, no surface.
    ParameterError
        A parameter out of range or unknown.
    VoxregError
        Over the memory budget (``max_memory``), or the computation failed.
    """
    colors, materials, names = _palette(palette)
    # The library's options (its `Overrides`, the CLI's flags), by name; None is not given.
    options = dict(
        regions=regions, normals=normals, radius=radius, alpha=alpha, beta=beta, gamma=gamma,
        refine=refine, preserve_size=preserve_size, texture_aware=texture_aware, solver=solver,
        clamp=clamp, smoothness=smoothness, tolerance=tolerance, sharpen=sharpen,
        sharpen_threshold=sharpen_threshold, intermediate_tolerance=intermediate_tolerance,
    )
    d = _voxreg.regularize(
        _labels(labels), _triple("spacing", spacing), _triple("origin", origin),
        label_argument("background", background),
        preset, options, threads, progress, colors, materials, max_memory, palette_names=names,
    )
    mesh = Mesh._from_core(d, _report(d), d["surface"], None, d["summary"])
    mesh._spacing = _triple("spacing", spacing)
    return mesh


def read(
    path: "str | os.PathLike[str]",
    threshold: Optional[float] = None,
    dims: Optional[Sequence[int]] = None,
    dtype: Optional[str] = None,
    endian: Optional[str] = None,
    spacing: Optional[Sequence[float]] = None,
    keep_labels: Optional[Sequence[int]] = None,
    background: Optional[int] = None,
) -> Tuple[npt.NDArray[np.uint32], Dict[str, Any]]:
    """Reads a voxel file as the ``voxreg`` command does.

    Formats by extension: .vol, .longvol, .pgm3d (DGtal), .vox (MagicaVoxel), .nii,
    .nii.gz (NIfTI-1), .vti (VTK image data), .npy (NumPy, shape (X, Y, Z)), .tif/.tiff
    stacks, .nrrd/.nhdr, .mrc/.map/.rec, a .zarr directory (Zarr v2/v3, OME-Zarr level 0
    or a level such as ``image.ome.zarr/1``; arrays [z, y, x]), or raw data with ``dims``.

    Parameters
    ----------
    path : str or path-like
    threshold : float, default None
        Make a binary volume: voxels whose value is > threshold are inside (label 1).
        Needed for grey-level data (fractional, negative or scaled values).
    dims : three ints, default None
        Read the file as raw data (no header, x fastest) of these dimensions.
    dtype : str, default None ("u8")
        Raw data: u8, u16, u32, f32, i8, i16, i32, u64, i64 or f64.
    endian : str, default None ("little")
        Raw data: "little" or "big".
    spacing : three floats, default None
        The size of a voxel, for raw data, or overriding the file's.
    keep_labels : list of int, default None
        Keep only these labels; every other becomes the background.
    background : int, default None (the file's, else 0)
        The background label.

    Returns
    -------
    labels : ndarray of uint32, shape (X, Y, Z), Fortran order (moved, not copied)
    info : dict
        ``spacing``, ``origin`` (tuples, physical units), ``background`` (int or None),
        ``palette`` (``{"colors": (n, 4) uint8, "materials": [dict], "names": {label:
        name}}`` or None; ``names`` holds the labels the file names, such as 3D Slicer
        segments) and
        ``preset`` ("voxel_art" for .vox files, else "default"): the keyword arguments
        that make ``regularize(labels, **info)`` do what ``voxreg regularize`` does.

    Raises
    ------
    IoError
        The file cannot be read or its format is unknown.
    InputError
        Grey-level data without a threshold; raw data without dims.
    ParameterError
        A parameter out of range or an unknown dtype or byte order.
    """
    spacing_t = None if spacing is None else _triple("spacing", spacing)
    dims_t = None if dims is None else tuple(int(d) for d in dims)
    keep = None if keep_labels is None else [int(l) for l in keep_labels]
    return _voxreg.read(os.fspath(path), threshold, dims_t, dtype, endian, spacing_t, keep,
                        label_argument("background", background))


def check(mesh: Union[Mesh, Tuple[npt.ArrayLike, npt.ArrayLike]]) -> MeshReport:
    """Counts the self-intersections and folds of a quad mesh (``voxreg check``).

    Quads are split into two triangles; faces may touch only along the edges and at the
    corners they share (exact tests); a repeated face counts, and so does a face with a
    non-finite vertex (``invalid_faces``).

    Parameters
    ----------
    mesh : Mesh or (vertices (n, 3), quads (m, 4))

    Returns
    -------
    dict
        ``faces``, ``intersecting_pairs`` (self-intersecting face pairs),
        ``invalid_faces`` (with a NaN or infinite vertex), ``folded_quads``,
        ``folded_pairs`` (folded adjacent pairs), ``first_intersection`` (a pair of face
        indices, or None), ``clean`` (none of these) and ``mean_angle_deg`` (the mean
        angle between edge-adjacent quads, in degrees).
    """
    vertices: npt.ArrayLike
    quads: npt.ArrayLike
    if isinstance(mesh, Mesh):
        vertices, quads = mesh.vertices, mesh.quads
    else:
        vertices, quads = mesh
    return cast(MeshReport, _voxreg.check(np.ascontiguousarray(vertices, dtype=np.float64),
                                          np.ascontiguousarray(quads, dtype=np.int64)))
