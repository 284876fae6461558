"""Grid convergence of the grown field at reduced size (geometry/DESIGN.md 7, *Grid convergence*; issue 27).

The Tapado season on a 2 m domain, 30 days, on grids of 6.25, 3.1 and 1.6 cm cells from one seed: the start
is the same continuous surface on all three (DESIGN.md 3.12) and light absorbed below the surface spreads over
l = 6 cm (3.10), so the field's numbers settle as the cells shrink, as in the full study on 8 m
(benchmarks/grid_convergence.py). Also the Richardson extrapolation and the resolution guard."""

from pathlib import Path

import numpy as np
import pytest

from geometry import ablation, convergence, irradiance
from pipeline.config import load_config, load_raw
from pipeline.schema.geometry import GeometryConfig

ROOT = Path(__file__).resolve().parents[2]
SITES = ROOT / "configs" / "presets" / "sites"


def _season(grid: int, slope_order: int = 2) -> dict:
    site = load_raw(SITES / "tapado.yaml")["geometry"]
    cfg = GeometryConfig(
        **{**site, "grid_cells": grid, "domain_size": 2.0, "days": 30, "snapshots": 2, "slope_order": slope_order}
    )
    rng = np.random.default_rng(1)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    h = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng).height
    horizons = irradiance.compute_horizons(h, cfg.spacing, 16)
    return {"rms": float(h.std()), "sky_view": float(horizons.sky_view.mean()), "height": h, "cell": cfg.spacing}


@pytest.fixture(scope="module")
def seasons():
    return {grid: _season(grid) for grid in (32, 64, 128)}


def test_the_field_settles_as_the_cells_halve(seasons, validation):
    """RMS relief and mean sky view converge monotonically: each halving of the cell moves them less than the
    one before (on 2 m, 30 days into the season, seed 1, measured 9.1, 12.2, 13.2 cm RMS: steps of 3.1 and
    1.0 cm), and the 128^2 field seen on the 64^2 nodes is the 64^2 field (the same forms in the same places)."""
    for key in ("rms", "sky_view"):
        coarse, medium, fine = (seasons[g][key] for g in (32, 64, 128))
        first, second = medium - coarse, fine - medium
        validation.record(
            f"grid convergence of the {'RMS relief' if key == 'rms' else 'mean sky view'}: "
            "change from 64² to 128² / change from 32² to 64²",
            second / first,
            reference="monotone convergence",
            tolerance="between 0 and 0.8",
            against="the same 30-day Tapado season on 2 m at half and a quarter of the cells",
        )
        assert first * second > 0 and abs(second) < 0.8 * abs(first), (key, coarse, medium, fine)
    fine, medium = seasons[128]["height"][::2, ::2], seasons[64]["height"]
    assert np.corrcoef(fine.ravel(), medium.ravel())[0, 1] > 0.9


def test_second_order_slopes_close_the_gap_between_grids(seasons):
    """DESIGN.md 6.1, 7 (*Grid convergence*, item 4): the first-order scheme's numerical diffusion shrinks with the
    cell, so its 64^2 season lags the 128^2 one; second-order slopes halve that lag (RMS relief on 2 m, 30 days,
    seed 1: first order 9.40 against 11.36 cm, second order 12.21 against 13.18 cm)."""
    first = {grid: _season(grid, slope_order=1)["rms"] for grid in (64, 128)}
    second = {grid: seasons[grid]["rms"] for grid in (64, 128)}
    assert first[128] - first[64] > 0 and second[128] - second[64] > 0
    assert second[128] - second[64] < 0.6 * (first[128] - first[64]), (first, second)


def test_richardson_recovers_a_known_limit():
    """f(cell) = 2 + 3 cell^p on cells 4, 2, 1: the limit 2 and the order p, measured; an oscillating
    sequence falls back to the scheme's first order and says so."""
    for order in (1.0, 2.0):
        values = [2.0 + 3.0 * cell**order for cell in (4.0, 2.0, 1.0)]
        estimate = convergence.richardson(*values)
        assert estimate.extrapolated == pytest.approx(2.0, rel=1e-12)
        assert estimate.order == pytest.approx(order, rel=1e-12)
        assert estimate.order_measured
    oscillating = convergence.richardson(1.0, 1.2, 1.1)
    assert not oscillating.order_measured
    assert oscillating.order == convergence.SCHEME_ORDER
    assert oscillating.extrapolated == pytest.approx(1.0)


def test_validate_warns_on_the_demo_at_64_cells():
    """pipeline validate names the length the grid misses and a grid that resolves it."""
    cfg = load_config(ROOT / "configs" / "demo.yaml", ["geometry.grid_cells=64"]).geometry
    warnings = cfg.resolution_warnings()
    assert len(warnings) == 1
    assert "geometry.grid_cells = 64" in warnings[0] and "geometry.initial_correlation_length" in warnings[0]
    suggested = int(warnings[0].split("Set geometry.grid_cells: ")[1].split()[0])
    resolved = load_config(ROOT / "configs" / "demo.yaml", [f"geometry.grid_cells={suggested}"]).geometry
    assert resolved.resolution_warnings() == []
    assert load_config(ROOT / "configs" / "demo.yaml").geometry.resolution_warnings() == []


def test_validate_warns_on_first_order_slopes():
    """DESIGN.md 6.1: the first-order scheme is kept for comparison, and validate says what it costs."""
    cfg = load_config(ROOT / "configs" / "demo.yaml", ["geometry.slope_order=1"]).geometry
    assert any("geometry.slope_order = 1" in w and "slope_order: 2" in w for w in cfg.resolution_warnings())


def test_validate_warns_on_a_white_noise_start():
    cfg = GeometryConfig(initial_correlation_length=None, grid_cells=512)
    assert any("white-noise start" in w for w in cfg.resolution_warnings())
    lab = GeometryConfig(**load_raw(SITES / "lab_micro.yaml")["geometry"])
    assert lab.resolution_warnings() == []  # sublimation only: V1's linear start


def _flat_season_energy(cfg, sky) -> float:
    """Sum over the season's days of the flat ground's absorbed shortwave less the day's loss to the sky, each day
    floored at 0 [J m-2]: (1 - a)(S_b sin e + S_d) over the day's sun positions (V2's flat identity), minus
    sky_loss x 24 h (V_sky = 1)."""
    from geometry import sunpath

    total = 0.0
    for day in range(cfg.days):
        sun = sunpath.daily_sun_positions(cfg.latitude, cfg.start_day_of_year + day, cfg.sun_positions_per_day)
        elevations = np.arcsin(sun.vectors[:, 2])
        flux = [sky.direct_normal(e) * np.sin(e) + sky.diffuse_horizontal(e) for e in elevations]
        absorbed = (1 - cfg.albedo) * float(np.dot(flux, sun.durations))
        total += max(0.0, absorbed - cfg.sky_loss * sunpath.SECONDS_PER_DAY)
    return total


@pytest.mark.parametrize("sky_loss", [0.0, 110.0])
def test_flat_ground_sublimates_what_it_absorbs_beyond_the_sky_loss(sky_loss):
    """The model on flat ground (ablation.flat_season_lowering) against the energy balance summed by hand: the
    ground is open to the sky, unshaded and unsheltered, so it sublimates (1 - a) x shortwave - sky_loss per day
    at L_s. Tapado's preset in the constant-loss mode (no geometry.meteorology) over 10 days from 25 Nov (one horizon period a
    day, so the day is the balance's unit)."""
    raw = load_raw(SITES / "tapado.yaml")["geometry"]
    cfg = GeometryConfig(**{**raw, "meteorology": None, "start_day_of_year": 329, "days": 10, "sky_loss": sky_loss})
    settings = ablation.settings_from_config(cfg)
    assert cfg.horizon_refreshes_per_day == 1
    expected = (
        _flat_season_energy(cfg, settings.sky)
        * cfg.ablation_efficiency
        / (cfg.density * ablation.LATENT_HEAT_SUBLIMATION)
    )
    assert expected > 0.01  # Tapado's ice loses centimetres in ten days even with the loss
    assert ablation.flat_season_lowering(settings, cfg.spacing) == pytest.approx(expected, rel=1e-9)


def test_validate_warns_when_the_sky_loss_takes_all_the_light():
    """DESIGN.md 7, Limits: Rio Blanco's snow (albedo 0.8) under the constant-loss mode's default 90 W m-2 sky loss
    does not ablate, so its season grows nothing; validate and the geometry stage say so and name the keys.
    Without the loss the same ground loses centimetres, and Tapado's ice is not warned about."""
    rio_raw = load_raw(SITES / "rio_blanco.yaml")["geometry"]
    rio = GeometryConfig(**{**rio_raw, "meteorology": None, "days": 60})
    assert _flat_season_energy(rio, ablation.settings_from_config(rio).sky) == 0.0
    warnings = ablation.energy_warnings(rio)
    assert len(warnings) == 1 and "geometry.sky_loss = 90" in warnings[0] and "geometry.albedo = 0.8" in warnings[0]
    open_sky = rio.model_copy(update={"sky_loss": 0.0})
    assert ablation.flat_season_lowering(ablation.settings_from_config(open_sky), rio.spacing) > 0.01
    assert ablation.energy_warnings(open_sky) == []
    assert ablation.energy_warnings(load_config(ROOT / "configs" / "demo.yaml").geometry) == []


def test_v_groove_albedo_limits():
    """Flat (depth 0) returns the wall albedo; deep grooves trap light; the issue's H = S example."""
    assert irradiance.v_groove_albedo(0.55, 1.0, 0.0) == pytest.approx(0.55)
    sin_theta = 0.5 / np.hypot(1.0, 0.5)
    expected = 0.55 * sin_theta / (1 - 0.55 * (1 - sin_theta))
    assert irradiance.v_groove_albedo(0.55, 1.0, 1.0) == pytest.approx(expected, rel=1e-12)
    assert irradiance.v_groove_albedo(0.55, 1.0, 10.0) < 0.1
    with pytest.raises(ValueError, match="V-groove"):
        irradiance.v_groove_albedo(0.55, 0.0, 1.0)
