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


def test_frames_json_describes_the_stack_in_one_place(scene_dir):
    from common.units import NS_PER_M_OPL
    from render.output.files import RenderOutputs

    cfg = PTPBConfig(iterations=2, light_paths_per_iteration=2000, initial_beam_radius=BeamRadius(value=0.03, unit="m"))
    for mode in ("bins", "gate"):
        out = scene_dir / mode
        run_render_stage(
            scene_dir, cfg.model_copy(update={"seed": 1, "threads": 2, "frame_mode": mode}), out, quiet=True
        )
        about = json.loads((out / "frames.json").read_text())
        film = json.loads((scene_dir / "ptpb_scene.json").read_text())["film"]
        assert about["frame_mode"] == mode and about["shape"] == [30, 10, 12, 3]
        assert ("per metre of OPL" if mode == "gate" else "per bin") in about["unit"]
        centres = np.asarray(about["frame_centres_opl_m"])
        np.testing.assert_allclose(centres, film["start_opl"] + (np.arange(30) + 0.5) * film["bin_width_opl"])
        np.testing.assert_allclose(
            about["frame_centres_ns_since_first_light"], (centres - film["start_opl"]) * NS_PER_M_OPL
        )
        outputs = RenderOutputs.read(out)
        assert outputs.axis is not None and outputs.axis.frame_mode == mode
        scale = film["bin_width_opl"] if mode == "gate" else 1.0
        np.testing.assert_allclose(outputs.frames_as_bins(), np.load(out / "frames.npy") * scale)
