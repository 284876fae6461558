"""Typed stub of render._core, the C++ core (render/core/bindings): the Embree ray engine and the
PTPB renderer. Scene and settings travel as plain dicts (built by render/ptpb/settings.py and render/ptpb/api.py); see
render/core/bindings/convert_ptpb.cpp for the scene's keys and for_each_setting in
render/core/include/ptpb/settings.hpp for the settings'. Lengths are in metres, times in metres of OPL."""

from collections.abc import Callable, Mapping
from typing import Any, Literal, TypedDict

import numpy as np
import numpy.typing as npt

# Embree ray engine (register_raytrace.cpp)

INVALID_ID: int
"""prim/mesh id of a ray that hit nothing."""

class RayScene:
    """Triangle meshes traced by Embree 3. Add meshes, commit, then query."""

    def __init__(self) -> None: ...
    def add_mesh(self, vertices: npt.ArrayLike, faces: npt.ArrayLike, mesh_id: int) -> None:
        """vertices (N, 3) float32, faces (M, 3) uint32."""

    def add_instanced_mesh(
        self, vertices: npt.ArrayLike, faces: npt.ArrayLike, offsets: npt.ArrayLike, mesh_id: int
    ) -> None:
        """The mesh placed at each of the (K, 3) float64 offsets, as instances of one copy."""

    def commit(self) -> None: ...
    @property
    def committed(self) -> bool: ...
    @property
    def mesh_count(self) -> int: ...
    @property
    def triangle_count(self) -> int: ...
    @property
    def placed_triangle_count(self) -> int: ...
    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(lower, upper) corners of the committed scene's box."""

    def intersect(
        self,
        origins: npt.ArrayLike,
        directions: npt.ArrayLike,
        tnear: float = 0.0,
        tfar: npt.ArrayLike | None = None,
        threads: int = 0,
    ) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32], npt.NDArray[np.uint32], npt.NDArray[np.float32]]:
        """Closest hits of N rays: (t (N,), prim id (N,), mesh id (N,), normal (N, 3)); misses have
        t = inf and ids INVALID_ID. The GIL is released."""

    def occluded(
        self,
        origins: npt.ArrayLike,
        directions: npt.ArrayLike,
        tnear: float = 0.0,
        tfar: npt.ArrayLike | None = None,
        threads: int = 0,
    ) -> npt.NDArray[np.bool_]:
        """Whether each of N rays hits anything within [tnear, tfar]. The GIL is released."""

# PTPB renderer (register_ptpb.cpp)

SPEED_OF_LIGHT: float
"""m/s."""
PS_PER_M_OPL: float
"""Picoseconds per metre of optical path length."""

def ptpb_render(
    scene: Mapping[str, Any],
    settings: Mapping[str, Any],
    progress: Callable[[dict[str, Any]], bool | None] | None = None,
    resume: Mapping[str, Any] | None = None,
    checkpoint: Callable[[dict[str, Any]], bool | None] | None = None,
) -> dict[str, Any]:
    """Render a scene dict with the PTPB renderer; returns a dict of arrays and statistics.

    Returns ``steady`` (H, W, 3), ``frames`` (F, H, W, 3), ``early`` and ``late`` (H, W, 3), all
    float32; ``snapshots`` (a list of (iteration, (H, W, 3) array)); ``snapshot_seconds``; and
    ``stats`` (counters, timings, final bandwidths, cancelled/interrupted, window fractions), which
    also reports the schedule the core resolved from the settings and its defaults (render/core/DESIGN.md §6):
    ``alpha`` (unset: 2/3 in gate, 4/5 in bins/steady), ``surface_alpha`` (unset: 4/7 in gate, 2/3
    otherwise), ``initial_beam_radius_m``, ``initial_time_half_width_m`` (unset: R_0),
    ``initial_surface_radius_m`` (unset: R_0) and ``initial_surface_time_half_width_m`` (unset: the
    beams' T_0). A missing or None settings key is unset.

    The GIL is released while rendering; ``progress(info) -> bool|None`` is called about twice a
    second and after each iteration; returning False or Ctrl-C stops when the iteration under way is
    complete. ``checkpoint(state) -> bool|None`` receives the accumulated state (sums, stats,
    snapshots) every settings.checkpoint_every_iterations iterations or checkpoint_every_s seconds,
    and once more on cancellation; ``resume=state`` continues it. Bad input raises ValueError naming
    the key."""

def ptpb_memory_bytes(scene: Mapping[str, Any], settings: Mapping[str, Any], state_copy: bool = False) -> float:
    """Peak bytes of the render's image buffers, as checked against settings.memory_budget_gib."""

def ptpb_schedule_gamma(iteration: int, alpha: float) -> float:
    """Kernel-volume factor gamma_i = prod_{k=1..i} (k + alpha) / (k + 1), gamma_0 = 1."""

class RenderSettingSpec(TypedDict):
    """One setting as render/core/include/ptpb/settings.hpp declares it."""

    key: str
    kind: Literal["int", "float", "bool", "enum", "optional"]  # optional: a float or None
    default: int | float | bool | str | None  # enums by name; unset schedule values, zeros that mean none: None
    choices: list[str] | None  # an enum's names
    ge: int | float | None  # bounds of the value, whole numbers as int
    gt: int | float | None
    le: int | float | None
    lt: int | float | None
    description: str  # ends with its [unit]
    config: bool  # False: no config sets it; callers of the API do (tests, shards)

def render_settings_spec() -> list[RenderSettingSpec]:
    """Every setting the core parses, in the order of for_each_setting, with its key, kind, default,
    choices, bounds, description and whether a config sets it."""

# Snow as grains (register_grains.cpp, render/lidar/grains.py, render/lidar/LIDAR.md §10)

def grains_trace_packing(
    centres: npt.ArrayLike,
    radii: npt.ArrayLike,
    cell_size: float,
    ice_index: float,
    ice_group_index: float,
    ice_absorption: float,
    photons: int,
    seed: int,
    start_opl: float,
    bin_width_opl: float,
    temporal_bins: int,
    cone_half_angle: float,
    depth_bin_width: float,
    depth_bins: int,
    max_path: float,
    threads: int = 0,
    progress: Callable[[int, int], bool | None] | None = None,
) -> dict[str, Any]:
    """A nadir beam into a periodic packing of ice spheres: centres (N, 3) with x, y in [0, Lc) and z in [-Lc, 0),
    radii (N,). Returns per-photon sums: ``time_flux``, ``time_cone``, ``air_by_bin``, ``ice_by_bin``
    (temporal_bins,), ``absorbed_depth`` (depth_bins,) float64 arrays; floats ``albedo``, ``cone_fraction``,
    ``absorbed``, ``truncated``, ``early``, ``late``, ``exit_opl``, ``air_path``, ``ice_path``, ``exit_air_path``,
    ``exit_ice_path``, ``sphere_hits``, ``interactions``, ``total_internal_reflections``; ``photons_done`` and
    ``cancelled``. The GIL is released; ``progress(done, total)`` returning False, or Ctrl-C, stops after the
    group of photons under way. Identical for any thread count."""

def grains_trace_homogeneous(
    scattering: float,
    absorption: float,
    asymmetry: float,
    time_index: float,
    photons: int,
    seed: int,
    start_opl: float,
    bin_width_opl: float,
    temporal_bins: int,
    cone_half_angle: float,
    depth_bin_width: float,
    depth_bins: int,
    max_path: float,
    threads: int = 0,
    progress: Callable[[int, int], bool | None] | None = None,
) -> dict[str, Any]:
    """The same beam and receivers in a homogeneous Henyey–Greenstein half-space; its path is ``air_path``
    (``ice_path`` 0) and OPL = time_index x path. Same keys as grains_trace_packing."""

def grains_scatter_sphere(
    radius: float, ice_index: float, ice_absorption: float, rays: int, seed: int = 0
) -> dict[str, float]:
    """One sphere lit over its cross-section: ``absorbed`` per incident photon, ``mean_ice_path`` [m],
    ``mean_cos`` (g without diffraction), ``energy_out`` (1 to rounding), ``total_internal_reflections`` (0)."""
