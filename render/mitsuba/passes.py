"""Mitsuba volpath and mitransient renders in passes of ``spp_per_pass``, optionally in tiles, with timings
(render/mitsuba/export.py: each pass of each tile has its own seed; tiles against Mitsuba's ray offsets)."""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from common.memory import PeakMemory
from render.mitsuba.export import Tile, disk_sun_opl_shift, pass_seed, plan_tiles, scene_to_mitsuba, use_variant
from render.scene.model import Scene

log = logging.getLogger(__name__)


def _render_passes(
    scene: Scene,
    scene_dir: Path,
    *,
    transient: bool,
    spp: int,
    spp_per_pass: int,
    seed: int,
    time_budget_s: float | None,
    variant: str,
    quiet: bool,
    tiles: int,
) -> tuple[list[np.ndarray], dict]:
    import mitsuba as mi
    from tqdm import tqdm

    variant = use_variant(variant, transient=transient)
    plan: list[Tile | None] = list(plan_tiles(scene, scene_dir, tiles)) if tiles else [None]
    with PeakMemory() as memory:  # the reference renderer's own peak (common/memory.py)
        # One tile keeps its scene loaded; several are loaded in turn, so that only one is in memory.
        loaded = (
            mi.load_dict(scene_to_mitsuba(scene, scene_dir, transient=transient, spp=spp_per_pass))
            if not tiles
            else None
        )
        sums: list[np.ndarray] = []
        done = passes = 0
        last = 0.0
        start = time.perf_counter()
        desc = "mitransient" if transient else "mitsuba"
        with tqdm(total=None if time_budget_s else spp, unit="spp", desc=desc, leave=False, disable=quiet) as bar:
            while True:
                elapsed = time.perf_counter() - start
                if time_budget_s is None and done >= spp:
                    break
                # The budget replaces spp (ReferenceConfig): stop before the pass that would overrun it.
                if time_budget_s is not None and passes and elapsed + last > time_budget_s:
                    break
                n = spp_per_pass if time_budget_s is not None else min(spp_per_pass, spp - done)
                t0 = time.perf_counter()
                images = _render_pass(mi, scene, scene_dir, plan, loaded, transient, spp_per_pass, seed, passes, n)
                images = [im * n for im in images]
                sums = images if not sums else [a + b for a, b in zip(sums, images)]
                last = time.perf_counter() - t0
                done += n
                passes += 1
                bar.update(n)
    timing = {
        "seconds": time.perf_counter() - start,
        "spp": done,
        "passes": passes,
        "spp_per_pass": spp_per_pass,
        "seed": seed,
        "tiles": len(plan) if tiles else 0,
        **memory.record(),
        "variant": variant,
        "integrator": "transient_prbvolpath" if transient else "volpath",
    }
    return [s / done for s in sums], timing


def _render_pass(mi, scene, scene_dir, plan, loaded, transient, spp_per_pass, seed, index, spp) -> list[np.ndarray]:
    """One pass over every tile: the frames as (H, W, T, 3) and the steady image (H, W, 3), float64."""
    height, width = scene.camera.height, scene.camera.width
    out: list[np.ndarray] = []
    for k, tile in enumerate(plan):
        mi_scene = loaded or mi.load_dict(
            scene_to_mitsuba(scene, scene_dir, transient=transient, spp=spp_per_pass, tile=tile)
        )
        result = mi.render(mi_scene, seed=pass_seed(seed, k, index), spp=spp)
        images = [np.array(result[1]), np.array(result[0])] if transient else [np.array(result)]
        images = [im[..., :3].astype(np.float64) for im in images]
        if tile is None:
            return images
        if not out:
            out = [np.zeros((height, width, *im.shape[2:])) for im in images]
        for whole, part in zip(out, images):
            # mitransient 1.x sizes its transient block by the whole film and fills it from the corner.
            whole[tile.y : tile.y + tile.height, tile.x : tile.x + tile.width] = part[: tile.height, : tile.width]
    return out


def render_steady(
    scene: Scene,
    scene_dir: Path,
    *,
    spp: int,
    spp_per_pass: int = 16,
    seed: int = 0,
    time_budget_s: float | None = None,
    variant: str = "llvm_ad_rgb",
    quiet: bool = False,
    tiles: int = 0,
) -> tuple[np.ndarray, dict]:
    """Mitsuba volpath image (H, W, 3) float32 and its timing {seconds, spp, passes, tiles, peak_memory_mib, variant};
    ``tiles`` > 0 renders the film in that many tiles along its longer side (export.py, ``plan_tiles``)."""
    (image,), timing = _render_passes(
        scene,
        scene_dir,
        transient=False,
        spp=spp,
        spp_per_pass=spp_per_pass,
        seed=seed,
        time_budget_s=time_budget_s,
        variant=variant,
        quiet=quiet,
        tiles=tiles,
    )
    return np.ascontiguousarray(image, dtype=np.float32), timing


def render_transient(
    scene: Scene,
    scene_dir: Path,
    *,
    spp: int,
    spp_per_pass: int = 16,
    seed: int = 0,
    time_budget_s: float | None = None,
    quiet: bool = False,
    tiles: int = 0,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """mitransient frames (T, H, W, 3) float32 in bins of scene.film, its own steady image (H, W, 3), timing;
    ``tiles`` as in ``render_steady``."""
    (frames, steady), timing = _render_passes(
        scene,
        scene_dir,
        transient=True,
        spp=spp,
        spp_per_pass=spp_per_pass,
        seed=seed,
        time_budget_s=time_budget_s,
        variant="llvm_ad_rgb",
        quiet=quiet,
        tiles=tiles,
    )
    frames = np.ascontiguousarray(np.moveaxis(frames, 2, 0), dtype=np.float32)  # (H, W, T, C) -> (T, H, W, C)
    timing["start_opl_shift_m"] = disk_sun_opl_shift(scene, scene_dir)
    return frames, np.ascontiguousarray(steady, dtype=np.float32), timing
