"""A film larger than memory: 1920x1080 x 480 gate frames (11.1 GiB of float32) rendered in frame windows
under render.memory_budget_gib = 8, with its wall time and peak resident memory (docs/guide/assets.md).

    python -m pipeline run configs/assets/video_preview.yaml --stage geometry --stage scene
    /usr/bin/time -v python benchmarks/bench_windows.py runs/video_preview/scene /tmp/big_frames.npy

The scene is the video preview's, filmed at full size with four times its frames over the same window. Prints
the figures as JSON and writes them to benchmarks/results/bench_windows.md and .csv.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from _results import start, write_results

from common.memory import PeakMemory
from render.ptpb import load_scene
from render.ptpb.split import render_windowed


def main(scene_dir: str, frames_path: str) -> None:
    run = start()
    scene = load_scene(scene_dir)
    film = scene["film"]
    scene["camera"] = {**scene["camera"], "width": 1920, "height": 1080}
    scene["film"] = {**film, "temporal_bins": 480, "bin_width_opl": film["bin_width_opl"] * film["temporal_bins"] / 480}
    settings = {"iterations": 1, "light_paths_per_iteration": 2000, "frame_mode": "gate", "memory_budget_gib": 8.0}
    t0 = time.perf_counter()
    with PeakMemory() as memory:
        out = render_windowed(scene, settings, frames_path)
    frames = np.load(frames_path, mmap_mode="r")
    report = {
        "frames_shape": list(frames.shape),
        "frames_gib": frames.nbytes / 2**30,
        "windows": out.windows,
        "wall_s": round(time.perf_counter() - t0, 1),
        **memory.record(),
    }
    print(json.dumps(report, indent=2))
    Path(frames_path).unlink()
    table = ["| figure | value |", "|---|---|", *(f"| {key} | {value} |" for key, value in report.items())]
    intro = (
        "A film larger than memory: 1920x1080 x 480 gate frames rendered in frame windows under "
        "render.memory_budget_gib = 8; wall time and peak resident memory of the render.\n\n"
    )
    write_results("bench_windows", intro + "\n".join(table), run, rows=[report])


if __name__ == "__main__":
    main(*sys.argv[1:3])
