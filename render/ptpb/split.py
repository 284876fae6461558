"""One render split two ways: frame windows (a film larger than the memory budget) and shards (its
iterations over many machines). Both give the film a single pass would give (render/core/DESIGN.md §9
"Windows and shards").

**Windows.** Each pass re-traces the same keyed random streams and keeps only the frames of its window
[first, first + count) (the film's ``window_first``/``window_count``); early and late stay relative to the
whole film, and steady, early and late come out the same in every pass, so the first pass's are kept.
Frames go straight into a disk-backed ``frames.npy`` (created by ``np.lib.format.open_memmap``, written
with plain file writes), so the whole film never sits in memory. ``plan_windows`` sizes the windows so
that one pass fits the budget.

**Shards.** Shard k of K runs iterations [a_k, b_k) of the global schedule (the bandwidths depend only on
the iteration index) with ``keep_sums``: the core sums its frames in float64 and returns the undivided
sums. ``save_shard`` writes them to a folder (``frames_sum.npy`` float64, ``sums.npz`` with steady, early,
late and the stats), atomically; ``merge_shards`` adds the shards in index order and divides by the total
iteration count. Windows apply inside a shard too.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from common.atomic import atomic_path, write_json_atomic
from pipeline.schema.ptpb import PTPBConfig
from render.ptpb.api import RenderResult, core_inputs, render

SHARD_SUMS = "sums.npz"
SHARD_FRAMES = "frames_sum.npy"
SHARD_DONE = "shard.json"  # written last: a shard folder without it is incomplete
GIB = float(1 << 30)
# Renders with fewer pixel-iterations than this skip the calibration (a few minutes on 2 cores at most).
CALIBRATE_FROM_PIXEL_ITERATIONS = 2e7
# Calibration probes a film larger than four times this on a camera shrunk to about this many pixels.
PROBE_PIXELS = 1 << 17


class SplitError(ValueError):
    """A window or shard plan that cannot work; the message names the key to change."""


def frame_count(scene: Mapping[str, Any], frame_mode: str | None = None) -> int:
    """Frames of the whole film (0 in steady mode)."""
    film = scene["film"]
    return 0 if (frame_mode or film["frame_mode"]) == "steady" else int(film.get("temporal_bins", 0))


def with_window(scene: Mapping[str, Any], first: int, count: int) -> dict:
    """The scene with its film restricted to frames [first, first + count)."""
    return {**scene, "film": {**scene["film"], "window_first": int(first), "window_count": int(count)}}


def window_bytes(scene: dict, core_settings: dict, count: int) -> float:
    """Peak bytes of the core's image buffers for one pass of ``count`` frames."""
    from render import _core

    return float(_core.ptpb_memory_bytes(with_window(scene, 0, count), core_settings, False))


def plan_windows(scene: dict, core_settings: dict, budget_gib: float | None) -> list[tuple[int, int]]:
    """Windows (first, count) covering the film, each pass within ``budget_gib`` (None: one pass).
    The buffers grow linearly with the frame count, so the largest window follows from two sizes."""
    frames = frame_count(scene)
    if budget_gib is None or frames == 0:
        return [(0, max(frames, 0))] if frames else [(0, 0)]
    budget = budget_gib * GIB
    one, two = window_bytes(scene, core_settings, 1), window_bytes(scene, core_settings, 2)
    per_frame, fixed = two - one, one - (two - one)
    fit = int((budget - fixed) // per_frame) if per_frame > 0 else frames
    if fit < 1:
        raise SplitError(
            f"render.memory_budget_gib = {budget_gib:g} holds not even one frame of this film "
            f"({one / GIB:.2f} GiB for a window of one frame); raise render.memory_budget_gib or lower "
            "scene.camera.width/height"
        )
    count = min(fit, frames)
    passes = math.ceil(frames / count)
    count = math.ceil(frames / passes)  # even windows: the same work in every pass
    return [(first, min(count, frames - first)) for first in range(0, frames, count)]


def shard_ranges(iterations: int, shards: int) -> list[tuple[int, int]]:
    """Iterations [a_k, b_k) of each of ``shards`` shards: contiguous, as even as possible."""
    if shards < 1:
        raise SplitError(f"--shards must be >= 1, got {shards}")
    if shards > iterations:
        raise SplitError(
            f"--shards {shards} exceeds render.iterations = {iterations}; use at most as many shards as iterations"
        )
    bounds = [iterations * k // shards for k in range(shards + 1)]
    return list(zip(bounds[:-1], bounds[1:], strict=True))


def refuse_time_budget(cfg: PTPBConfig) -> None:
    """Time-budgeted renders cannot be split into shards: a shard runs a fixed range of iterations."""
    if cfg.time_budget_s is not None:
        raise SplitError(
            "render.time_budget_s and --shards do not mix: a shard runs a fixed range of render.iterations; "
            "set render.time_budget_s: null (and render.iterations), or run without --shards"
        )


def create_npy(path: Path, shape: tuple[int, ...], dtype: type) -> int:
    """Create an ``.npy`` of ``shape`` (sparse on disk until written); return the offset of its data."""
    np.lib.format.open_memmap(path, mode="w+", dtype=dtype, shape=shape).flush()
    return path.stat().st_size - int(np.prod(shape)) * np.dtype(dtype).itemsize


def write_frames_at(path: Path, offset: int, first: int, frames: np.ndarray) -> None:
    """Write ``frames`` as frames ``first`` on of the ``.npy`` at ``path`` with plain file writes, a frame at a
    time: unlike a memory map, written pages never count in this process's resident memory."""
    frame_bytes = int(np.prod(frames.shape[1:])) * frames.dtype.itemsize
    with open(path, "r+b") as handle:
        handle.seek(offset + first * frame_bytes)
        for frame in frames:
            handle.write(np.ascontiguousarray(frame).data)


@dataclass
class Windowed:
    """What a windowed render leaves besides its frames file."""

    result: RenderResult  # steady, early, late and stats of the first pass; frames: the memmap
    windows: list[tuple[int, int]]
    seconds: float


def _passes(
    scene: dict,
    core_settings: dict,
    windows: Sequence[tuple[int, int]],
    progress: bool | Callable[[dict], bool | None],
    **overrides: Any,
) -> Iterator[tuple[int, int, RenderResult]]:
    for first, count in windows:
        result = render(with_window(scene, first, count), core_settings, progress=progress, **overrides)
        if result.stats.get("interrupted") or result.stats.get("cancelled"):
            raise KeyboardInterrupt
        yield first, count, result


def render_windowed(
    scene: dict,
    settings: PTPBConfig | Mapping[str, Any],
    frames_path: str | Path,
    windows: Sequence[tuple[int, int]] | None = None,
    *,
    progress: bool | Callable[[dict], bool | None] = False,
) -> Windowed:
    """Render ``scene`` window by window into ``frames_path`` (a ``frames.npy`` written under a temporary
    name and renamed when complete). ``windows`` default to ``plan_windows`` under the settings' memory
    budget. Checkpoints do not apply (each pass is short)."""
    scene, core_settings = core_inputs(scene, settings)
    budget = core_settings.get("memory_budget_gib")
    windows = list(windows) if windows is not None else plan_windows(scene, core_settings, budget)
    total = frame_count(scene)
    film = scene["film"]
    shape = (total, int(scene["camera"]["height"]), int(scene["camera"]["width"]), 3)
    t0 = time.perf_counter()
    first_result: RenderResult | None = None
    with atomic_path(frames_path) as tmp:
        offset = create_npy(tmp, shape, np.float32)
        for first, _count, result in _passes(scene, core_settings, windows, progress):
            write_frames_at(tmp, offset, first, result.frames)
            if first_result is None:
                first_result = result
                first_result.frames = np.empty((0, *shape[1:]), np.float32)
            else:
                first_result.stats["time_total_s"] += result.stats["time_total_s"]
            del result
    assert first_result is not None
    first_result.stats["windows"] = [list(w) for w in windows]
    first_result.stats["temporal_bins"] = film.get("temporal_bins", 0)
    first_result.frames = np.load(frames_path, mmap_mode="r")
    return Windowed(first_result, windows, time.perf_counter() - t0)


def render_shard(
    scene: dict,
    settings: PTPBConfig | Mapping[str, Any],
    folder: str | Path,
    index: int,
    shards: int,
    *,
    progress: bool | Callable[[dict], bool | None] = False,
    fingerprint: Mapping[str, Any] | None = None,
) -> dict:
    """Render shard ``index`` of ``shards`` into ``folder`` (float64 sums; windows under the memory budget)
    and return its record. The folder appears complete or not at all."""
    if isinstance(settings, PTPBConfig):
        refuse_time_budget(settings)
    scene, core_settings = core_inputs(scene, settings)
    if core_settings.get("time_budget_s"):
        raise SplitError("render.time_budget_s and --shards do not mix; set render.time_budget_s: null")
    first_iteration, end = shard_ranges(int(core_settings["iterations"]), shards)[index]
    core_settings = {
        **core_settings,
        "iterations": end,
        "first_iteration": first_iteration,
        "keep_sums": True,
        "snapshot_every": 0,
        "checkpoint_every_iterations": 0,
        "checkpoint_every_s": 0.0,
    }
    budget = core_settings.get("memory_budget_gib")
    windows = plan_windows(scene, core_settings, budget) if frame_count(scene) else [(0, 0)]
    folder = Path(folder)
    staging = folder.with_name(f".{folder.name}.staging")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    t0 = time.perf_counter()
    shape = (frame_count(scene), int(scene["camera"]["height"]), int(scene["camera"]["width"]), 3)
    offset = create_npy(staging / SHARD_FRAMES, shape, np.float64)
    stats: dict[str, Any] = {}
    sums: dict[str, np.ndarray] = {}
    passes = windows if shape[0] else []
    if not passes:  # steady film: one pass, no frames
        out = render(scene, core_settings, progress=progress)
        sums, stats = _shard_sums(out)
    for first, _count, out in _passes(scene, core_settings, passes, progress):
        write_frames_at(staging / SHARD_FRAMES, offset, first, out.frames)
        if not sums:
            sums, stats = _shard_sums(out)
        del out
    with open(staging / SHARD_SUMS, "wb") as handle:
        np.savez(handle, steady=sums["steady"], early=sums["early"], late=sums["late"])
    record = {
        "index": index,
        "shards": shards,
        "first_iteration": first_iteration,
        "end_iteration": end,
        "iterations": end - first_iteration,
        "windows": [list(w) for w in windows],
        "seconds": time.perf_counter() - t0,
        "stats": stats,
        "fingerprint": dict(fingerprint or {}),
    }
    write_json_atomic(staging / SHARD_DONE, record)
    shutil.rmtree(folder, ignore_errors=True)
    staging.replace(folder)
    return record


def _shard_sums(out: RenderResult) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    # A keep_sums render carries its float64 sums in RenderResult's image fields (see api.render).
    sums = {"steady": out.steady, "early": out.early, "late": out.late}
    stats = {k: (v.item() if hasattr(v, "item") else v) for k, v in out.stats.items()}
    return sums, stats


def read_shard(folder: str | Path) -> dict | None:
    """A finished shard's record, or None when the folder is missing or incomplete."""
    path = Path(folder) / SHARD_DONE
    return json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None


def merge_shards(
    folders: Sequence[str | Path], frames_path: str | Path, *, chunk_bytes: float = 512 * 2**20
) -> RenderResult:
    """Add the shards' float64 sums in index order and divide by the total iterations; the frames go
    to ``frames_path`` (float32, written under a temporary name, about ``chunk_bytes`` of sums at a time)."""
    records = [read_shard(f) for f in folders]
    missing = [str(f) for f, r in zip(folders, records, strict=True) if r is None]
    if missing:
        raise SplitError(f"shards not finished: {', '.join(missing)}; run them first (pipeline shard ...)")
    done = [r for r in records if r is not None]
    order = sorted(range(len(done)), key=lambda k: done[k]["index"])
    total = sum(r["iterations"] for r in done)
    ranges = sorted((r["first_iteration"], r["end_iteration"]) for r in done)
    if ranges[0][0] != 0 or any(a[1] != b[0] for a, b in zip(ranges, ranges[1:], strict=False)):
        raise SplitError(f"the shards' iteration ranges {ranges} do not cover [0, N) without gaps; rerun the shards")
    images: dict[str, np.ndarray] = {}
    for k in order:
        with np.load(Path(folders[k]) / SHARD_SUMS) as z:
            for name in ("steady", "early", "late"):
                images[name] = images[name] + z[name] if name in images else z[name].astype(np.float64)
    shard_paths = [Path(folders[k]) / SHARD_FRAMES for k in order]
    shape = np.load(shard_paths[0], mmap_mode="r").shape
    frames_per_chunk = max(1, int(chunk_bytes // (8 * max(1, int(np.prod(shape[1:]))))))
    with atomic_path(frames_path) as tmp:
        offset = create_npy(tmp, shape, np.float32)
        for start in range(0, shape[0], frames_per_chunk):
            chunk = slice(start, start + frames_per_chunk)
            acc: np.ndarray | None = None
            for path in shard_paths:  # mapped a chunk at a time, so mapped pages never add up to the film
                part = np.load(path, mmap_mode="r")
                acc = np.array(part[chunk], dtype=np.float64) if acc is None else acc + part[chunk]
                del part
            assert acc is not None
            write_frames_at(tmp, offset, start, (acc / total).astype(np.float32))
    steady_total = float(images["steady"].sum())
    stats = dict(done[order[0]]["stats"])
    stats.update(
        {
            "iterations": total,
            "shards": len(done),
            "shard_ranges": ranges,
            "shard_seconds": [done[k]["seconds"] for k in order],
            "time_total_s": sum(done[k]["stats"].get("time_total_s", 0.0) for k in order),
            "light_paths": sum(done[k]["stats"].get("light_paths", 0) for k in order),
            "beams": sum(done[k]["stats"].get("beams", 0) for k in order),
            "out_of_window_fraction": float((images["early"].sum() + images["late"].sum()) / steady_total)
            if steady_total > 0
            else 0.0,
            "early_fraction": float(images["early"].sum() / steady_total) if steady_total > 0 else 0.0,
            "late_fraction": float(images["late"].sum() / steady_total) if steady_total > 0 else 0.0,
        }
    )
    return RenderResult(
        (images["steady"] / total).astype(np.float32),
        np.load(frames_path, mmap_mode="r"),
        (images["early"] / total).astype(np.float32),
        (images["late"] / total).astype(np.float32),
        stats,
    )


def probe_factors(width: int, height: int) -> tuple[int, ...]:
    """The factors by which calibration shrinks the camera in each axis: (1,), the real size, for a film
    of up to PROBE_PIXELS x 4 pixels; above it (k, 2k), k the smallest power of two that brings the film
    down to PROBE_PIXELS or fewer."""
    pixels = width * height
    if pixels <= 4 * PROBE_PIXELS:
        return (1,)
    k = 2
    while pixels / (k * k) > PROBE_PIXELS:
        k *= 2
    return (k, 2 * k)


def shrunk(scene: Mapping[str, Any], k: int) -> dict:
    """The scene with its camera k times coarser in each axis: the same field of view and pose, so a pixel
    costs what it costs at the real size (the kernel radii are already in metres)."""
    camera = scene["camera"]
    size = {"width": max(1, round(camera["width"] / k)), "height": max(1, round(camera["height"] / k))}
    return {**scene, "camera": {**camera, **size}}


def calibrate(
    scene: dict, core_settings: dict, windows: Sequence[tuple[int, int]], shards: int = 1
) -> dict[str, Any] | None:
    """Time two iterations of the first window and predict the whole render: wall time and peak memory of
    one pass. None for a short render (below CALIBRATE_FROM_PIXEL_ITERATIONS) or a time-budgeted one.

    A pass costs a fixed part (the scene's structures, the film's buffers, the average at the end) and its
    iterations; the first iteration also has the widest kernels. Timing the iterations apart (a snapshot
    after each) gives the fixed part with the first iteration, the second iteration alone, and the finish:
    a pass is predicted as fixed + first + (iterations - 1) x second + finish, times the windows, split
    evenly over shards. One iteration's total times the iterations counted the fixed part and the first
    iteration's kernels every time: 75 % high on the full video (issue 32).

    A large film is not probed at its own size, which cost the full video 2.6 min and would cost the 4K
    poster about 7 min of rendering thrown away. The camera is shrunk instead (``probe_factors``) and
    probed at two sizes P1 > P2 pixels: an iteration costs a + b P, a part that does not depend on the
    pixels (light paths, beams and their structure) and one that does (the camera paths), and the two
    timings give both. The start-up is the larger probe's, with one iteration at the real size; the finish
    (averaging the sums) scales with the pixels; the peak memory is the larger probe's with its image
    buffers replaced by the real film's."""
    from common.memory import PeakMemory

    iterations = int(core_settings.get("iterations", 0))
    width, height = int(scene["camera"]["width"]), int(scene["camera"]["height"])
    pixels = width * height
    if core_settings.get("time_budget_s") or pixels * iterations < CALIBRATE_FROM_PIXEL_ITERATIONS:
        return None
    first, count = windows[0]
    window = with_window(scene, first, count) if count else scene
    probe_iterations = min(2, iterations)
    probes = []
    for k in probe_factors(width, height):
        probe = shrunk(window, k)
        with PeakMemory() as memory:
            out = render(
                probe,
                {
                    **core_settings,
                    "iterations": probe_iterations,
                    "snapshot_every": 1,
                    "checkpoint_every_iterations": 0,
                },
            )
        timing = pass_timing(float(out.stats["time_total_s"]), list(out.snapshot_seconds))
        probe_pixels = int(probe["camera"]["width"]) * int(probe["camera"]["height"])
        probe_buffers = window_bytes(probe, core_settings, count) if count else 0.0
        probes.append((probe_pixels, timing, memory.peak_mib * 2**20 - probe_buffers))
        del out
    (p1, timing, other_bytes), *rest = probes
    if rest:
        p2, t2, _ = rest[0]
        slope = max(0.0, (timing["per_iteration_s"] - t2["per_iteration_s"]) / (p1 - p2))
        fixed = max(0.0, timing["per_iteration_s"] - slope * p1)
        per_iteration = fixed + slope * pixels
        to_first = timing["to_first_s"] - timing["per_iteration_s"] + per_iteration
        finish = timing["finish_s"] * pixels / p1
    else:
        per_iteration, to_first, finish = timing["per_iteration_s"], timing["to_first_s"], timing["finish_s"]
    passes = max(1, len([w for w in windows if w[1] > 0]))
    per_pass = to_first + finish + (iterations - 1) * per_iteration
    wall = per_pass * passes
    per_shard = wall / max(1, shards)
    buffers = window_bytes(scene, core_settings, max(c for _, c in windows)) if windows[0][1] else 0.0
    peak = (other_bytes + buffers) / GIB
    probed = f"{width}x{height}" if not rest else f"{width}x{height} shrunk to {p1} and {rest[0][0]} pixels"
    summary = (
        f"calibration: {probe_iterations} iterations of {count or 'no'} frames at {probed}: start-up and first "
        f"iteration {to_first:.1f} s, then {per_iteration:.1f} s an iteration, {finish:.1f} s to finish; "
        f"predicted {wall / 60:.1f} min for {iterations} iterations x {passes} window(s)"
        + (f", {per_shard / 60:.1f} min per shard on {shards} shards" if shards > 1 else "")
        + f", peak memory about {peak:.2f} GiB ({buffers / GIB:.2f} GiB of image buffers a pass)"
    )
    return {
        "seconds_per_iteration": per_iteration,
        "seconds_to_first_iteration": to_first,
        "seconds_to_finish": finish,
        "predicted_wall_s": wall,
        "predicted_wall_s_per_shard": per_shard,
        "windows": passes,
        "predicted_peak_gib": peak,
        "image_buffers_gib": buffers / GIB,
        "probe_pixels": [p for p, _, _ in probes],
        "summary": summary,
    }


def pass_timing(total_s: float, snapshot_seconds: Sequence[float]) -> dict[str, float]:
    """A calibration render's time split at its snapshots (one after each iteration): ``to_first_s`` (start-up
    and the first iteration), ``per_iteration_s`` (the second iteration; the first when only one ran) and
    ``finish_s`` (from the last iteration to the result)."""
    if not snapshot_seconds:
        raise ValueError("calibration needs the render's snapshot after each iteration (snapshot_every = 1)")
    times = [float(t) for t in snapshot_seconds]
    per_iteration = times[1] - times[0] if len(times) > 1 else times[0]
    return {"to_first_s": times[0], "per_iteration_s": per_iteration, "finish_s": max(0.0, total_s - times[-1])}
