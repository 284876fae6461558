"""The core's settings dict from a ``render`` config section: every length resolved to metres.

A key of the section that the core takes as it is goes through unchanged; its default is the core's
(pipeline/schema/ptpb.py reads them). The rules for the start radius and the temporal half-width
(DESIGN.md §6) live here; the core owns the schedule defaults it fills in for keys that are absent
(alpha, surface alpha, the surface radius)."""

from __future__ import annotations

import numpy as np

from pipeline.schema.ptpb import BeamRadius, PTPBConfig, TimeHalfWidth

# Core settings keys that a render section gives in its own units, resolved to metres by resolve_settings.
RESOLVED_KEYS = {
    "initial_beam_radius": "render.initial_beam_radius (m, scene radii or pixel footprints)",
    "initial_time_half_width": "render.initial_time_half_width (m of OPL, bins or n R_0)",
    "initial_surface_radius": "render.initial_surface_radius (m, scene radii or pixel footprints)",
    "initial_surface_time_half_width": "render.initial_time_half_width, with r_0 in place of R_0",
}
# Keys of a render section that go into the core's scene dict, not its settings, with where.
SCENE_KEYS = {"frame_mode": "render.ptpb.api.core_inputs, into the film (scene['film']['frame_mode'])"}


def scene_bounding_sphere(scene: dict) -> tuple[np.ndarray, float]:
    """Centre and radius of the bounding sphere of the shapes' axis-aligned box (as Mitsuba builds it)."""
    pts = [np.asarray(s["vertices"], dtype=np.float64).reshape(-1, 3) for s in scene.get("shapes", [])]
    if not pts:
        return np.zeros(3), 1.0
    allp = np.concatenate(pts)
    lo, hi = allp.min(0), allp.max(0)
    centre = 0.5 * (lo + hi)
    return centre, max(float(np.linalg.norm(hi - centre)), 1e-4)


def _tan_half_fov_x(cam: dict) -> float:
    from render.scene.model import Camera, tan_half_fov

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
    2 z tan(fov_x/2) / W at the distance z from the camera to the scene centre (render/core/DESIGN.md §6);
    an orthographic camera's pixel is ortho_width / W wherever it looks."""
    if spec.unit == "m":
        return spec.value
    if spec.unit == "scene_radius":
        return spec.value * radius
    cam = scene["camera"]
    if cam.get("projection") == "orthographic":
        return spec.value * float(cam["ortho_width"]) / cam["width"]
    depth = float(np.linalg.norm(centre - np.asarray(cam["origin"], dtype=np.float64))) or radius
    return spec.value * 2 * depth * _tan_half_fov_x(cam) / cam["width"]


def _resolve_half_width(spec: TimeHalfWidth, n: float, radius_m: float, bin_width: float) -> float:
    """A temporal half-width in metres of OPL, with the floor of half a bin (render/core/DESIGN.md §6)."""
    if spec.unit == "m_opl":
        t0 = spec.value
    elif spec.unit == "bin_width":
        t0 = spec.value * bin_width
    else:
        t0 = spec.value * n * radius_m
    return max(t0, 0.5 * bin_width)


def resolve_settings(scene: dict, cfg: PTPBConfig) -> dict:
    """Turn a PTPBConfig into the core's settings dict: units resolved to metres (render/core/DESIGN.md §6).

    Beams and surface photons (§7) run separate schedules: R_0, T_0, alpha for the beams and
    r_0, their own T_0 (the same rule with r_0 in place of R_0) and surface_alpha for surfaces. An alpha
    left null goes to the core as None: the core picks the frame mode's default and reports it in stats."""
    film = scene["film"]
    centre, radius = scene_bounding_sphere(scene)
    r0 = _resolve_radius(cfg.initial_beam_radius, scene, centre, radius)
    r0_surface = _resolve_radius(cfg.initial_surface_radius, scene, centre, radius)
    n = max([m.get("ior", 1.0) for m in scene.get("media", [])] + [scene.get("ambient_ior", 1.0)])
    bin_width = film.get("bin_width_opl", 0.003)
    t0 = _resolve_half_width(cfg.initial_time_half_width, n, r0, bin_width)
    t0_surface = _resolve_half_width(cfg.initial_time_half_width, n, r0_surface, bin_width)
    resolved = {
        "initial_beam_radius": r0,
        "initial_time_half_width": t0,
        "initial_surface_radius": r0_surface,
        "initial_surface_time_half_width": t0_surface,
    }
    as_given = {key: getattr(cfg, key) for key in type(cfg).model_fields if key not in {*RESOLVED_KEYS, *SCENE_KEYS}}
    return as_given | resolved
