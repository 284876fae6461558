"""The `render` stage: run our PTPB renderer on a scene folder and write its outputs.

Outputs in ``out_dir``: ``steady.exr`` and ``steady.npy`` (H, W, 3), ``frames.npy`` (F, H, W, 3)
float32, ``snapshots.npz`` (the steady average every ``snapshot_every`` iterations, with their
iteration counts and wall times, for error-against-time curves) and ``stats.json`` (run
statistics, resolved R_0/T_0, film and time conventions).

With ``render.checkpoint_every_iterations`` or ``checkpoint_every_s`` set, the accumulated render
is saved to ``checkpoint_dir/checkpoint.npz`` as it goes (render/ptpb/checkpoint.py). A checkpoint
found there is continued: the stage runner leaves one only under ``pipeline run --resume``, and a
checkpoint of another scene or other settings is refused. An interrupted render (Ctrl-C) saves
its completed iterations and raises KeyboardInterrupt, so a partial render is never published.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from common.atomic import atomic_path, save_npy_atomic, write_json_atomic
from common.memory import PeakMemory
from pipeline.schema.ptpb import PTPBConfig
from render.engine import load_core_scene
from render.output.exr import write_exr
from render.output.figures import rendered_image
from render.output.files import FRAME_UNITS, FRAMES, OURS_STATS, STEADY, FrameAxis, describe_frames, write_frames
from render.ptpb.api import RenderResult, core_inputs, render
from render.ptpb.checkpoint import CHECKPOINT_NAME, load_checkpoint, render_fingerprint, save_checkpoint
from render.ptpb.split import (
    calibrate,
    frame_count,
    merge_shards,
    plan_windows,
    read_shard,
    refuse_time_budget,
    render_shard,
    render_windowed,
    shard_ranges,
)

log = logging.getLogger(__name__)


def run_render_stage(
    scene_dir: Path,
    cfg: PTPBConfig,
    out_dir: Path,
    *,
    quiet: bool = False,
    checkpoint_dir: Path | None = None,
    shards: int = 1,
    shards_dir: Path | None = None,
) -> dict:
    """Render the scene in ``scene_dir`` with ``cfg`` (in a pipeline, ``Config.render_settings()``: the
    render section with the root's seed and threads and the scene's path depth).

    ``checkpoint_dir`` holds the checkpoint that ``render.checkpoint_every_*`` saves and a resumed run
    continues from (the stage runner passes ``.render.checkpoint`` next to ``out_dir``); without it the
    render neither saves nor resumes checkpoints.

    A film whose buffers exceed ``render.memory_budget_gib`` renders in frame windows straight into
    ``frames.npy``; ``shards`` > 1 renders the iterations in that many shards under ``shards_dir`` (a
    finished shard of the same scene and settings is kept, so shards that SLURM jobs rendered are only
    merged) and merges them (render/ptpb/split.py). A long render first times one iteration and logs
    the predicted wall time and peak memory."""
    out_dir = Path(out_dir)
    scene = load_core_scene(Path(scene_dir))
    path = Path(checkpoint_dir) / CHECKPOINT_NAME if checkpoint_dir is not None else None
    fingerprint = render_fingerprint(*core_inputs(scene, cfg))
    resume = None
    if path is not None and path.exists():
        try:
            resume = load_checkpoint(path, fingerprint)
        except ValueError as exc:
            raise ValueError(
                f"render: {exc}; run without --resume to start over (that removes the checkpoint)"
            ) from None
        log.info("render: resuming from %s after %d iterations", path, resume["stats"]["iterations"])

    def save(state: dict, path: Path) -> None:
        save_checkpoint(path, state, fingerprint)
        log.info("render: checkpoint after %d iterations -> %s", state["stats"]["iterations"], path)

    checkpoint = (lambda state: save(state, path)) if path is not None else None
    out_dir.mkdir(parents=True, exist_ok=True)
    core_scene, core_settings = core_inputs(scene, cfg)
    windows = plan_windows(core_scene, core_settings, cfg.memory_budget_gib) if frame_count(core_scene) else [(0, 0)]
    if shards > 1 and shards_dir is None:
        raise ValueError("render: shards need a folder for their sums (shards_dir)")
    shards_left = (
        shards > 1 and shards_dir is not None and not _all_shards_done(cfg, shards, Path(shards_dir), fingerprint)
    )
    # The merge job of a SLURM run finds every shard done: nothing is left to predict.
    plan = calibrate(core_scene, core_settings, windows, shards) if shards == 1 or shards_left else None
    if plan is not None:
        log.info("render: %s", plan["summary"])
    frames_written = False
    with PeakMemory() as memory:  # this render's own peak, not the whole run's (common/memory.py)
        if shards > 1 and shards_dir is not None:
            result = _render_in_shards(scene, cfg, shards, Path(shards_dir), out_dir / FRAMES, fingerprint, quiet)
            frames_written = True
        elif len(windows) > 1:
            if cfg.checkpoint_every_iterations or cfg.checkpoint_every_s:
                log.warning("render: a windowed render takes no checkpoints (each window is its own pass)")
            log.info(
                "render: %d frames over the memory budget: %d windows %s",
                frame_count(core_scene),
                len(windows),
                windows,
            )
            result = render_windowed(scene, cfg, out_dir / FRAMES, windows, progress=not quiet).result
            frames_written = True
        else:
            result = render(scene, cfg, progress=not quiet, resume=resume, checkpoint=checkpoint)
    if plan is not None:
        result.stats["calibration"] = plan
    if result.stats.get("interrupted"):
        done = result.stats["iterations"]
        if path is not None and (cfg.checkpoint_every_iterations or cfg.checkpoint_every_s):
            log.warning(
                "render interrupted after %d iterations, which %s keeps; continue with `pipeline run --resume`",
                done,
                path,
            )
        else:
            log.warning(
                "render interrupted after %d iterations; set render.checkpoint_every_iterations to be able to "
                "resume interrupted renders",
                done,
            )
        raise KeyboardInterrupt
    write_exr(out_dir / "steady.exr", result.steady)
    rendered_image(
        result.steady,
        out_dir / "steady.png",
        f"ours (PTPB), {result.stats['iterations']} iterations, {result.stats['time_total_s']:.0f} s",
    )
    if result.snapshots:
        with atomic_path(out_dir / "snapshots.npz") as tmp:
            with open(tmp, "wb") as handle:
                np.savez(
                    handle,
                    iterations=np.array([it for it, _ in result.snapshots]),
                    seconds=np.array(result.snapshot_seconds),
                    steady=np.stack([im for _, im in result.snapshots]),
                )
    save_npy_atomic(out_dir / STEADY, result.steady)
    film = scene["film"]
    frame_mode = cfg.frame_mode or film["frame_mode"]
    axis = FrameAxis(film.get("start_opl", 0.0), film.get("bin_width_opl", 0.003), frame_mode, len(result.frames))
    about = {"renderer": "ours (PTPB)", "camera_leg_included": not cfg.camera_unwarp}
    if frames_written:
        describe_frames(out_dir, result.frames.shape, axis, **about)
    else:
        write_frames(out_dir, result.frames, axis, **about)
    stats = {
        **{k: (v.item() if hasattr(v, "item") else v) for k, v in result.stats.items()},
        **memory.record(),
        "frame_mode": frame_mode,
        "temporal_bins": film.get("temporal_bins", 0),
        "start_opl_m": film.get("start_opl", 0.0),
        "bin_width_opl_m": film.get("bin_width_opl", 0.003),
        "frame_units": FRAME_UNITS.get(frame_mode, ""),
        "camera_leg_included": not cfg.camera_unwarp,
        "config": cfg.model_dump(),
    }
    write_json_atomic(out_dir / OURS_STATS, stats)
    return stats


def shard_folder(shards_dir: Path, index: int) -> Path:
    return Path(shards_dir) / f"shard-{index}"


def run_render_shard(
    scene_dir: Path, cfg: PTPBConfig, shards_dir: Path, index: int, shards: int, *, quiet: bool = False
) -> dict:
    """Render shard ``index`` of ``shards`` of the scene in ``scene_dir`` into ``shards_dir/shard-<index>``
    (one SLURM job of `pipeline run --shards K --profile slurm`); a finished shard of the same scene
    and settings is kept."""
    refuse_time_budget(cfg)
    scene = load_core_scene(Path(scene_dir))
    fingerprint = render_fingerprint(*core_inputs(scene, cfg))
    folder = shard_folder(shards_dir, index)
    if _shard_done(read_shard(folder), fingerprint, shard_ranges(cfg.iterations, shards)[index]):
        log.info("render: shard %d/%d is already done (%s)", index + 1, shards, folder)
        return read_shard(folder) or {}
    return render_shard(scene, cfg, folder, index, shards, progress=not quiet, fingerprint=fingerprint)


def _shard_done(record: dict | None, fingerprint: dict, iterations: tuple[int, int]) -> bool:
    """A finished shard of this scene and settings over the same iterations."""
    return (
        record is not None
        and record.get("fingerprint") == fingerprint
        and (record["first_iteration"], record["end_iteration"]) == tuple(iterations)
    )


def _all_shards_done(cfg: PTPBConfig, shards: int, shards_dir: Path, fingerprint: dict) -> bool:
    ranges = shard_ranges(cfg.iterations, shards)
    return all(_shard_done(read_shard(shard_folder(shards_dir, k)), fingerprint, ranges[k]) for k in range(shards))


def _render_in_shards(
    scene: dict, cfg: PTPBConfig, shards: int, shards_dir: Path, frames_path: Path, fingerprint: dict, quiet: bool
) -> RenderResult:
    refuse_time_budget(cfg)
    ranges = shard_ranges(cfg.iterations, shards)  # refuses more shards than iterations before any work
    folders = [shard_folder(shards_dir, k) for k in range(shards)]
    t0 = time.perf_counter()
    rendered = 0
    for k, folder in enumerate(folders):
        if _shard_done(read_shard(folder), fingerprint, ranges[k]):
            log.info("render: shard %d/%d already done", k + 1, shards)
            continue
        render_shard(scene, cfg, folder, k, shards, progress=not quiet, fingerprint=fingerprint)
        rendered += 1
        per_shard = (time.perf_counter() - t0) / rendered
        log.info(
            "render: shard %d/%d done; ETA %.0f s for the %d left",
            k + 1,
            shards,
            per_shard * (shards - k - 1),
            shards - k - 1,
        )
    return merge_shards(folders, frames_path)
