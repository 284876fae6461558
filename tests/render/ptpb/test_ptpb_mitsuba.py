"""Steady comparison with Mitsuba 3 volpath on render/core/DESIGN.md §10 test 4's cube, reduced for CI:
24x24 pixels, Mitsuba at 16384 spp, ours with 32 iterations of 100k light paths (R_0 = 1 cm)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_ptpb_physics import cube_scene  # noqa: E402

from render.ptpb.api import render  # noqa: E402

RES = 24
MAXD = 64


def mitsuba_cube(
    spp: int,
    seed: int = 0,
    film: dict | None = None,
    *,
    interior: dict | None = None,
    origin=None,
    max_depth: int = MAXD,
    rr_depth: int = 5,
    units: float = 1.0,
    shift=(0.0, 0.0, 0.0),
    tile: int = 0,
):
    """The cube in Mitsuba volpath (steady image), or with ``film`` (temporal_bins, start_opl,
    bin_width_opl) in mitransient's transient_prbvolpath: then (frames (T, H, W, 3), steady).
    ``interior`` replaces the cube's medium and ``origin`` the camera position. ``units`` scene units
    make a metre (1000: millimetres), and ``shift`` [m] moves the whole scene: the same physical scene, which
    Mitsuba's single-precision ray offsets (about 9e-5 (1 + |p|) scene units) bias less in dense media when
    the lit face lies near the origin of a millimetre frame (render/core/DESIGN.md §12). With ``tile`` > 0
    the film is rendered in tiles of that many pixels, each with the whole scene moved so that the point
    its central ray meets on the cube lies at the origin: there the offsets shrink with the tile's extent
    instead of the cube's (tiles that miss the cube keep ``shift``)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("llvm_ad_rgb")
    opts = dict(
        spp=spp, film=film, interior=interior, origin=origin, max_depth=max_depth, rr_depth=rr_depth, units=units
    )
    if tile <= 0:
        return _render_cube(mi, seed=seed, shift=shift, crop=None, **opts)
    probe = mi.load_dict(
        _cube_dict(mi, **{**opts, "spp": 1, "film": None, "units": 1.0}, seed=0, shift=(0, 0, 0), crop=None)
    )
    sensor = probe.sensors()[0]
    steady = np.zeros((RES, RES, 3))
    frames = None if film is None else np.zeros((film["temporal_bins"], RES, RES, 3))
    corners = [(x0, y0) for y0 in range(0, RES, tile) for x0 in range(0, RES, tile)]
    for k, (x0, y0) in enumerate(corners):
        w, h = min(tile, RES - x0), min(tile, RES - y0)
        centre = mi.Point2f((x0 + 0.5 * w) / RES, (y0 + 0.5 * h) / RES)
        ray, _ = sensor.sample_ray(0.0, 0.5, centre, mi.Point2f(0.5, 0.5))
        hit = probe.ray_intersect(ray)
        moved = tuple(-float(v[0]) for v in hit.p) if bool(hit.is_valid()[0]) else shift
        # Each tile its own seed: a cropped film numbers its pixels from 0, so equal seeds would repeat streams.
        key = seed * len(corners) + k
        out = _render_cube(mi, seed=key, shift=moved, crop=(x0, y0, w, h), **opts)
        if film is None:
            steady[y0 : y0 + h, x0 : x0 + w] = out
        else:
            # mitransient 1.x sizes its transient block by the whole film and fills it from the corner.
            frames[:, y0 : y0 + h, x0 : x0 + w] = out[0][:, :h, :w]
            steady[y0 : y0 + h, x0 : x0 + w] = out[1]
    return steady if film is None else (frames, steady)


def _cube_dict(mi, *, spp, seed, film, interior, origin, max_depth, rr_depth, units, shift, crop) -> dict:
    T = mi.ScalarTransform4f
    frame = T().scale(units) @ T().translate(list(shift))
    cam = cube_scene(res=RES)["camera"]
    if origin is not None:
        cam["origin"] = origin
    if film is None:
        integrator = {"type": "volpath", "max_depth": max_depth, "rr_depth": rr_depth}
        film_dict = {"type": "hdrfilm", "width": RES, "height": RES, "rfilter": {"type": "box"}, "pixel_format": "rgb"}
    else:
        import mitransient  # noqa: F401  (registers its plugins for the variant set above)

        integrator = {
            "type": "transient_prbvolpath",
            "max_depth": max_depth,
            "rr_depth": rr_depth,
            "camera_unwarp": False,
        }
        film_dict = {
            "type": "transient_hdr_film",
            "width": RES,
            "height": RES,
            "rfilter": {"type": "box"},
            "temporal_bins": film["temporal_bins"],
            "start_opl": film["start_opl"] * units,
            "bin_width_opl": film["bin_width_opl"] * units,
        }
    if crop is not None:
        film_dict.update(crop_offset_x=crop[0], crop_offset_y=crop[1], crop_width=crop[2], crop_height=crop[3])
    medium = dict(
        interior
        or {
            "type": "homogeneous",
            "scale": 8.0,
            "sigma_t": {"type": "rgb", "value": [0.5, 0.75, 1.0]},
            "albedo": {"type": "rgb", "value": [0.9, 0.9, 0.9]},
            "phase": {"type": "hg", "g": 0.7},
        }
    )
    medium["scale"] = medium["scale"] / units
    return {
        "type": "scene",
        "integrator": integrator,
        "sensor": {
            # near_clip: Mitsuba's default of 1 cm would start mitransient's OPL 1 cm past the pinhole.
            "type": "perspective",
            "fov": 40,
            "fov_axis": "x",
            "near_clip": 1e-4 * units,
            "to_world": T().look_at(
                origin=frame @ mi.ScalarPoint3f(cam["origin"]),
                target=frame @ mi.ScalarPoint3f(0, 0, 0),
                up=[0, 1, 0],
            ),
            "film": film_dict,
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
        "cube": {
            "type": "cube",
            "to_world": frame @ T().scale(0.5),
            "bsdf": {"type": "null"},
            "interior": medium,
        },
        "light": {
            "type": "rectangle",
            "to_world": frame @ T().look_at(origin=[0, 1.5, 0], target=[0, 0, 0], up=[0, 0, 1]) @ T().scale(0.25),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [20, 20, 20]}},
        },
    }


def _render_cube(mi, **kw):
    scene = mi.load_dict(_cube_dict(mi, **kw))
    spp, film = kw["spp"], kw["film"]
    if film is None:
        return np.asarray(mi.render(scene, spp=spp), dtype=np.float64)[..., :3]
    steady, transient = mi.render(scene, spp=spp)
    frames = np.moveaxis(np.asarray(transient, dtype=np.float64)[..., :3], 2, 0)  # (H, W, T, C) -> (T, H, W, C)
    return frames, np.asarray(steady, dtype=np.float64)[..., :3]


@pytest.mark.mitsuba
@pytest.mark.slow
def test_steady_cube_mean_and_convergence_against_mitsuba_volpath(validation):
    # Two independent 16384-spp references: their average is ~10x less noisy than our renders below.
    ref_a, ref_b = mitsuba_cube(spp=16384, seed=0), mitsuba_cube(spp=16384, seed=1)
    ref = 0.5 * (ref_a + ref_b)
    medium = ref.mean(-1) > 1e-3 * ref.mean(-1).max()  # pixels that see the lit medium
    assert medium.sum() > 0.2 * RES * RES
    settings = {
        "iterations": 64,
        "light_paths_per_iteration": 20000,
        "initial_beam_radius": 0.02,
        "alpha": 0.8,
        "max_depth": MAXD,
        "rr_depth": 5,
        "threads": 2,
        "medium_estimator": "beams",
        "snapshot_every": 8,
    }
    runs = [render(cube_scene("steady", res=RES), {**settings, "seed": seed}) for seed in range(12, 18)]
    ratio = np.mean([r.steady[medium].mean(0) for r in runs], axis=0) / ref[medium].mean(0)
    print("ours/mitsuba per channel:", ratio)
    # Issue 4 asks for the mean within 2 %; per channel we allow 3 % for the noise of the runs.
    volpath = "Mitsuba 3 volpath, 2 × 16384 spp"
    validation.record(
        "medium cube, steady: ours / volpath, mean of channels",
        ratio.mean(),
        reference=1.0,
        tolerance="±2 %",
        against=volpath,
    )
    validation.record(
        "medium cube, steady: ours / volpath, per channel (R, G, B)",
        ratio,
        reference=1.0,
        tolerance="±3 %",
        against=volpath,
    )
    assert abs(ratio.mean() - 1) < 0.02
    np.testing.assert_allclose(ratio, 1.0, atol=0.03)
    its = np.array([it for it, _ in runs[0].snapshots], dtype=float)
    rel = np.mean([[((s - ref) ** 2 / (ref**2 + 1e-2)).mean() for _, s in r.snapshots] for r in runs], axis=0)
    # The reference's own noise adds to every point and flattens the fit: take out its expected share,
    # E[(a - b)^2] / 4 per value for the mean of two independent halves.
    ref_noise = ((ref_a - ref_b) ** 2 / 4 / (ref**2 + 1e-2)).mean()
    print("iterations", its, "relMSE", rel, "reference noise", ref_noise)
    rel = rel - ref_noise
    assert ref_noise < 0.2 * rel[-1]  # a small correction
    upper = its >= 16
    assert np.all(np.diff(rel[its >= 8][::2]) < 0), rel  # 8, 24, 40, 56 iterations: falling
    slope = np.polyfit(np.log(its[upper]), np.log(rel[upper]), 1)[0]
    print("slope over 16-64 iterations", slope)
    validation.record(
        "medium cube, steady: slope of log relMSE against log iterations (16-64)",
        slope,
        reference=-0.8,
        tolerance="±0.15",
        against="the beam kernel's N^-4/5 (render/core/DESIGN.md §6), error against volpath",
    )
    # Theory for the 1D beam kernel in bins/steady mode: relMSE ~ N^-alpha with alpha = 4/5 (render/core/DESIGN.md §6).
    assert abs(slope - (-0.8)) < 0.15, slope


@pytest.mark.mitsuba
@pytest.mark.slow
def test_transient_bins_match_mitransient_frame_by_frame(validation):
    """Issue 4: per-frame means within 3 % of mitransient for every frame above 1 % of the energy.

    The frame mean is the image-plane average of a box-filtered pinhole film, the same at any
    resolution, so ours renders the cube at 72 x 72 (nine times the queries of 24 x 24 per light
    path) against mitransient at 24 x 24. A single run of either side scatters by a few per cent a
    frame, so both sides average 16 runs; the first frame carries the kernel's loss at the lit faces
    and sets the tolerance."""
    film = {**cube_scene("bins")["film"], "temporal_bins": 27, "bin_width_opl": 0.15}  # the pulse and its tail
    refs = [mitsuba_cube(spp=16384, seed=seed, film=film) for seed in range(3, 19)]
    ref_profiles = np.array([frames.mean(axis=(1, 2, 3)) for frames, _ in refs])
    frames_ref = np.mean([frames for frames, _ in refs], axis=0)
    steady_ref = np.mean([steady for _, steady in refs], axis=0)
    assert frames_ref.shape == (film["temporal_bins"], RES, RES, 3)
    # Both sides bin the same energy: the frames sum to each side's steady image (render/core/DESIGN.md §10 test 1).
    assert frames_ref.sum() == pytest.approx(steady_ref.sum(), rel=3e-3)  # less the tail after end_opl

    scene = cube_scene("bins", res=3 * RES)
    scene["film"] = film
    # R_0 = 1 cm: the kernel's mass lost outside the lit faces takes the earliest light first.
    settings = {
        "iterations": 48,
        "light_paths_per_iteration": 40000,
        "initial_beam_radius": 0.01,
        "alpha": 0.8,
        "max_depth": MAXD,
        "rr_depth": 5,
        "threads": 2,
        "medium_estimator": "beams",
    }
    profiles = np.array(
        [render(scene, {**settings, "seed": seed}).frames.mean(axis=(1, 2, 3)) for seed in range(31, 47)]
    )

    profile_ref, profile = ref_profiles.mean(axis=0), profiles.mean(axis=0)
    energetic = profile_ref > 0.01 * profile_ref.sum()
    assert energetic.sum() >= 10
    ratio = profile[energetic] / profile_ref[energetic]
    # The comparison must be able to resolve 3 %: the standard error of the ratio, from the spread
    # of the runs on both sides, is 0.3-0.9 % on most frames and 1.1-1.4 % on the late, faint ones.
    se = np.hypot(
        profiles.std(axis=0, ddof=1) / profile / np.sqrt(len(profiles)),
        ref_profiles.std(axis=0, ddof=1) / profile_ref / np.sqrt(len(ref_profiles)),
    )[energetic]
    print("per-frame ours/mitransient:", np.round(ratio, 4))
    print("standard error of the ratio:", np.round(se, 4))
    assert se.max() < 0.015 and np.median(se) < 0.008
    validation.record(
        "medium cube, transient bins: ours / mitransient per frame above 1 % of the energy",
        ratio,
        reference=1.0,
        tolerance="±3 % each",
        against="mitransient transient_prbvolpath, 16 × 16384 spp",
    )
    np.testing.assert_allclose(ratio, 1.0, atol=0.03)
    assert np.mean(np.abs(ratio - 1)) < 0.015
    # The onset: the first frame above 1 % of the peak is the same on both sides, within one frame.
    onset = lambda p: int(np.argmax(p > 0.01 * p.max()))  # noqa: E731
    assert abs(onset(profile) - onset(profile_ref)) <= 1


def ice_slab_scene(res: int) -> dict:
    """A 1 x 0.3 x 1 m slab of lightly scattering ice (IOR 1.31, smooth dielectric) under the cube scene's
    area light. A slab, not a sphere: a sphere focuses the light into a caustic that few camera rays
    sample, and the estimate's noise would swamp a 3 % comparison."""
    from render.scene.shapes import box_mesh

    scene = cube_scene("steady", res=res)
    sv, sf = box_mesh((-0.5, -0.15, -0.5), (0.5, 0.15, 0.5))
    # g = 0.5: a sharper forward lobe (bubbles: 0.86) makes the few pairs aimed at the camera dominate the noise.
    scene["media"] = [{"sigma_s": (2.0, 2.0, 2.0), "sigma_a": (0.24, 0.047, 0.022), "g": 0.5, "ior": 1.31}]
    scene["shapes"][0] = {"vertices": sv, "faces": sf, "kind": "dielectric", "interior": 0, "exterior": -1}
    return scene


def mitsuba_ice_slab(tmp_path, spp: int, seed: int) -> np.ndarray:
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("llvm_ad_rgb")
    from geometry.meshio import write_ply

    T = mi.ScalarTransform4f
    scene = ice_slab_scene(RES)
    write_ply(tmp_path / "slab.ply", scene["shapes"][0]["vertices"], scene["shapes"][0]["faces"])
    write_ply(tmp_path / "light.ply", scene["shapes"][1]["vertices"], scene["shapes"][1]["faces"])
    m = scene["media"][0]
    sigma_t = np.add(m["sigma_s"], m["sigma_a"])
    cam = scene["camera"]
    loaded = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "volpath", "max_depth": MAXD, "rr_depth": 5},
            "sensor": {
                # near_clip: Mitsuba's default of 1 cm would start mitransient's OPL 1 cm past the pinhole.
                "type": "perspective",
                "fov": 40,
                "fov_axis": "x",
                "near_clip": 1e-4,
                "to_world": T().look_at(origin=list(cam["origin"]), target=[0, 0, 0], up=[0, 1, 0]),
                "film": {
                    "type": "hdrfilm",
                    "width": RES,
                    "height": RES,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgb",
                },
                "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
            },
            "slab": {
                "type": "ply",
                "filename": str(tmp_path / "slab.ply"),
                "face_normals": True,
                "bsdf": {"type": "dielectric", "int_ior": 1.31, "ext_ior": 1.0},
                "interior": {
                    "type": "homogeneous",
                    "scale": float(sigma_t.max()),
                    "sigma_t": {"type": "rgb", "value": (sigma_t / sigma_t.max()).tolist()},
                    "albedo": {"type": "rgb", "value": (np.asarray(m["sigma_s"]) / sigma_t).tolist()},
                    "phase": {"type": "hg", "g": m["g"]},
                },
            },
            "light": {
                "type": "ply",
                "filename": str(tmp_path / "light.ply"),
                "face_normals": True,
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [20, 20, 20]}},
            },
        }
    )
    return np.asarray(mi.render(loaded, spp=spp), dtype=np.float64)[..., :3]


@pytest.mark.mitsuba
@pytest.mark.slow
def test_dielectric_ice_slab_matches_mitsuba_volpath(tmp_path, validation):
    ref = 0.5 * (mitsuba_ice_slab(tmp_path, spp=16384, seed=0) + mitsuba_ice_slab(tmp_path, spp=16384, seed=1))
    settings = {
        "iterations": 48,
        "light_paths_per_iteration": 40000,
        "initial_beam_radius": 0.02,
        "alpha": 0.8,
        "max_depth": MAXD,
        "rr_depth": 5,
        "threads": 2,
        "medium_estimator": "beams",
    }
    ours = np.mean([render(ice_slab_scene(RES), {**settings, "seed": seed}).steady for seed in (21, 22)], axis=0)
    # Both images hold the slab's scattered glow and the light seen through refraction and reflection.
    slab = ref.mean(-1) > 1e-3 * ref.mean(-1).max()
    assert slab.sum() > 0.1 * RES * RES
    ratio = ours[slab].mean(0) / ref[slab].mean(0)
    print("ours/mitsuba per channel (ice slab):", ratio)
    validation.record(
        "dielectric ice slab, steady: ours / volpath, mean of channels",
        ratio.mean(),
        reference=1.0,
        tolerance="±3 % (±4 % per channel)",
        against="Mitsuba 3 volpath, 2 × 16384 spp",
    )
    # Measured 0.97-0.985 over four seeds; the two references differ by ~1.3 % between seeds.
    assert abs(ratio.mean() - 1) < 0.03
    np.testing.assert_allclose(ratio, 1.0, atol=0.04)
