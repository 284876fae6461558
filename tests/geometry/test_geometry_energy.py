"""The surface energy balance of geometry/energy.py (geometry/DESIGN.md 3.9, *Surface energy balance*) in closed
form, its config (geometry.meteorology) and the growth it drives on reduced grids."""

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from geometry import ablation, energy
from pipeline.config import load_raw
from pipeline.schema.geometry import GeometryConfig

SITES = Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites"
# Guanaco-like dry air (MacDonell et al. 2013: e_a 1.1 hPa, u 10 m/s) at about 5300 m.
DRY = energy.Meteorology(270.15, 110.0, 10.0, 0.0, 53000.0, 2.0, 0.002, 0.001)


def test_brutsaert_emissivity_at_known_air():
    """1.24 (e_a / T_a)^(1/7) with e_a in hPa: 10 hPa at 283.15 K gives 0.769; 1.1 hPa at 270.15 K 0.565."""
    assert energy.clear_sky_emissivity(1000.0, 283.15) == pytest.approx(1.24 * (10 / 283.15) ** (1 / 7), rel=1e-12)
    assert energy.clear_sky_emissivity(1000.0, 283.15) == pytest.approx(0.7691, abs=1e-4)
    assert energy.clear_sky_emissivity(110.0, 270.15) == pytest.approx(0.5649, abs=1e-4)


def test_cloud_raises_the_sky_to_the_cloud_emissivity():
    clear = energy.clear_sky_emissivity(110.0, 270.15)
    assert energy.sky_emissivity(110.0, 270.15, 0.0) == pytest.approx(clear)
    assert energy.sky_emissivity(110.0, 270.15, 1.0) == pytest.approx(energy.CLOUD_EMISSIVITY)
    assert energy.sky_emissivity(110.0, 270.15, 0.5) == pytest.approx(0.75 * clear + 0.25 * energy.CLOUD_EMISSIVITY)


def test_saturation_over_ice_at_the_triple_point_and_below():
    """611.21 Pa at 273.16 K; 103.2 Pa at -20 C (the tables give 103.3 Pa over ice)."""
    assert energy.saturation_vapour_pressure_ice(273.16) == pytest.approx(611.21, rel=1e-12)
    assert energy.saturation_vapour_pressure_ice(253.15) == pytest.approx(103.3, rel=0.01)


def test_neutral_transfer_coefficient_and_air_density():
    assert energy.bulk_transfer_coefficient(2.0, 0.002, 0.002) == pytest.approx(0.41**2 / np.log(1000) ** 2)
    assert energy.air_density(101325.0, 273.15) == pytest.approx(1.292, abs=1e-3)


def test_a_surface_in_equilibrium_has_no_net_flux():
    """Air at 0 C saturated over ice, a black open sky at the air temperature: a 0 C surface that absorbs no
    shortwave exchanges nothing, whatever the wind; the solver keeps it at 0 C with no melt and no sublimation."""
    saturated = energy.saturation_vapour_pressure_ice(energy.MELTING_POINT)
    black = energy.Meteorology(energy.MELTING_POINT, float(saturated), 8.0, 1.0, 60000.0, 2.0, 0.002, 0.001, 1.0)
    black = energy.Meteorology(**{**black.__dict__, "surface_emissivity": energy.CLOUD_EMISSIVITY})
    flux, _ = energy.net_flux(energy.MELTING_POINT, 0.0, 1.0, 1.0, black)
    assert float(flux) == pytest.approx(0.0, abs=1e-9)
    state = energy.surface_state(np.zeros(3), np.ones(3), np.array([0.0, 0.5, 1.0]), black)
    assert np.allclose(state.temperature, energy.MELTING_POINT)
    assert np.allclose(state.melt_flux, 0.0, atol=1e-9) and np.allclose(state.sublimation_flux, 0.0, atol=1e-9)


def test_cold_surfaces_balance_to_zero_and_only_sublimate():
    """Dry windy air: a facet absorbing 200 W m-2 stays below 0 C, its balance closes (|Q| < 1e-6 W m-2) and all
    its mass loss is sublimation, -LE / L_s."""
    shortwave = np.array([0.0, 100.0, 200.0])
    state = energy.surface_state(shortwave, np.ones(3), np.ones(3), DRY)
    assert np.all(state.temperature < energy.MELTING_POINT - 2.0)
    flux, _ = energy.net_flux(state.temperature, shortwave, 1.0, 1.0, DRY)
    assert np.max(np.abs(flux)) < 1e-6
    assert np.all(state.melt_flux == 0.0)
    latent = energy.latent_flux(state.temperature, 1.0, DRY)
    assert state.sublimation_flux == pytest.approx(-latent)
    assert state.mass_rate() == pytest.approx(-latent / energy.LATENT_HEAT_SUBLIMATION)


def test_still_air_melts_what_ventilated_air_sublimates():
    """Lliboutry's switch: the same 300 W m-2 on the same facet melts in still air (no turbulent loss; surplus
    300 - (L_out - L_in) at 0 C) and sublimates below 0 C in the open wind, losing several times less mass."""
    open_air = energy.surface_state(np.array([300.0]), np.ones(1), np.ones(1), DRY)
    still = energy.surface_state(np.array([300.0]), np.ones(1), np.zeros(1), DRY)
    longwave_loss = DRY.surface_emissivity * energy.STEFAN_BOLTZMANN * energy.MELTING_POINT**4 - DRY.sky_longwave
    assert still.temperature[0] == energy.MELTING_POINT
    assert still.melt_flux[0] == pytest.approx(300.0 - longwave_loss)
    assert still.sublimation_flux[0] == 0.0
    assert open_air.temperature[0] < energy.MELTING_POINT and open_air.melt_flux[0] == 0.0
    assert still.mass_rate()[0] > 5.0 * open_air.mass_rate()[0]


def test_walls_cut_the_longwave_loss_with_the_sky_view():
    """A facet seeing half sky loses half the net longwave of an open one (its walls are at its own temperature)."""
    open_sky, _ = energy.net_flux(energy.MELTING_POINT, 0.0, 1.0, 0.0, DRY)
    half, _ = energy.net_flux(energy.MELTING_POINT, 0.0, 0.5, 0.0, DRY)
    assert float(half) == pytest.approx(0.5 * float(open_sky))


def test_meteorology_and_the_constant_loss_cannot_both_be_set():
    """A changed constant-loss key beside geometry.meteorology is refused, naming both and the fix; a key at its
    default is not a choice, so a dumped config (every key present) validates again."""
    raw = load_raw(SITES / "tapado.yaml")["geometry"]
    with pytest.raises(ValidationError, match="geometry.sky_loss and geometry.meteorology are both set") as error:
        GeometryConfig(**{**raw, "sky_loss": 110.0})
    assert "geometry.meteorology: null" in str(error.value)
    tapado = GeometryConfig(**raw)
    assert GeometryConfig.model_validate(tapado.model_dump()) == tapado
    constant = GeometryConfig(**{**raw, "meteorology": None, "sky_loss": 110.0})
    assert ablation.settings_from_config(constant).meteorology is None


def test_presets_carry_their_site_meteorology():
    for preset in ("tapado.yaml", "rio_blanco.yaml", "guanaco_snow.yaml", "high_latitude_65s.yaml"):
        cfg = GeometryConfig(**load_raw(SITES / preset)["geometry"])
        assert cfg.meteorology is not None, preset
        assert "sky_loss" not in cfg.model_fields_set, preset


def _flat_balance_lowering(cfg) -> float:
    """The season's lowering of flat, open, ventilated ground summed by hand [m]: each day's sun positions in
    ablation.BALANCE_STEPS_PER_PERIOD consecutive groups, each group's balance at its mean absorbed flux
    (1 - a)(S_b sin e + S_d), plus the night's balance without shortwave."""
    from geometry import sunpath

    settings = ablation.settings_from_config(cfg)
    met = settings.meteorology
    mass = 0.0
    for day in range(cfg.days):
        sun = sunpath.daily_sun_positions(cfg.latitude, cfg.start_day_of_year + day, cfg.sun_positions_per_day)
        energies = [
            (1 - cfg.albedo) * d * (settings.sky.direct_normal(e) * np.sin(e) + settings.sky.diffuse_horizontal(e))
            for d, e in zip(sun.durations, np.arcsin(sun.vectors[:, 2]))
        ]
        for group in np.array_split(np.arange(len(energies)), ablation.BALANCE_STEPS_PER_PERIOD):
            seconds = float(sun.durations[group].sum())
            state = energy.surface_state(np.array([sum(energies[j] for j in group) / seconds]), 1.0, 1.0, met)
            mass += float(state.mass_rate()[0]) * seconds
        night = sunpath.SECONDS_PER_DAY - float(sun.durations.sum())
        mass += float(energy.surface_state(np.zeros(1), 1.0, 1.0, met).mass_rate()[0]) * night
    return cfg.ablation_efficiency * mass / cfg.density


def test_flat_ground_ablates_what_its_balance_says():
    """The growth model on flat ground (ablation.flat_season_lowering: open sky, no shelter, full wind) lowers it
    by the balance summed by hand to 1e-9, at Guanaco (snow, sublimation only: the flat snow never reaches 0 C)."""
    cfg = GeometryConfig(**{**load_raw(SITES / "guanaco_snow.yaml")["geometry"], "days": 5})
    expected = _flat_balance_lowering(cfg)
    assert 0.002 < expected < 0.05  # millimetres to centimetres in five days
    assert ablation.flat_season_lowering(ablation.settings_from_config(cfg), cfg.spacing) == pytest.approx(
        expected, rel=1e-9
    )
