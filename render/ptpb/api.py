"""Python face of the C++ PTPB renderer: ``render(scene, settings) -> RenderResult``.

``scene`` is the core's plain scene dict (all lengths in metres, colours linear RGB)::

    {"media": [{"sigma_s": (3,), "sigma_a": (3,), "g": float, "ior": float}, ...],
     "shapes": [{"vertices": (N,3), "faces": (M,3), "kind": "null"|"dielectric"|"diffuse",
                 "interior": medium id or -1, "exterior": medium id or -1,
                 "albedo": (3,), "radiance": (3,)  # one-sided area emission along the outward normal
                }, ...],
     "point_lights": [{"position", "intensity" (W/sr), "medium"}],
     "directional_lights": [{"to_sun", "irradiance" (W/m^2), "reference_point" or None,
                             "beam_radius" (m, 1/e^2; 0 uniform), "beam_center" (a point of the beam's axis)}],
     "environment_radiance": (3,),  # constant sky, steady image only
     "environment_up": (3,),  # optional: next-event estimation samples the sky's hemisphere around it
     "ambient_ior": 1.0,
     "camera": {"origin", "target", "up", "fov" (deg), "fov_axis", "width", "height", "medium",
                "projection": "perspective"|"orthographic", "ortho_width" (m, orthographic's film width)},
     "film": {"frame_mode": "steady"|"bins"|"gate", "temporal_bins", "start_opl" (m), "bin_width_opl" (m)}}

Free flights sample the channel-average mixture of the three exponentials and carry all three
channels (no hero wavelength), as in render/core/DESIGN.md §3.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.schema.ptpb import PTPBConfig
from render.ptpb.settings import resolve_settings, scene_bounding_sphere

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


def is_core_settings(settings: Mapping[str, Any]) -> bool:
    """A dict that gives ``initial_beam_radius`` as a number is the core's own settings dict (lengths
    already in metres); any other dict holds keys of the config's render section."""
    return isinstance(settings.get("initial_beam_radius"), (int, float))


def core_inputs(scene: dict, settings: PTPBConfig | Mapping[str, Any], **overrides: Any) -> tuple[dict, dict]:
    """The scene and settings dicts the core renders. ``settings`` is a PTPBConfig, or a plain dict of
    its keys (validated, defaults filled in, e.g. ``{"iterations": 16}``), both resolved to metres with
    their frame_mode, when set, replacing the film's; or the core's settings dict (see
    ``is_core_settings``), passed as it is. ``overrides`` replace core settings keys."""
    scene = dict(scene)
    if not isinstance(settings, PTPBConfig) and not is_core_settings(settings):
        settings = PTPBConfig.model_validate(dict(settings))
    if isinstance(settings, PTPBConfig):
        core_settings = resolve_settings(scene, settings)
        if settings.frame_mode is not None:
            scene["film"] = {**scene["film"], "frame_mode": settings.frame_mode}
    else:
        core_settings = dict(settings)
    core_settings.update(overrides)
    return scene, core_settings


def memory_bytes(scene: dict, settings: PTPBConfig | Mapping[str, Any], *, state_copy: bool = False) -> float:
    """Peak bytes of the render's image buffers, the figure render.memory_budget_gib is checked against
    (``state_copy``: with checkpoints or a resume state)."""
    from render import _core

    return _core.ptpb_memory_bytes(*core_inputs(scene, settings), state_copy)


def render(
    scene: dict,
    settings: PTPBConfig | Mapping[str, Any],
    *,
    progress: bool | Callable[[dict], bool | None] = False,
    resume: dict | None = None,
    checkpoint: Callable[[dict], bool | None] | None = None,
    **overrides: Any,
) -> RenderResult:
    """Render ``scene`` (the core dict above; ``load_scene(folder)`` reads one that the scene stage wrote)
    with ``settings``: a PTPBConfig, a plain dict of its keys with defaults for the rest
    (``{"iterations": 16, "frame_mode": "bins"}``), or the core's settings dict with R_0/T_0 already
    in metres (``is_core_settings``). ``overrides`` replace core settings keys (e.g. jitter).
    ``progress=True`` shows a tqdm bar; a callable receives the core's progress dicts.
    Ctrl-C (or a callback returning False) stops once the iteration under way is complete: its tiles
    add straight into the sums, so it is finished rather than dropped; ``stats["interrupted"]`` tells.

    ``checkpoint(state)`` receives the accumulated state (``width``, ``height``, ``frame_count``,
    ``seed``, float64 sums ``steady``/``early``/``late`` (H, W, 3), float32 sums ``frames`` (F, H, W, 3)
    and, past 10^4 iterations, their float32 rounding remainders ``frames_carry``, the
    ``stats`` counters, ``snapshot_iterations``/``snapshot_seconds``/``snapshots``) every
    ``checkpoint_every_iterations`` iterations or ``checkpoint_every_s`` seconds and once more when
    the run is cancelled; ``resume=state`` continues from one, bit-identically (render/core/DESIGN.md §9).

    The film's ``window_first``/``window_count`` keep only those frames (a windowed pass), and the
    overrides ``first_iteration``/``keep_sums`` run a shard whose images are float64 sums, not averages
    (render/ptpb/split.py)."""
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
    stats = dict(out["stats"])  # with the resolved schedule: alpha, surface_alpha, initial_*_m
    # keep_sums (a shard, render/ptpb/split.py): the undivided float64 sums in the same fields.
    suffix = "_sum" if "steady_sum" in out else ""
    return RenderResult(
        out["steady" + suffix],
        out["frames" + suffix],
        out["early" + suffix],
        out["late" + suffix],
        stats,
        list(out.get("snapshots", [])),
        list(out.get("snapshot_seconds", [])),
    )
