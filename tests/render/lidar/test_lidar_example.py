"""The worked example quoted in render/lidar/LIDAR.md §6 is what ``python -m render.lidar.example`` computes."""

from __future__ import annotations

import pytest

from render.lidar.example import worked_example


def test_worked_example_numbers_quoted_in_lidar_md():
    snow, (zero, extrapolated) = worked_example()
    assert snow.ice_absorption == pytest.approx(0.03500, abs=5e-6)
    assert snow.absorption == pytest.approx(0.01832, abs=5e-6)
    assert snow.reduced_scattering == pytest.approx(274.8, abs=0.05)
    assert snow.transport_mean_free_path * 1e3 == pytest.approx(3.639, abs=5e-4)
    assert snow.diffusion_medium().effective_attenuation == pytest.approx(3.887, abs=5e-4)
    quoted = {
        # boundary: albedo, mean-range bias (m), mode-range bias (mm), estimator biases for 1.5 ns (mm)
        "zero": (0.9860, 0.1930, 0.910, dict(first_return=11.17, peak=14.03, median=26.60, gaussian_fit=16.89)),
        "extrapolated": (
            0.9767,
            0.3204,
            0.923,
            dict(first_return=17.50, peak=22.36, median=44.25, gaussian_fit=27.45),
        ),
    }
    for case in (zero, extrapolated):
        albedo, mean_bias, mode_bias, estimators = quoted[case.boundary]
        assert case.albedo == pytest.approx(albedo, abs=5e-5)
        assert case.mean_range_bias == pytest.approx(mean_bias, abs=5e-5)
        assert case.mode_range_bias * 1e3 == pytest.approx(mode_bias, abs=5e-4)
        for name, value in estimators.items():
            assert getattr(case.estimates, name) * 1e3 == pytest.approx(value, abs=5e-3), name
    assert zero.estimates.centroid * 1e3 == pytest.approx(116.5, abs=0.05)
    assert extrapolated.estimates.centroid * 1e3 == pytest.approx(192.3, abs=0.05)


def test_lidar_md_numbers_follow_from_g_0845():
    """lidar.md's 18 cm, 30 cm and 0.8 mm come back with g = 0.845 instead of our 0.86."""
    _, (zero, extrapolated) = worked_example(asymmetry=0.845)
    assert zero.mean_range_bias == pytest.approx(0.18, abs=0.005)
    assert extrapolated.mean_range_bias == pytest.approx(0.30, abs=0.005)
    assert zero.mode_range_bias * 1e3 == pytest.approx(0.8, abs=0.05)
