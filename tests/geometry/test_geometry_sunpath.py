"""V0 sun-path checks (geometry/DESIGN.md 3.2 and 7) against closed-form values."""

import numpy as np
import pytest

from geometry import sunpath


@pytest.mark.parametrize("latitude", [-60.0, -33.0, -30.1, 0.0, 23.0, 47.0])
@pytest.mark.parametrize("day", [1, 80, 172, 329, 355])
def test_noon_zenith_equals_latitude_minus_declination(latitude, day):
    delta = float(sunpath.declination(day))
    sun = sunpath.sun_vector(latitude, delta, 0.0)
    zenith = np.degrees(np.arccos(sun[2]))
    assert zenith == pytest.approx(abs(latitude - np.degrees(delta)), abs=1e-9)
    assert np.linalg.norm(sun) == pytest.approx(1.0, abs=1e-12)


def test_reference_example_30s_solstice():
    delta = np.radians(-23.44)
    sun = sunpath.sun_vector(-30.0, delta, 0.0)
    elevation, azimuth = sunpath.elevation_azimuth(sun)
    assert 90 - np.degrees(elevation) == pytest.approx(6.56, abs=0.01)
    assert np.degrees(azimuth) == pytest.approx(0.0, abs=1e-9)  # the noon sun stands to the north
    half = sunpath.daylight_half_angle(-30.0, delta)
    assert 2 * np.degrees(half) / 15 == pytest.approx(13.9, abs=0.05)  # day length [h]
    sunrise = sunpath.sun_vector(-30.0, delta, -half)
    assert sunrise[2] == pytest.approx(0.0, abs=1e-12)
    assert np.degrees(sunpath.elevation_azimuth(sunrise)[1]) == pytest.approx(117.0, abs=0.5)


def test_daily_positions_cover_daylight_and_stay_up():
    sun = sunpath.daily_sun_positions(-30.1, 355, 12)
    assert np.all(sun.vectors[:, 2] > 0)
    assert sun.durations.sum() / 3600 == pytest.approx(
        2 * np.degrees(sunpath.daylight_half_angle(-30.1, sun.declination)) / 15
    )
    assert np.allclose(sun.vectors[:, 0], -sun.vectors[::-1, 0])  # morning and afternoon mirror
    assert sunpath.daily_sun_positions(-80.0, 172, 12).vectors.shape[0] == 0  # polar night


def test_bad_positions_per_day_names_the_key():
    with pytest.raises(ValueError, match="geometry.sun_positions_per_day"):
        sunpath.daily_sun_positions(-30.0, 355, 0)
