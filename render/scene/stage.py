"""The `scene` stage: write the scene folder (scene.json, ptpb_scene.json, meshes/, optics.json)
from the config's scene section and the geometry stage's mesh (render/scene/build.py)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from common.atomic import write_json_atomic
from pipeline.schema.scene import SceneConfig
from render.scene import optics as optics_mod
from render.scene.build import build_scene
from render.scene.model import to_ptpb_core

log = logging.getLogger(__name__)


# A cap that leaves more than this fraction of the light still scattering, in an unbounded medium of the
# same albedo, cuts off light that matters (dense snow scatters hundreds of times before absorption).
SURVIVING_AT_CAP = 0.05


def depth_cap_problems(max_depth: int, media: dict[str, optics_mod.MediumOptics]) -> list[str]:
    """Warnings for media whose light a finite ``scene.max_depth`` truncates: in an unbounded medium a
    fraction albedo^max_depth of the paths is still scattering when the cap ends it."""
    if max_depth < 0:
        return []
    problems = []
    for key, medium in media.items():
        albedo = float(np.max(optics_mod.derived_quantities(medium).single_scattering_albedo))
        surviving = albedo ** max(max_depth - 1, 0)
        if surviving > SURVIVING_AT_CAP:
            problems.append(
                f"scene.max_depth={max_depth} truncates light in medium '{key}': with albedo {albedo:.5g}, "
                f"{surviving:.0%} of its paths would still be scattering at the cap (about "
                f"{1 / max(1 - albedo, 1e-12):.0f} scatterings before absorption); set scene.max_depth: -1 "
                "(unbounded, Russian roulette ends paths)"
            )
    return problems


def run_scene_stage(
    cfg: SceneConfig, out_dir: Path, *, geometry_dir: Path | None = None, site: dict | None = None
) -> dict:
    """Build and write the scene folder; return a small summary."""
    out_dir = Path(out_dir)
    scene, media = build_scene(cfg, out_dir, geometry_dir=geometry_dir, site=site)
    optics_report = {
        key: {"medium": m.to_dict(), "derived": optics_mod.derived_quantities(m).to_dict()} for key, m in media.items()
    }
    write_json_atomic(out_dir / "optics.json", optics_report)
    for problem in depth_cap_problems(cfg.max_depth, media):
        log.warning("%s", problem)
        scene.notes.append(problem)
    core, omitted, approximated = to_ptpb_core(scene)
    for item in omitted:  # the user can act: remove the light, or rely on the reference for it
        log.warning("PTPB scene leaves out %s; the reference renders it", item)
    for item in approximated:  # by design, nothing to change: recorded in scene.json's notes
        log.info("PTPB scene: %s", item)
    write_json_atomic(out_dir / "ptpb_scene.json", core)
    scene.notes.extend(f"PTPB: {item}" for item in omitted + approximated)
    scene.save(out_dir / "scene.json")
    film = scene.film
    if scene.bounding_sphere is None:
        raise RuntimeError("build_scene returned a scene without its bounding sphere; it always sets one")
    return {
        "camera_origin": list(scene.camera.origin),
        "camera_target": list(scene.camera.target),
        "bounding_radius_m": scene.bounding_sphere["radius"],
        "film": {
            "mode": film.mode,
            "temporal_bins": film.temporal_bins,
            "start_opl": film.start_opl,
            "bin_width_opl": film.bin_width_opl,
            "frame_mode": film.frame_mode,
        },
        "media": {
            k: {
                "sigma_s": list(m.sigma_s),
                "sigma_a": list(m.sigma_a),
                "g": m.render_g,
                "form": m.form,
                "diffuse_albedo": optics_report[k]["derived"]["diffuse_albedo"],
                "efolding_depth_m": optics_report[k]["derived"]["efolding_depth"],
            }
            for k, m in media.items()
        },
        "omitted_by_ptpb": omitted,
    }
