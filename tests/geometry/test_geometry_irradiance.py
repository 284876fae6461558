"""V2 radiation checks (geometry/DESIGN.md 7): flat snow exact, sky-view identities, spherical bowl.

The bowl uses D_c / spacing = 64 (not 128) to stay fast; V_sky is within 1 % there and the
scattered irradiance within 5 % (the issue's tolerance).
"""

import numpy as np
import pytest

from geometry import irradiance


def _bowl(cells_per_diameter, depth_ratio, margin=1.5):
    n = int(cells_per_diameter * margin)
    spacing = 1.0 / cells_per_diameter
    x = (np.arange(n) - n / 2 + 0.5) * spacing
    xx, yy = np.meshgrid(x, x)
    r = np.hypot(xx, yy)
    d = depth_ratio
    radius = (0.25 + d**2) / (2 * d)
    z = np.where(r <= 0.5, -d + radius - np.sqrt(np.maximum(radius**2 - r**2, 0)), 0.0)
    return z, spacing, r


@pytest.mark.parametrize("albedo", [0.5, 0.8])
def test_flat_snow_absorbs_one_minus_albedo_times_incident(albedo):
    h = np.zeros((32, 32))
    sun = np.array([0.3, -0.4, np.sqrt(1 - 0.25)])
    horizons = irradiance.compute_horizons(h, 0.05, 16, rotation=0.3)
    budget = irradiance.radiation_budget(h, 0.05, sun, 1000.0, 70.0, albedo, horizons, bounces=3)
    expected = (1 - albedo) * (1000.0 * sun[2] + 70.0)
    np.testing.assert_allclose(budget.absorbed, expected, rtol=1e-6)
    assert np.all(horizons.sky_view == 1.0)


def test_uniform_horizon_gives_cos_squared():
    """The centre of a flat-floored round pit (radius 0.8 m, walls 0.8 m high) sees a uniform
    horizon of 45 deg: V_sky = cos^2 45 = 0.5."""
    n, spacing = 128, 0.025
    x = (np.arange(n) - n / 2) * spacing
    xx, yy = np.meshgrid(x, x)
    h = np.where(np.hypot(xx, yy) < 0.8, 0.0, 0.8)
    horizons = irradiance.compute_horizons(h, spacing, 32, rotation=0.1)
    centre = horizons.sky_view[n // 2, n // 2]
    assert centre == pytest.approx(0.5, abs=0.015)


def test_spherical_bowl_sky_view_and_scattered_light(validation):
    z, spacing, r = _bowl(64, 0.25)
    f = 0.2
    horizons = irradiance.compute_horizons(z, spacing, 32, rotation=0.1)
    inside = r < 0.45
    validation.record(
        "V2 spherical bowl, depth / diameter 0.25: mean sky view inside",
        horizons.sky_view[inside].mean(),
        reference=1 - f,
        tolerance="±1 %",
        against="the bowl's closed form 1 − f",
    )
    assert horizons.sky_view[inside].mean() == pytest.approx(1 - f, rel=0.01)
    for albedo, elevation in ((0.5, 60.0), (0.8, 30.0), (0.9, 45.0)):
        beta = np.radians(elevation)
        sun = np.array([0.0, np.cos(beta), np.sin(beta)])
        budget = irradiance.radiation_budget(z, spacing, sun, 1000.0, 0.0, albedo, horizons, bounces=10)
        scattered = 1000.0 * np.sin(beta) * albedo * f * (1 - f) / (1 - albedo * f)
        validation.record(
            f"V2 spherical bowl, albedo {albedo}, sun at {elevation:g}°: scattered irradiance inside [W m⁻²]",
            budget.terrain[inside].mean(),
            reference=scattered,
            tolerance="±5 %",
            against="the spherical cavity's uniform radiosity, a f (1 − f) / (1 − a f) of the beam",
        )
        assert budget.terrain[inside].mean() == pytest.approx(scattered, rel=0.05)
        if elevation < 40:  # a low sun shadows part of the bowl; shadowed points get only scattered light
            shadowed = inside & (budget.sun_visible == 0)
            assert shadowed.sum() > 50
            np.testing.assert_allclose(budget.direct[shadowed], 0.0)


def test_shadow_sweep_of_a_wall():
    """A 1 m wall along x at y = 0 shades exactly 1 m / tan(e) to its south when the sun is north."""
    n, spacing = 128, 0.05
    h = np.zeros((n, n))
    h[64:66, :] = 1.0  # a wall two cells thick (y = 3.2-3.3 m)
    elevation = np.radians(45.0)
    sun = np.array([0.0, np.cos(elevation), np.sin(elevation)])
    lit = irradiance.sun_visibility(h, spacing, sun)
    column = lit[:, 10]
    shaded = np.where(column[:64] == 0)[0]
    assert shaded.min() == 64 - 20 and shaded.max() == 63  # 1 m / tan 45 deg = 20 cells


def test_nan_height_field_is_rejected():
    h = np.zeros((16, 16))
    h[3, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        irradiance.compute_horizons(h, 0.1, 8)


def test_bright_closed_field_returns_light_to_the_sky():
    """V0 energy: with a = 1 and no sky light, what comes in goes back out (to the gather residual)."""
    n, spacing = 64, 0.05
    x = np.arange(n) * spacing
    h = 0.3 * np.cos(2 * np.pi * x / 1.6)[None, :] * np.ones((n, 1))
    horizons = irradiance.compute_horizons(h, spacing, 24, rotation=0.2)
    sun = np.array([0.2, 0.3, np.sqrt(1 - 0.13)])
    budget = irradiance.radiation_budget(h, spacing, sun, 1000.0, 0.0, 1.0, horizons, bounces=8)
    albedo, _ = irradiance.field_albedo(budget, horizons, 1000.0 * sun[2])
    assert albedo == pytest.approx(1.0, abs=0.05)
