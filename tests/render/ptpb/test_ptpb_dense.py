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
from halfspace import chandrasekhar_h, reflected_radiance, sky_reflected_radiance  # noqa: E402
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


def mitsuba_dense_cube(
    sigma_t: float,
    albedo: float,
    g: float,
    spp: int,
    seed: int,
    rr_depth: int = 200,
    units: float = 1.0,
    shift=(0.0, 0.0, 0.0),
    tile: int = 0,
    film: dict | None = None,
):
    """Mitsuba volpath, unbounded depth, or with ``film`` mitransient (then (frames, steady)). Roulette starts
    late: with Mitsuba's survival cap of 0.95 a path of several hundred collisions is almost never sampled,
    and the mean comes out low however many samples. ``units`` per metre, ``shift`` and ``tile``: see
    ``mitsuba_cube``."""
    interior = {
        "type": "homogeneous",
        "scale": float(sigma_t),
        "sigma_t": {"type": "rgb", "value": [1.0, 1.0, 1.0]},
        "albedo": {"type": "rgb", "value": [albedo] * 3},
        "phase": {"type": "hg", "g": g},
    }
    return mitsuba_cube(
        spp,
        seed,
        film,
        interior=interior,
        origin=CAMERA,
        max_depth=-1,
        rr_depth=rr_depth,
        units=units,
        shift=shift,
        tile=tile,
    )


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


@pytest.mark.parametrize("g", [0.85, 0.0], ids=["hg", "isotropic-with-hops"])
def test_paths_are_bit_identical_across_threads_and_sum_to_steady(g):
    scene = dense_cube(400.0, 0.9995, g, mode="bins")
    scene["film"] = {"frame_mode": "bins", "temporal_bins": 60, "start_opl": 3.0, "bin_width_opl": 0.05}
    # With splitting in time: a split path's copies draw their streams from the path's own.
    runs = [
        render(scene, settings(iterations=3, threads=t, tile_size=ts, path_splits=3))
        for t, ts in [(1, 16), (2, 16), (2, 5)]
    ]
    digests = {hashlib.sha256(r.frames.tobytes() + r.steady.tobytes()).hexdigest() for r in runs}
    assert len(digests) == 1
    r = runs[0]
    assert r.stats["path_media"] == 1 and r.stats["path_connections"] > 0 and r.stats["path_splits"] > 0
    # Hops (DESIGN.md §12) only where the phase function is isotropic; their tables are the same in every run.
    assert (r.stats["path_hops"] > 0) == (g == 0.0)
    total = r.frames.sum(axis=0) + r.early + r.late
    np.testing.assert_allclose(total, r.steady, rtol=1e-4, atol=1e-7 * r.steady.max())
    # The window holds most of the light. Over three iterations the late tail's share is noisy: 0-18 % over
    # seeds 0-2, before and after the shadow roulette alike (30 iterations: 2-4.5 %).
    assert r.stats["out_of_window_fraction"] < 0.25


def test_paths_scale_invariance_in_the_semi_infinite_limit(validation):
    """At max_depth 100 the light stays within ~10 mean free paths of the lit face, a millimetre or two
    here, so the cube is semi-infinite and the image cannot depend on sigma_t. A ray epsilon that skipped
    faces near scattering vertices cost 5 % at sigma_t = 2000 (DESIGN.md §12)."""
    means = []
    for sigma_t in (400.0, 2000.0, 10000.0):
        r = render(dense_cube(sigma_t, 0.9995, 0.0), settings(iterations=600, max_depth=100, rr_depth=101))
        means.append(r.steady.mean())
    validation.record(
        "dense cube, σ_t 400, 2000, 10000 per m: brightest / darkest image mean",
        max(means) / min(means),
        reference=1.0,
        tolerance="< +1.5 %",
        against="scale invariance of a semi-infinite medium",
    )
    assert max(means) / min(means) - 1 < 0.015, means


@pytest.mark.mitsuba
def test_paths_match_volpath_on_the_translucent_cube(validation):
    ref = mitsuba_cube(spp=8192, seed=3)
    medium = ref.mean(-1) > 1e-3 * ref.mean(-1).max()
    r = render(cube_scene("steady", res=RES), settings(medium_estimator="paths", iterations=4096, max_depth=64))
    ratio = r.steady[medium].mean(0) / ref[medium].mean(0)
    print("paths / volpath per channel:", ratio)
    validation.record(
        "medium cube, path tracer: ours / volpath per channel (R, G, B)",
        ratio,
        reference=1.0,
        tolerance="±2 %",
        against="Mitsuba 3 volpath, 8192 spp",
    )
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)


# ----------------------------------------------------------------- fast: the exact half-space

HALF_SPACE_RES = 16
HALF_SPACE_FOV = 8.0


def half_space(sigma_t: float, albedo: float, mu0: float) -> dict:
    """A 6 m x 6 m x 1.5 m index-matched slab, isotropic, under a sun at cos(zenith) = ``mu0`` (irradiance 1),
    seen straight down from 5 m through an 8 degree pinhole. At sigma_t >= 400 per m and albedo 0.9995 light
    diffuses sideways over 1/sigma_eff <= 6.5 cm and down as far, so the slab is a half-space to 1e-6."""
    v, f = box_mesh((-3, -3, -1.5), (3, 3, 0.0))
    return {
        "media": [{"sigma_s": (sigma_t * albedo,) * 3, "sigma_a": (sigma_t * (1 - albedo),) * 3, "g": 0.0, "ior": 1.0}],
        "shapes": [{"vertices": v, "faces": f, "kind": "null", "interior": 0, "exterior": -1}],
        "directional_lights": [
            {"to_sun": (0.0, float(np.sqrt(1 - mu0 * mu0)), mu0), "irradiance": (1, 1, 1), "reference_point": (0, 0, 0)}
        ],
        "camera": {
            "origin": (0, 1e-3, 5.0),
            "target": (0, 0, 0),
            "up": (0, 1, 0),
            "fov": HALF_SPACE_FOV,
            "width": HALF_SPACE_RES,
            "height": HALF_SPACE_RES,
        },
        "film": {"frame_mode": "steady", "temporal_bins": 1, "start_opl": 5.0, "bin_width_opl": 1.0},
    }


def half_space_expected(albedo: float, mu0: float) -> float:
    """Chandrasekhar's radiance averaged over the pixels' centre directions (view cosines 0.995-1)."""
    t = np.tan(np.radians(HALF_SPACE_FOV / 2))
    c = ((np.arange(HALF_SPACE_RES) + 0.5) / HALF_SPACE_RES * 2 - 1) * t
    x, y = np.meshgrid(c, c)
    return float(reflected_radiance(albedo, 1 / np.sqrt(1 + x * x + y * y), mu0).mean())


@pytest.mark.parametrize("albedo", [0.9, 0.99, 0.9995])
def test_h_function_satisfies_its_exact_identities(albedo):
    """The solver behind the half-space reference: H's zeroth moment is (2/omega)(1 - sqrt(1 - omega)), and
    the reflected flux of the radiance formula is the albedo 1 - sqrt(1 - omega) H(mu0) (Chandrasekhar 1960)."""
    H = chandrasekhar_h(albedo)
    x, w = np.polynomial.legendre.leggauss(200)
    mu, w = 0.5 * (x + 1), 0.5 * w
    assert (w * H(mu)).sum() == pytest.approx(2 / albedo * (1 - np.sqrt(1 - albedo)), rel=1e-9)
    for mu0 in (1.0, 0.5):
        flux = 2 * np.pi * (w * reflected_radiance(albedo, mu, mu0) * mu).sum() / mu0
        assert flux == pytest.approx(1 - np.sqrt(1 - albedo) * H(np.array(mu0)), rel=1e-9)


@pytest.mark.parametrize(("sigma_t", "mu0"), [(2000.0, 1.0), (400.0, 0.5)])
def test_paths_match_the_exact_half_space_at_snow_density(sigma_t, mu0, validation):
    """Snow's density and albedo (mean free path 0.5-2.5 mm, 2000 collisions a path) against the closed
    form: within 1.5 %. One run's scatter is about 0.3 % (six seeds at sigma_t = 2000: 0.998 +- 0.0013)."""
    r = render(half_space(sigma_t, 0.9995, mu0), settings(iterations=1_500))
    assert r.stats["path_media"] == 1
    ratio = r.steady.mean() / half_space_expected(0.9995, mu0)
    print(f"sigma_t {sigma_t}, mu0 {mu0}: ours / Chandrasekhar {ratio:.4f} ({r.stats['iterations']} iterations)")
    validation.record(
        f"half-space, σ_t {sigma_t:g} per m, ω 0.9995, sun at μ0 {mu0:g}: ours / exact",
        ratio,
        reference=1.0,
        tolerance="±1.5 %",
        against="Chandrasekhar's exact half-space (tests/render/ptpb/halfspace.py)",
    )
    assert abs(ratio - 1) < 0.015


@pytest.mark.parametrize("up", [None, (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)], ids=["sphere", "up", "down"])
def test_sky_on_the_exact_half_space_whatever_hemisphere_is_sampled(up, validation):
    """A uniform sky over snow (DESIGN.md §12, "The sky's hemisphere"): next-event estimation samples the
    whole sphere, the hemisphere above the surface, or (perversely) the one below it, where the ground
    blocks it all and only sampled directions find the sky. All three are exact, against 1 - H(1)sqrt(1-w)
    = 0.9374, within 1.5 %. A run of four iterations scatters by about 3 % (eight seeds, either way), so
    each variant gets 3 s."""
    scene = half_space(400.0, 0.9995, 1.0)
    scene["directional_lights"] = []
    scene["environment_radiance"] = (1.0, 1.0, 1.0)
    if up is not None:
        scene["environment_up"] = up
    r = render(scene, settings(iterations=1_100))
    ratio = r.steady.mean() / float(sky_reflected_radiance(0.9995, 1.0))
    print(f"sky, environment_up {up}: ours / Chandrasekhar {ratio:.4f} ({r.stats['iterations']} iterations)")
    validation.record(
        f"half-space under a uniform sky, sampling {'the whole sphere' if up is None else f'the hemisphere up = {up}'}: "
        "ours / exact",
        ratio,
        reference=1.0,
        tolerance="±1.5 %",
        against="Chandrasekhar's exact half-space (tests/render/ptpb/halfspace.py)",
    )
    assert abs(ratio - 1) < 0.015


def test_chromatic_medium_is_its_three_grey_media():
    """A medium whose extinction differs tenfold between channels (DESIGN.md §12, "Chromatic media"): each
    channel of its image must be the image of a grey medium with that channel's coefficients. The path
    tracer picks the flight's channel by the throughput, so no channel's weight can run away. Four seeds:
    0.981-1.019 per channel, largest pixel 0.71-0.80; with the channel picked uniformly (the mixture before)
    0.57-1.95, largest pixel up to 25."""
    sigma_t, albedo, g = (200.0, 60.0, 20.0), 0.99, 0.85
    chromatic = dense_cube(1.0, albedo, g)
    chromatic["media"][0]["sigma_s"] = tuple(s * albedo for s in sigma_t)
    chromatic["media"][0]["sigma_a"] = tuple(s * (1 - albedo) for s in sigma_t)
    common = settings(iterations=1_000, medium_estimator="paths")
    mixed = render(chromatic, common)
    grey = [render(dense_cube(s, albedo, g), common).steady.mean(axis=(0, 1))[c] for c, s in enumerate(sigma_t)]
    ratio = mixed.steady.mean(axis=(0, 1)) / np.array(grey)
    print(f"chromatic / grey per channel {np.round(ratio, 4)}, largest pixel {mixed.steady.max():.3g}")
    assert np.all(np.abs(ratio - 1) < 0.05)


# ----------------------------------------------------------------- slow: the figures of issue 16


# Mitsuba's references in dense media (DESIGN.md §12, "An exact check, and Mitsuba's offsets"): roulette
# from 3000 collisions (from 200 volpath's mean on the dense cube came out 1-2 % low at sigma_t = 400), the
# scene in millimetres, and the film rendered in 2 x 2-pixel tiles, each with the scene moved so that its
# own patch of the cube lies at the origin, where Mitsuba's single-precision ray offsets (9e-5 (1 + |p|)
# scene units) skip almost none of the medium. With the whole film at once and only the lit face through
# the origin they skipped about 0.05 mean free paths at sigma_t = 2000, and volpath came out 2 % above ours.
MI_RR = 3000
MI_UNITS = 1000.0
MI_SHIFT = (0.0, -0.5, 0.0)
MI_TILE = 2


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize(("sigma_t", "g"), [(400.0, 0.0), (400.0, 0.85), (2000.0, 0.0), (2000.0, 0.85)])
def test_dense_cube_steady_mean_against_volpath(sigma_t, g, validation):
    """Issue 16: within 2 % of volpath per channel, at unbounded depth."""
    refs = [
        mitsuba_dense_cube(
            sigma_t, 0.9995, g, spp=2048, seed=s, rr_depth=MI_RR, units=MI_UNITS, shift=MI_SHIFT, tile=MI_TILE
        )
        for s in range(4)
    ]
    ref = np.mean(refs, axis=0)
    lit = ref.mean(-1) > 1e-2 * ref.mean(-1).max()
    runs = [render(dense_cube(sigma_t, 0.9995, g), settings(iterations=1, time_budget_s=15, seed=s)) for s in (1, 2)]
    ours = np.mean([r.steady[lit].mean(0) for r in runs], axis=0)
    ratio = ours / ref[lit].mean(0)
    spread = np.std([x[lit].mean() for x in refs], ddof=1) / np.sqrt(len(refs)) / ref[lit].mean()
    print(f"sigma_t {sigma_t} g {g}: ours/volpath {ratio}, volpath's standard error {spread:.4f}")
    validation.record(
        f"dense cube, σ_t {sigma_t:g} per m, g {g}, steady: ours / volpath per channel",
        ratio,
        reference=1.0,
        tolerance="±2 %",
        against="Mitsuba 3 volpath in millimetre tiles, 4 × 2048 spp",
    )
    np.testing.assert_allclose(ratio, 1.0, atol=0.02)


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize(("sigma_t", "g"), [(400.0, 0.0), (400.0, 0.85), (2000.0, 0.0), (2000.0, 0.85)])
def test_dense_cube_frames_against_mitransient(sigma_t, g):
    """Issue 16: per-frame energy within 3 % of mitransient's for every frame holding more than 1 % of it
    (plus three standard errors of the measured noise of the two sides)."""
    film = {"frame_mode": "bins", "temporal_bins": 40, "start_opl": 3.0, "bin_width_opl": 0.1}
    refs = [
        mitsuba_dense_cube(
            sigma_t,
            0.9995,
            g,
            spp=8192,
            seed=s,
            rr_depth=MI_RR,
            units=MI_UNITS,
            shift=MI_SHIFT,
            tile=MI_TILE,
            film=film,
        )[0].sum(axis=(1, 2, 3))
        for s in range(4)
    ]
    ref = np.mean(refs, axis=0)
    scene = dense_cube(sigma_t, 0.9995, g, mode="bins")
    scene["film"] = film
    runs = [render(scene, settings(iterations=1, time_budget_s=30, seed=s)) for s in (1, 2)]
    ours = np.mean([r.frames.sum(axis=(1, 2, 3)) for r in runs], axis=0)
    held = ref > 0.01 * ref.sum()
    ratio = ours[held] / ref[held]
    ref_error = np.std(refs, axis=0, ddof=1)[held] / np.sqrt(len(refs)) / ref[held]
    ours_error = np.abs(runs[0].frames.sum(axis=(1, 2, 3)) - runs[1].frames.sum(axis=(1, 2, 3)))[held] / 2 / ref[held]
    print(
        f"sigma_t {sigma_t} g {g}: {held.sum()} frames, ours/mitransient {ratio.min():.4f}-{ratio.max():.4f}, "
        f"total {ours.sum() / ref.sum():.4f}; per frame {np.round(ratio, 3)}; mitransient's standard error up to "
        f"{ref_error.max():.3f}, ours up to {ours_error.max():.3f}"
    )
    assert held.sum() >= 3
    # The last frames hold about 1 % each and carry 1-2 % of noise on either side at g = 0.85: allow three
    # standard errors of the difference on top of the 3 %.
    noise = 3 * np.hypot(ref_error, ours_error)
    assert np.all(np.abs(ratio - 1) <= 0.03 + noise), (ratio, noise)


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize(("sigma_t", "mfps"), [(400.0, (0.1, 1.0, 10.0, 100.0)), (4.0, (0.1, 1.0, 10.0, 100.0))])
def test_no_start_radius_biases_the_mean(sigma_t, mfps):
    """Start radii from 0.1 to 100 mean free paths, on the dense cube and a thin one of the same albedo."""
    ref = np.mean(
        [
            mitsuba_dense_cube(sigma_t, 0.9995, 0.0, spp=2048, seed=s, rr_depth=MI_RR, units=MI_UNITS, shift=MI_SHIFT)
            for s in range(4)
        ],
        axis=0,
    )
    lit = ref.mean(-1) > 1e-2 * ref.mean(-1).max()
    for mfp in mfps:
        r = render(
            dense_cube(sigma_t, 0.9995, 0.0),
            settings(iterations=1, time_budget_s=12, initial_beam_radius=mfp / sigma_t),
        )
        ratio = r.steady[lit].mean() / ref[lit].mean()
        print(f"sigma_t {sigma_t}, R0 = {mfp} mfp: ours/volpath {ratio:.4f}, media on paths {r.stats['path_media']}")
        assert abs(ratio - 1) < 0.02


def mitsuba_half_space(sigma_t: float, albedo: float, spp: int, seed: int, rr_depth: int, units: float = 1.0):
    """``half_space``'s slab under a zenith sun in Mitsuba's volpath, steady (``units`` per metre)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("llvm_ad_rgb")
    T = mi.ScalarTransform4f
    scene = {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": rr_depth},
        "sensor": {
            "type": "perspective",
            "fov": HALF_SPACE_FOV,
            "fov_axis": "x",
            "near_clip": 1e-4 * units,
            "to_world": T().look_at(origin=[0, 1e-3 * units, 5.0 * units], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": HALF_SPACE_RES, "height": HALF_SPACE_RES, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "slab": {
            "type": "cube",
            "to_world": T().translate([0, 0, -0.75 * units]) @ T().scale([3 * units, 3 * units, 0.75 * units]),
            "bsdf": {"type": "null"},
            "interior": {
                "type": "homogeneous",
                "scale": sigma_t / units,
                "sigma_t": {"type": "rgb", "value": [1.0] * 3},
                "albedo": {"type": "rgb", "value": [albedo] * 3},
                "phase": {"type": "isotropic"},
            },
        },
        "sun": {"type": "directional", "direction": [0, 0, -1], "irradiance": {"type": "rgb", "value": [1] * 3}},
    }
    return np.asarray(mi.render(mi.load_dict(scene), spp=spp, seed=seed), dtype=np.float64)[..., :3]


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize("sigma_t", [400.0, 2000.0])
def test_mitsuba_references_against_the_exact_half_space(sigma_t):
    """Why the references above run in millimetres: against Chandrasekhar's half-space, volpath in metres
    comes out 1.2 % high at sigma_t = 400 and 4.4 % high at 2000 (its ray offset skips the top of the
    medium, where the upward radiance is lowest), in millimetres 0.3 % and 1.2 %. Ours is checked against
    the same value in the fast test above."""
    expected = half_space_expected(0.9995, 1.0)
    ratios = {
        units: float(np.mean([mitsuba_half_space(sigma_t, 0.9995, 512, s, MI_RR, units) for s in range(3)])) / expected
        for units in (1.0, MI_UNITS)
    }
    print(f"sigma_t {sigma_t}: volpath / Chandrasekhar in metres {ratios[1.0]:.4f}, millimetres {ratios[MI_UNITS]:.4f}")
    assert ratios[MI_UNITS] - 1 < 0.5 * (ratios[1.0] - 1)  # millimetres at least halve the bias
    assert abs(ratios[MI_UNITS] - 1) < 0.02


def diffusion_slab(frames: int = 160, width: float = 0.05) -> dict:
    """``half_space``'s slab with sigma_s' = 60 and sigma_a = 0.6 per m (snow in its isotropic reduced form, a
    little more absorbing so that the tail fits a test) under a plane-wave pulse from the zenith. The sun's
    wavefront passes the top face at tau = 0, so light that entered and left at once reaches the camera at
    5 m of OPL."""
    scene = half_space(60.6, 60.0 / 60.6, 1.0)
    scene["film"] = {"frame_mode": "bins", "temporal_bins": frames, "start_opl": 5.0, "bin_width_opl": width}
    return scene


def test_splitting_in_time_keeps_the_estimate_and_quiets_the_tail():
    """Splitting in time (DESIGN.md §12) on the diffusion slab's 8 m film: with path_splits 3 a path
    doubles at 1, 2 and 4 m of OPL past its first vertex. Frames before 1 m are bit-identical to the
    unsplit render (nothing is split there); later, each copy walks on independently, so at equal
    iterations a pixel's variance falls to about 1/2, 1/4 and 1/8 (measured 0.60, 0.30, 0.14), and the
    frames' energy and the steady image keep their expectation."""
    s = (np.arange(160) + 0.5) * 0.05
    runs = {
        splits: [render(diffusion_slab(), settings(iterations=150, seed=k, path_splits=splits)) for k in range(4)]
        for splits in (0, 3)
    }
    assert runs[0][0].stats["path_splits"] == 0 and runs[3][0].stats["path_splits"] > 1000
    early = s < 1.0
    assert all(np.array_equal(a.frames[early], b.frames[early]) for a, b in zip(runs[0], runs[3]))
    for (lo, hi), bound in zip([(1, 2), (2, 4), (4, 8)], [0.75, 0.4, 0.2]):
        band = (s > lo) & (s < hi)
        var = {
            k: np.mean([((r[i].frames[band] - r[i + 1].frames[band]) ** 2).mean() for i in (0, 2)])
            for k, r in runs.items()
        }
        print(f"{lo}-{hi} m: pixel variance with splitting / without {var[3] / var[0]:.3f}")
        assert var[3] / var[0] < bound
    for name, get in [
        ("late frames", lambda r: r.frames[s > 1.0].sum()),
        ("steady", lambda r: r.steady.sum()),
    ]:
        x = {k: np.array([get(r) for r in rs]) for k, rs in runs.items()}
        error = np.hypot(*(v.std(ddof=1) / np.sqrt(v.size) for v in x.values()))
        print(f"{name}: split / unsplit {x[3].mean() / x[0].mean():.4f}, standard error {error / x[0].mean():.4f}")
        assert abs(x[3].mean() - x[0].mean()) < 4 * error + 1e-3 * x[0].mean()


def test_hops_keep_every_frame_and_the_mean_time(validation):
    """Shell transport (DESIGN.md §12, "Hops") on the dense cube at albedo 0.9999, where hops carry most of
    the path length (about 60 %): each frame holding over 1 % of the energy and the mean OPL of the light
    must be those of the collision-by-collision walk, the frames within 1 % or three standard errors of the
    difference, the mean OPL within 0.5 %. Six seeds of each; with the hop's time left out of the OPL the
    mean time falls by tens of per cent, with its absorption left out the late frames rise."""
    scene = dense_cube(400.0, 0.9999, 0.0, mode="bins", res=16)
    scene["film"] = {"frame_mode": "bins", "temporal_bins": 12, "start_opl": 3.0, "bin_width_opl": 0.5}
    centres = 3.0 + (np.arange(12) + 0.5) * 0.5
    energy, stats = {}, {}
    for hops in (False, True):
        runs = [render(scene, settings(iterations=600, seed=k, path_hops=hops)) for k in range(6)]
        energy[hops] = np.array([r.frames.sum(axis=(1, 2, 3)) for r in runs])
        stats[hops] = runs[0].stats
    skipped = stats[True]["path_hop_scatterings"]
    share = skipped / (skipped + stats[True]["path_vertices"])
    print(
        f"collisions hopped over: {share:.3f}; vertices {stats[False]['path_vertices']} -> {stats[True]['path_vertices']}"
    )
    assert stats[False]["path_hops"] == 0 and share > 0.5
    mean = {k: e.mean(axis=0) for k, e in energy.items()}
    error = np.hypot(*(e.std(axis=0, ddof=1) / np.sqrt(e.shape[0]) for e in energy.values()))
    held = mean[False] > 0.01 * mean[False].sum()
    ratio = mean[True][held] / mean[False][held]
    print("frames, hops / none:", np.round(ratio, 4), "standard error:", np.round(error[held] / mean[False][held], 4))
    assert np.all(np.abs(mean[True] - mean[False])[held] < np.maximum(0.01 * mean[False], 3 * error)[held])
    opl = {k: (m * centres).sum() / m.sum() for k, m in mean.items()}
    print(f"mean OPL: hops {opl[True]:.4f} m, none {opl[False]:.4f} m")
    validation.record(
        "dense cube at ω 0.9999, mean OPL of the light [m]: with hops",
        opl[True],
        reference=opl[False],
        tolerance="±0.5 %",
        against="the collision-by-collision walk, 6 seeds each",
    )
    assert opl[True] == pytest.approx(opl[False], rel=0.005)


def test_hops_in_a_chromatic_medium_keep_each_channel():
    """A hop's walk is drawn for one channel; the others take the ratio of the walk's densities (DESIGN.md §12,
    "Hops"). With sigma_s 2 % apart between channels and sigma_a fivefold (the demo's firn is 1.9 % apart),
    each channel's mean must be the one without hops: within 1.5 % or three standard errors, four seeds each
    (measured 0.994, 0.994, 0.997, standard errors about 0.7 %)."""
    scene = dense_cube(400.0, 0.9995, 0.0, res=16)
    scene["media"][0]["sigma_s"] = (392.0, 400.0, 408.0)
    scene["media"][0]["sigma_a"] = (0.5, 0.2, 0.05)
    means, hops_taken = {}, 0
    for hops in (False, True):
        runs = [render(scene, settings(iterations=400, seed=k, path_hops=hops)) for k in range(4)]
        means[hops] = np.array([r.steady.mean(axis=(0, 1)) for r in runs])
        hops_taken += sum(r.stats["path_hops"] for r in runs) if hops else 0
    assert hops_taken > 1000
    error = np.hypot(*(m.std(axis=0, ddof=1) / 2 for m in means.values()))
    ratio = means[True].mean(axis=0) / means[False].mean(axis=0)
    print(
        "per channel, hops / none:",
        np.round(ratio, 4),
        "standard error:",
        np.round(error / means[False].mean(axis=0), 4),
    )
    assert np.all(
        np.abs(means[True].mean(axis=0) - means[False].mean(axis=0))
        < np.maximum(0.015 * means[False].mean(axis=0), 3 * error)
    )


@pytest.mark.mitsuba
@pytest.mark.slow
def test_time_resolved_diffusion_tail_of_a_thick_slab(validation):
    """R(s) ~ s^(-3/2) exp(-sigma_a s) (DESIGN.md §12): fit the power and sigma_a over s = 1-6 m of
    excess OPL, and compare the total with volpath's steady image. The tail starts late: fitted over
    0.3-6 m, the extrapolated-boundary dipole itself gives -1.43 and sigma_a +2.8 % (its image source sits
    z0 + 4D = 3.9 cm deep), over 1-6 m -1.46 and +1.2 %. The tail is noisy: one long path lights many late
    frames at once, so the fit scatters as a whole (10 s runs, seven seeds: power -1.36 to -1.65, sigma_a
    0.52 to 0.64; merging frames does not help). At 30 s that scatter (about 0.06 in the power) was close to
    the tolerance, and one seed failed; 90 s keeps it near a third of it."""
    r = render(diffusion_slab(), settings(iterations=1, time_budget_s=90))
    energy = r.frames.mean(axis=(1, 2, 3))
    s = (np.arange(energy.size) + 0.5) * 0.05
    fit = (s > 1.0) & (s < 6.0)
    design = np.stack([np.ones(fit.sum()), np.log(s[fit]), s[fit]], axis=1)
    (_, power, slope), *_ = np.linalg.lstsq(design, np.log(energy[fit]), rcond=None)
    print(
        f"power {power:.3f} (diffusion -1.5), sigma_a {-slope:.4f} (0.6), late fraction {r.stats['late_fraction']:.2e}"
    )
    validation.record(
        "thick slab, time-resolved tail over 1-6 m of excess OPL: fitted power of s",
        power,
        reference=-1.5,
        tolerance="±0.1",
        against="diffusion theory, R(s) ∝ s^-3/2 e^(-σ_a s)",
    )
    assert abs(power + 1.5) < 0.1
    assert abs(-slope / 0.6 - 1) < 0.05

    total = mitsuba_half_space(60.6, 60.0 / 60.6, 4096, 5, rr_depth=200).mean()
    ours = (r.frames.sum(axis=0) + r.early + r.late).mean()
    print(f"ours {ours:.5f}, volpath {total:.5f}, ratio {ours / total:.4f}")
    assert abs(ours / total - 1) < 0.03
