"""The whole pipeline on a tiny scene: every stage runs, agrees with the physics it depends on, and a
second run skips everything. A lit block of snow-like medium stands in for the penitente field so the
test needs no geometry stage."""

from __future__ import annotations

import json

import numpy as np
import pytest
from block_scene import block_config

from pipeline.config import load_config
from pipeline.runner import run_stages
from pipeline.stages import STAGES
from render.output.video import probe_mp4


@pytest.mark.mitsuba
def test_every_stage_runs_and_agrees_with_the_reference(tmp_path):
    config_file = tmp_path / "tiny.yaml"
    config_file.write_text(
        block_config(
            tmp_path / "runs",
            name="tiny",
            seed=3,
            reference={"spp": 256, "transient_spp": 256, "spp_per_pass": 128},
            render={"iterations": 12, "snapshot_every": 4, "light_paths_per_iteration": 6000},
        )
    )
    cfg = load_config(config_file)
    results = run_stages(cfg, STAGES, quiet=True)
    status = {r.name: r.status for r in results}
    assert status == {
        "geometry": "disabled",
        "scene": "ran",
        "reference": "ran",
        "render": "ran",
        "composite": "ran",
        "compare": "ran",
        "lidar": "disabled",
    }
    run = tmp_path / "runs" / "tiny"
    for stage in ("scene", "reference", "render", "composite", "compare"):
        manifest = json.loads((run / stage / "manifest.json").read_text())
        assert manifest["outputs"], stage

    # Ours and Mitsuba see the same lit block: mean radiance within 10 % at these tiny budgets.
    ours, ref = np.load(run / "render" / "steady.npy"), np.load(run / "reference" / "steady.npy")
    lit = ref.mean(-1) > 0.05 * ref.mean(-1).max()
    assert lit.sum() > 50
    ratio = ours[lit].mean() / ref[lit].mean()
    assert abs(ratio - 1) < 0.10, ratio
    # Both transient stacks share the auto window and hold the steady energy (no sky here).
    frames, frames_ref = np.load(run / "render" / "frames.npy"), np.load(run / "reference" / "frames.npy")
    assert frames.shape == frames_ref.shape == (12, 16, 24, 3)
    stats = json.loads((run / "render" / "stats.json").read_text())
    assert frames.sum() / ours.sum() == pytest.approx(1 - stats["out_of_window_fraction"], abs=1e-4)
    assert stats["out_of_window_fraction"] < 0.05

    video = probe_mp4(run / "composite" / "transient.mp4")
    assert video["frames"] == 12 and video["height"] >= 64
    assert probe_mp4(run / "composite" / "side_by_side.mp4")["frames"] == 12
    table = (run / "compare" / "comparison.csv").read_text()
    assert "ours (PTPB)" in table and "Mitsuba volpath" in table
    report = (run / "compare" / "report.html").read_text()
    for name in ("transient.mp4", "streak_x.png", "side_by_side.png", "error_vs_time.png"):
        assert name in report, name

    again = run_stages(cfg, STAGES, quiet=True)
    assert {r.name: r.status for r in again if r.status != "disabled"} == {
        s: "skipped" for s in ("scene", "reference", "render", "composite", "compare")
    }
