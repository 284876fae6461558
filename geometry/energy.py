"""Bulk surface energy balance of a snow or ice facet from the site's meteorology (DESIGN.md 3.9).

Per unit true surface area, with every flux positive toward the surface [W m-2]:

    Q(T_s) = S + L_in - L_out + H + LE
    L_in   = V eps_a sigma T_a^4 + (1 - V) eps_s sigma T_s^4       the walls a facet sees are at its own T_s
    L_out  = eps_s sigma T_s^4
    H      = rho_a c_p C u (T_a - T_s)
    LE     = rho_a L_s C u 0.622 (e_a - e_i(T_s)) / p
    C      = kappa^2 / (ln(z / z0) ln(z / z0s))                     neutral bulk transfer coefficient

S is the absorbed shortwave. Q decreases with T_s, so each facet has one state: where Q(0 C) > 0 the surface
sits at 0 C and the surplus melts, while LE sublimates; below, T_s solves Q(T_s) = 0 and all mass loss is
sublimation, -LE / L_s. Pure numpy, vectorised over cells. Temperatures [K], pressures [Pa].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STEFAN_BOLTZMANN = 5.670374e-8  # sigma [W m-2 K-4]
VON_KARMAN = 0.41  # kappa [-]
MELTING_POINT = 273.15  # [K]
SPECIFIC_HEAT_AIR = 1005.0  # c_p of dry air [J kg-1 K-1]
GAS_CONSTANT_DRY_AIR = 287.05  # R_d [J kg-1 K-1]
WATER_TO_AIR_MOLAR_MASS = 0.622  # [-]
LATENT_HEAT_SUBLIMATION = 2.834e6  # L_s [J kg-1]
LATENT_HEAT_FUSION = 0.334e6  # L_f [J kg-1]
CLOUD_EMISSIVITY = 0.976  # emissivity of an overcast sky, Konzelmann et al. (1994) [-]
# Tetens' form of e_i(T) over ice (ECMWF IFS Cy45r1, Part IV): A exp(B (T - T0) / (T - T1)).
_TETENS_A, _TETENS_B, _TETENS_T0, _TETENS_T1 = 611.21, 22.587, 273.16, -0.7  # [Pa], [-], [K], [K]
_NEWTON_ITERATIONS = 30
_NEWTON_TOLERANCE = 1e-4  # [K]
_COLDEST_SURFACE = 150.0  # [K], a floor that no physical state reaches


@dataclass(frozen=True)
class Meteorology:
    """A site's air, in SI units (MeteorologyConfig in pipeline/schema/geometry.py gives the config's units)."""

    air_temperature: float  # T_a [K]
    vapour_pressure: float  # e_a [Pa]
    wind_speed: float  # u at measurement_height [m s-1]
    cloud_fraction: float  # n [-]
    air_pressure: float  # p [Pa]
    measurement_height: float  # z [m]
    roughness_length: float  # z0, momentum [m]
    scalar_roughness_length: float  # z0s, heat and vapour [m]
    surface_emissivity: float = 0.99  # eps_s [-]

    @property
    def transfer_coefficient(self) -> float:
        return bulk_transfer_coefficient(self.measurement_height, self.roughness_length, self.scalar_roughness_length)

    @property
    def air_density(self) -> float:
        return air_density(self.air_pressure, self.air_temperature)

    @property
    def sky_longwave(self) -> float:
        """Longwave from an open sky, eps_a sigma T_a^4 [W m-2]."""
        emissivity = sky_emissivity(self.vapour_pressure, self.air_temperature, self.cloud_fraction)
        return float(emissivity * STEFAN_BOLTZMANN * self.air_temperature**4)


def clear_sky_emissivity(vapour_pressure: float, air_temperature: float) -> float:
    """Brutsaert (1975): eps_cs = 1.24 (e_a / T_a)^(1/7), e_a in hPa, T_a in K; takes e_a [Pa]."""
    return 1.24 * (vapour_pressure / 100.0 / air_temperature) ** (1.0 / 7.0)


def sky_emissivity(vapour_pressure: float, air_temperature: float, cloud_fraction: float) -> float:
    """Clear sky raised by cloud as in Konzelmann et al. (1994): eps_cs (1 - n^2) + eps_cl n^2, eps_cl = 0.976."""
    clear = clear_sky_emissivity(vapour_pressure, air_temperature)
    return clear * (1.0 - cloud_fraction**2) + CLOUD_EMISSIVITY * cloud_fraction**2


def saturation_vapour_pressure_ice(temperature):
    """e_i(T) over ice [Pa], the Tetens form of the ECMWF IFS (Cy45r1, Part IV): 611.21 exp(22.587 (T - 273.16)
    / (T + 0.7))."""
    temperature = np.asarray(temperature, float)
    return _TETENS_A * np.exp(_TETENS_B * (temperature - _TETENS_T0) / (temperature - _TETENS_T1))


def air_density(air_pressure: float, air_temperature: float) -> float:
    """rho_a = p / (R_d T_a) [kg m-3]; the vapour (under 1 % of p in the dry Andes) is left out."""
    return air_pressure / (GAS_CONSTANT_DRY_AIR * air_temperature)


def bulk_transfer_coefficient(
    measurement_height: float, roughness_length: float, scalar_roughness_length: float
) -> float:
    """Neutral bulk transfer coefficient C = kappa^2 / (ln(z / z0) ln(z / z0s)) [-], the same for heat and vapour
    (z0s for both, as Winkler et al. 2009 fit them on a dry tropical glacier)."""
    return VON_KARMAN**2 / (
        np.log(measurement_height / roughness_length) * np.log(measurement_height / scalar_roughness_length)
    )


@dataclass(frozen=True)
class _Coefficients:
    """The per-cell constants of Q(T) = S + V (L_sky - eps sigma T^4) + g (c_p (T_a - T) + b (e_a - e_i(T)))."""

    shortwave: np.ndarray  # S [W m-2]
    sky_view: np.ndarray  # V [-]
    conductance: np.ndarray  # g = rho_a C u ventilation [kg m-2 s-1]
    met: Meteorology

    @property
    def vapour_factor(self) -> float:
        """b = L_s 0.622 / p [J kg-1 Pa-1]."""
        return LATENT_HEAT_SUBLIMATION * WATER_TO_AIR_MOLAR_MASS / self.met.air_pressure

    def latent(self, temperature):
        """LE = g b (e_a - e_i(T)) [W m-2] at ``temperature`` [K]; negative while the surface sublimates."""
        return (
            self.conductance
            * self.vapour_factor
            * (self.met.vapour_pressure - saturation_vapour_pressure_ice(temperature))
        )


def _coefficients(shortwave, sky_view, ventilation, met: Meteorology) -> _Coefficients:
    shortwave, sky_view, ventilation = np.broadcast_arrays(
        np.asarray(shortwave, float), np.asarray(sky_view, float), np.asarray(ventilation, float)
    )
    conductance = met.air_density * met.transfer_coefficient * met.wind_speed * ventilation
    return _Coefficients(shortwave, sky_view, conductance, met)


def _net_flux(temperature, c: _Coefficients, slope: bool = True):
    """Q(T) and dQ/dT (None unless ``slope``) of the facets of ``c`` at ``temperature`` [K]."""
    met = c.met
    sigma_eps = STEFAN_BOLTZMANN * met.surface_emissivity
    cube = temperature**3
    # Walls emit at the facet's own temperature, so the longwave exchanged is the sky's share alone.
    longwave = c.sky_view * (met.sky_longwave - sigma_eps * cube * temperature)
    saturation = saturation_vapour_pressure_ice(temperature)
    turbulent = SPECIFIC_HEAT_AIR * (met.air_temperature - temperature) + c.vapour_factor * (
        met.vapour_pressure - saturation
    )
    flux = c.shortwave + longwave + c.conductance * turbulent
    if not slope:
        return flux, None
    d_saturation = saturation * (_TETENS_B * (_TETENS_T0 - _TETENS_T1)) / (temperature - _TETENS_T1) ** 2
    d_turbulent = -SPECIFIC_HEAT_AIR - c.vapour_factor * d_saturation
    return flux, -4.0 * sigma_eps * c.sky_view * cube + c.conductance * d_turbulent


def net_flux(temperature, shortwave, sky_view, ventilation, met: Meteorology):
    """Q(T_s) and dQ/dT_s [W m-2, W m-2 K-1] of facets at ``temperature`` [K] absorbing ``shortwave`` [W m-2],
    seeing the sky view ``sky_view`` [-], in wind ``ventilation`` x met.wind_speed."""
    return _net_flux(np.asarray(temperature, float), _coefficients(shortwave, sky_view, ventilation, met))


def latent_flux(temperature, ventilation, met: Meteorology):
    """LE [W m-2] at surface temperature ``temperature`` [K]; negative while the surface sublimates."""
    return _coefficients(0.0, 1.0, ventilation, met).latent(np.asarray(temperature, float))


@dataclass(frozen=True)
class SurfaceState:
    """The balance's answer per cell: surface temperature [K], the energy that melts and the energy that
    sublimates [W m-2, >= 0; sublimation is -LE, deposition counts as 0]."""

    temperature: np.ndarray
    melt_flux: np.ndarray
    sublimation_flux: np.ndarray

    def mass_rate(self) -> np.ndarray:
        """Mass lost per unit true area and time [kg m-2 s-1]: melt at L_f, sublimation at L_s."""
        return self.melt_flux / LATENT_HEAT_FUSION + self.sublimation_flux / LATENT_HEAT_SUBLIMATION


def surface_state(shortwave, sky_view, ventilation, met: Meteorology) -> SurfaceState:
    """Solve each facet's balance for T_s <= 0 C (DESIGN.md 3.9, *Surface energy balance*).

    Q(T) is decreasing and concave in T (longwave -T^4, sensible linear, latent -e_i(T)), so Newton's method
    from 0 C never overshoots the root and converges monotonically from above; melting facets (Q(0 C) > 0) keep
    0 C, their step clipped to 0."""
    c = _coefficients(shortwave, sky_view, ventilation, met)
    temperature = np.full(c.shortwave.shape, MELTING_POINT)
    at_melting, _ = _net_flux(temperature, c, slope=False)
    for _ in range(_NEWTON_ITERATIONS):
        flux, slope = _net_flux(temperature, c)
        step = np.minimum(flux, 0.0) / np.minimum(slope, -1e-9)  # >= 0 where the facet is colder than 0 C
        temperature = np.maximum(temperature - step, _COLDEST_SURFACE)
        if float(step.max(initial=0.0)) < _NEWTON_TOLERANCE:
            break
    return SurfaceState(temperature, np.maximum(at_melting, 0.0), np.maximum(-c.latent(temperature), 0.0))
