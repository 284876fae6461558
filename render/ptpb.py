"""Python face of the C++ PTPB renderer: ``render(scene, settings) -> RenderResult``.

``scene`` is the core's plain scene dict (all lengths in metres, colours linear RGB)::

    {"media": [{"sigma_s": (3,), "sigma_a": (3,), "g": float, "ior": float}, ...],
     "shapes": [{"vertices": (N,3), "faces": (M,3), "kind": "null"|"dielectric"|"diffuse",
                 "interior": medium id or -1, "exterior": medium id or -1,
                 "albedo": (3,), "radiance": (3,)  # one-sided area emission along the outward normal
                }, ...],
     "point_lights": [{"position", "intensity" (W/sr), "medium"}],
     "directional_lights": [{"to_sun", "irradiance" (W/m^2), "reference_point" or None}],
     "environment_radiance": (3,),  # constant sky, steady image only
     "ambient_ior": 1.0,
     "camera": {"origin", "target", "up", "fov" (deg), "fov_axis", "width", "height", "medium"},
     "film": {"frame_mode": "steady"|"bins"|"gate", "temporal_bins", "start_opl" (m), "bin_width_opl" (m)}}

Free flights sample the channel-average mixture of the three exponentials and carry all three
channels (no hero wavelength), as in ptpb.md §3.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.schema.ptpb import BeamRadius, PTPBConfig, TimeHalfWidth

__all__ = ["RenderResult", "core_inputs", "memory_bytes", "render", "resolve_settings", "scene_bounding_sphere"]


@dataclass
class RenderResult:
    """Images of one render: ``steady`` (H, W, 3) radiance, ``frames`` (F, H, W, 3) float32
    (bins: W m^-2 sr^-1 per bin; gate: per metre of OPL), energy outside the window, stats."""

    steady: np.ndarray
    frames: np.ndarray
    early: np.ndarray
    late: np.ndarray
    stats: dict[str, Any]
    snapshots: list[tuple[int, np.ndarray]] = field(default_factory=list)
    snapshot_seconds: list[float] = field(default_factory=list)  # wall time of each snapshot since the start


def scene_bounding_sphere(scene: dict) -> tuple[np.ndarray, float]:
    """Centre and radius of the bounding sphere of the shapes' axis-aligned box (as Mitsuba builds it)."""
    pts = [np.asarray(s["vertices"], dtype=np.float64).reshape(-1, 3) for s in scene.get("shapes", [])]
    if not pts:
        return np.zeros(3), 1.0
    allp = np.concatenate(pts)
    lo, hi = allp.min(0), allp.max(0)
    centre = 0.5 * (lo + hi)
    return centre, float(max(np.linalg.norm(hi - centre), 1e-4))


def _tan_half_fov_x(cam: dict) -> float:
    from render.scene import Camera, tan_half_fov

    fov_only = Camera(
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 1.0),
        (0.0, 1.0, 0.0),
        cam["fov"],
        cam["width"],
        cam["height"],
        cam.get("fov_axis", "x"),
    )
    return tan_half_fov(fov_only)[0]


def _resolve_radius(spec: BeamRadius, scene: dict, centre: np.ndarray, radius: float) -> float:
    """A kernel radius in metres: absolute, a fraction of the scene radius, or pixel footprints
    2 z tan(fov_x/2) / W at the distance z from the camera to the scene centre (ptpb.md §6)."""
    if spec.unit == "m":
        return spec.value
    if spec.unit == "scene_radius":
        return spec.value * radius
    cam = scene["camera"]
    depth = float(np.linalg.norm(centre - np.asarray(cam["origin"], dtype=np.float64))) or radius
    return spec.value * 2 * depth * _tan_half_fov_x(cam) / cam["width"]


def _resolve_half_width(spec: TimeHalfWidth, n: float, radius_m: float, bin_width: float) -> float:
    """A temporal half-width in metres of OPL, with the floor of half a bin (ptpb.md §6)."""
    if spec.unit == "m_opl":
        t0 = spec.value
    elif spec.unit == "bin_width":
        t0 = spec.value * bin_width
    else:
        t0 = spec.value * n * radius_m
    return max(t0, 0.5 * bin_width)


def resolve_settings(scene: dict, cfg: PTPBConfig) -> dict:
    """Turn a PTPBConfig into the core's settings dict: units resolved to metres (ptpb.md §6).

    Beams and surface photons (§7) run separate schedules: R_0, T_0, alpha for the beams and
    r_0, their own T_0 (the same rule with r_0 in place of R_0) and surface_alpha for surfaces."""
    film = scene["film"]
    mode = cfg.frame_mode or film["frame_mode"]
    alpha = cfg.alpha if cfg.alpha is not None else (2.0 / 3.0 if mode == "gate" else 0.8)
    # alpha* = 4 / (d + 4): the disk (d = 2) in bins/steady, the disk x time kernel (d = 3) in gate.
    surface_alpha = cfg.surface_alpha if cfg.surface_alpha is not None else (4.0 / 7.0 if mode == "gate" else 2.0 / 3.0)
    centre, radius = scene_bounding_sphere(scene)
    r0 = _resolve_radius(cfg.initial_beam_radius, scene, centre, radius)
    r0_surface = _resolve_radius(cfg.initial_surface_radius, scene, centre, radius)
    n = max([m.get("ior", 1.0) for m in scene.get("media", [])] + [scene.get("ambient_ior", 1.0)])
    bin_width = film.get("bin_width_opl", 0.003)
    t0 = _resolve_half_width(cfg.initial_time_half_width, n, r0, bin_width)
    t0_surface = _resolve_half_width(cfg.initial_time_half_width, n, r0_surface, bin_width)
    return {
        "iterations": cfg.iterations,
        "time_budget_s": cfg.time_budget_s or 0.0,
        "light_paths_per_iteration": cfg.light_paths_per_iteration,
        "alpha": alpha,
        "initial_beam_radius": r0,
        "initial_time_half_width": t0,
        "initial_surface_radius": r0_surface,
        "initial_surface_time_half_width": t0_surface,
        "surface_alpha": surface_alpha,
        "surface_normal_cos": cfg.surface_normal_cos,
        "spatial_kernel": cfg.spatial_kernel,
        "temporal_kernel": cfg.temporal_kernel,
        "photon_beam_kind": cfg.photon_beam_kind,
        "query_beam_kind": cfg.query_beam_kind,
        "parallel_guard_sin2": cfg.parallel_guard_sin2,
        "max_depth": cfg.max_depth,
        "rr_depth": cfg.rr_depth,
        "seed": cfg.seed,
        "threads": cfg.threads,
        "accel": cfg.accel,
        "grid_resolution": cfg.grid_resolution,
        "transmittance_cutoff": cfg.transmittance_cutoff,
        "camera_unwarp": cfg.camera_unwarp,
        "snapshot_every": cfg.snapshot_every,
        "checkpoint_every_iterations": cfg.checkpoint_every_iterations,
        "checkpoint_every_s": cfg.checkpoint_every_s or 0.0,
        "memory_budget_gib": cfg.memory_budget_gib,
    }


def core_inputs(scene: dict, settings: PTPBConfig | dict, **overrides: Any) -> tuple[dict, dict]:
    """The scene and settings dicts the core renders: a PTPBConfig resolved to metres (its
    frame_mode, when set, replacing the film's), a core settings dict as it is; ``overrides``
    replace core settings keys."""
    scene = dict(scene)
    if isinstance(settings, PTPBConfig):
        core_settings = resolve_settings(scene, settings)
        if settings.frame_mode is not None:
            scene["film"] = {**scene["film"], "frame_mode": settings.frame_mode}
    else:
        core_settings = dict(settings)
    core_settings.update(overrides)
    return scene, core_settings


def memory_bytes(scene: dict, settings: PTPBConfig | dict, *, state_copy: bool = False) -> float:
    """Peak bytes of the render's image buffers, the figure render.memory_budget_gib is checked against
    (``state_copy``: with checkpoints or a resume state)."""
    from render import _core

    return _core.ptpb_memory_bytes(*core_inputs(scene, settings), state_copy)


def render(
    scene: dict,
    settings: PTPBConfig | dict,
    *,
    progress: bool | Callable[[dict], bool | None] = False,
    resume: dict | None = None,
    checkpoint: Callable[[dict], bool | None] | None = None,
    **overrides: Any,
) -> RenderResult:
    """Render ``scene`` (the core dict above) with ``settings`` (a PTPBConfig, or a core settings
    dict with R_0/T_0 already in metres). ``overrides`` replace core settings keys (e.g. jitter).
    ``progress=True`` shows a tqdm bar; a callable receives the core's progress dicts.
    Ctrl-C (or a callback returning False) stops once the iteration under way is complete: its tiles
    add straight into the sums, so it is finished rather than dropped; ``stats["interrupted"]`` tells.

    ``checkpoint(state)`` receives the accumulated state (``width``, ``height``, ``frame_count``,
    ``seed``, float64 sums ``steady``/``early``/``late`` (H, W, 3), float32 sums ``frames`` (F, H, W, 3)
    and, past 10^4 iterations, their float32 rounding remainders ``frames_carry``, the
    ``stats`` counters, ``snapshot_iterations``/``snapshot_seconds``/``snapshots``) every
    ``checkpoint_every_iterations`` iterations or ``checkpoint_every_s`` seconds and once more when
    the run is cancelled; ``resume=state`` continues from one, bit-identically (ptpb.md §9)."""
    from render import _core

    scene, core_settings = core_inputs(scene, settings, **overrides)
    bar = None
    callback = progress if callable(progress) else None
    if progress is True:
        from tqdm import tqdm

        budget = core_settings.get("time_budget_s", 0.0)
        bar = tqdm(total=None if budget else core_settings.get("iterations"), unit="it", desc="ptpb", leave=False)

        def callback(info: dict) -> bool:
            bar.n = info["iteration"]
            bar.set_postfix(
                R=f"{info['radius']:.3g}",
                beams=info["beams"],
                r_s=f"{info['surface_radius']:.3g}",
                photons=info["surface_photons"],
                refresh=False,
            )
            bar.refresh()
            return True

    try:
        out = _core.ptpb_render(scene, core_settings, callback, resume, checkpoint)
    finally:
        if bar is not None:
            bar.close()
    stats = dict(out["stats"])
    stats["initial_beam_radius_m"] = core_settings["initial_beam_radius"]
    stats["initial_time_half_width_m"] = core_settings.get(
        "initial_time_half_width", core_settings["initial_beam_radius"]
    )
    stats["alpha"] = core_settings.get("alpha", 0.8)
    # The core falls back to the beams' R_0 and T_0, and to the per-mode alpha*, without these keys.
    stats["initial_surface_radius_m"] = core_settings.get(
        "initial_surface_radius", core_settings["initial_beam_radius"]
    )
    stats["initial_surface_time_half_width_m"] = core_settings.get(
        "initial_surface_time_half_width", stats["initial_time_half_width_m"]
    )
    surface_alpha = core_settings.get("surface_alpha")
    stats["surface_alpha"] = (
        surface_alpha
        if surface_alpha is not None
        else (4.0 / 7.0 if scene["film"]["frame_mode"] == "gate" else 2.0 / 3.0)
    )
    return RenderResult(
        out["steady"],
        out["frames"],
        out["early"],
        out["late"],
        stats,
        list(out["snapshots"]),
        list(out["snapshot_seconds"]),
    )
