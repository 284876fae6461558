"""The `reference` stage: render the scene folder with Mitsuba 3 (steady) and mitransient (frames)."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Any, TypedDict

from common.atomic import save_npy_atomic, write_json_atomic
from pipeline.schema.scene import ReferenceConfig
from render.mitsuba.export import TRANSIENT_SEED_OFFSET, check_reference_limits
from render.mitsuba.passes import render_steady, render_transient
from render.output.exr import write_exr, write_exr_frames
from render.output.figures import rendered_image
from render.output.files import FRAME_UNITS, REFERENCE_TIMING, STEADY, FrameAxis, write_frames
from render.scene.model import Scene
from render.scene.roulette import (
    MITSUBA_SURVIVAL_CAP,
    RouletteDepth,
    auto_rr_depth,
    dark_reference,
    reduced_channels,
    worst_missed,
)

log = logging.getLogger(__name__)


class _PassOptions(TypedDict):
    """The keywords render_steady and render_transient share."""

    spp_per_pass: int
    time_budget_s: float | None
    quiet: bool
    tiles: int


def reference_roulette(scene: Scene, cfg: ReferenceConfig) -> tuple[RouletteDepth, str]:
    """The references' roulette depth for ``scene`` and what it is expected to leave out, with where the depth
    came from: ``auto`` (chosen from the media) or ``reference.rr_depth``."""
    media = {name: reduced_channels(m.sigma_s, m.sigma_a, [m.g] * 3) for name, m in scene.media.items()}
    samples = min(cfg.spp, cfg.transient_spp or cfg.spp)
    if cfg.rr_depth == "auto":
        return auto_rr_depth(media, MITSUBA_SURVIVAL_CAP, samples), "auto"
    missed, where = worst_missed(media, cfg.rr_depth, MITSUBA_SURVIVAL_CAP, samples)
    return RouletteDepth(rr_depth=cfg.rr_depth, missed=missed, medium=where), "reference.rr_depth"


def reference_scene(scene_dir: Path, cfg: ReferenceConfig) -> Scene:
    """The scene folder's scene as the references render it (``reference_scene_and_roulette``)."""
    return reference_scene_and_roulette(scene_dir, cfg)[0]


def reference_scene_and_roulette(scene_dir: Path, cfg: ReferenceConfig) -> tuple[Scene, RouletteDepth, str]:
    """The scene folder's scene as the references render it, with the roulette depth of ``reference_roulette``
    (it changes their noise and what a finite render misses, not what they estimate; render/core/DESIGN.md §12),
    on a film ``cfg.downsample`` times coarser in each axis; and that depth, with its source."""
    scene = Scene.load(Path(scene_dir) / "scene.json")
    roulette, source = reference_roulette(scene, cfg)
    scene = dataclasses.replace(scene, rr_depth=roulette.rr_depth)
    if cfg.downsample > 1:
        camera, k = scene.camera, cfg.downsample
        if camera.width % k or camera.height % k:
            raise ValueError(
                f"reference.downsample {k} does not divide the film's {camera.width} x {camera.height} pixels: "
                "set scene.camera.width and height to multiples of it, or reference.downsample to a common divisor"
            )
        # The same camera on a film k times coarser: its pixels are k x k blocks of ours (compare box-averages).
        scene = dataclasses.replace(
            scene, camera=dataclasses.replace(camera, width=camera.width // k, height=camera.height // k)
        )
    return scene, roulette, source


def run_reference_stage(
    scene_dir: Path, cfg: ReferenceConfig, out_dir: Path, *, seed: int, quiet: bool = False
) -> dict:
    """Render ``scene_dir/scene.json`` as ``cfg`` asks and write the reference outputs into ``out_dir``:
    steady.exr/.npy, frames.npy, frames/frame_NNNN.exr, transient_steady.npy and timing.json."""
    scene_dir, out_dir = Path(scene_dir), Path(out_dir)
    scene, roulette, source = reference_scene_and_roulette(scene_dir, cfg)
    transient = cfg.transient and scene.film.mode == "transient"
    warnings = check_reference_limits(scene, transient=transient, force=cfg.force)
    log.info(
        "reference: roulette from collision %d (%s), expected to leave out %.2g %% of the light (%s)",
        roulette.rr_depth,
        source,
        100 * roulette.missed,
        roulette.medium or "no medium",
    )
    dark = dark_reference(roulette)
    if dark:
        warnings.append(f"the {dark}")
    if cfg.transient and not transient:
        warnings.append("reference.transient is set but scene.film.mode is steady: no transient reference")
    for w in warnings:
        log.warning("reference: %s", w)
    out_dir.mkdir(parents=True, exist_ok=True)
    common: _PassOptions = {
        "spp_per_pass": cfg.spp_per_pass,
        "time_budget_s": cfg.time_budget_s,
        "quiet": quiet,
        "tiles": cfg.tiles,
    }
    timing: dict[str, Any] = {
        "steady": None,
        "transient": None,
        "warnings": warnings,
        "roulette": {**dataclasses.asdict(roulette), "source": source},
        "camera_leg_included": True,
        "frame_units": FRAME_UNITS["bins"],
        "film": {
            "mode": scene.film.mode,
            "temporal_bins": scene.film.temporal_bins,
            "start_opl": scene.film.start_opl,
            "bin_width_opl": scene.film.bin_width_opl,
            "end_opl": scene.film.start_opl + scene.film.temporal_bins * scene.film.bin_width_opl,
            "width": scene.camera.width,
            "height": scene.camera.height,
            "frame_mode": "bins",
            "downsample": cfg.downsample,
        },
    }
    if cfg.steady:
        image, timing["steady"] = render_steady(scene, scene_dir, spp=cfg.spp, seed=seed, variant=cfg.variant, **common)
        write_exr(out_dir / "steady.exr", image)
        steady_timing = timing["steady"]
        rendered_image(
            image,
            out_dir / "steady.png",
            f"Mitsuba 3 volpath, {steady_timing['spp']} spp, {steady_timing['seconds']:.0f} s",
        )
        save_npy_atomic(out_dir / STEADY, image)
    if transient:
        frames, steady, timing["transient"] = render_transient(
            scene, scene_dir, spp=cfg.transient_spp or cfg.spp, seed=seed + TRANSIENT_SEED_OFFSET, **common
        )
        axis = FrameAxis(scene.film.start_opl, scene.film.bin_width_opl, "bins", scene.film.temporal_bins)
        write_frames(out_dir, frames, axis, renderer="mitransient", camera_leg_included=True)
        save_npy_atomic(out_dir / "transient_steady.npy", steady)
        write_exr_frames(out_dir / "frames", frames, axis)
        timing["film"]["start_opl_shift_m"] = timing["transient"]["start_opl_shift_m"]
    write_json_atomic(out_dir / REFERENCE_TIMING, timing)
    return {
        "steady": timing["steady"] is not None,
        "transient": timing["transient"] is not None,
        "frames": scene.film.temporal_bins if transient else 0,
        "seconds": sum(t["seconds"] for t in (timing["steady"], timing["transient"]) if t),
        "warnings": warnings,
    }
