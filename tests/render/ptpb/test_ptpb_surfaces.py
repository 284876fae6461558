"""Surface photons on diffuse surfaces (render/core/DESIGN.md §7) against closed-form radiance and timing.

Every scene here is lit by a delta light with no media in the way (or a pure absorber, or a
glass slab), so the radiance of a Lambertian plane is known exactly: L = E_perp ρ / π, with
E_perp the irradiance on the plane.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest

from pipeline.schema.ptpb import PTPBConfig
from render import _core
from render.ptpb.api import render, scene_bounding_sphere
from render.scene.shapes import box_mesh, quad_mesh

ALBEDO = 0.5
CAMERA = np.array([0.0, 0.0, 3.0])


def plane(half: float = 0.5, albedo: float = ALBEDO) -> dict:
    """Diffuse square z = 0 of half-size ``half`` (m), normal +z."""
    v, f = quad_mesh(center=(0, 0, 0), u=(half, 0, 0), v=(0, half, 0))
    return {"vertices": v, "faces": f, "kind": "diffuse", "albedo": (albedo,) * 3}


def sun(theta_deg: float, irradiance: float) -> dict:
    th = math.radians(theta_deg)
    return {"to_sun": (math.sin(th), 0.0, math.cos(th)), "irradiance": (irradiance,) * 3}


def scene(
    shapes: list,
    *,
    media=(),
    directional=(),
    point=(),
    res: int = 16,
    fov: float = 10.0,
    origin=tuple(CAMERA),
    mode: str = "steady",
    bins: int = 0,
    start: float = 0.0,
    width: float = 0.01,
) -> dict:
    """Camera looking straight down at the origin (up = +y)."""
    return {
        "media": list(media),
        "shapes": list(shapes),
        "directional_lights": list(directional),
        "point_lights": list(point),
        "camera": {"origin": origin, "target": (0, 0, 0), "up": (0, 1, 0), "fov": fov, "width": res, "height": res},
        "film": {"frame_mode": mode, "temporal_bins": bins, "start_opl": start, "bin_width_opl": width},
    }


def settings(**kw) -> dict:
    base = {
        "medium_estimator": "beams",  # these tests check the beam estimator (render/core/DESIGN.md §12)
        "iterations": 8,
        "light_paths_per_iteration": 200000,
        "initial_beam_radius": 0.05,
        "initial_surface_radius": 0.06,
        "max_depth": 16,
        "seed": 1,
        "threads": 2,
    }
    base.update(kw)
    return base


def pixel_hits(sc: dict) -> np.ndarray:
    """(H, W, 3) points where the pixel-centre rays (jitter off) meet the plane z = 0."""
    cam = sc["camera"]
    w, h = cam["width"], cam["height"]
    o = np.asarray(cam["origin"], dtype=np.float64)
    forward = -o / np.linalg.norm(o)
    left = np.cross(np.asarray(cam["up"], dtype=np.float64), forward)
    left /= np.linalg.norm(left)
    up = np.cross(forward, left)
    tx = math.tan(math.radians(cam["fov"]) / 2)
    ty = tx * h / w
    sx = (np.arange(w) + 0.5) / w
    sy = (np.arange(h) + 0.5) / h
    d = left * ((1 - 2 * sx)[None, :, None] * tx) + up * ((1 - 2 * sy)[:, None, None] * ty) + forward
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    t = -o[2] / d[..., 2]
    return o + d * t[..., None]


def centre(a: np.ndarray, k: int) -> np.ndarray:
    h, w = a.shape[:2]
    return a[h // 2 - k // 2 : h // 2 + k // 2, w // 2 - k // 2 : w // 2 + k // 2]


def sun_tau(sc: dict, x: np.ndarray, theta_deg: float) -> np.ndarray:
    """Arrival OPL of unscattered sunlight at x in air: R_s − (x − C)·s (render/core/DESIGN.md §1)."""
    c, r_s = scene_bounding_sphere(sc)
    th = math.radians(theta_deg)
    s = np.array([math.sin(th), 0.0, math.cos(th)])
    return r_s - (x - c) @ s


@pytest.mark.parametrize("theta", [0.0, 60.0])
def test_sunlit_plane_radiance_is_E_cos_rho_over_pi(theta):
    E = 2.0
    sc = scene([plane()], directional=[sun(theta, E)])
    # The PTPBConfig path: r_0 defaults to 2 pixel footprints at the camera-to-centre distance.
    cfg = PTPBConfig(iterations=10, light_paths_per_iteration=400000, seed=7, threads=2, max_depth=16)
    r = render(sc, cfg)
    footprint = 2 * 3.0 * math.tan(math.radians(5.0)) / 16
    assert r.stats["initial_surface_radius_m"] == pytest.approx(2 * footprint, rel=1e-9)
    assert r.stats["surface_alpha"] == pytest.approx(2 / 3)
    assert r.stats["final_surface_radius"] == pytest.approx(
        2 * footprint * math.sqrt(_core.ptpb_schedule_gamma(9, 2 / 3)), rel=1e-9
    )
    assert r.stats["surface_photons"] > 0 and r.stats["surface_pairs"] > 0
    expected = E * math.cos(math.radians(theta)) * ALBEDO / math.pi
    ratio = float(centre(r.steady, 8).mean(dtype=np.float64)) / expected
    print(f"sun at {theta:.0f} deg: centre 8x8 / (E cos ρ/π) = {ratio:.4f}, {r.stats['time_total_s']:.2f} s")
    assert abs(ratio - 1) < 0.02, ratio
    # Every channel and every centre pixel, not only the mean (per-pixel noise is ~4%).
    assert np.all(np.abs(centre(r.steady, 8) / expected - 1) < 0.2)


@pytest.mark.parametrize("theta", [0.0, 60.0])
def test_sunlit_plane_bins_sum_to_steady_and_arrive_on_time(theta):
    E, width = 2.0, 0.01
    sc = scene([plane()], directional=[sun(theta, E)], mode="bins", bins=60, start=3.4, width=width)
    r = render(sc, settings(iterations=4), jitter=False)
    total = r.frames.sum(0, dtype=np.float64) + r.early + r.late
    np.testing.assert_allclose(total, r.steady, rtol=1e-4, atol=1e-7 * float(r.steady.max()))
    assert r.stats["out_of_window_fraction"] == 0.0
    # Predicted OPL per pixel: the sun's τ at the hit point plus the camera leg.
    x = pixel_hits(sc)
    tau = sun_tau(sc, x, theta) + np.linalg.norm(x - CAMERA, axis=-1)
    energy = r.frames[..., 0].astype(np.float64)  # (F, H, W)
    centres = 3.4 + (np.arange(60) + 0.5) * width
    if theta == 0.0:
        # Every photon has τ_p = R_s exactly, so each pixel's light sits in the one predicted bin.
        k = np.floor((tau - 3.4) / width).astype(int)
        clear = np.abs((tau - 3.4) / width - np.round((tau - 3.4) / width)) > 1e-3  # not on a bin edge
        assert clear.sum() > 200
        frac = np.take_along_axis(energy, k[None], 0)[0] / energy.sum(0)
        assert np.all(frac[clear] > 0.9999), frac[clear].min()
    else:
        # τ_p varies by ± r sin θ across the kernel; a symmetric kernel keeps its mean at τ(x).
        mean_tau = (energy * centres[:, None, None]).sum(0) / energy.sum(0)
        err = np.abs(mean_tau - tau)
        print(f"sun at 60 deg: |mean τ − predicted| max {err.max() * 1e3:.2f} mm, mean {err.mean() * 1e3:.2f} mm")
        assert err.max() < 0.5 * width, err.max()
        reach = 0.06 * math.sin(math.radians(theta)) + width
        first = centres[np.argmax(energy > 0, axis=0)]
        assert np.all(first >= tau - reach), (first - tau).min()
    # camera_unwarp drops the camera leg: the light arrives at the plane's own τ.
    sc_u = scene([plane()], directional=[sun(theta, E)], mode="bins", bins=60, start=0.4, width=width)
    u = render(sc_u, settings(iterations=1, light_paths_per_iteration=50000, camera_unwarp=True), jitter=False)
    mean_u = (u.frames[..., 0].sum((1, 2), dtype=np.float64) * (0.4 + (np.arange(60) + 0.5) * width)).sum() / u.frames[
        ..., 0
    ].sum(dtype=np.float64)
    assert mean_u == pytest.approx(float(sun_tau(sc_u, pixel_hits(sc_u), theta).mean()), abs=0.5 * width)


def test_gate_frames_use_the_surface_time_kernel_and_schedule():
    # Normal incidence, jitter off: pixel p's light is a delta at τ_p, so with the per-iteration
    # estimates L_i (from the snapshots) gate frame k must be (1/N) Σ_i L_i K_{T_i}(τ_k − τ_p), with
    # the surfaces' own T_i = T_0 γ_i^(1/3) (α = 4/7), not the beams' T.
    width, bins, start, t0 = 0.01, 60, 3.4, 0.03
    sc = scene([plane()], directional=[sun(0.0, 2.0)], mode="gate", bins=bins, start=start, width=width)
    n = 3
    r = render(
        sc,
        settings(
            iterations=n,
            light_paths_per_iteration=50000,
            initial_time_half_width=0.011,
            initial_surface_time_half_width=t0,
            snapshot_every=1,
        ),
        jitter=False,
    )
    gammas = [_core.ptpb_schedule_gamma(i, 4 / 7) for i in range(n)]
    assert r.stats["final_surface_time_half_width"] == pytest.approx(t0 * gammas[-1] ** (1 / 3), rel=1e-12)
    assert r.stats["final_surface_radius"] == pytest.approx(0.06 * gammas[-1] ** (1 / 3), rel=1e-12)
    snaps = [s[1].astype(np.float64) for s in r.snapshots]
    per_it = [snaps[0]] + [(i + 1) * snaps[i] - i * snaps[i - 1] for i in range(1, n)]
    x = pixel_hits(sc)
    tau = sun_tau(sc, x, 0.0) + np.linalg.norm(x - CAMERA, axis=-1)
    tk = start + (np.arange(bins) + 0.5) * width
    expected = np.zeros(r.frames.shape)
    for L, g in zip(per_it, gammas):
        T = t0 * g ** (1 / 3)
        d = (tk[:, None, None] - tau[None]) / T
        K = np.where(np.abs(d) <= 1, 0.75 / T * (1 - d * d), 0.0)  # Epanechnikov
        expected += K[..., None] * L[None] / n
    np.testing.assert_allclose(r.frames, expected, rtol=2e-4, atol=1e-5 * expected.max())


def test_point_light_over_plane_foot_radiance_is_I_rho_over_pi_h2():
    intensity, h = 1.5, 1.0
    # Camera 2.5 m up, looking through the (point, invisible) light at its foot; image ±0.2 m.
    fov = 2 * math.degrees(math.atan(0.2 / 2.5))
    sc = scene(
        [plane(half=1.0)], point=[{"position": (0, 0, h), "intensity": (intensity,) * 3}], origin=(0, 0, 2.5), fov=fov
    )
    r = render(sc, settings(iterations=8, light_paths_per_iteration=1000000, initial_surface_radius=0.05), jitter=False)
    x = pixel_hits(sc)
    rho2 = (x[..., :2] ** 2).sum(-1)
    analytic = intensity * ALBEDO * h / (math.pi * (h * h + rho2) ** 1.5)  # E = I cos θ / d²
    foot = intensity * ALBEDO / (math.pi * h * h)
    est = centre(r.steady[..., 0], 4).mean(dtype=np.float64)
    ratio_pixels = est / centre(analytic, 4).mean()
    ratio_foot = est / foot
    wide = centre(r.steady[..., 0], 12).mean(dtype=np.float64) / centre(analytic, 12).mean()
    print(
        f"point light: centre 4x4 / analytic {ratio_pixels:.4f}, / I ρ/(π h²) {ratio_foot:.4f}, "
        f"12x12 {wide:.4f}, {r.stats['time_total_s']:.2f} s"
    )
    assert abs(ratio_foot - 1) < 0.03
    assert abs(ratio_pixels - 1) < 0.03
    assert abs(wide - 1) < 0.02


@pytest.mark.parametrize("mode", ["bins", "gate"])
def test_surfaces_with_media_are_bit_identical_across_threads(mode):
    # A scattering cube standing on a diffuse floor under the sun: beams, photons and beams fed by
    # photons (light reflected off the floor into the medium) all meet in one image.
    cv, cf = box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 0.6))
    sc = scene(
        [plane(half=1.0), {"vertices": cv, "faces": cf, "kind": "null", "interior": 0, "exterior": -1}],
        media=[{"sigma_s": (2.0, 3.0, 4.0), "sigma_a": (0.2, 0.2, 0.2), "g": 0.5, "ior": 1.0}],
        directional=[sun(40.0, 2.0)],
        origin=(0.0, -2.0, 2.0),
        fov=50,
        mode=mode,
        bins=40,
        start=3.0,
        width=0.05,
    )
    sc["camera"]["up"] = (0, 0, 1)
    results = []
    for threads in (1, 2):
        r = render(
            sc,
            settings(
                iterations=2, light_paths_per_iteration=20000, threads=threads, alpha=2 / 3 if mode == "gate" else 0.8
            ),
        )
        results.append(r)
    a, b = results
    assert a.stats["surface_pairs"] > 0 and a.stats["pair_evaluations"] > 0
    assert hashlib.sha256(a.steady.tobytes()).hexdigest() == hashlib.sha256(b.steady.tobytes()).hexdigest()
    assert hashlib.sha256(a.frames.tobytes()).hexdigest() == hashlib.sha256(b.frames.tobytes()).hexdigest()
    assert a.stats["surface_photons"] == b.stats["surface_photons"]
    assert a.stats["surface_pairs"] == b.stats["surface_pairs"]


def test_floor_under_an_absorbing_slab_is_attenuated_twice():
    # Index-matched slab 0.1 m thick (z in [0.1, 0.2]), pure absorber: sunlight loses
    # exp(−σ_a d / cos θ_sun) on the way down and the camera ray exp(−σ_a d / cos φ) on the way up.
    sigma_a = np.array([1.0, 2.0, 4.0])
    theta, E, d = 30.0, 2.0, 0.1
    sv, sf = box_mesh((-0.8, -0.6, 0.1), (0.8, 0.6, 0.2))
    sc = scene(
        [plane(), {"vertices": sv, "faces": sf, "kind": "null", "interior": 0, "exterior": -1}],
        media=[{"sigma_s": (0, 0, 0), "sigma_a": tuple(sigma_a), "g": 0.0, "ior": 1.0}],
        directional=[sun(theta, E)],
    )
    r = render(sc, settings(iterations=10, light_paths_per_iteration=400000, max_depth=2), jitter=False)
    x = pixel_hits(sc)
    cos_cam = (CAMERA[2] - x[..., 2]) / np.linalg.norm(CAMERA - x, axis=-1)
    cos_sun = math.cos(math.radians(theta))
    analytic = (
        E
        * cos_sun
        * ALBEDO
        / math.pi
        * np.exp(-sigma_a * d / cos_sun)[None, None]
        * np.exp(-sigma_a[None, None] * d / cos_cam[..., None])
    )
    ratio = centre(r.steady, 8).mean((0, 1), dtype=np.float64) / centre(analytic, 8).mean((0, 1))
    print(f"absorbing slab: centre 8x8 / analytic per channel {np.round(ratio, 4).tolist()}")
    assert np.all(np.abs(ratio - 1) < 0.02), ratio


def test_max_depth_counts_light_and_camera_interactions_through_glass():
    # Sun at normal incidence through a glass slab (n = 1.5) onto the floor, seen through it: the
    # shortest path is 2 light-side + 2 camera-side interfaces + the reflection, depth 6.
    # max_depth = 5 must leave the floor black; at 6 only the transmit-transmit chains count, so
    # L = E ρ/π (1 − F(0))² (1 − F(φ))² (the camera's (n_i/n_t)² factors cancel in and out).
    gv, gf = box_mesh((-0.6, -0.6, 0.1), (0.6, 0.6, 0.2))
    glass = {"vertices": gv, "faces": gf, "kind": "dielectric", "interior": 0, "exterior": -1}
    sc = scene(
        [plane(), glass],
        media=[{"sigma_s": (0, 0, 0), "sigma_a": (0, 0, 0), "g": 0.0, "ior": 1.5}],
        directional=[sun(0.0, 2.0)],
    )
    base = settings(iterations=10, light_paths_per_iteration=400000, rr_depth=64)
    black = render(sc, {**base, "iterations": 1, "max_depth": 5}, jitter=False)
    assert black.stats["surface_photons"] > 0 and float(black.steady.max()) == 0.0
    r6 = render(sc, {**base, "max_depth": 6}, jitter=False)

    def fresnel(cos_i, n_i=1.0, n_t=1.5):
        sin_t2 = (n_i / n_t) ** 2 * (1 - cos_i**2)
        cos_t = np.sqrt(1 - sin_t2)
        rs = (n_i * cos_i - n_t * cos_t) / (n_i * cos_i + n_t * cos_t)
        rp = (n_t * cos_i - n_i * cos_t) / (n_t * cos_i + n_i * cos_t)
        return 0.5 * (rs * rs + rp * rp)

    # The camera rays leave the pixel centres at angle φ to the vertical; the floor is uniform, so
    # the lateral shift inside the glass does not matter.
    x = pixel_hits(sc)
    cos_cam = CAMERA[2] / np.linalg.norm(CAMERA - x, axis=-1)
    analytic = 2.0 * ALBEDO / math.pi * (1 - fresnel(1.0)) ** 2 * (1 - fresnel(cos_cam)) ** 2
    ratio = centre(r6.steady[..., 0], 8).mean(dtype=np.float64) / centre(analytic, 8).mean()
    unbounded = render(sc, {**base, "iterations": 4, "max_depth": -1}, jitter=False)
    gain = centre(unbounded.steady[..., 0], 8).mean(dtype=np.float64) / centre(r6.steady[..., 0], 8).mean(
        dtype=np.float64
    )
    print(f"glass: depth 6 / analytic {ratio:.4f}; unbounded / depth 6 {gain:.4f}")
    assert abs(ratio - 1) < 0.02, ratio
    assert gain > 1.01  # inter-reflections between floor and glass add light beyond depth 6


def test_progress_reports_surface_photons_and_radius():
    seen = []
    sc = scene([plane()], directional=[sun(0.0, 1.0)], res=8)
    render(sc, settings(iterations=2, light_paths_per_iteration=5000), progress=lambda info: seen.append(info))
    last = seen[-1]
    assert last["surface_photons"] > 0
    assert last["surface_radius"] == pytest.approx(0.06 * math.sqrt(_core.ptpb_schedule_gamma(1, 2 / 3)))
