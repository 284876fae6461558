"""Shared set-up of the render-stage tests: a scene stage's output for the §10 cube."""

from __future__ import annotations

import json

import numpy as np
import pytest

from render.scene.shapes import box_mesh, quad_mesh


@pytest.fixture
def scene_dir(tmp_path):
    """tmp_path holding ptpb_scene.json and its mesh: the cube of render/core/DESIGN.md §10 test 4 (null boundary)
    under a 0.5 m area light, 12 x 10 pixels, 30 bins of 5 cm from 3.5 m."""
    cv, cf = box_mesh()
    lv, lf = quad_mesh(center=(0, 1.5, 0), u=(0.25, 0, 0), v=(0, 0, 0.25))
    np.savez(tmp_path / "cube.npz", vertices=cv, faces=cf)
    scene = {
        "media": [{"sigma_s": [3.6, 5.4, 7.2], "sigma_a": [0.4, 0.6, 0.8], "g": 0.7}],
        "shapes": [
            {"mesh": "cube.npz", "kind": "null", "interior": 0},
            {"vertices": lv.tolist(), "faces": lf.tolist(), "kind": "diffuse", "radiance": [20, 20, 20]},
        ],
        "camera": {
            "origin": [0, 0.8, 2.89],
            "target": [0, 0, 0],
            "up": [0, 1, 0],
            "fov": 40,
            "width": 12,
            "height": 10,
        },
        "film": {"frame_mode": "bins", "temporal_bins": 30, "start_opl": 3.5, "bin_width_opl": 0.05},
    }
    (tmp_path / "ptpb_scene.json").write_text(json.dumps(scene))
    return tmp_path
