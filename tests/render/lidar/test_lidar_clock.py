"""The snow's clock (render/lidar/LIDAR.md §5.1): the group index of ice from Warren & Brandt's real index, the
snow's n_snow = (1 − φ) + B φ n_g at its limits, and a flat-snow render whose subsurface delays stretch by it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.schema.lidar import LidarConfig
from render.lidar.optics import ice_group_index, snow_group_index
from render.lidar.scene import Receiver, medium, shot_scene
from render.lidar.stage import channel_optics, group_index_of, snow_medium
from render.ptpb.api import render
from render.scene.optics import RHO_ICE


def test_ice_group_index_is_n_minus_lambda_dn_dlambda_from_the_table():
    """By hand from TARTES's W&B 2008 rows (520: 1.3121, 530: 1.3117, 540: 1.3114, 550: 1.3110; 1050: 1.3007,
    1060: 1.3005, 1070: 1.3003, 1080: 1.3002), n linear between rows, dn/dλ over ±10 nm."""
    n_522, n_532, n_542 = 1.3121 - 0.2 * 0.0004, 1.3117 - 0.2 * 0.0003, 1.3114 - 0.2 * 0.0004
    assert ice_group_index(532.0) == pytest.approx(n_532 - 532.0 * (n_542 - n_522) / 20.0, abs=1e-9)
    assert ice_group_index() == pytest.approx(1.33026, abs=1e-5)
    n_1054, n_1064, n_1074 = 1.3007 - 0.4 * 0.0002, 1.3005 - 0.4 * 0.0002, 1.3003 - 0.4 * 0.0001
    assert ice_group_index(1064.0) == pytest.approx(n_1064 - 1064.0 * (n_1074 - n_1054) / 20.0, abs=1e-9)
    # Normal dispersion: light in ice is slower than its phase index says.
    assert ice_group_index(532.0) > 1.3116 and ice_group_index(1064.0) > 1.3004


def test_snow_group_index_runs_from_air_to_ice():
    assert snow_group_index(0.0) == pytest.approx(1.0, abs=1e-12)
    assert snow_group_index(RHO_ICE, absorption_enhancement=1.0) == pytest.approx(ice_group_index(), abs=1e-12)
    assert snow_group_index(RHO_ICE, 1.0, 1064.0) == pytest.approx(ice_group_index(1064.0), abs=1e-12)
    # The values LIDAR.md §5.1 quotes (B = 1.6, 532 nm), and linear in B φ.
    assert snow_group_index(300.0) == pytest.approx(1.3692, abs=1e-4)
    assert snow_group_index(550.0) == pytest.approx(1.6768, abs=1e-4)
    phi = 550.0 / RHO_ICE
    assert snow_group_index(550.0, 1.25) - snow_group_index(550.0, 1.0) == pytest.approx(
        0.25 * phi * ice_group_index(), abs=1e-12
    )


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: snow_group_index(-1.0), "density"),
        (lambda: snow_group_index(RHO_ICE + 1), "density"),
        (lambda: snow_group_index(float("nan")), "density"),
        (lambda: snow_group_index(300.0, 0.0), "absorption_enhancement"),
        (lambda: snow_group_index(300.0, 1.6, 633.0), "wavelength_nm"),
        (lambda: ice_group_index(700.0), "wavelength_nm"),
        (lambda: medium((1.0,) * 3, (0.1,) * 3, 0.0, 0.9), "group index"),
    ],
)
def test_bad_clock_inputs_say_what_is_wrong(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_the_stage_sets_the_snow_medium_clock_from_the_config():
    """Default: the 532 nm group index of the configured snow for every channel; a number overrides it."""
    cfg = LidarConfig(density=550.0)
    optics = channel_optics(cfg)
    assert group_index_of(cfg, optics) == pytest.approx(snow_group_index(550.0, 1.6, 532.0), rel=1e-12)
    assert snow_medium(optics, cfg.form, group_index_of(cfg, optics))["ior"] == pytest.approx(1.6768, abs=1e-4)
    assert group_index_of(LidarConfig(group_index=1.0), optics) == 1.0
    assert snow_medium(optics, "full")["ior"] == 1.0
    with pytest.raises(ValueError, match="group_index"):
        LidarConfig(group_index=0.5)


def test_flat_snow_delays_below_the_surface_stretch_by_the_group_index():
    """Behind null faces the paths do not depend on the clock, so with one seed every subsurface delay (OPL less
    the air's round trip 2 z_ref) is n times the index-matched one: the mean delay scales by n exactly, up to the
    bins' rounding (bins about 1/40 of the mean delay; over seeds the ratio stays within 3e-4 of n)."""
    n = snow_group_index(300.0)
    sigma_s, sigma_a = 1.0 / 0.004, 20.0  # absorbing, so the tail ends inside the film
    z_ref, width = 0.02, 0.0005
    receiver = Receiver((0.0, 0.0), 0.05, 4, z_ref, width, 2000)
    settings = {"iterations": 40, "frame_mode": "bins", "max_depth": -1, "medium_estimator": "paths", "seed": 3}
    delays = []
    for group_index in (1.0, n):
        grey = medium((sigma_s,) * 3, (sigma_a,) * 3, 0.0, group_index)
        r = render(shot_scene("flat_snow", receiver, snow=grey, depth=0.5), settings)
        waveform = r.frames.mean(axis=(1, 2))[:, 1].astype(float)
        late = float(r.late.mean(axis=(0, 1))[1])
        assert late < 1e-4 * waveform.sum()
        opl = (np.arange(receiver.temporal_bins) + 0.5) * width
        delays.append(float((waveform * (opl - 2 * z_ref)).sum() / waveform.sum()))
    print(
        f"mean delay below the surface {delays[0]:.5f} m -> {delays[1]:.5f} m: x{delays[1] / delays[0]:.4f}, n {n:.4f}"
    )
    assert delays[0] > 30 * width
    assert delays[1] / delays[0] == pytest.approx(n, rel=1e-3)
