"""Radiative ablation of a periodic height field (DESIGN.md 3.8-3.12, 5, 6).

    dh/dt = - eps k (1 - a) / (rho L_eff) * [ E_dir,h + (E_sky + E_ter) sqrt(1 + |grad h|^2) ]
            + D lap h - K lap^2 h  [+ A_B (-(-lap)^(1/2) h)]

E_dir,h = S_b V_sun max(0, s_z - s . grad h) is the direct beam per unit horizontal area; under one
sun it is an advection along the beam, so the slope is upwinded on the sun's side. Sky and terrain
light are per unit true area and recede along the normal (Godunov factor). L_eff blends
sublimation and melt through Lliboutry's switch. A steep cell's column stands for its top and for
the wall face down to the neighbour its upwind slope is taken to, so 1/L_eff is integrated over
that surface: the top at the cell's own value, the face at the mean of its two ends (trapezoid
rule). Weighting the whole column by its top would let a one-cell crest sublimate its sunlit
wall, however deep and sheltered, and grid-scale walls between pits would never fall.
k = max(0, Q - sink) / Q keeps the part of each day's absorbed shortwave Q above the loss to the
sky (geometry.sky_loss times the sky view, its turbulent share stopping where the air is still).
The switch reads sheltering from the shelter index of the horizons, and the melt fraction, the sky and
terrain light and the scattered light are spread over the e-folding depth l of absorbed light,
1 / (1 + (k l)^2), which selects the onset wavelength 2 pi l and gives the field its smallest physical
scale, so that it converges once the cells resolve l (DESIGN.md 3.9, 3.10, 7). The linear terms are integrated exactly
in Fourier space on flux time. Time stepping freezes the geometry for each horizon refresh (one per
simulated day by default), integrates the absorbed energy over that period's sun positions, and
applies it in sub-steps that each respect the Hamilton-Jacobi CFL limit (6.2). Heights are [m],
times [s].
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.fft

from geometry import energy, irradiance, sunpath

log = logging.getLogger(__name__)

LATENT_HEAT_SUBLIMATION = energy.LATENT_HEAT_SUBLIMATION  # L_s [J kg-1]
LATENT_HEAT_FUSION = energy.LATENT_HEAT_FUSION  # L_f [J kg-1]


def wavenumbers(n: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Angular wavenumbers (kx, ky) [rad m-1] of an n x n periodic grid, for numpy's fft2 layout."""
    k = 2.0 * np.pi * np.fft.fftfreq(n, d=spacing)
    ky, kx = np.meshgrid(k, k, indexing="ij")
    return kx, ky


def linear_growth_rate(
    k: np.ndarray,
    scattered_coefficient: float,
    diffusivity: float,
    hyperdiffusivity: float = 0.0,
    efolding_depth: float = 0.0,
) -> np.ndarray:
    """sigma(k) = A_B |k| / (1 + (k l)^2) - D k^2 - K k^4 [s-1] for |k| [rad m-1], A_B [m s-1], D [m2 s-1],
    K [m4 s-1], l [m]: the scattered light absorbed is spread over the e-folding depth l like all light."""
    k = np.abs(k)
    spread = 1.0 / (1.0 + (k * efolding_depth) ** 2)
    return scattered_coefficient * k * spread - diffusivity * k**2 - hyperdiffusivity * k**4


def spectral_linear_step(
    h: np.ndarray,
    spacing: float,
    duration: float,
    scattered_coefficient: float,
    diffusivity: float,
    hyperdiffusivity: float,
    efolding_depth: float = 0.0,
) -> np.ndarray:
    """Exact (exponential-integrator) step of the linear terms over ``duration`` [s] (6.2).

    grow_field passes the flux time (time integral of the horizontal flux over the reference flux),
    so A_B and D scale together with the sun and the band stays at lambda* = 4 pi D / A_B.
    """
    kx, ky = wavenumbers(h.shape[0], spacing)
    sigma = linear_growth_rate(np.hypot(kx, ky), scattered_coefficient, diffusivity, hyperdiffusivity, efolding_depth)
    spectrum = np.fft.fft2(h) * np.exp(sigma * duration)
    return np.real(np.fft.ifft2(spectrum))


def betterton_intensity_1d(h: np.ndarray, spacing: float, periods: int = 4) -> np.ndarray:
    """Scattered-light integral of DESIGN.md 3.11 by direct quadrature on a periodic 1-D profile.

    I(x) = (1/pi) integral of [dh - h'(x) dx] / (dx^2 + dh^2) dx', summed cell by cell over
    +-``periods`` periodic images. The singular cell takes its limit h''/2; the far images beyond
    contribute -(h - mean h) * 2 / (pi R). For small slopes I -> -|k| h (the V1 kernel).
    """
    h = np.asarray(h, float)
    n = h.size
    slope = (np.roll(h, -1) - np.roll(h, 1)) / (2.0 * spacing)
    curvature = (np.roll(h, -1) - 2.0 * h + np.roll(h, 1)) / spacing**2
    offsets = np.arange(-periods * n, periods * n + 1)
    offsets = offsets[offsets != 0]
    dx = offsets * spacing
    # Rows: target cells; columns: source offsets (images included through the modulo).
    dh = h[(np.arange(n)[:, None] + offsets[None, :]) % n] - h[:, None]
    integrand = (dh - slope[:, None] * dx[None, :]) / (dx[None, :] ** 2 + dh**2)
    reach = (periods * n + 0.5) * spacing
    near = (integrand.sum(axis=1) + 0.5 * curvature) * spacing / np.pi
    return near - (h - h.mean()) * 2.0 / (np.pi * reach)


def melt_fraction(exposure: np.ndarray, centre: float, width: float) -> np.ndarray:
    """Lliboutry switch weight w = clip((V_c - exposure) / dV, 0, 1): sheltered cells melt (3.9).

    exposure is a sky view in [0, 1]; the growth loop passes the openness (sky view of a level
    receiver) or the facet's own sky view factor, as configured.
    """
    return np.clip((centre - exposure) / width, 0.0, 1.0)


def sheltered_melt_fraction(shelter: np.ndarray, full_melt_deg: float) -> np.ndarray:
    """Lliboutry switch weight read from ventilation (DESIGN.md 3.9): w = clip(Sx / tan(theta_m), 0, 1).

    Sx is the shelter index of the horizons (mean over azimuths of how far the horizon's tangent
    rises above the wake slope): 0 on a point that nothing around stands above, which the wind
    skimming the field keeps cold and sublimating; the surface fully melts at Sx = tan(theta_m).
    """
    return np.clip(shelter / np.tan(np.radians(full_melt_deg)), 0.0, 1.0)


def switch_melt_fraction(horizons: irradiance.Horizons, s: GrowthSettings) -> np.ndarray:
    """Melt fraction w of every cell from the configured sheltering proxy (DESIGN.md 3.9)."""
    if s.switch_proxy == "shelter":
        return sheltered_melt_fraction(horizons.shelter, s.shelter_full_melt_deg)
    exposure = horizons.sky_view if s.switch_proxy == "sky_view" else horizons.openness
    return melt_fraction(exposure, s.switch_centre, s.switch_width)


def net_energy_fraction(absorbed: np.ndarray, sink: np.ndarray) -> np.ndarray:
    """Share of the absorbed energy left for ablation after the sink, max(0, absorbed - sink) / absorbed [-].

    The sink is net longwave and turbulent loss, which scales with the sky view: a trough's walls
    trade longwave with each other at the same temperature, an exposed crest radiates to a cold sky.
    """
    return np.divide(np.maximum(absorbed - sink, 0.0), absorbed, out=np.zeros_like(absorbed), where=absorbed > 0)


MELT_GATE_RAMP = 50.0  # [W m-2] over which the net-gain gate opens (DESIGN.md 3.9)


def net_gain_gate(
    absorbed: np.ndarray, seconds: float, sky_view: np.ndarray, sky_loss: float, multiple: float
) -> np.ndarray:
    """The share of a cell's melt fraction that a period allows (DESIGN.md 3.9, *Melt needs a net gain*): a surface
    reaches 0 °C only while it absorbs more than it loses, so the gate opens as the period's mean absorbed flux
    (``absorbed`` [J m-2] over ``seconds``) rises past ``multiple`` x sky_loss x V_sky, over MELT_GATE_RAMP."""
    flux = absorbed / max(seconds, 1e-9)
    return np.clip((flux - multiple * sky_loss * sky_view) / MELT_GATE_RAMP, 0.0, 1.0)


def inverse_latent_heat(melt: np.ndarray) -> np.ndarray:
    """1 / L_eff = w / L_f + (1 - w) / L_s [kg J-1]."""
    return melt / LATENT_HEAT_FUSION + (1.0 - melt) / LATENT_HEAT_SUBLIMATION


def face_mean(cell: np.ndarray, axis: int, step) -> np.ndarray:
    """Mean of a cell field over the wall face between each cell and its neighbour ``step`` cells
    along ``axis`` (+1 or -1, a scalar or one per cell): the trapezoid rule over the face's two ends."""
    step = np.asarray(step)
    neighbour = np.where(step > 0, np.roll(cell, -1, axis=axis), np.roll(cell, 1, axis=axis))
    return 0.5 * (cell + neighbour)


def one_sided_slopes(h: np.ndarray, spacing: float, axis: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Backward and forward slopes of a periodic field along ``axis`` (1 = x, 0 = y) [-].

    order 1: the plain differences D-h, D+h. order 2: second-order ENO with a minmod switch (Osher & Shu 1991),
    each difference corrected by half a cell times the minmod of the two second differences on its side, so a
    smooth surface's slope is second-order accurate, a kink (a crest, a trough) is not smeared across it, and
    cell-scale noise, whose second differences alternate in sign, falls back to first order (DESIGN.md 6.1)."""
    forward = (np.roll(h, -1, axis=axis) - h) / spacing
    backward = np.roll(forward, 1, axis=axis)
    if order == 1:
        return backward, forward
    curvature = (forward - backward) / spacing
    toward_back, toward_front = np.roll(curvature, 1, axis=axis), np.roll(curvature, -1, axis=axis)
    back_correction = 0.5 * spacing * minmod(curvature, toward_back)
    front_correction = 0.5 * spacing * minmod(curvature, toward_front)
    return backward + back_correction, forward - front_correction


def minmod(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smaller in magnitude of a and b where they share a sign, else 0."""
    return np.where(a * b > 0.0, np.where(np.abs(a) <= np.abs(b), a, b), 0.0)


@dataclass(frozen=True)
class OneSidedSlopes:
    """Backward and forward slopes of a field along x (east) and y (north), one_sided_slopes of each axis."""

    back_x: np.ndarray
    fwd_x: np.ndarray
    back_y: np.ndarray
    fwd_y: np.ndarray

    @classmethod
    def of(cls, h: np.ndarray, spacing: float, order: int) -> OneSidedSlopes:
        return cls(*one_sided_slopes(h, spacing, 1, order), *one_sided_slopes(h, spacing, 0, order))


def _godunov_slopes(
    h: np.ndarray, spacing: float, order: int = 1
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Squared upwind slopes (x, y) of a receding surface (6.1) and the side (+1 east/north, -1
    west/south) of the downhill neighbour each one is taken to."""
    slopes = OneSidedSlopes.of(h, spacing, order)
    back_x, fwd_x, back_y, fwd_y = slopes.back_x, slopes.fwd_x, slopes.back_y, slopes.fwd_y
    back_x, fwd_x = np.maximum(back_x, 0.0) ** 2, np.minimum(fwd_x, 0.0) ** 2
    back_y, fwd_y = np.maximum(back_y, 0.0) ** 2, np.minimum(fwd_y, 0.0) ** 2
    return (
        np.maximum(back_x, fwd_x),
        np.maximum(back_y, fwd_y),
        np.where(back_x >= fwd_x, -1, 1),
        np.where(back_y >= fwd_y, -1, 1),
    )


def surface_inverse_latent_heat(
    h: np.ndarray, spacing: float, inverse_heat: np.ndarray, max_slope_deg: float, order: int = 1
) -> tuple[np.ndarray, float]:
    """1/L_eff integrated over the surface a column exposes to sky and terrain light, per unit
    horizontal area [kg J-1]. The surface is the upwind true area sqrt(1 + |grad h|^2) of a normal
    recession (6.1), slope clamped at ``max_slope_deg``: its top (area 1) at the cell's own value,
    the rest (its wall faces) at the face means with the downhill neighbours. Where 1/L_eff is
    uniform this is 1/L_eff times the Godunov slope factor. Also returns the fraction of cells
    whose slope hit the clamp."""
    grad2_x, grad2_y, side_x, side_y = _godunov_slopes(h, spacing, order)
    grad2 = grad2_x + grad2_y
    limit2 = np.tan(np.radians(max_slope_deg)) ** 2
    factor = np.sqrt(1.0 + np.minimum(grad2, limit2))
    share_x = np.divide(grad2_x, grad2, out=np.full_like(h, 0.5), where=grad2 > 0)
    faces = share_x * face_mean(inverse_heat, 1, side_x) + (1.0 - share_x) * face_mean(inverse_heat, 0, side_y)
    return inverse_heat + (factor - 1.0) * faces, float(np.mean(grad2 > limit2))


def sunward_slopes(
    h: np.ndarray, spacing: float, sun: np.ndarray, max_slope_deg: float, order: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """One-sided slopes (dh/dx, dh/dy) taken on the sun's side of each cell, the upwind differences of
    the direct-beam lowering (see direct_beam_lowering), clamped in magnitude at ``max_slope_deg``;
    ``order`` 2 corrects them to second order (one_sided_slopes)."""
    return sunward_of(OneSidedSlopes.of(h, spacing, order), sun, max_slope_deg)


def sunward_of(slopes: OneSidedSlopes, sun: np.ndarray, max_slope_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """sunward_slopes from a field's one-sided slopes, which a frozen period computes once for all its suns."""
    p = slopes.fwd_x if sun[0] >= 0 else slopes.back_x
    q = slopes.fwd_y if sun[1] >= 0 else slopes.back_y
    grad = np.hypot(p, q)
    limit = np.tan(np.radians(max_slope_deg))
    scale = np.where(grad > limit, limit / np.maximum(grad, 1e-300), 1.0)
    return p * scale, q * scale


def direct_beam_lowering(p: np.ndarray, q: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Unshadowed direct beam per unit horizontal area and unit direct-normal irradiance [-], from
    sunward slopes p, q (sunward_slopes).

    max(0, n.s) sqrt(1 + |grad h|^2) = max(0, s_z - s_x p - s_y q) is linear in the slope: under one
    sun the surface recedes along the beam (an advection), so the slopes must be upwinded on the
    sun's side. Central slopes times the symmetric Godunov factor treat every crest and trough
    bottom as if the sun stood overhead and erase the sun-facing/shaded wall asymmetry.
    """
    return np.clip(sun[2] - sun[0] * p - sun[1] * q, 0.0, None)


def direct_beam_mass(p: np.ndarray, q: np.ndarray, sun: np.ndarray, inverse_heat: np.ndarray) -> np.ndarray:
    """direct_beam_lowering times 1/L_eff [kg J-1], with 1/L_eff integrated over what the beam hits:
    s_z on the cell's top at its own value, -s_x p and -s_y q on the wall faces toward the sunward
    neighbours (those the slopes p, q are taken to) at the face means. Zero where the beam misses."""
    along_x = -sun[0] * p * face_mean(inverse_heat, 1, 1 if sun[0] >= 0 else -1)
    along_y = -sun[1] * q * face_mean(inverse_heat, 0, 1 if sun[1] >= 0 else -1)
    weighted = np.clip(sun[2] * inverse_heat + along_x + along_y, 0.0, None)
    return np.where(direct_beam_lowering(p, q, sun) > 0.0, weighted, 0.0)


def penetration_filter(n: int, spacing: float, efolding_depth: float) -> np.ndarray:
    """Transfer function 1 / (1 + (|k| l)^2) of absorbed energy spread by diffuse light (DESIGN.md 3.10),
    on the rfft2 layout of an n x n grid; l = efolding_depth [m]. It keeps the mean (k = 0) and
    damps features smaller than l."""
    ky = 2.0 * np.pi * np.fft.fftfreq(n, d=spacing)
    kx = 2.0 * np.pi * np.fft.rfftfreq(n, d=spacing)
    k2 = ky[:, None] ** 2 + kx[None, :] ** 2
    return 1.0 / (1.0 + k2 * efolding_depth**2)


def spread_by_penetration(field: np.ndarray, transfer: np.ndarray | None) -> np.ndarray:
    """Apply a penetration_filter to a periodic field (None leaves it as it is)."""
    if transfer is None:
        return field
    return scipy.fft.irfft2(scipy.fft.rfft2(field) * transfer, s=field.shape)


def onset_wavelength(efolding_depth: float) -> float:
    """lambda* = 2 pi l [m]: where a scale-free growth rate c |k| filtered by 1 / (1 + (k l)^2) peaks
    (DESIGN.md 7, V1)."""
    return 2.0 * np.pi * efolding_depth


# A Gaussian amplitude filter exp(-(k lc)^2 / 8) is below 1e-4 beyond k lc = 8.6: a spectral grid whose
# Nyquist wavenumber pi m / L reaches that holds the whole correlated surface.
_SPECTRAL_CUTOFF = 8.6
_MAX_SPECTRAL_CELLS = 4096


def spectral_grid_cells(domain_size: float, correlation_length: float) -> int:
    """Cells per side of the grid on which a correlated start is drawn (DESIGN.md 3.12): even, and fine
    enough that its Nyquist wavenumber holds the surface's whole spectrum; it depends on the domain and the
    correlation length only, never on the growth grid."""
    cells = 2 * int(np.ceil(_SPECTRAL_CUTOFF * domain_size / (2.0 * np.pi * correlation_length)))
    if cells > _MAX_SPECTRAL_CELLS:
        raise ValueError(
            f"geometry.initial_correlation_length ({correlation_length} m) is too short for geometry.domain_size "
            f"({domain_size} m): the start would need a {cells}^2 spectral grid (at most {_MAX_SPECTRAL_CELLS}); "
            "raise the correlation length or shrink the domain"
        )
    return max(cells, 8)


def correlated_height_field(
    n: int, spacing: float, rms: float, correlation_length: float, rng: np.random.Generator
) -> np.ndarray:
    """A Gaussian-correlated random surface [m], C(r) = rms^2 exp(-r^2 / lc^2), sampled on an n x n grid.

    The surface is drawn once on a spectral grid set by the domain and lc alone (spectral_grid_cells), so one
    seed gives the same continuous surface on every growth grid: a finer grid samples it more densely, a grid
    coarser than the spectral one keeps the modes it can hold (DESIGN.md 3.12). ``rms`` is the RMS of the
    whole surface; a grid that cannot hold all of it shows a little less."""
    domain = n * spacing
    m = spectral_grid_cells(domain, correlation_length)
    kx, ky = wavenumbers(m, domain / m)
    amplitude = np.exp(-(kx**2 + ky**2) * correlation_length**2 / 8.0)
    amplitude[0, 0] = 0.0
    spectrum = np.fft.fft2(rng.standard_normal((m, m))) * amplitude
    scale = rms / float(np.real(np.fft.ifft2(spectrum)).std())
    # Keep the modes both grids hold, Nyquist rows excluded so that the embedded spectrum stays Hermitian.
    keep = min(m, n) // 2 - 1
    index = np.r_[0 : keep + 1, -keep:0]
    embedded = np.zeros((n, n), complex)
    embedded[np.ix_(index % n, index % n)] = spectrum[np.ix_(index % m, index % m)]
    return np.real(np.fft.ifft2(embedded)) * (n * n / (m * m)) * scale


def initial_height_field(
    n: int,
    spacing: float,
    rms: float,
    wavelength: float | None,
    rng: np.random.Generator,
    correlation_length: float | None = None,
) -> np.ndarray:
    """Flat snow plus Gaussian noise [m] with RMS ``rms`` [m] (DESIGN.md 3.12).

    With ``correlation_length`` [m] a Gaussian-correlated surface that is the same at every grid
    (correlated_height_field); with ``wavelength`` [m] isotropic band-limited noise with its power centred on
    it (a Gaussian band of relative width 0.5 in |k|, the explicit override); with neither, white noise,
    whose slopes grow and whose long waves shrink as the cells shrink (so only for the linear-stability
    starts of V1, where the growth selects the scale)."""
    if wavelength is None and correlation_length is not None:
        return correlated_height_field(n, spacing, rms, correlation_length, rng)
    white = rng.standard_normal((n, n))
    if wavelength is None:
        noise = white - white.mean()
        return noise * (rms / noise.std())
    kx, ky = wavenumbers(n, spacing)
    k = np.hypot(kx, ky)
    k0 = 2.0 * np.pi / wavelength
    band = np.exp(-0.5 * ((k - k0) / (0.5 * k0)) ** 2)
    band[0, 0] = 0.0
    noise = np.real(np.fft.ifft2(np.fft.fft2(white) * band))
    std = noise.std()
    if std == 0.0:
        raise ValueError(
            "the seeded noise band is empty: geometry.initial_wavelength must be between 2 cells and the domain size"
        )
    return noise * (rms / std)


def initial_height_field_from_config(cfg, rng: np.random.Generator) -> np.ndarray:
    """The start of a growth run from a GeometryConfig (pipeline.schema.geometry), DESIGN.md 3.12."""
    return initial_height_field(
        cfg.grid_cells,
        cfg.spacing,
        cfg.initial_roughness_rms,
        cfg.initial_wavelength,
        rng,
        correlation_length=cfg.initial_correlation_length,
    )


@dataclass(frozen=True)
class Sky:
    """Clear-sky shortwave: direct normal irradiance attenuated by air mass, diffuse a fraction of it."""

    direct_normal_zenith: float  # S_b with the sun at the zenith [W m-2]
    optical_depth: float  # broadband extinction per extra air mass [-]
    diffuse_fraction: float  # S_d = fraction * S_b * sin(e) [-]

    def direct_normal(self, elevation: float) -> float:
        """S_b(e) [W m-2]: Beer-Lambert with air mass 1/sin(e) (floored at 3 deg of elevation)."""
        air_mass = 1.0 / max(np.sin(elevation), np.sin(np.radians(3.0)))
        return self.direct_normal_zenith * float(np.exp(-self.optical_depth * (air_mass - 1.0)))

    def diffuse_horizontal(self, elevation: float) -> float:
        """S_d(e) [W m-2]."""
        return self.diffuse_fraction * self.direct_normal(elevation) * max(np.sin(elevation), 0.0)


@dataclass(frozen=True)
class GrowthSettings:
    """Plain-number settings of a growth run (units as in the GeometryConfig fields)."""

    latitude: float  # [deg]
    start_day_of_year: int
    days: int
    sun_positions_per_day: int
    refreshes_per_day: int
    sky: Sky
    albedo: float
    density: float  # [kg m-3]
    ablation_efficiency: float  # eps [-]
    melt_enabled: bool
    switch_centre: float
    switch_width: float
    switch_proxy: str  # "shelter", "sky_view" or "openness"
    shelter_full_melt_deg: float  # theta_m of the shelter proxy [deg]
    diffusivity: float  # D [m2 s-1]
    hyperdiffusivity: float  # K [m4 s-1]
    scattered_coefficient: float  # A_B at the reference flux [m s-1]
    scattered_reference_flux: float  # [W m-2]
    azimuths: int
    bounces: int
    max_slope_deg: float
    sky_loss: float  # net longwave + turbulent loss of a facet open to the sky, day mean [W m-2]
    cfl: float
    snapshots: int
    wake_slope: float = 0.0  # [-]
    turbulent_share: float = 0.0  # share of sky_loss that stops where the air is still [-]
    efolding_depth: float = 0.0  # l [m], 0 = no penetration spreading
    slope_order: int = 2  # 2: second-order (minmod ENO) slopes, 1: first-order upwind (DESIGN.md 6.1)
    melt_gain_threshold: float = 1.0  # melt needs absorbed flux above this x sky_loss x V_sky; 0 = off (3.9)
    meteorology: energy.Meteorology | None = None  # set: the surface energy balance replaces sky_loss (3.9)
    still_air_shelter_deg: float = 15.0  # theta_v: ventilation 1 - Sx / tan(theta_v) of the balance [deg]


@dataclass
class GrowthResult:
    """A grown field plus its history. Heights are relative to the initial mean surface [m]."""

    height: np.ndarray
    spacing: float
    snapshots: np.ndarray  # (S, N, N) [m]
    snapshot_days: np.ndarray  # (S,) simulated days at each snapshot
    relief_history: np.ndarray  # (days + 1,) RMS height after each day [m]
    sky_view: np.ndarray  # of the final field [-]
    melt: np.ndarray  # melt fraction w of the final field [-]
    daily_absorbed: np.ndarray  # absorbed shortwave of the last day, per true area [J m-2]
    clamp_fraction: float  # mean fraction of cells whose slope hit the clamp
    max_daily_change: float  # largest height change within one frozen-geometry period [m]
    timings: dict = field(default_factory=dict)


@dataclass
class PeriodLight:
    """What one frozen-geometry period's sun and sky give the field, whatever melts: each sun position's lit
    energy and sunward slopes (``beams``), the sky and terrain light per unit true area [J m-2], the gross
    absorbed flux per unit true area [J m-2], the period's daylight [s] and its flux time [s] (time integral
    of the horizontal incident flux over the reference flux)."""

    beams: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]  # (lit, p, q, sun vector)
    sky: np.ndarray
    terrain: np.ndarray
    absorbed: np.ndarray
    seconds: float
    flux_seconds: float
    moments: list[tuple[float, np.ndarray]] = field(default_factory=list)  # (duration [s], direct + sky [J m-2])

    def absorbed_at_each_sun(self, albedo: float) -> list[tuple[float, np.ndarray]]:
        """Each sun position's duration [s] and absorbed energy per unit true area [J m-2]. The terrain light
        a cell gathers comes from the whole field, so each position takes the share of it that its field-mean
        direct + sky light has of the period's (exact for the period's sum)."""
        total = float(sum(float(np.mean(incident)) for _, incident in self.moments))
        parts = []
        for duration, incident in self.moments:
            share = float(np.mean(incident)) / total if total > 0 else 0.0
            parts.append((duration, (1.0 - albedo) * (incident + share * self.terrain)))
        return parts


def _period_light(
    h: np.ndarray,
    spacing: float,
    s: GrowthSettings,
    sun: sunpath.DailySun,
    chunk: np.ndarray,
    horizons: irradiance.Horizons,
) -> PeriodLight:
    """The period's light (``PeriodLight``); it does not depend on the melt fraction, so the net-gain gate
    (3.9) reads its ``absorbed`` before the melt fraction is settled."""
    direct = np.zeros_like(h)  # per true area
    sky = np.zeros_like(h)
    flux_seconds = 0.0
    beams = []
    moments: list[tuple[float, np.ndarray]] = []
    slopes = OneSidedSlopes.of(h, spacing, s.slope_order)  # the geometry is frozen for the period
    for j in chunk:
        vector, duration = sun.vectors[j], float(sun.durations[j])
        elevation = float(np.arcsin(vector[2]))
        s_b, s_d = s.sky.direct_normal(elevation), s.sky.diffuse_horizontal(elevation)
        flux_seconds += duration * (s_b * np.sin(elevation) + s_d) / s.scattered_reference_flux
        p, q = sunward_of(slopes, vector, s.max_slope_deg)
        lit = duration * s_b * irradiance.sun_visibility(h, spacing, vector)
        beams.append((lit, p, q, vector))
        direct_now = lit * direct_beam_lowering(p, q, vector) / np.sqrt(1.0 + p * p + q * q)
        sky_now = duration * s_d * horizons.sky_view
        moments.append((duration, direct_now + sky_now))
        direct += direct_now
        sky += sky_now
    terrain = irradiance.bounce_terrain_light(direct + sky, s.albedo, spacing, horizons, s.bounces)
    absorbed = (1.0 - s.albedo) * (direct + sky + terrain)
    return PeriodLight(beams, sky, terrain, absorbed, float(sun.durations[chunk].sum()), flux_seconds, moments)


def _period_energy(
    light: PeriodLight, s: GrowthSettings, inverse_heat: np.ndarray, kept: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The period's light split for the recession step: the direct beam per unit horizontal area, already
    weighted by 1/L_eff over the surface it hits (direct_beam_mass) [kg m-2], and the sky + terrain light per
    unit true area [J m-2], both absorbed and scaled by ``kept``, the share of the absorbed energy that ablates."""
    absorptance = 1.0 - s.albedo
    direct_mass = np.zeros_like(light.sky)  # per horizontal area, times 1/L_eff
    for lit, p, q, vector in light.beams:
        direct_mass += lit * direct_beam_mass(p, q, vector, inverse_heat)
    return absorptance * direct_mass * kept, absorptance * (light.sky + light.terrain) * kept


def constant_loss_kept(
    light: PeriodLight, s: GrowthSettings, sun: sunpath.DailySun, horizons: irradiance.Horizons, melt: np.ndarray
) -> np.ndarray:
    """Share of the period's absorbed energy above the constant loss to the sky (DESIGN.md 3.8): the whole day's
    (24 h) sky_loss, shared among the day's periods by their daylight, times V_sky, its turbulent share
    stopping where the air is still (melt fraction ``melt``)."""
    share = light.seconds / float(sun.durations.sum())
    ventilated = 1.0 - s.turbulent_share * melt
    sink = s.sky_loss * sunpath.SECONDS_PER_DAY * share * horizons.sky_view * ventilated
    return net_energy_fraction(light.absorbed, sink)


def ventilation(horizons: irradiance.Horizons, s: GrowthSettings) -> np.ndarray:
    """Share of the open field's wind that reaches each cell [-]: clip(1 - Sx / tan(theta_v), 0, 1) from the
    shelter index Sx of the horizons (DESIGN.md 3.9, *Ventilation*)."""
    return 1.0 - sheltered_melt_fraction(horizons.shelter, s.still_air_shelter_deg)


# Balance solves per period: consecutive sun positions share one, at their mean absorbed flux (DESIGN.md 3.9).
BALANCE_STEPS_PER_PERIOD = 2


def balance_split(
    light: PeriodLight, s: GrowthSettings, horizons: irradiance.Horizons
) -> tuple[np.ndarray, np.ndarray]:
    """The surface energy balance of a daylight period (DESIGN.md 3.9, *Surface energy balance*) as the growth
    loop's two fields: the share of the absorbed energy that ablates, (melt + sublimation energy) / absorbed, and
    the melt fraction w of that energy; then k (1/L_eff) Q = melt / L_f + sublimation / L_s. The balance is solved
    BALANCE_STEPS_PER_PERIOD times through the period's sun positions, each at their mean absorbed flux, with the
    cell's sky view and ventilation: melt is a threshold, and the midday flux crosses it where the day's mean
    would not."""
    assert s.meteorology is not None
    draft = ventilation(horizons, s)
    melt_energy, sublimation_energy = np.zeros_like(light.absorbed), np.zeros_like(light.absorbed)
    moments = light.absorbed_at_each_sun(s.albedo)
    for group in np.array_split(np.arange(len(moments)), min(BALANCE_STEPS_PER_PERIOD, len(moments))):
        duration = sum(moments[j][0] for j in group)
        absorbed = sum(moments[j][1] for j in group)
        state = energy.surface_state(absorbed / duration, horizons.sky_view, draft, s.meteorology)
        melt_energy += state.melt_flux * duration
        sublimation_energy += state.sublimation_flux * duration
    total = melt_energy + sublimation_energy
    kept = np.divide(total, light.absorbed, out=np.zeros_like(total), where=light.absorbed > 0)
    if not s.melt_enabled:
        return kept, np.zeros_like(total)
    return kept, np.divide(melt_energy, total, out=np.zeros_like(total), where=total > 0)


def night_lowering(
    h: np.ndarray, spacing: float, s: GrowthSettings, horizons: irradiance.Horizons, seconds: float
) -> np.ndarray:
    """Lowering [m] by the night's sublimation (DESIGN.md 3.9, *Night*): no shortwave, each cell's balance at
    its sky view and ventilation for ``seconds``, per unit true area and so times the Godunov area factor."""
    assert s.meteorology is not None
    state = energy.surface_state(0.0, horizons.sky_view, ventilation(horizons, s), s.meteorology)
    area, _ = surface_inverse_latent_heat(h, spacing, np.ones_like(h), s.max_slope_deg, s.slope_order)
    return s.ablation_efficiency / s.density * state.mass_rate() * seconds * area


def grow_field(
    h0: np.ndarray,
    spacing: float,
    settings: GrowthSettings,
    rng: np.random.Generator,
    progress: Callable[[int], object] | None = None,
) -> GrowthResult:
    """Grow a field from ``h0`` over ``settings.days`` days of sun (DESIGN.md section 5)."""
    import time

    h = irradiance.check_height_field(h0, "initial height field").copy()
    s = settings
    snapshot_every = max(1, int(np.ceil(s.days / max(1, s.snapshots - 1))))
    snapshots, snapshot_days = [h.copy()], [0.0]
    relief = [float(h.std())]
    clamp_sum, clamp_count, max_change = 0.0, 0, 0.0
    timings = {"horizons_s": 0.0, "radiation_s": 0.0, "update_s": 0.0}
    horizons, absorbed, melt = None, np.zeros_like(h), np.zeros_like(h)
    transfer = penetration_filter(h.shape[0], spacing, s.efolding_depth) if s.efolding_depth > 0 else None
    for day in range(s.days):
        sun = sunpath.daily_sun_positions(s.latitude, s.start_day_of_year + day, s.sun_positions_per_day)
        for chunk in np.array_split(np.arange(len(sun.durations)), s.refreshes_per_day):
            if chunk.size == 0:
                continue
            t0 = time.perf_counter()
            horizons = irradiance.compute_horizons(
                h, spacing, s.azimuths, rotation=rng.uniform(0, 2 * np.pi), wake_slope=s.wake_slope
            )
            t1 = time.perf_counter()
            light = _period_light(h, spacing, s, sun, chunk, horizons)
            absorbed, flux_seconds = light.absorbed, light.flux_seconds
            if s.meteorology is not None:
                kept, melt = balance_split(light, s, horizons)
            else:
                melt = switch_melt_fraction(horizons, s) if s.melt_enabled else np.zeros_like(h)
                if s.melt_gain_threshold > 0:
                    gate = net_gain_gate(absorbed, light.seconds, horizons.sky_view, s.sky_loss, s.melt_gain_threshold)
                    melt = melt * gate
            # Absorbed light warms the ice over the e-folding depth: the melting state varies over l, not per cell.
            melt = np.clip(spread_by_penetration(melt, transfer), 0.0, 1.0)
            if s.meteorology is None:
                kept = constant_loss_kept(light, s, sun, horizons, melt)
            inverse_heat = inverse_latent_heat(melt)
            direct_mass, diffuse = _period_energy(light, s, inverse_heat, kept)
            # All light is absorbed over l below the surface and spreads as far sideways, so no feature
            # narrower than l ablates apart from its surroundings (DESIGN.md 3.10, 7 Grid convergence).
            direct_mass = np.maximum(spread_by_penetration(direct_mass, transfer), 0.0)
            diffuse = np.maximum(spread_by_penetration(diffuse, transfer), 0.0)
            t2 = time.perf_counter()
            volume_per_mass = s.ablation_efficiency / s.density  # [m3 kg-1]
            h_before = h.copy()
            surface_heat, clamped = surface_inverse_latent_heat(
                h, spacing, inverse_heat, s.max_slope_deg, s.slope_order
            )
            lowering = volume_per_mass * (direct_mass + diffuse * surface_heat)
            substeps = max(1, int(np.ceil(float(np.max(lowering)) / (s.cfl * spacing))))
            for step in range(substeps):
                if step:
                    surface_heat, clamped = surface_inverse_latent_heat(
                        h, spacing, inverse_heat, s.max_slope_deg, s.slope_order
                    )
                    lowering = volume_per_mass * (direct_mass + diffuse * surface_heat)
                h -= lowering / substeps
                clamp_sum, clamp_count = clamp_sum + clamped, clamp_count + 1
            # Linear terms run on flux time, like A_B, so the selected band stays lambda* = 4 pi D / A_B.
            h = spectral_linear_step(
                h, spacing, flux_seconds, s.scattered_coefficient, s.diffusivity, s.hyperdiffusivity, s.efolding_depth
            )
            irradiance.check_height_field(h, f"height field after day {day + 1}")
            change = h - h_before
            max_change = max(max_change, float(change.max() - change.min()))
            t3 = time.perf_counter()
            for key, dt in zip(timings, (t1 - t0, t2 - t1, t3 - t2)):
                timings[key] += dt
        if s.meteorology is not None and horizons is not None:
            night = sunpath.SECONDS_PER_DAY - float(sun.durations.sum())
            if night > 0:
                h = h - spread_by_penetration(night_lowering(h, spacing, s, horizons, night), transfer)
        relief.append(float(h.std()))
        if (day + 1) % snapshot_every == 0 or day + 1 == s.days:
            snapshots.append(h.copy())
            snapshot_days.append(float(day + 1))
        if progress is not None:
            progress(1)
    if horizons is None:
        horizons = irradiance.compute_horizons(h, spacing, s.azimuths)
    return GrowthResult(
        height=h,
        spacing=spacing,
        snapshots=np.array(snapshots),
        snapshot_days=np.array(snapshot_days),
        relief_history=np.array(relief),
        sky_view=horizons.sky_view,
        melt=melt,
        daily_absorbed=absorbed,
        clamp_fraction=clamp_sum / max(clamp_count, 1),
        max_daily_change=max_change,
        timings=timings,
    )


FLAT_LOWERING_FLOOR = 1e-4  # [m]: a season that lowers flat ground by less than this ablates next to nothing


def flat_season_lowering(settings: GrowthSettings, spacing: float) -> float:
    """How far the season lowers flat ground [m]: the growth model itself on a small flat field, which is
    unshaded, open to the whole sky and unsheltered (so it sublimates), 0.1-0.4 s a season."""
    flat = grow_field(np.zeros((8, 8)), spacing, replace(settings, snapshots=2), np.random.default_rng(0))
    return float(-flat.height.mean())


def energy_warnings(cfg) -> list[str]:
    """Why a config's season may grow nothing: its loss to the sky takes all that flat ground absorbs
    (DESIGN.md 7, *Limits*: the Rio Blanco preset). Returns the warnings, empty when the ground ablates."""
    lowering = flat_season_lowering(settings_from_config(cfg), cfg.spacing)
    if lowering >= FLAT_LOWERING_FLOOR:
        return []
    if cfg.meteorology is not None:
        met = cfg.meteorology
        loss = (
            f"under geometry.meteorology (air {met.air_temperature:g} C, vapour {met.vapour_pressure:g} hPa, wind "
            f"{met.wind_speed:g} m/s) the longwave and turbulent losses take"
        )
        fix = "Check the site's forcing, the albedo and the season"
    else:
        loss = f"geometry.sky_loss = {cfg.sky_loss:g} W m-2 takes"
        fix = "Set geometry.meteorology for the site's air (the surface energy balance), or check the albedo and the season"
    return [
        f"flat ground loses {1000 * max(0.0, lowering):.2g} mm over the {cfg.days}-day season: {loss} nearly all "
        f"that a surface of geometry.albedo = {cfg.albedo:g} absorbs at geometry.latitude = {cfg.latitude:g} from day "
        f"{cfg.start_day_of_year}, so the field will barely grow. {fix} (geometry/DESIGN.md 7, Limits)"
    ]


def config_warnings(cfg) -> list[str]:
    """Everything ``pipeline validate`` and the geometry stage warn about in a GeometryConfig: cells too coarse for
    its lengths (``resolution_warnings``) and a season that cannot ablate (``energy_warnings``)."""
    return [*cfg.resolution_warnings(), *energy_warnings(cfg)]


def settings_from_config(cfg) -> GrowthSettings:
    """GrowthSettings from a GeometryConfig (pipeline.schema.geometry)."""
    return GrowthSettings(
        latitude=cfg.latitude,
        start_day_of_year=cfg.start_day_of_year,
        days=cfg.days,
        sun_positions_per_day=cfg.sun_positions_per_day,
        refreshes_per_day=cfg.horizon_refreshes_per_day,
        sky=Sky(cfg.direct_normal_irradiance, cfg.optical_depth, cfg.diffuse_fraction),
        albedo=cfg.albedo,
        density=cfg.density,
        ablation_efficiency=cfg.ablation_efficiency,
        melt_enabled=cfg.melt_enabled,
        switch_centre=cfg.switch_centre,
        switch_width=cfg.switch_width,
        switch_proxy=cfg.switch_proxy,
        shelter_full_melt_deg=cfg.shelter_full_melt_deg,
        wake_slope=cfg.wake_slope,
        turbulent_share=cfg.turbulent_loss_share,
        melt_gain_threshold=cfg.melt_gain_threshold,
        efolding_depth=cfg.optical_efolding_depth,
        diffusivity=cfg.diffusivity,
        hyperdiffusivity=cfg.hyperdiffusivity,
        scattered_coefficient=cfg.scattered_light_coefficient,
        scattered_reference_flux=cfg.scattered_light_reference_flux,
        azimuths=cfg.azimuths,
        bounces=cfg.bounces,
        max_slope_deg=cfg.max_slope_deg,
        sky_loss=cfg.sky_loss,
        meteorology=meteorology_from_config(cfg.meteorology),
        still_air_shelter_deg=(
            cfg.meteorology.still_air_shelter_deg if cfg.meteorology else GrowthSettings.still_air_shelter_deg
        ),
        cfl=cfg.cfl,
        snapshots=cfg.snapshots,
        slope_order=cfg.slope_order,
    )


def meteorology_from_config(met) -> energy.Meteorology | None:
    """energy.Meteorology in SI units from a MeteorologyConfig (degC, hPa), or None."""
    if met is None:
        return None
    return energy.Meteorology(
        air_temperature=met.air_temperature + energy.MELTING_POINT,
        vapour_pressure=met.vapour_pressure * 100.0,
        wind_speed=met.wind_speed,
        cloud_fraction=met.cloud_fraction,
        air_pressure=met.air_pressure * 100.0,
        measurement_height=met.measurement_height,
        roughness_length=met.roughness_length,
        scalar_roughness_length=met.scalar_roughness_length,
        surface_emissivity=met.surface_emissivity,
    )
