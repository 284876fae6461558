"""Snow optics at one laser wavelength (532 or 1064 nm) in the weak-absorption limit (LIDAR.md §5).

    σ_e = ρ SSA / 2 = 3ρ/(ρ_ice d)     extinction (grains ≫ λ, each blocks twice its cross-section) [m⁻¹]
    γ   = 4πk/λ                       absorption coefficient of bulk ice [m⁻¹]
    σ_a = B γ ρ/ρ_ice                  absorption of the snow [m⁻¹]
    σ_s = σ_e − σ_a,  σ_s′ = σ_s (1 − g),  ℓ* = 1/σ_s′

d is the optical grain diameter, d = 2 r_opt = 6/(ρ_ice SSA). The imaginary index k of ice comes from one of
two named data sets, read from the tables distributed with TARTES (github.com/ghislainp/tartes,
``tartes/refractive_index.py``, MIT licence); the rows around the laser lines are copied below and
interpolated linearly in ln k against λ:

- ``warren_brandt_2008`` (default): Warren & Brandt 2008, JGR 113, D14220, arrays ``wl2008``/``refice2008_i``.
- ``picard_2016``: Picard, Libois & Arnaud 2016, The Cryosphere 10, 2655, array ``ki2016_clean_i`` (γ in m⁻¹
  every 5 nm, 320–600 nm; k = γλ/(4π)). 532 nm only: the data set stops at 600 nm.

The project's ``derive_snow`` (render/scene/optics.py, OPTICS.md §3) gives the same medium per RGB channel with
the Kokhanovsky–Zege form of 1 − ω; at one wavelength the two agree to first order in c = 2γ r_opt
(tests/render/lidar/test_lidar_optics.py states the tolerance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from render.lidar.diffusion import Boundary, DiffusionMedium
from render.scene.optics import RHO_ICE

LASER_WAVELENGTHS_NM = (532.0, 1064.0)
ICE_DATA_SETS = ("warren_brandt_2008", "picard_2016")
DEFAULT_ICE_DATA_SET = "warren_brandt_2008"

# Imaginary index of ice k against wavelength [nm], the rows of ghislainp/tartes tartes/refractive_index.py
# (commit 1f8d5e2) around each laser line. W&B 2008: wl2008 / refice2008_i, as printed there.
_WARREN_BRANDT_2008_K = MappingProxyType(
    {
        520.0: 1.076e-9,
        530.0: 1.409e-9,  # gamma = 0.03341 m-1, snow_optics.md section 2 quotes 0.0334
        540.0: 1.813e-9,
        550.0: 2.289e-9,
        1050.0: 2.170e-6,
        1060.0: 1.960e-6,
        1070.0: 1.810e-6,
        1080.0: 1.740e-6,
    }
)
# Real index of ice n against wavelength [nm], the same rows and commit: W&B 2008, wl2008 / refice2008_r (four
# decimals, as printed there), for the group index n - lambda dn/dlambda.
_WARREN_BRANDT_2008_N = MappingProxyType(
    {
        520.0: 1.3121,
        530.0: 1.3117,
        540.0: 1.3114,
        550.0: 1.3110,
        1050.0: 1.3007,
        1060.0: 1.3005,
        1070.0: 1.3003,
        1080.0: 1.3002,
    }
)
_N_TABLE_STEP_NM = 10.0  # the rows' spacing: the group index's central difference spans one row either side
# Picard et al. 2016: ki2016_clean_i is the absorption coefficient gamma [m-1] on wls2016 = 320, 325, ... 600 nm.
_PICARD_2016_GAMMA = MappingProxyType(
    {
        525.0: 4.388446405361826064e-02,
        530.0: 4.708083395543986860e-02,  # snow_optics.md section 2 quotes 0.0471
        535.0: 5.067129262305845178e-02,
        540.0: 5.461812971470113298e-02,
    }
)


def _picard_k() -> dict[float, float]:
    return {wl: gamma * wl * 1e-9 / (4.0 * math.pi) for wl, gamma in _PICARD_2016_GAMMA.items()}


def _check_wavelength(wavelength_nm: float) -> float:
    if not any(math.isclose(wavelength_nm, w) for w in LASER_WAVELENGTHS_NM):
        raise ValueError(
            f"wavelength_nm must be one of the laser lines {LASER_WAVELENGTHS_NM} nm, got {wavelength_nm}; "
            "other wavelengths need their own rows of the ice tables (render/lidar/optics.py)"
        )
    return float(wavelength_nm)


def ice_imaginary_index(wavelength_nm: float, data_set: str = DEFAULT_ICE_DATA_SET) -> float:
    """k of ice at ``wavelength_nm`` (532 or 1064), interpolated linearly in ln k between table rows."""
    wavelength = _check_wavelength(wavelength_nm)
    if data_set == "warren_brandt_2008":
        table = dict(_WARREN_BRANDT_2008_K)
    elif data_set == "picard_2016":
        if wavelength > 600.0:
            raise ValueError(
                f"data_set 'picard_2016' covers 320-600 nm only, not {wavelength:g} nm; use 'warren_brandt_2008'"
            )
        table = _picard_k()
    else:
        raise ValueError(f"data_set must be one of {ICE_DATA_SETS}, got {data_set!r}")
    wavelengths = np.array(sorted(table))
    ln_k = np.log([table[w] for w in wavelengths])
    return float(np.exp(np.interp(wavelength, wavelengths, ln_k)))


def ice_absorption_coefficient(wavelength_nm: float, data_set: str = DEFAULT_ICE_DATA_SET) -> float:
    """γ = 4πk/λ of bulk ice [m⁻¹]: W&B 2008 0.03500 at 532 nm and 22.42 at 1064 nm; Picard 2016 0.04848 at 532."""
    return 4.0 * math.pi * ice_imaginary_index(wavelength_nm, data_set) / (wavelength_nm * 1e-9)


def ice_refractive_index(wavelength_nm: float = 532.0) -> float:
    """Real (phase) index of ice, Warren & Brandt 2008 interpolated linearly: 1.3117 at 532 nm."""
    wavelengths = np.array(sorted(_WARREN_BRANDT_2008_N))
    return float(np.interp(wavelength_nm, wavelengths, [_WARREN_BRANDT_2008_N[w] for w in wavelengths]))


def ice_group_index(wavelength_nm: float = 532.0) -> float:
    """Group index n_g = n − λ dn/dλ of ice (Warren & Brandt 2008 real index, linear between rows): 1.3303 at
    532 nm, 1.3196 at 1064 nm. dn/dλ is the central difference one table row (10 nm) either side of λ."""
    wavelength = _check_wavelength(wavelength_nm)
    step = _N_TABLE_STEP_NM
    slope = (ice_refractive_index(wavelength + step) - ice_refractive_index(wavelength - step)) / (2.0 * step)
    return ice_refractive_index(wavelength) - wavelength * slope


def snow_group_index(density: float, absorption_enhancement: float = 1.6, wavelength_nm: float = 532.0) -> float:
    """The snow's clock: time per metre of path in the homogenised (index-matched) medium, in units of 1/c
    (LIDAR.md §5.1). n_snow = (1 − φ) + B φ n_g, φ = ρ/ρ_ice: per metre of homogenised path light crosses 1 − φ
    of air and, by the absorption the medium is given (σ_a = B γ φ), B φ of ice, where it runs at the group index
    n_g (``ice_group_index``). 1.369 at 300 kg m⁻³ and 1.677 at 550 kg m⁻³ with B = 1.6 at 532 nm."""
    if not (math.isfinite(density) and 0 <= density <= RHO_ICE):
        raise ValueError(f"density must lie in [0, {RHO_ICE:g}] kg/m3 (0: air, {RHO_ICE:g}: ice), got {density}")
    if not (math.isfinite(absorption_enhancement) and absorption_enhancement > 0):
        raise ValueError(
            f"absorption_enhancement B must be positive (1.6 for natural snow, 1.25 for spheres), got "
            f"{absorption_enhancement}"
        )
    volume_fraction = density / RHO_ICE
    return (1.0 - volume_fraction) + absorption_enhancement * volume_fraction * ice_group_index(wavelength_nm)


@dataclass(frozen=True)
class SnowOptics:
    """Snow at one wavelength: coefficients in m⁻¹, lengths in m (LIDAR.md §5)."""

    density: float  # ρ [kg m-3]
    grain_diameter: float  # optical diameter d = 6/(rho_ice SSA) [m]
    wavelength_nm: float
    ice_data_set: str
    ice_absorption: float  # γ of bulk ice [m-1]
    absorption_enhancement: float  # B [-]
    extinction: float  # σ_e = rho SSA / 2 [m-1]
    scattering: float  # σ_s = σ_e − σ_a [m-1]
    absorption: float  # σ_a = B γ rho/rho_ice [m-1]
    asymmetry: float  # g [-]

    @property
    def specific_surface_area(self) -> float:
        """SSA = 6/(ρ_ice d) [m² kg⁻¹]."""
        return 6.0 / (RHO_ICE * self.grain_diameter)

    @property
    def reduced_scattering(self) -> float:
        """σ_s′ = σ_s (1 − g) [m⁻¹]."""
        return self.scattering * (1.0 - self.asymmetry)

    @property
    def transport_mean_free_path(self) -> float:
        """ℓ* = 1/σ_s′ [m]."""
        return 1.0 / self.reduced_scattering

    def diffusion_medium(
        self, boundary: Boundary = "extrapolated", boundary_coefficient: float = 1.0
    ) -> DiffusionMedium:
        """This snow as the half-space of render.lidar.diffusion (σ_s′, σ_a)."""
        return DiffusionMedium(self.reduced_scattering, self.absorption, boundary, boundary_coefficient)


def snow_optics(
    density: float,
    grain_diameter: float,
    wavelength_nm: float = 532.0,
    *,
    ice_data_set: str = DEFAULT_ICE_DATA_SET,
    absorption_enhancement: float = 1.6,
    asymmetry: float = 0.86,
) -> SnowOptics:
    """Snow of ``density`` [kg m⁻³] and optical ``grain_diameter`` [m] at a laser line (module docstring).

    Defaults: B = 1.6 (natural snow, Libois et al. 2014), g = 0.86 (the classic natural-snow value, OPTICS.md §3's
    ``g0_natural``), Warren & Brandt 2008 ice. The weak-absorption forms hold while c = 2γ r_opt ≪ 1 (2·10⁻⁵ at
    532 nm, ~10⁻² at 1064 nm for millimetre grains).
    """
    if not (math.isfinite(density) and 0 < density < RHO_ICE):
        raise ValueError(
            f"density must lie in (0, {RHO_ICE:g}) kg/m3 (snow is ice grains in air), got {density}; "
            "ice itself is no snow: use render.scene.optics.derive_bubbly_ice or derive_clear_ice"
        )
    if not (math.isfinite(grain_diameter) and grain_diameter > 0):
        raise ValueError(
            f"grain_diameter must be a positive optical diameter in metres (d = 6/(rho_ice SSA)), got {grain_diameter}"
        )
    if not (math.isfinite(absorption_enhancement) and absorption_enhancement > 0):
        raise ValueError(
            f"absorption_enhancement B must be positive (1.6 for natural snow), got {absorption_enhancement}"
        )
    if not (math.isfinite(asymmetry) and -1 < asymmetry < 1):
        raise ValueError(f"asymmetry g must lie in (-1, 1) (about 0.86 for snow), got {asymmetry}")
    gamma = ice_absorption_coefficient(wavelength_nm, ice_data_set)
    extinction = 3.0 * density / (RHO_ICE * grain_diameter)
    absorption = absorption_enhancement * gamma * density / RHO_ICE
    return SnowOptics(
        density=float(density),
        grain_diameter=float(grain_diameter),
        wavelength_nm=float(wavelength_nm),
        ice_data_set=ice_data_set,
        ice_absorption=gamma,
        absorption_enhancement=float(absorption_enhancement),
        extinction=extinction,
        scattering=extinction - absorption,
        absorption=absorption,
        asymmetry=float(asymmetry),
    )


__all__ = [
    "DEFAULT_ICE_DATA_SET",
    "ICE_DATA_SETS",
    "LASER_WAVELENGTHS_NM",
    "SnowOptics",
    "ice_absorption_coefficient",
    "ice_group_index",
    "ice_imaginary_index",
    "snow_group_index",
    "snow_optics",
]
