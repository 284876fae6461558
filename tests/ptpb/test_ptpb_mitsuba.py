"""Steady comparison with Mitsuba 3 volpath on ptpb.md §10 test 4's cube, reduced for CI:
24x24 pixels, Mitsuba at 4096 spp, ours with 32 iterations of 100k light paths (R_0 = 1 cm)."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_ptpb_physics import cube_scene  # noqa: E402

from render.ptpb import render  # noqa: E402

RES = 24
MAXD = 64


def mitsuba_cube(spp: int, seed: int = 0) -> np.ndarray:
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("llvm_ad_rgb")
    T = mi.ScalarTransform4f
    cam = cube_scene(res=RES)["camera"]
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": MAXD, "rr_depth": 5},
        "sensor": {
            "type": "perspective", "fov": 40, "fov_axis": "x",
            "to_world": T().look_at(origin=list(cam["origin"]), target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
        "cube": {
            "type": "cube", "to_world": T().scale(0.5), "bsdf": {"type": "null"},
            "interior": {"type": "homogeneous", "scale": 8.0, "sigma_t": {"type": "rgb", "value": [0.5, 0.75, 1.0]},
                         "albedo": {"type": "rgb", "value": [0.9, 0.9, 0.9]}, "phase": {"type": "hg", "g": 0.7}},
        },
        "light": {
            "type": "rectangle",
            "to_world": T().look_at(origin=[0, 1.5, 0], target=[0, 0, 0], up=[0, 0, 1]) @ T().scale(0.25),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [20, 20, 20]}},
        },
    })
    return np.asarray(mi.render(scene, spp=spp), dtype=np.float64)[..., :3]


@pytest.mark.mitsuba
@pytest.mark.slow
def test_steady_cube_mean_and_convergence_against_mitsuba_volpath():
    ref = mitsuba_cube(spp=4096)
    ours = render(cube_scene("steady", res=RES), {"iterations": 32, "light_paths_per_iteration": 100000,
                                                  "initial_beam_radius": 0.01, "alpha": 0.8, "max_depth": 64,
                                                  "rr_depth": 5, "seed": 12, "threads": 2, "snapshot_every": 8})
    medium = ref.mean(-1) > 1e-3 * ref.mean(-1).max()  # pixels that see the lit medium
    assert medium.sum() > 0.2 * RES * RES
    ratio = ours.steady[medium].mean(0) / ref[medium].mean(0)
    print("ours/mitsuba per channel:", ratio)
    # Measured 0.974-0.985 over two seeds: the kernel loses mass within R of the lit face (bias ~ R sigma_t).
    assert abs(ratio.mean() - 1) < 0.03
    np.testing.assert_allclose(ratio, 1.0, atol=0.045)
    its = np.array([it for it, _ in ours.snapshots], dtype=float)
    rel = np.array([((s - ref) ** 2 / (ref**2 + 1e-2)).mean() for _, s in ours.snapshots])
    assert np.all(np.diff(rel) < 0), rel
    slope = np.polyfit(np.log(its), np.log(rel), 1)[0]
    print("relMSE", rel, "slope", slope)
    assert abs(slope - (-0.8)) < 0.15, slope
