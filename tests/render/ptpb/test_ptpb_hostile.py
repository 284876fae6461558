"""Hostile inputs through the core directly (render.ptpb.api.render with a dict scene): broken meshes,
extreme but legal media, the memory budget and C++ exceptions. Each case is refused with a
ValueError that keeps the core's message, or renders finite values in bounded time."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from common.paths import PROJECT_ROOT
from pipeline.schema.ptpb import BeamRadius, PTPBConfig
from render.ptpb.api import memory_bytes, render
from render.scene.shapes import box_mesh, quad_mesh


def scene(medium: dict | None = None, box=None, res: int = 12, bins: int = 16) -> dict:
    """A 1 m box of medium under a 0.5 m area light, seen from 3 m (render/core/DESIGN.md §10 test 4, smaller)."""
    cv, cf = box if box is not None else box_mesh()
    lv, lf = quad_mesh(center=(0, 1.5, 0), u=(0.25, 0, 0), v=(0, 0, 0.25))
    return {
        "media": [medium or {"sigma_s": (3.6, 5.4, 7.2), "sigma_a": (0.4, 0.6, 0.8), "g": 0.7}],
        "shapes": [
            {"vertices": cv, "faces": cf, "kind": "null", "interior": 0, "exterior": -1},
            {"vertices": lv, "faces": lf, "kind": "diffuse", "albedo": (0, 0, 0), "radiance": (20, 20, 20)},
        ],
        "camera": {
            "origin": (0, 0.8, math.sqrt(9 - 0.64)),
            "target": (0, 0, 0),
            "up": (0, 1, 0),
            "fov": 40,
            "width": res,
            "height": res,
        },
        "film": {"frame_mode": "bins", "temporal_bins": bins, "start_opl": 3.5, "bin_width_opl": 0.1},
    }


def settings(**kw) -> dict:
    base = {
        "iterations": 2,
        "light_paths_per_iteration": 2000,
        "initial_beam_radius": 0.03,
        "max_depth": -1,
        "rr_depth": 5,
        "seed": 2,
        "threads": 2,
    }
    base.update(kw)
    return base


def assert_finite(result) -> None:
    for name in ("steady", "frames", "early", "late"):
        assert np.isfinite(getattr(result, name)).all(), name


# ---------------------------------------------------------------- meshes


def with_vertex(value, index=3, axis=1):
    v, f = box_mesh()
    v = v.astype(np.float64)
    v[index, axis] = value
    return v, f


@pytest.mark.parametrize(
    "box, message",
    [
        ((np.zeros((0, 3)), np.zeros((0, 3), np.uint32)), r"shapes\[0\]: the mesh is empty"),
        (([], []), r"shapes\[0\].vertices is empty"),
        (with_vertex(np.nan), r"shapes\[0\].vertices\[3\] is NaN or infinite"),
        (with_vertex(np.inf), r"shapes\[0\].vertices\[3\] is NaN or infinite"),
        (with_vertex(1e300), r"shapes\[0\].vertices\[3\] is NaN or infinite"),  # beyond float32: infinite
        ((box_mesh()[0], np.vstack([box_mesh()[1], [[0, 1, 99]]])), r"shapes\[0\].faces\[12\] refers to vertex 99"),
        (
            (box_mesh()[0], np.vstack([box_mesh()[1].astype(np.int64), [[0, -1, 2]]])),
            r"shapes\[0\].faces\[12\] has vertex index -1",
        ),
        ((box_mesh()[0][:, :2], box_mesh()[1]), r"shapes\[0\].vertices must be \(N, 3\)"),
        (("abc", box_mesh()[1]), r"shapes\[0\].vertices must be an array of numbers"),
    ],
)
@pytest.mark.filterwarnings("ignore:overflow encountered in cast")  # 1e300 as float32
def test_broken_meshes_are_refused_naming_the_shape(box, message):
    with pytest.raises(ValueError, match=message):
        render(scene(box=box), settings())


def test_a_shape_without_vertices_is_refused_naming_the_key():
    sc = scene()
    del sc["shapes"][0]["vertices"]
    with pytest.raises(ValueError, match=r"shapes\[0\].vertices is required"):
        render(sc, settings())
    with pytest.raises(ValueError, match=r"scene.shapes\[1\] must be a dict"):
        render({**scene(), "shapes": [scene()["shapes"][0], "box"]}, settings())


def fin_box():
    v, f = box_mesh()
    return np.vstack([v, [[2, 2, 2]]]).astype(np.float32), np.vstack([f, [[0, 1, 8]]]).astype(np.uint32)


def degenerate_box():
    v, f = box_mesh()
    v = np.vstack([v, [[0.0, -0.5, -0.5]]]).astype(np.float32)
    return v, np.vstack([f, [[0, 0, 1], [0, 8, 1], [4, 4, 4]]]).astype(np.uint32)


def open_box():
    v, f = box_mesh()
    return v, f[:-2]  # one face of the box missing: light and camera paths leave through the hole


@pytest.mark.parametrize(
    "name, box",
    [
        ("non-manifold (an extra fin)", fin_box()),
        ("degenerate triangles", degenerate_box()),
        ("inverted normals (medium outside the box)", (box_mesh()[0], box_mesh()[1][:, ::-1].copy())),
        ("open (not watertight)", open_box()),
    ],
)
def test_meshes_the_scene_stage_refuses_still_render_finite_in_the_core(name, box):
    # The core trusts the winding (scene_build refuses these meshes); it must not crash or make NaNs.
    result = render(scene(box=box), settings())
    assert_finite(result)
    assert result.stats["iterations"] == 2, name


# ---------------------------------------------------------------- media

EXTREME_MEDIA = {
    "sigma = 0": {"sigma_s": (0, 0, 0), "sigma_a": (0, 0, 0), "g": 0.0},
    "sigma = 1e6 /m, albedo 0.99": {"sigma_s": (0.99e6,) * 3, "sigma_a": (0.01e6,) * 3, "g": 0.0},
    "sigma = 1e6 /m, albedo 1": {"sigma_s": (1e6,) * 3, "sigma_a": (0, 0, 0), "g": 0.0},
    "albedo 1, sigma 50 /m": {"sigma_s": (50.0, 50.0, 50.0), "sigma_a": (0, 0, 0), "g": 0.5},
    "g = +0.999": {"sigma_s": (3.0, 4.0, 5.0), "sigma_a": (0.1, 0.1, 0.1), "g": 0.999},
    "g = -0.999": {"sigma_s": (3.0, 4.0, 5.0), "sigma_a": (0.1, 0.1, 0.1), "g": -0.999},
    "mixed 0 and 1e6 channels": {"sigma_s": (0.0, 1e6, 3.0), "sigma_a": (0.0, 0.0, 1e6), "g": 0.9},
}

# Renders every extreme medium in a child process, so a hang or an abort fails the test instead of
# freezing or killing pytest; prints one JSON line per medium.
CHILD = """
import json, sys, time
import numpy as np
sys.path.insert(0, {tests!r})
from test_ptpb_hostile import EXTREME_MEDIA, scene, settings
from render.ptpb.api import render
for name, medium in EXTREME_MEDIA.items():
    t0 = time.perf_counter()
    r = render(scene(medium=medium), settings())
    finite = all(bool(np.isfinite(a).all()) for a in (r.steady, r.frames, r.early, r.late))
    print(json.dumps({{"name": name, "finite": finite, "seconds": time.perf_counter() - t0,
                      "beams_per_path": r.stats["beams"] / max(1, r.stats["light_paths"]), "steady_sum": float(r.steady.sum())}}),
          flush=True)
"""


def test_extreme_but_legal_media_render_finite_in_bounded_time():
    child = subprocess.run(
        [sys.executable, "-c", CHILD.format(tests=str(PROJECT_ROOT / "tests" / "render" / "ptpb"))],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=PROJECT_ROOT,
    )
    assert child.returncode == 0, child.stderr[-2000:]  # not killed by a signal (abort, segfault)
    rows = {row["name"]: row for row in map(json.loads, child.stdout.splitlines())}
    assert set(rows) == set(EXTREME_MEDIA)
    for name, row in rows.items():
        assert row["finite"], name
        assert row["seconds"] < 30, (name, row["seconds"])
        # Roulette survival is capped at 0.95: even a lossless medium averages a few tens of beams per path.
        assert row["beams_per_path"] < 200, (name, row["beams_per_path"])
        assert row["steady_sum"] >= 0, name
    # Thin media let the light through to the camera; at 1e6 /m beams and queries are micrometres long,
    # so at R = 3 cm their closest approaches almost never fall inside both: black, not NaN.
    assert rows["g = +0.999"]["steady_sum"] > 0 and rows["albedo 1, sigma 50 /m"]["steady_sum"] > 0


@pytest.mark.parametrize(
    "medium, message",
    [
        ({"sigma_s": (1, 1, 1), "g": 1.0}, r"media\[0\].g must lie in \(-1, 1\)"),
        ({"sigma_s": (1, 1, 1), "g": -1.0}, r"media\[0\].g must lie in \(-1, 1\)"),
        ({"sigma_s": (-1, 1, 1)}, r"media\[0\].sigma_s must be finite and >= 0"),
        ({"sigma_s": (np.nan, 1, 1)}, r"media\[0\].sigma_s must be finite and >= 0"),
        ({"sigma_a": (np.inf, 0, 0)}, r"media\[0\].sigma_a must be finite and >= 0"),
        ({"sigma_s": (1, 1, 1), "ior": 0.0}, r"media\[0\].ior must be > 0"),
        ({"sigma_s": (1, 1)}, r"media\[0\].sigma_s must have 3 components"),
    ],
)
def test_illegal_media_are_refused_naming_the_key(medium, message):
    with pytest.raises(ValueError, match=message):
        render(scene(medium=medium), settings())


# ---------------------------------------------------------------- memory budget


def test_memory_estimate_counts_every_image_buffer_of_the_core():
    sc = scene(res=12, bins=16)
    px3, frames = 12 * 12 * 3, 16
    s = settings()
    threads = s["threads"] or os.cpu_count()
    tiles = threads * 16 * 16 * 3 * (3 + frames) * 8  # one double tile film (16 x 16 px) per thread
    base = px3 * 3 * (8 + 4) + px3 * frames * 4 + tiles  # double steady/early/late + float32 results; float32 frames
    assert memory_bytes(sc, s) == base
    assert memory_bytes(sc, s, state_copy=True) == base + px3 * 3 * 8 + px3 * frames * 4
    assert memory_bytes(sc, settings(snapshot_every=1)) == base + 2 * px3 * 4
    steady = {**sc, "film": {**sc["film"], "frame_mode": "steady"}}
    assert memory_bytes(steady, s) == px3 * 3 * 12 + threads * 16 * 16 * 3 * 3 * 8


def test_a_film_over_the_memory_budget_is_refused_at_once_with_the_keys_to_change():
    huge = scene(res=4096, bins=1000)  # 1000 float32 frames of 4096^2 x 3 values and the double planes: 189 GiB
    cfg = PTPBConfig(iterations=2, light_paths_per_iteration=100, initial_beam_radius=BeamRadius(value=0.03, unit="m"))
    t0 = time.perf_counter()
    with pytest.raises(ValueError) as refused:
        render(huge, cfg)
    assert time.perf_counter() - t0 < 5  # nothing was allocated or rendered
    message = str(refused.value)
    px3, threads = 4096 * 4096 * 3, cfg.threads or os.cpu_count()
    need = (px3 * 3 * 12 + px3 * 1000 * 4 + threads * 16 * 16 * 3 * 1003 * 8) / 2**30  # 189.20 GiB on 2 threads
    assert (
        f"the film needs {need:.2f} GiB" in message
        and "render the film in frame windows" in message
        and "1000 frames of 4096 x 4096 px" in message
    )
    for key in (
        "render.memory_budget_gib = 8",
        "scene.film.temporal_bins",
        "scene.camera.width/height",
        "raise render.memory_budget_gib",
    ):
        assert key in message, key
    small = scene(res=12, bins=16)
    with pytest.raises(ValueError, match="more than render.memory_budget_gib = 1e-05"):
        render(small, cfg.model_copy(update={"memory_budget_gib": 1e-5}))  # 10.7 kB < 164 kB
    assert render(small, cfg.model_copy(update={"memory_budget_gib": None})).stats["iterations"] == 2  # no limit
    # With a checkpoint callback the copy handed to it counts too.
    budget = memory_bytes(small, cfg) / 2**30 * 1.1
    checkpointing = cfg.model_copy(update={"memory_budget_gib": budget, "checkpoint_every_iterations": 1})
    render(small, checkpointing)
    with pytest.raises(ValueError, match="memory_budget_gib"):
        render(small, checkpointing, checkpoint=lambda state: None)


# ---------------------------------------------------------------- exceptions


def test_core_exceptions_become_python_exceptions_with_their_message():
    with pytest.raises(ValueError, match="grid_resolution must lie in"):
        render(scene(), settings(accel="grid", grid_resolution=0))
    with pytest.raises(ValueError, match="settings.iterations has the wrong type"):
        render(scene(), settings(iterations="many"))
    with pytest.raises(ValueError, match="camera fov must lie in"):
        render({**scene(), "camera": {**scene()["camera"], "fov": 180}}, settings())
    with pytest.raises(ValueError, match="scene.camera is required"):
        render({k: v for k, v in scene().items() if k != "camera"}, settings())


def test_errors_raised_in_callbacks_come_back_unchanged():
    def failing_progress(info):
        raise ZeroDivisionError("progress callback failed")

    with pytest.raises(ZeroDivisionError, match="progress callback failed"):
        render(scene(), settings(), progress=failing_progress)

    def failing_checkpoint(state):
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left on device"):
        render(scene(), settings(iterations=3, checkpoint_every_iterations=1), checkpoint=failing_checkpoint)


def test_a_resume_state_that_is_not_a_render_state_is_refused():
    with pytest.raises(ValueError, match="resume must be a dict"):
        render(scene(), settings(), resume=[1, 2, 3])
    with pytest.raises(ValueError, match="resume.width is required"):
        render(scene(), settings(), resume={"steady": np.zeros((12, 12, 3))})
    states = []
    render(scene(), settings(iterations=3, checkpoint_every_iterations=1), checkpoint=states.append)
    bad = {**states[0], "frames": states[0]["frames"][:, :, :-1]}
    with pytest.raises(ValueError, match="resume.frames does not have the shape"):
        render(scene(), settings(iterations=3), resume=bad)
