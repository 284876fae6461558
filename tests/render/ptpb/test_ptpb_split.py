"""Split invariance (render/core/DESIGN.md §9 "Windows and shards"): a film rendered in frame windows, or
its iterations in shards merged, equals the single-pass render of all iterations."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.schema.ptpb import PTPBConfig
from render.ptpb import render
from render.ptpb.split import SplitError, merge_shards, plan_windows, render_shard, render_windowed, shard_ranges
from render.scene.shapes import box_mesh, quad_mesh

ITERATIONS = 8


def medium_and_floor_scene(frame_mode: str) -> dict:
    """A scattering cube on a diffuse floor under an area light: beams and surface photons both splat."""
    cv, cf = box_mesh()
    lv, lf = quad_mesh(center=(0, 1.5, 0), u=(0.25, 0, 0), v=(0, 0, 0.25))
    fv, ff = quad_mesh(center=(0, -0.5, 0), u=(2.0, 0, 0), v=(0, 0, -2.0))
    return {
        "media": [{"sigma_s": [3.6, 5.4, 7.2], "sigma_a": [0.4, 0.6, 0.8], "g": 0.7}],
        "shapes": [
            {"vertices": cv, "faces": cf, "kind": "null", "interior": 0},
            {"vertices": lv, "faces": lf, "kind": "diffuse", "radiance": [20, 20, 20]},
            {"vertices": fv, "faces": ff, "kind": "diffuse", "albedo": [0.8, 0.7, 0.6]},
        ],
        "camera": {
            "origin": [0, 0.8, 2.89],
            "target": [0, 0, 0],
            "up": [0, 1, 0],
            "fov": 40,
            "width": 12,
            "height": 10,
        },
        "film": {"frame_mode": frame_mode, "temporal_bins": 30, "start_opl": 3.5, "bin_width_opl": 0.05},
    }


SETTINGS: dict = {
    "iterations": ITERATIONS,
    "light_paths_per_iteration": 300,
    "snapshot_every": 0,
    "threads": 2,
    "seed": 5,
    "memory_budget_gib": None,
}


def assert_close(ours: np.ndarray, reference: np.ndarray) -> None:
    assert ours.shape == reference.shape
    scale = np.maximum(np.abs(reference), 1e-30)
    relative = np.abs(ours.astype(np.float64) - reference) / scale
    assert np.count_nonzero(reference) > 0
    assert relative.max() <= 1e-6, f"largest relative difference {relative.max():.3g}"


# The medium's estimators (render/core/DESIGN.md §12): each splats through the same film, so windows and
# shards must join for both.
ESTIMATORS = ["beams", "paths"]


@pytest.mark.parametrize("estimator", ESTIMATORS)
@pytest.mark.parametrize("frame_mode", ["bins", "gate"])
def test_windows_join_into_the_single_pass_film(tmp_path, frame_mode, estimator):
    scene = medium_and_floor_scene(frame_mode)
    settings = {**SETTINGS, "medium_estimator": estimator}
    whole = render(scene, settings)
    assert whole.stats["surface_pairs"] > 0
    assert estimator == "paths" or whole.stats["pair_evaluations"] > 0  # the medium's beams were gathered
    windows = [(0, 7), (7, 7), (14, 9), (23, 7)]
    first = render_windowed(scene, settings, tmp_path / "a.npy", windows)
    again = render_windowed(scene, settings, tmp_path / "b.npy", windows)
    assert_close(np.asarray(first.result.frames), whole.frames)
    np.testing.assert_array_equal(np.asarray(first.result.frames), np.asarray(again.result.frames))
    for name in ("steady", "early", "late"):
        np.testing.assert_array_equal(getattr(first.result, name), getattr(whole, name))


def test_a_window_keeps_only_its_frames_and_early_late_mean_outside_the_whole_film():
    scene = medium_and_floor_scene("bins")
    whole = render(scene, SETTINGS)
    window = render({**scene, "film": {**scene["film"], "window_first": 10, "window_count": 5}}, SETTINGS)
    assert window.frames.shape == (5, 10, 12, 3)
    np.testing.assert_array_equal(window.frames, whole.frames[10:15])
    np.testing.assert_array_equal(window.late, whole.late)
    np.testing.assert_array_equal(window.early, whole.early)


@pytest.mark.parametrize("estimator", ESTIMATORS)
@pytest.mark.parametrize("frame_mode", ["bins", "gate"])
def test_four_shards_merged_equal_the_single_process_render(tmp_path, frame_mode, estimator):
    scene = medium_and_floor_scene(frame_mode)
    settings = {**SETTINGS, "medium_estimator": estimator}
    whole = render(scene, settings)
    folders = [tmp_path / f"shard-{k}" for k in range(4)]
    for k in (2, 0, 3, 1):  # finishing order does not matter
        render_shard(scene, settings, folders[k], k, 4)
    merged = merge_shards(folders, tmp_path / "frames.npy", chunk_bytes=7 * 8 * 360)  # 7 frames a chunk
    assert merged.stats["iterations"] == ITERATIONS
    assert_close(np.asarray(merged.frames), whole.frames)
    for name in ("steady", "early", "late"):
        assert_close(getattr(merged, name), getattr(whole, name))


def test_windows_fit_the_budget_and_cover_the_film():
    from render.ptpb.api import core_inputs
    from render.ptpb.split import window_bytes

    scene, core = core_inputs(medium_and_floor_scene("gate"), SETTINGS)
    budget = window_bytes(scene, core, 8) / 2**30
    windows = plan_windows(scene, core, budget)
    assert len(windows) == 4 and sum(c for _, c in windows) == 30
    assert all(window_bytes(scene, core, c) <= budget * 2**30 for _, c in windows)
    assert [f for f, _ in windows] == [0, 8, 16, 24]


def test_shard_ranges_and_refusals():
    assert shard_ranges(10, 4) == [(0, 2), (2, 5), (5, 7), (7, 10)]
    with pytest.raises(SplitError, match="--shards 5 exceeds render.iterations"):
        shard_ranges(4, 5)
    from render.ptpb.split import refuse_time_budget

    with pytest.raises(SplitError, match="render.time_budget_s"):
        refuse_time_budget(PTPBConfig(time_budget_s=10))


def test_render_stage_windows_over_budget_and_merges_shards(scene_dir, tmp_path):
    from render.ptpb.stage import run_render_stage

    cfg = PTPBConfig(iterations=4, light_paths_per_iteration=200, snapshot_every=0, threads=2, seed=3)
    single = run_render_stage(
        scene_dir, cfg.model_copy(update={"memory_budget_gib": None}), tmp_path / "one", quiet=True
    )
    frames = np.load(tmp_path / "one" / "frames.npy")
    # A budget that holds about a third of the 30 frames: the stage renders windows into frames.npy.
    tight = cfg.model_copy(update={"memory_budget_gib": 0.16e-3})
    windowed = run_render_stage(scene_dir, tight, tmp_path / "win", quiet=True)
    assert len(windowed["windows"]) > 1 and "windows" not in single
    np.testing.assert_array_equal(np.load(tmp_path / "win" / "frames.npy"), frames)
    shards = run_render_stage(scene_dir, cfg, tmp_path / "sh", quiet=True, shards=2, shards_dir=tmp_path / "shards")
    assert shards["shards"] == 2 and shards["iterations"] == 4
    assert_close(np.load(tmp_path / "sh" / "frames.npy"), frames)


def test_calibration_predicts_from_the_second_iteration_and_counts_the_start_up_once(monkeypatch):
    """Start-up and the first iteration take 15 s, each later one 2 s, the finish 3 s: 64 iterations in two
    windows take 2 x (15 + 63 x 2 + 3) = 288 s. One iteration's total times the iterations (the old
    prediction) would say 2 x 64 x 18 = 2304 s. A film this small (640 x 360) is probed at its own size."""
    from render.ptpb import split

    class Timed:
        stats = {"time_total_s": 20.0}
        snapshot_seconds = [15.0, 17.0]

    asked = []

    def fake_render(scene, settings, **kwargs):
        asked.append((dict(scene["camera"]), dict(settings)))
        return Timed()

    monkeypatch.setattr(split, "render", fake_render)
    monkeypatch.setattr(split, "window_bytes", lambda scene, settings, count: count * 1e6)
    scene = {"camera": {"width": 640, "height": 360}, "film": {"temporal_bins": 240, "frame_mode": "bins"}}
    plan = split.calibrate(scene, {"iterations": 256}, [(0, 120), (120, 120)])
    assert [(c["width"], c["height"], s["iterations"], s["snapshot_every"]) for c, s in asked] == [(640, 360, 2, 1)]
    assert plan is not None and plan["predicted_wall_s"] == pytest.approx(2 * (15 + 255 * 2 + 3))
    assert plan["seconds_per_iteration"] == pytest.approx(2.0) and plan["seconds_to_finish"] == pytest.approx(3.0)
    with pytest.raises(ValueError, match="snapshot after each iteration"):
        split.pass_timing(4.0, [])


def test_calibration_of_a_large_film_probes_a_shrunk_camera_at_two_sizes(monkeypatch):
    """A 1920 x 1080 film is probed at 480 x 270 and 240 x 135 with the same field of view. With a start-up of
    10 s, an iteration of 0.5 s + 20 us a pixel and a finish of 1 us a pixel, the prediction is the real
    size's: 2 windows x (10 + 64 iterations of 41.97 s + 2.07 s); the image buffers of the peak memory are
    the real film's, not the probe's."""
    from render.ptpb import split

    asked = []

    def fake_render(scene, settings, **kwargs):
        camera = dict(scene["camera"])
        asked.append(camera)
        pixels = camera["width"] * camera["height"]
        iteration = 0.5 + 2e-5 * pixels
        film = np.ones((120, pixels, 3), np.float32)  # the probe's buffers, in the process's peak
        del film

        class Timed:
            stats = {"time_total_s": 10.0 + 2 * iteration + 1e-6 * pixels}
            snapshot_seconds = [10.0 + iteration, 10.0 + 2 * iteration]

        return Timed()

    monkeypatch.setattr(split, "render", fake_render)
    monkeypatch.setattr(
        split,
        "window_bytes",
        lambda scene, settings, count: count * 12.0 * scene["camera"]["width"] * scene["camera"]["height"],
    )
    camera = {"width": 1920, "height": 1080, "fov": 40.0, "fov_axis": "x"}
    scene = {"camera": camera, "film": {"temporal_bins": 240, "frame_mode": "bins"}}
    plan = split.calibrate(scene, {"iterations": 64}, [(0, 120), (120, 120)])
    assert [(c["width"], c["height"], c["fov"]) for c in asked] == [(480, 270, 40.0), (240, 135, 40.0)]
    full = 0.5 + 2e-5 * 1920 * 1080
    assert plan is not None and plan["probe_pixels"] == [480 * 270, 240 * 135]
    assert plan["seconds_per_iteration"] == pytest.approx(full)
    assert plan["predicted_wall_s"] == pytest.approx(2 * (10 + 64 * full + 1e-6 * 1920 * 1080))
    buffers = 120 * 12.0 * 1920 * 1080 / 2**30
    assert plan["image_buffers_gib"] == pytest.approx(buffers)
    assert buffers < plan["predicted_peak_gib"] < buffers + 4  # the process (Python, numpy) and the real buffers
    assert split.probe_factors(3840, 2160) == (8, 16) and split.probe_factors(640, 360) == (1,)
