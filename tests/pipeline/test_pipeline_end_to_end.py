"""The whole pipeline on a tiny scene: every stage runs, agrees with the physics it depends on, and a
second run skips everything. A lit block of snow-like medium stands in for the penitente field so the
test needs no geometry stage."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
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


@pytest.mark.mitsuba
def test_references_on_a_coarser_film_face_our_frames_box_averaged(tmp_path):
    """reference.downsample 2: Mitsuba and mitransient render the same camera on a 24 x 16 film while ours is
    48 x 32. Box-averaging ours over 2 x 2 pixels is what the coarser film records, so it must agree with the
    references pixel by pixel (aligned: shifting it by one coarse pixel makes the error several times larger),
    and the compare and composite stages must do exactly that."""
    config = yaml.safe_load(
        block_config(
            tmp_path / "runs",
            name="coarse",
            seed=5,
            width=48,
            height=32,
            reference={"spp": 256, "transient_spp": 256, "spp_per_pass": 128, "downsample": 2},
            render={"iterations": 12, "snapshot_every": 4, "light_paths_per_iteration": 6000},
        )
    )
    # A disk sun: mitransient's directional sun is no plane wavefront, so its frames cannot be compared
    # (render/core/DESIGN.md §11); the disk's are, and that is what the agreement below checks.
    config["scene"]["sun"]["kind"] = "disk"
    config_file = tmp_path / "coarse.yaml"
    config_file.write_text(yaml.safe_dump(config, sort_keys=False))
    cfg = load_config(config_file)
    results = run_stages(cfg, STAGES, quiet=True)
    assert {r.name: r.status for r in results if r.status != "disabled"} == {
        s: "ran" for s in ("scene", "reference", "render", "composite", "compare")
    }
    run = tmp_path / "runs" / "coarse"
    frames, frames_ref = np.load(run / "render" / "frames.npy"), np.load(run / "reference" / "frames.npy")
    assert frames.shape == (12, 32, 48, 3) and frames_ref.shape == (12, 16, 24, 3)
    ours = np.load(run / "render" / "steady.npy").reshape(16, 2, 24, 2, 3).mean(axis=(1, 3))
    ref = np.load(run / "reference" / "steady.npy")
    assert ref.shape == (16, 24, 3)
    lit = ref.mean(-1) > 0.05 * ref.mean(-1).max()
    assert abs(ours[lit].mean() / ref[lit].mean() - 1) < 0.10
    aligned = np.mean((ours - ref) ** 2)
    for axis in (0, 1):
        assert aligned < 0.25 * np.mean((np.roll(ours, 1, axis=axis) - ref) ** 2), axis

    rows = {
        (r["renderer"], r["quantity"]): r
        for r in json.loads((run / "compare" / "manifest.json").read_text())["summary"]["rows"]
    }
    assert ("ours (PTPB)", "frames (bins)") in rows and rows[("ours (PTPB)", "frames (bins)")]["relmse"] is not None
    table = (run / "compare" / "comparison.csv").read_text()
    assert "DISAGREES" not in table
    assert "2× coarser" in (run / "compare" / "report.html").read_text()
    assert probe_mp4(run / "composite" / "side_by_side.mp4")["frames"] == 12
    timing = json.loads((run / "reference" / "timing.json").read_text())
    assert timing["film"]["width"] == 24 and timing["film"]["downsample"] == 2
