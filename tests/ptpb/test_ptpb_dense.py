"""Dense media (render/core/DESIGN.md §12): the choice between beams and paths, the path tracer against
Mitsuba's volpath, the start radius that no longer biases the result, and the time-resolved diffusion
tail of a thick slab (Patterson, Chance & Wilson 1989)."""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_ptpb_mitsuba import mitsuba_cube  # noqa: E402
from test_ptpb_physics import cube_scene  # noqa: E402

from render.ptpb.api import render  # noqa: E402
from render.scene.shapes import box_mesh  # noqa: E402

RES = 24
# The camera of the dense cube looks down at 38 degrees onto the lit top face (test 4's camera sees it
# edge-on, and a dense cube's light stays within millimetres of the lit face).
CAMERA = (0.0, 2.0, 2.6)


def dense_cube(sigma_t: float, albedo: float, g: float, mode: str = "steady", res: int = RES) -> dict:
    """Test 4's 1 m cube under its 0.5 m area light, filled with a grey medium."""
    scene = cube_scene(mode, res=res)
    scene["camera"]["origin"] = CAMERA
    scene["media"] = [
        {"sigma_s": (sigma_t * albedo,) * 3, "sigma_a": (sigma_t * (1 - albedo),) * 3, "g": g, "ior": 1.0}
    ]
    return scene


def mitsuba_dense_cube(sigma_t: float, albedo: float, g: float, spp: int, seed: int, rr_depth: int = 200):
    """Mitsuba volpath, unbounded depth. Roulette starts late: with Mitsuba's survival cap of 0.95 a path of
    several hundred collisions is almost never sampled, and the mean comes out low however many samples."""
    interior = {
        "type": "homogeneous",
        "scale": float(sigma_t),
        "sigma_t": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
        "albedo": {"type": "rgb", "value": [albedo] * 3},
        "phase": {"type": "hg", "g": g},
    }
    return mitsuba_cube(spp, seed, interior=interior, origin=CAMERA, max_depth=-1, rr_depth=rr_depth)


def settings(**kw) -> dict:
    base = {
        "iterations": 64,
        "light_paths_per_iteration": 20000,
        "initial_beam_radius": 0.02,
        "max_depth": -1,
        "rr_depth": 5,
        "seed": 1,
        "threads": 2,
    }
    base.update(kw)
    return base


# ----------------------------------------------------------------- fast: the choice and the bookkeeping


@pytest.mark.parametrize(
    ("sigma_t", "radius", "paths"),
    [
        (400.0, 0.02, 1),  # snow: 8 mean free paths, and 350 of them across the scene
        (400.0, 1e-5, 1),  # tiny radius: still optically dense at the scene's scale
        (4.0, 0.02, 0),  # thin: R = 0.08 mfp keeps beams
        (4.0, 0.2, 1),  # thin but R = 0.8 mfp: beams would be biased low
    ],
)
def test_auto_picks_paths_where_beams_would_be_biased(sigma_t, radius, paths):
    r = render(dense_cube(sigma_t, 0.9995, 0.0), settings(iterations=1, initial_beam_radius=radius))
    assert r.stats["path_media"] == paths
    assert (r.stats["path_vertices"] > 0) == bool(paths)
    assert (r.stats["beams"] > 0) == (not paths)
    assert r.steady.mean() > 0


def test_paths_are_bit_identical_across_threads_and_sum_to_steady():
    scene = dense_cube(400.0, 0.9995, 0.85, mode="bins")
    scene["film"] = {"frame_mode": "bins", "temporal_bins": 60, "start_opl": 3.0, "bin_width_opl": 0.05}
    runs = [render(scene, settings(iterations=3, threads=t, tile_size=ts)) for t, ts in [(1, 16), (2, 16), (2, 5)]]
    digests = {hashlib.sha256(r.frames.tobytes() + r.steady.tobytes()).hexdigest() for r in runs}
    assert len(digests) == 1
    r = runs[0]
    assert r.stats["path_media"] == 1 and r.stats["path_connections"] > 0
    total = r.frames.sum(axis=0) + r.early + r.late
    np.testing.assert_allclose(total, r.steady, rtol=1e-4, atol=1e-7 * r.steady.max())
    assert r.stats["out_of_window_fraction"] < 0.05  # the window holds the light


def test_paths_scale_invariance_in_the_semi_infinite_limit():
    """At max_depth 100 the light stays within ~10 mean free paths of the lit face, a millimetre or two
    here, so the cube is semi-infinite and the image cannot depend on sigma_t. A ray epsilon that skipped
    faces near scattering vertices cost 5 % at sigma_t = 2000 (DESIGN.md §12)."""
    means = []
    for sigma_t in (400.0, 2000.0, 10000.0):
        r = render(dense_cube(sigma_t, 0.9995, 0.0), settings(iterations=600, max_depth=100, rr_depth=101))
        means.append(r.steady.mean())
    assert max(means) / min(means) - 1 < 0.015, means


@pytest.mark.mitsuba
def test_paths_match_volpath_on_the_translucent_cube():
    ref = mitsuba_cube(spp=8192, seed=3)
    medium = ref.mean(-1) > 1e-3 * ref.mean(-1).max()
    r = render(cube_scene("steady", res=RES), settings(medium_estimator="paths", iterations=4096, max_depth=64))
    ratio = r.steady[medium].mean(0) / ref[medium].mean(0)
    print("paths / volpath per channel:", ratio)
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)


# ----------------------------------------------------------------- slow: the figures of issue 16


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize(
    ("sigma_t", "g", "rr_depth", "tolerance"),
    [(400.0, 0.0, 200, 0.02), (400.0, 0.85, 3000, 0.02), (2000.0, 0.0, 200, 0.05), (2000.0, 0.85, 3000, 0.05)],
)
def test_dense_cube_steady_mean_against_volpath(sigma_t, g, rr_depth, tolerance):
    """Issue 16 asks for 2 %. At g = 0.85 a path leaves the snow after several times more collisions, so
    volpath's roulette must start later still (3000) or its mean comes out 6 % low. At sigma_t = 2000 per m
    volpath itself is off by a few per cent: single precision and its relative ray epsilon (DESIGN.md §12;
    `test_paths_scale_invariance_in_the_semi_infinite_limit` shows ours is not), so only 5 % is asserted
    there, and the closing note of issue 16 says that point is not met."""
    refs = [mitsuba_dense_cube(sigma_t, 0.9995, g, spp=2048, seed=seed, rr_depth=rr_depth) for seed in range(4)]
    ref = np.mean(refs, axis=0)
    lit = ref.mean(-1) > 1e-2 * ref.mean(-1).max()
    runs = [render(dense_cube(sigma_t, 0.9995, g), settings(iterations=1, time_budget_s=15, seed=s)) for s in (1, 2)]
    ours = np.mean([r.steady[lit].mean(0) for r in runs], axis=0)
    ratio = ours / ref[lit].mean(0)
    spread = np.std([x[lit].mean() for x in refs], ddof=1) / np.sqrt(len(refs)) / ref[lit].mean()
    print(f"sigma_t {sigma_t} g {g}: ours/volpath {ratio}, volpath's standard error {spread:.4f}")
    np.testing.assert_allclose(ratio, 1.0, atol=tolerance)


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize(("sigma_t", "mfps"), [(400.0, (0.1, 1.0, 10.0, 100.0)), (4.0, (0.1, 1.0, 10.0, 100.0))])
def test_no_start_radius_biases_the_mean(sigma_t, mfps):
    """Start radii from 0.1 to 100 mean free paths, on the dense cube and a thin one of the same albedo."""
    ref = np.mean([mitsuba_dense_cube(sigma_t, 0.9995, 0.0, spp=2048, seed=s) for s in range(4)], axis=0)
    lit = ref.mean(-1) > 1e-2 * ref.mean(-1).max()
    for mfp in mfps:
        r = render(
            dense_cube(sigma_t, 0.9995, 0.0),
            settings(iterations=1, time_budget_s=12, initial_beam_radius=mfp / sigma_t),
        )
        ratio = r.steady[lit].mean() / ref[lit].mean()
        print(f"sigma_t {sigma_t}, R0 = {mfp} mfp: ours/volpath {ratio:.4f}, media on paths {r.stats['path_media']}")
        assert abs(ratio - 1) < 0.02


def diffusion_slab(res: int = 16, frames: int = 160, width: float = 0.05) -> dict:
    """A 6 m x 6 m x 1.5 m index-matched slab (sigma_s' = 60, sigma_a = 0.6 per m: snow in its isotropic
    reduced form, a little more absorbing so that the tail fits a test) under a plane-wave pulse from the
    zenith, seen from 5 m above through an 8 degree pinhole. The sun's wavefront passes the top face at
    tau = 0, so light that entered and left at once reaches the camera at 5 m of OPL."""
    v, f = box_mesh((-3, -3, -1.5), (3, 3, 0.0))
    return {
        "media": [{"sigma_s": (60.0,) * 3, "sigma_a": (0.6,) * 3, "g": 0.0, "ior": 1.0}],
        "shapes": [{"vertices": v, "faces": f, "kind": "null", "interior": 0, "exterior": -1}],
        "directional_lights": [{"to_sun": (0, 0, 1), "irradiance": (1, 1, 1), "reference_point": (0, 0, 0)}],
        "camera": {
            "origin": (0, 1e-3, 5.0),
            "target": (0, 0, 0),
            "up": (0, 1, 0),
            "fov": 8,
            "width": res,
            "height": res,
        },
        "film": {"frame_mode": "bins", "temporal_bins": frames, "start_opl": 5.0, "bin_width_opl": width},
    }


@pytest.mark.mitsuba
@pytest.mark.slow
def test_time_resolved_diffusion_tail_of_a_thick_slab():
    """R(s) ~ s^(-3/2) exp(-sigma_a s) (DESIGN.md §12): fit the power and sigma_a over s = 0.3-6 m of
    excess OPL, and compare the total with volpath's steady image."""
    r = render(diffusion_slab(), settings(iterations=1, time_budget_s=30))
    energy = r.frames.mean(axis=(1, 2, 3))
    s = (np.arange(energy.size) + 0.5) * 0.05
    fit = (s > 0.3) & (s < 6.0)
    design = np.stack([np.ones(fit.sum()), np.log(s[fit]), s[fit]], axis=1)
    (_, power, slope), *_ = np.linalg.lstsq(design, np.log(energy[fit]), rcond=None)
    print(
        f"power {power:.3f} (diffusion -1.5), sigma_a {-slope:.4f} (0.6), late fraction {r.stats['late_fraction']:.2e}"
    )
    assert abs(power + 1.5) < 0.1
    assert abs(-slope / 0.6 - 1) < 0.05

    mi = pytest.importorskip("mitsuba")
    mi.set_variant("llvm_ad_rgb")
    T = mi.ScalarTransform4f
    ref = mi.render(
        mi.load_dict(
            {
                "type": "scene",
                "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 200},
                "sensor": {
                    "type": "perspective",
                    "fov": 8,
                    "fov_axis": "x",
                    "near_clip": 1e-4,
                    "to_world": T().look_at(origin=[0, 1e-3, 5.0], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": 16, "height": 16, "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent", "sample_count": 4096, "seed": 5},
                },
                "slab": {
                    "type": "cube",
                    "to_world": T().translate([0, 0, -0.75]) @ T().scale([3, 3, 0.75]),
                    "bsdf": {"type": "null"},
                    "interior": {
                        "type": "homogeneous",
                        "scale": 60.6,
                        "sigma_t": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
                        "albedo": {"type": "rgb", "value": [60.0 / 60.6] * 3},
                        "phase": {"type": "isotropic"},
                    },
                },
                "sun": {
                    "type": "directional",
                    "direction": [0, 0, -1],
                    "irradiance": {"type": "rgb", "value": [1, 1, 1]},
                },
            }
        ),
        spp=4096,
    )
    total = np.asarray(ref, dtype=np.float64)[..., :3].mean()
    ours = (r.frames.sum(axis=0) + r.early + r.late).mean()
    print(f"ours {ours:.5f}, volpath {total:.5f}, ratio {ours / total:.4f}")
    assert abs(ours / total - 1) < 0.03
