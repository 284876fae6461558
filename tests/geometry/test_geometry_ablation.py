"""Recession terms of the growth loop (geometry/DESIGN.md 3.8, 3.9, 6.1): the upwinded direct beam, the
loss to the sky, the flux-time clock of the linear terms (lambda* = 4 pi D / A_B in a full run), and
the Lliboutry switch integrated over the wall faces a column stands for."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from geometry import ablation, metrics, sunpath
from pipeline.config import load_raw
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


def test_second_order_slopes_converge_at_second_order_and_keep_kinks_sharp():
    """DESIGN.md 6.1: on a smooth sine the second-order (minmod ENO) one-sided slopes' error falls 4x per halving of the cell (the
    first-order differences' 2x), and at a V-shaped crest or trough each side keeps its exact slope (no
    smearing across the kink), so a sharp blade is not rounded by the scheme."""
    errors = {1: [], 2: []}
    for n in (32, 64, 128):
        spacing = 1.0 / n
        x = np.arange(n) * spacing
        h = np.repeat(np.sin(2 * np.pi * x)[None, :], 4, axis=0)
        for order in (1, 2):
            back, fwd = ablation.one_sided_slopes(h, spacing, 1, order)
            exact = 2 * np.pi * np.cos(2 * np.pi * x)
            errors[order].append(max(np.abs(back[0] - exact).max(), np.abs(fwd[0] - exact).max()))
    assert errors[1][0] / errors[1][1] == pytest.approx(2.0, rel=0.05)
    assert errors[2][0] / errors[2][1] > 3.6 and errors[2][1] / errors[2][2] > 3.8, errors[2]
    n, spacing = 32, 0.1
    y = np.arange(n) * spacing
    ridge = np.repeat((1.5 - np.abs(y - y[n // 2]))[:, None], 3, axis=1)  # slope 1 on both sides of row n/2
    back, fwd = ablation.one_sided_slopes(ridge, spacing, 0, 2)
    inside = slice(3, n - 3)  # away from the periodic wrap's trough
    expected_back = np.where(y > y[n // 2], -1.0, 1.0)
    expected_fwd = np.where(y >= y[n // 2], -1.0, 1.0)
    np.testing.assert_allclose(back[inside, 0], expected_back[inside], atol=1e-12)
    np.testing.assert_allclose(fwd[inside, 0], expected_fwd[inside], atol=1e-12)
    # The beam still nearly telescopes: a gentle periodic field intercepts S_b s_z per unit horizontal area.
    h = ablation.initial_height_field(64, 0.05, 0.02, 0.6, np.random.default_rng(4))
    sun = _sun(30.0, 200.0)
    lowering = ablation.direct_beam_lowering(*ablation.sunward_slopes(h, 0.05, sun, 85.0, order=2), sun)
    assert lowering.mean() == pytest.approx(sun[2], rel=5e-4)  # measured 1.0e-4


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
    incident = sum(
        d * (settings.sky.direct_normal(e) * np.sin(e) + settings.sky.diffuse_horizontal(e))
        for d, e in zip(sun.durations, sun.elevations)
    )
    net = (1 - cfg.albedo) * incident - cfg.sky_loss * sunpath.SECONDS_PER_DAY
    expected = cfg.ablation_efficiency * net / (cfg.density * ablation.LATENT_HEAT_SUBLIMATION)
    np.testing.assert_allclose(-grown.height, expected, rtol=1e-9)
    assert 0.4 < net / ((1 - cfg.albedo) * incident) < 0.5  # ~ the reference's eps = 0.5 on flat ice


def test_lab_preset_grows_at_lambda_star(validation):
    """V1 from white noise in a full sun-path run: the scattered light and all other absorbed light are
    spread over the e-folding depth l, so the field selects lambda* = 2 pi l (4.4 cm for l = 7 mm)."""
    cfg = GeometryConfig(**yaml.safe_load((SITES / "lab_micro.yaml").read_text())["geometry"])
    rng = np.random.default_rng(1)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    assert cfg.initial_wavelength is None  # white noise: nothing seeds the answer
    lambda_star = 2 * np.pi * cfg.optical_efolding_depth
    validation.record(
        "V1 lab preset, full sun path from white noise: dominant wavelength [m]",
        metrics.dominant_wavelength(grown.height, cfg.spacing),
        reference=lambda_star,
        tolerance="±15 %",
        against="2π l of the preset's e-folding depth",
    )
    assert metrics.dominant_wavelength(grown.height, cfg.spacing) == pytest.approx(lambda_star, rel=0.15)
    assert 5 < grown.height.std() / h0.std() < 500  # grows, but stays a lab-sized form


@pytest.mark.slow
def test_lab_onset_scales_with_the_efolding_depth():
    """V7 in a full sun-path run: doubling l (and the domain, and the days, since sigma* = A_B / (2 l))
    doubles the wavelength that white noise develops, within 20 %. 256^2 cells over 12 onset
    wavelengths, so that the spectrum's bins resolve the peak (the preset's 3 do not); ~1 min."""
    site = yaml.safe_load((SITES / "lab_micro.yaml").read_text())["geometry"]
    onsets = []
    for scale in (1, 2):
        cfg = GeometryConfig(
            **{
                **site,
                "optical_efolding_depth": scale * site["optical_efolding_depth"],
                "grid_cells": 256,
                "domain_size": scale * 4 * site["domain_size"],
                "days": scale * site["days"],
                "initial_roughness_rms": scale * site["initial_roughness_rms"],
            }
        )
        rng = np.random.default_rng(3)
        h0 = ablation.initial_height_field(cfg.grid_cells, cfg.spacing, cfg.initial_roughness_rms, None, rng)
        grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
        onsets.append(metrics.dominant_wavelength(grown.height, cfg.spacing))
    assert onsets[1] / onsets[0] == pytest.approx(2.0, rel=0.2), onsets


def test_uniform_latent_heat_leaves_the_recession_as_it_was():
    """Face means only matter where the switch varies: with one 1/L_eff everywhere the direct beam
    and the Godunov factor come back unweighted."""
    rng = np.random.default_rng(5)
    spacing = 0.05
    h = ablation.initial_height_field(32, spacing, 0.05, 0.4, rng)
    sun = _sun(40.0, 110.0)
    inverse_heat = np.full_like(h, 1.0 / ablation.LATENT_HEAT_SUBLIMATION)
    p, q = ablation.sunward_slopes(h, spacing, sun, 85.0)
    np.testing.assert_allclose(
        ablation.direct_beam_mass(p, q, sun, inverse_heat),
        ablation.direct_beam_lowering(p, q, sun) * inverse_heat,
        rtol=1e-12,
    )
    dx_back, dx_fwd = (h - np.roll(h, 1, 1)) / spacing, (np.roll(h, -1, 1) - h) / spacing
    dy_back, dy_fwd = (h - np.roll(h, 1, 0)) / spacing, (np.roll(h, -1, 0) - h) / spacing
    grad2 = np.maximum(np.maximum(dx_back, 0) ** 2, np.minimum(dx_fwd, 0) ** 2) + np.maximum(
        np.maximum(dy_back, 0) ** 2, np.minimum(dy_fwd, 0) ** 2
    )
    surface, _ = ablation.surface_inverse_latent_heat(h, spacing, inverse_heat, 89.0)
    np.testing.assert_allclose(surface, inverse_heat * np.sqrt(1 + grad2), rtol=1e-12)


def test_one_cell_crest_melts_its_sunlit_face_at_the_face_mean():
    """A sublimating one-cell N-S wall 1 m above a melting floor, sun from the east: the top takes
    s_z at L_s, the east face -s_x p at the mean of its ends (the crest sublimates, the foot melts)."""
    n, spacing = 16, 0.1
    h = np.zeros((n, n))
    h[:, n // 2] = 1.0
    melt = np.where(h > 0.5, 0.0, 1.0)
    inverse_heat = ablation.inverse_latent_heat(melt)
    sun = _sun(50.0, 90.0)
    p, q = ablation.sunward_slopes(h, spacing, sun, 89.0)
    crest = ablation.direct_beam_mass(p, q, sun, inverse_heat)[0, n // 2]
    l_s, l_f = ablation.LATENT_HEAT_SUBLIMATION, ablation.LATENT_HEAT_FUSION
    expected = sun[2] / l_s + sun[0] * (1.0 / spacing) * 0.5 * (1 / l_s + 1 / l_f)
    assert crest == pytest.approx(expected, rel=1e-12)


def test_thin_north_south_walls_fall_and_east_west_walls_stand():
    """Cathles et al. 2014 / Warren 2023 on a grid of square pits (0.8 m deep, 0.81 m apart) walled by
    walls 12.5 cm thick (twice the e-folding depth, four 3.1 cm cells) both ways, Tapado for 10 days from
    25 Nov: the morning and evening sun on the N-S walls' faces brings them down to the floor while the
    E-W walls stand (measured 0.72 m against 0.17 m; after 8 days 0.74 m against 0.35 m: light spread over l
    thins every wall a little, DESIGN.md 3.10, and the second-order slopes no longer round the walls, 6.1)."""
    cfg = GeometryConfig(
        **{
            **load_raw(SITES / "tapado.yaml")["geometry"],
            "start_day_of_year": 329,
            "grid_cells": 128,
            "domain_size": 4.0,
            "days": 10,
            "snapshots": 2,
        }
    )
    n, period, thickness = cfg.grid_cells, 26, 4
    wall = np.arange(n) % period < thickness
    middle = np.arange(n) % period == thickness + (period - thickness) // 2
    h = np.full((n, n), -0.8)
    h[wall, :] = 0.0  # E-W walls
    h[:, wall] = 0.0  # N-S walls
    grown = ablation.grow_field(h, cfg.spacing, ablation.settings_from_config(cfg), np.random.default_rng(0)).height
    east_west = grown[wall][:, ~wall].mean() - grown[middle][:, ~wall].mean()
    north_south = grown[:, wall][~wall].mean() - grown[:, middle][~wall].mean()
    assert north_south < 0.2
    assert east_west > 0.5 and east_west > 3 * north_south


def test_correlated_start_is_one_surface_at_every_grid():
    """DESIGN.md 3.12: one seed draws one continuous surface, whatever the growth grid. The 128^2 field
    sampled at every other node is the 64^2 field (both grids hold its whole spectrum), and its RMS and
    RMS slope are the Gaussian-correlated surface's sigma and sqrt(2) sigma / lc, not the grid's."""
    rms, lc, domain = 0.03, 0.15, 4.0
    fields = {
        n: ablation.initial_height_field(n, domain / n, rms, None, np.random.default_rng(5), correlation_length=lc)
        for n in (64, 128, 256)
    }
    # 64^2 is a little coarser than the spectral grid (74^2): it lacks modes of amplitude ~1e-3.
    np.testing.assert_allclose(fields[128][::2, ::2], fields[64], atol=5e-3 * rms)
    np.testing.assert_allclose(fields[256][::2, ::2], fields[128], atol=1e-6 * rms)
    fine = fields[256]
    slope = np.gradient(fine, domain / 256, axis=1)
    # One realisation of a 4 m surface holds ~(4 / 0.15)^2 correlation areas: its statistics scatter by ~5 %.
    assert fine.std() == pytest.approx(rms, rel=1e-9)
    assert slope.std() == pytest.approx(np.sqrt(2) * rms / lc, rel=0.1)
    # A white-noise start is not one surface: its slopes double as the cells halve.
    white = {n: ablation.initial_height_field(n, domain / n, rms, None, np.random.default_rng(5)) for n in (64, 128)}
    ratio = np.gradient(white[128], domain / 128, axis=1).std() / np.gradient(white[64], domain / 64, axis=1).std()
    assert ratio == pytest.approx(2.0, rel=0.1)


def test_correlated_start_refuses_a_correlation_length_the_domain_cannot_hold():
    with pytest.raises(ValueError, match="geometry.initial_correlation_length"):
        ablation.initial_height_field(64, 100.0 / 64, 0.03, None, np.random.default_rng(0), correlation_length=1e-3)
