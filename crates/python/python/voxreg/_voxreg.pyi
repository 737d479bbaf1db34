# The Rust core (crates/python/src). Private: use the voxreg package's functions.
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Part = Optional[Tuple[str, int, bool]]

class Surface:
    def mesh(self, part: _Part = None) -> Dict[str, Any]: ...
    def save(self, path: str, part: _Part = None) -> None: ...
    def interfaces(self) -> List[Tuple[str, Tuple[int, int], Tuple[int, int]]]: ...
    def region_of(self, label: int) -> Optional[int]: ...
    def region_labels(self) -> List[List[int]]: ...
    def background_region(self) -> Optional[int]: ...

def regularize(
    labels: npt.NDArray[Any],
    spacing: Tuple[float, float, float],
    origin: Tuple[float, float, float],
    background: Optional[int],
    preset: str,
    options: Dict[str, Any],
    threads: int,
    progress: Optional[Callable[[str, float], Any]],
    palette_colors: Optional[npt.NDArray[np.uint8]],
    palette_materials: Optional[List[Tuple[str, Tuple[int, ...], float, float, float, float]]],
    max_memory: Union[None, int, str],
    palette_names: Optional[Dict[int, str]] = None,
) -> Dict[str, Any]: ...
def read(
    path: str,
    threshold: Optional[float] = None,
    dims: Optional[Sequence[int]] = None,
    dtype: Optional[str] = None,
    endian: Optional[str] = None,
    spacing: Optional[Sequence[float]] = None,
    keep_labels: Optional[Sequence[int]] = None,
    background: Optional[int] = None,
) -> Tuple[npt.NDArray[np.uint32], Dict[str, Any]]: ...
def check(vertices: npt.NDArray[np.float64], quads: npt.NDArray[np.int64]) -> Dict[str, Any]: ...
def write_arrays(
    path: str,
    vertices: npt.NDArray[np.float64],
    quads: npt.NDArray[np.int64],
    labels: npt.NDArray[np.uint32],
    colors: Optional[npt.NDArray[np.uint8]] = None,
) -> None: ...
def simplify_arrays(
    vertices: npt.NDArray[np.float64],
    quads: npt.NDArray[np.int64],
    labels: npt.NDArray[np.uint32],
    targets: List[Tuple[Optional[float], float]],
    groups: Optional[npt.NDArray[np.int64]] = None,
    colors: Optional[npt.NDArray[np.uint8]] = None,
    progress: Optional[Callable[[str, float], Any]] = None,
) -> List[Tuple[Dict[str, Any], Dict[str, Any]]]: ...
def simplify_surface(
    surface: Surface,
    targets: List[Tuple[Optional[float], float]],
    part: _Part = None,
    progress: Optional[Callable[[str, float], Any]] = None,
) -> List[Tuple[Dict[str, Any], Dict[str, Any]]]: ...
def preset_halo(preset_name: str) -> int: ...
def pyramid_targets(levels: int, factor: float, max_error: float) -> List[Tuple[Optional[float], float]]: ...
