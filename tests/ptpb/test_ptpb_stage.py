"""The render stage writes steady.exr/.npy, frames.npy and stats.json whose numbers agree."""
from __future__ import annotations

import json

import numpy as np

from pipeline.schema.ptpb import BeamRadius, PTPBConfig
from render.ptpb_stage import run_render_stage
from render.shapes import box_mesh, quad_mesh


def test_render_stage_outputs(tmp_path):
    cv, cf = box_mesh()
    lv, lf = quad_mesh(center=(0, 1.5, 0), u=(0.25, 0, 0), v=(0, 0, 0.25))
    np.savez(tmp_path / "cube.npz", vertices=cv, faces=cf)
    scene = {
        "media": [{"sigma_s": [3.6, 5.4, 7.2], "sigma_a": [0.4, 0.6, 0.8], "g": 0.7}],
        "shapes": [{"mesh": "cube.npz", "kind": "null", "interior": 0},
                   {"vertices": lv.tolist(), "faces": lf.tolist(), "kind": "diffuse", "radiance": [20, 20, 20]}],
        "camera": {"origin": [0, 0.8, 2.89], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 40, "width": 12, "height": 10},
        "film": {"frame_mode": "bins", "temporal_bins": 30, "start_opl": 3.5, "bin_width_opl": 0.05},
    }
    (tmp_path / "ptpb_scene.json").write_text(json.dumps(scene))
    cfg = PTPBConfig(iterations=2, light_paths_per_iteration=2000, initial_beam_radius=BeamRadius(value=0.03, unit="m"))
    out = tmp_path / "out"
    stats = run_render_stage(tmp_path, cfg, out, seed=1, threads=2, quiet=True)
    steady, frames = np.load(out / "steady.npy"), np.load(out / "frames.npy")
    assert steady.shape == (10, 12, 3) and frames.shape == (30, 10, 12, 3) and frames.dtype == np.float32
    assert (out / "steady.exr").stat().st_size > 0
    saved = json.loads((out / "stats.json").read_text())
    assert saved["iterations"] == 2 and saved["frame_mode"] == "bins" and stats["iterations"] == 2
    assert abs(frames.sum() / steady.sum() + saved["out_of_window_fraction"] - 1) < 1e-3
