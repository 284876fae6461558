"""The render stage writes steady.exr/.npy, frames.npy and stats.json whose numbers agree."""

from __future__ import annotations

import json

import numpy as np

from pipeline.schema.ptpb import BeamRadius, PTPBConfig
from render.ptpb.stage import run_render_stage


def test_render_stage_outputs(scene_dir):
    cfg = PTPBConfig(iterations=2, light_paths_per_iteration=2000, initial_beam_radius=BeamRadius(value=0.03, unit="m"))
    out = scene_dir / "out"
    stats = run_render_stage(scene_dir, cfg.model_copy(update={"seed": 1, "threads": 2}), out, quiet=True)
    steady, frames = np.load(out / "steady.npy"), np.load(out / "frames.npy")
    assert steady.shape == (10, 12, 3) and frames.shape == (30, 10, 12, 3) and frames.dtype == np.float32
    assert (out / "steady.exr").stat().st_size > 0
    saved = json.loads((out / "stats.json").read_text())
    assert saved["iterations"] == 2 and saved["frame_mode"] == "bins" and stats["iterations"] == 2
    assert abs(frames.sum() / steady.sum() + saved["out_of_window_fraction"] - 1) < 1e-3
