import os
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str

class VoxregError(Exception): ...
class InputError(VoxregError, ValueError): ...
class ParameterError(VoxregError, ValueError): ...
class IoError(VoxregError, OSError): ...

class MeshReport(TypedDict):
    faces: int
    intersecting_pairs: int
    folded_quads: int
    folded_pairs: int
    first_intersection: Optional[Tuple[int, int]]
    clean: bool

class Mesh:
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
    ) -> None: ...
    def __len__(self) -> int: ...
    @property
    def summary(self) -> str: ...
    def interfaces(self) -> List[Tuple[int, int]]: ...
    def interface(self, a: int, b: int, manifold: bool = False) -> Mesh: ...
    def region(self, label: int, manifold: bool = True) -> Mesh: ...
    def regions(self) -> List[int]: ...
    def simplify(self, ratio: Optional[float] = None, max_error: Optional[float] = None) -> Mesh: ...
    def levels(self, n: int, factor: float = 4.0, max_error: Optional[float] = None) -> List[Mesh]: ...
    def triangles(self) -> npt.NDArray[np.int64]: ...
    def to_pyvista(self) -> Any: ...
    def to_trimesh(self) -> Any: ...
    def save(self, path: Union[str, os.PathLike[str]]) -> None: ...

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
    threads: int = 0,
    progress: Optional[Callable[[str, float], Any]] = None,
    palette: Any = None,
    max_memory: Union[None, int, str] = None,
) -> Mesh: ...
def read(
    path: Union[str, os.PathLike[str]],
    threshold: Optional[float] = None,
    dims: Optional[Sequence[int]] = None,
    dtype: Optional[str] = None,
    endian: Optional[str] = None,
    spacing: Optional[Sequence[float]] = None,
    keep_labels: Optional[Sequence[int]] = None,
    background: Optional[int] = None,
) -> Tuple[npt.NDArray[np.uint32], Dict[str, Any]]: ...
def check(mesh: Union[Mesh, Tuple[npt.ArrayLike, npt.ArrayLike]]) -> MeshReport: ...
