"""V3 morphology (geometry/DESIGN.md 7) on a reduced grid: 64^2 cells over 4 m (6.25 cm spacing, the
demo's spacing on a quarter of its area), the Tapado site preset (30.1 S, 25 Nov + 40 days, glacier
ice), full diurnal sun path with 12 positions per day; the control is the 65 S preset (the same
setting moved to 65 S). The rows here are 0.5-0.7 m apart crest to crest, so 4 m holds 6-8 of them:
enough for orientation, lean, the latitude null and a north-south spectral peak.
"""

from pathlib import Path

import numpy as np
import pytest

from geometry import ablation, metrics, sunpath
from pipeline.config import load_raw
from pipeline.schema.geometry import GeometryConfig

SITES = Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites"
REDUCED = dict(grid_cells=64, domain_size=4.0)


def _grow(preset: str):
    cfg = GeometryConfig(**{**load_raw(SITES / preset)["geometry"], **REDUCED})
    rng = np.random.default_rng(7)
    h0 = ablation.initial_height_field(
        cfg.grid_cells, cfg.spacing, cfg.initial_roughness_rms, cfg.initial_wavelength, rng
    )
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    return cfg, h0, grown


@pytest.fixture(scope="module")
def tapado():
    return _grow("tapado.yaml")


@pytest.fixture(scope="module")
def high_latitude():
    return _grow("high_latitude_65s.yaml")


def test_relief_grows_at_30s(tapado):
    cfg, h0, grown = tapado
    assert grown.height.std() > 3 * h0.std()
    assert np.all(np.isfinite(grown.height))


def test_ridges_run_east_west(tapado):
    cfg, _, grown = tapado
    orientation = metrics.ridge_orientation(grown.height, cfg.spacing)
    assert orientation["ridge_deviation_from_east_west_deg"] <= 30.0
    assert orientation["coherence"] > 0.1


def test_aspects_peak_north_and_south(tapado):
    """Nicholson et al. 2016 cross-check: steep facets face N and S, not E and W."""
    cfg, _, grown = tapado
    edges, fraction = metrics.aspect_histogram(grown.height, cfg.spacing, bins=8)
    centres = 0.5 * (edges[:-1] + edges[1:])  # 22.5, 67.5, ... deg
    north_south = fraction[(centres < 45) | (centres > 315) | (np.abs(centres - 180) < 45)].sum()
    assert north_south > 2 * (1 - north_south)


def test_65s_grows_no_comparable_relief(tapado, high_latitude):
    _, h0_low, low = tapado
    _, h0_high, high = high_latitude
    growth_low = low.height.std() - h0_low.std()
    growth_high = high.height.std() - h0_high.std()
    assert growth_high < 0.5 * growth_low


def test_blades_lean_toward_noon_sun(tapado):
    cfg, _, grown = tapado
    delta = float(sunpath.declination(cfg.start_day_of_year + cfg.days // 2))
    noon_zenith = np.degrees(sunpath.noon_zenith_angle(cfg.latitude, delta))
    lean = metrics.lean(grown.height, cfg.spacing)["lean_north_deg"]
    assert abs(lean - noon_zenith) <= 5.0


def test_spacing_comparable_to_height(tapado):
    """lambda_dom (peak of the north-south transect spectrum) over H (mean crest-to-trough relief
    along north-south transects); see metrics.row_spacing and metrics.crest_to_trough."""
    cfg, _, grown = tapado
    shape = metrics.morphology(grown.height, cfg.spacing)
    assert 0.5 <= shape["spacing_to_height"] <= 2.0
    assert shape["crest_to_trough_m"] > 0.5  # mature: metre-scale forms, not the seeded 5 cm
