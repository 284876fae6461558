"""Recession terms of the growth loop (penitentes.md 3.8, 3.9, 6.1): the upwinded direct beam, the
loss to the sky, and the flux-time clock of the linear terms (lambda* = 4 pi D / A_B in a full run)."""
from pathlib import Path

import numpy as np
import pytest
import yaml

from geometry import ablation, metrics, sunpath
from pipeline.schema.geometry import GeometryConfig

SITES = Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites"


def _sun(zenith_deg, azimuth_deg):
    z, a = np.radians(zenith_deg), np.radians(azimuth_deg)
    return np.array([np.sin(z) * np.sin(a), np.sin(z) * np.cos(a), np.cos(z)])


def test_direct_beam_per_horizontal_area_averages_to_s_z():
    """Without self-shadowing a periodic field intercepts exactly S_b s_z per unit horizontal area:
    the one-sided slopes telescope to zero mean."""
    rng = np.random.default_rng(4)
    h = ablation.initial_height_field(64, 0.05, 0.02, 0.6, rng)
    sun = _sun(30.0, 200.0)
    p, q = ablation.sunward_slopes(h, 0.05, sun, 85.0)
    lowering = ablation.direct_beam_lowering(p, q, sun)
    assert lowering.min() > 0  # gentle field: every facet faces this sun
    assert lowering.mean() == pytest.approx(sun[2], rel=1e-12)


def test_crest_ablates_as_its_sun_facing_facet():
    """A 45 deg ridge under a noon sun 7 deg north of the zenith: the crest cell gets the north
    facet's beam, cos(45 - 7) / cos 45 per unit horizontal area, not the symmetric cos(7) sqrt 2."""
    n, spacing = 32, 0.1
    y = np.arange(n) * spacing
    h = np.repeat(-np.abs(y - y[n // 2])[:, None], n, axis=1)  # crest row n/2, slope 1 both sides
    sun = _sun(7.0, 0.0)
    p, q = ablation.sunward_slopes(h, spacing, sun, 85.0)
    crest = ablation.direct_beam_lowering(p, q, sun)[n // 2, 0]
    assert crest == pytest.approx(np.cos(np.radians(38.0)) / np.cos(np.radians(45.0)), rel=1e-12)


def test_flat_ice_keeps_the_absorbed_shortwave_above_the_sky_loss():
    """Flat and exposed (V_sky = 1, no melt): one day lowers by eps max(0, Q - q 24 h) / (rho L_s)."""
    cfg = GeometryConfig(grid_cells=16, domain_size=1.0, days=1, initial_wavelength=0.25)
    settings = ablation.settings_from_config(cfg)
    grown = ablation.grow_field(np.zeros((16, 16)), cfg.spacing, settings, np.random.default_rng(0))
    sun = sunpath.daily_sun_positions(cfg.latitude, cfg.start_day_of_year, cfg.sun_positions_per_day)
    incident = sum(d * (settings.sky.direct_normal(e) * np.sin(e) + settings.sky.diffuse_horizontal(e))
                   for d, e in zip(sun.durations, sun.elevations))
    net = (1 - cfg.albedo) * incident - cfg.sky_loss * sunpath.SECONDS_PER_DAY
    expected = cfg.ablation_efficiency * net / (cfg.density * ablation.LATENT_HEAT_SUBLIMATION)
    np.testing.assert_allclose(-grown.height, expected, rtol=1e-9)
    assert 0.4 < net / ((1 - cfg.albedo) * incident) < 0.5  # ~ the reference's eps = 0.5 on flat ice


def test_lab_preset_grows_at_lambda_star():
    """A and D both run on flux time, so a full sun-path run selects lambda* = 4 pi D / A_B (4.4 cm)."""
    cfg = GeometryConfig(**yaml.safe_load((SITES / "lab_micro.yaml").read_text())["geometry"])
    rng = np.random.default_rng(1)
    h0 = ablation.initial_height_field(cfg.grid_cells, cfg.spacing, cfg.initial_roughness_rms, cfg.initial_wavelength, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    lambda_star = 4 * np.pi * cfg.diffusivity / cfg.scattered_light_coefficient
    assert metrics.dominant_wavelength(grown.height, cfg.spacing) == pytest.approx(lambda_star, rel=0.15)
    assert 5 < grown.height.std() / h0.std() < 500  # grows, but stays a lab-sized form
