"""Types of the private extension module render._core (render/core/bindings/*.cpp); keep in step with them."""

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

# register_raytrace.cpp
INVALID_ID: int

class RayScene:
    """Triangle meshes traced by Embree 3. Add meshes, commit, then query."""

    def __init__(self) -> None: ...
    def add_mesh(self, vertices: npt.ArrayLike, faces: npt.ArrayLike, mesh_id: int) -> None: ...
    def commit(self) -> None: ...
    @property
    def committed(self) -> bool: ...
    @property
    def mesh_count(self) -> int: ...
    @property
    def triangle_count(self) -> int: ...
    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]: ...
    def intersect(
        self,
        origins: npt.ArrayLike,
        directions: npt.ArrayLike,
        tnear: float = 0.0,
        tfar: npt.ArrayLike | None = None,
        threads: int = 0,
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32], npt.NDArray[np.uint32], npt.NDArray[np.float32]]: ...
    def occluded(
        self,
        origins: npt.ArrayLike,
        directions: npt.ArrayLike,
        tnear: float = 0.0,
        tfar: npt.ArrayLike | None = None,
        threads: int = 0,
    ) -> npt.NDArray[np.bool_]: ...

# register_ptpb.cpp
SPEED_OF_LIGHT: float
PS_PER_M_OPL: float

def ptpb_render(
    scene: dict[str, Any],
    settings: dict[str, Any],
    progress: Callable[[dict[str, Any]], bool | None] | None = None,
    resume: dict[str, Any] | None = None,
    checkpoint: Callable[[dict[str, Any]], bool | None] | None = None,
) -> dict[str, Any]: ...
def ptpb_memory_bytes(scene: dict[str, Any], settings: dict[str, Any], state_copy: bool = False) -> float: ...
def ptpb_schedule_gamma(iteration: int, alpha: float) -> float: ...
