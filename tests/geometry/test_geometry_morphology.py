"""V3 morphology (penitentes.md 7) on a reduced grid: 64^2 cells over 4 m (6.25 cm spacing, the
demo's spacing on a quarter of its area), Tapado defaults (30.1 S, 25 Nov + 40 days, glacier
ice), full diurnal sun path with 12 positions per day; the control runs the same at 65 S.

Known gaps are marked xfail(strict=True): they fail today and the marker turns red once fixed.
"""
import numpy as np
import pytest

from geometry import ablation, metrics, sunpath
from pipeline.schema.geometry import GeometryConfig

REDUCED = dict(grid_cells=64, domain_size=4.0)


def _grow(**overrides):
    cfg = GeometryConfig(**{**REDUCED, **overrides})
    rng = np.random.default_rng(7)
    h0 = ablation.initial_height_field(cfg.grid_cells, cfg.spacing, cfg.initial_roughness_rms, cfg.initial_wavelength, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    return cfg, h0, grown


@pytest.fixture(scope="module")
def tapado():
    return _grow()


@pytest.fixture(scope="module")
def high_latitude():
    return _grow(latitude=-65.0)


def test_relief_grows_at_30s(tapado):
    cfg, h0, grown = tapado
    assert grown.height.std() > 3 * h0.std()
    assert np.all(np.isfinite(grown.height))


def test_ridges_run_east_west(tapado):
    cfg, _, grown = tapado
    orientation = metrics.ridge_orientation(grown.height, cfg.spacing)
    assert orientation["ridge_deviation_from_east_west_deg"] <= 30.0
    assert orientation["coherence"] > 0.1


def test_65s_grows_no_comparable_relief(tapado, high_latitude):
    _, h0_low, low = tapado
    _, h0_high, high = high_latitude
    growth_low = low.height.std() - h0_low.std()
    growth_high = high.height.std() - h0_high.std()
    assert growth_high < 0.5 * growth_low


@pytest.mark.xfail(strict=True, reason="the height-field model grows melt hollows with near-symmetric walls; "
                                       "lean is ~1 deg, not the ~7 deg noon zenith angle")
def test_blades_lean_toward_noon_sun(tapado):
    cfg, _, grown = tapado
    delta = float(sunpath.declination(cfg.start_day_of_year + cfg.days // 2))
    noon_zenith = np.degrees(sunpath.noon_zenith_angle(cfg.latitude, delta))
    lean = metrics.lean(grown.height, cfg.spacing)["lean_north_deg"]
    assert abs(lean - noon_zenith) <= 5.0


@pytest.mark.xfail(strict=True, reason="hollows cluster at the domain scale; spacing/height is ~5, not 0.5-2")
def test_spacing_comparable_to_height(tapado):
    cfg, _, grown = tapado
    shape = metrics.morphology(grown.height, cfg.spacing)
    assert 0.5 <= shape["spacing_to_height"] <= 2.0
