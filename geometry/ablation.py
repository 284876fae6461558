"""Radiative ablation of a periodic height field (penitentes.md 3.8-3.12, 5, 6).

    dh/dt = - eps Q / (rho L_eff) sqrt(1 + |grad h|^2) + D lap h - K lap^2 h  [+ A_B (-(-lap)^(1/2) h)]

Q is the absorbed shortwave per unit true area (geometry.irradiance), L_eff blends sublimation and
melt through Lliboutry's switch, and the linear terms are integrated exactly in Fourier space.
Time stepping freezes the geometry for each horizon refresh (one per simulated day by default),
integrates the absorbed energy over that period's sun positions, and applies it in sub-steps that
each respect the Hamilton-Jacobi CFL limit (6.2). Heights are [m], times [s].
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from geometry import irradiance, sunpath

log = logging.getLogger(__name__)

LATENT_HEAT_SUBLIMATION = 2.834e6  # L_s [J kg-1]
LATENT_HEAT_FUSION = 0.334e6  # L_f [J kg-1]


def wavenumbers(n: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Angular wavenumbers (kx, ky) [rad m-1] of an n x n periodic grid, for numpy's fft2 layout."""
    k = 2.0 * np.pi * np.fft.fftfreq(n, d=spacing)
    ky, kx = np.meshgrid(k, k, indexing="ij")
    return kx, ky


def linear_growth_rate(k: np.ndarray, scattered_coefficient: float, diffusivity: float,
                       hyperdiffusivity: float = 0.0) -> np.ndarray:
    """sigma(k) = A_B |k| - D k^2 - K k^4 [s-1] for |k| [rad m-1], A_B [m s-1], D [m2 s-1], K [m4 s-1]."""
    k = np.abs(k)
    return scattered_coefficient * k - diffusivity * k**2 - hyperdiffusivity * k**4


def spectral_linear_step(h: np.ndarray, spacing: float, duration: float, scattered_coefficient: float,
                         diffusivity: float, hyperdiffusivity: float) -> np.ndarray:
    """Exact (exponential-integrator) step of the linear terms over ``duration`` [s] (6.2).

    The Betterton term A_B|k| is weighted by ``duration`` as given; callers scale it by the flux.
    """
    kx, ky = wavenumbers(h.shape[0], spacing)
    sigma = linear_growth_rate(np.hypot(kx, ky), scattered_coefficient, diffusivity, hyperdiffusivity)
    spectrum = np.fft.fft2(h) * np.exp(sigma * duration)
    return np.real(np.fft.ifft2(spectrum))


def betterton_intensity_1d(h: np.ndarray, spacing: float, periods: int = 4) -> np.ndarray:
    """Scattered-light integral of penitentes.md 3.11 by direct quadrature on a periodic 1-D profile.

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


def inverse_latent_heat(melt: np.ndarray) -> np.ndarray:
    """1 / L_eff = w / L_f + (1 - w) / L_s [kg J-1]."""
    return melt / LATENT_HEAT_FUSION + (1.0 - melt) / LATENT_HEAT_SUBLIMATION


def godunov_slope_factor(h: np.ndarray, spacing: float, max_slope_deg: float) -> tuple[np.ndarray, float]:
    """Upwind sqrt(1 + |grad h|^2) for a surface receding along its normal (6.1), with the slope
    clamped at ``max_slope_deg``. Returns the factor and the fraction of cells clamped."""
    back_x = (h - np.roll(h, 1, axis=1)) / spacing
    fwd_x = (np.roll(h, -1, axis=1) - h) / spacing
    back_y = (h - np.roll(h, 1, axis=0)) / spacing
    fwd_y = (np.roll(h, -1, axis=0) - h) / spacing
    grad2 = (np.maximum(np.maximum(back_x, 0.0) ** 2, np.minimum(fwd_x, 0.0) ** 2)
             + np.maximum(np.maximum(back_y, 0.0) ** 2, np.minimum(fwd_y, 0.0) ** 2))
    limit2 = np.tan(np.radians(max_slope_deg)) ** 2
    clamped = grad2 > limit2
    return np.sqrt(1.0 + np.minimum(grad2, limit2)), float(clamped.mean())


def initial_height_field(n: int, spacing: float, rms: float, wavelength: float,
                         rng: np.random.Generator) -> np.ndarray:
    """Flat snow plus isotropic band-limited Gaussian noise [m] with RMS ``rms`` [m], its power
    centred on ``wavelength`` [m] (a Gaussian band of relative width 0.5 in |k|)."""
    kx, ky = wavenumbers(n, spacing)
    k = np.hypot(kx, ky)
    k0 = 2.0 * np.pi / wavelength
    band = np.exp(-0.5 * ((k - k0) / (0.5 * k0)) ** 2)
    band[0, 0] = 0.0
    noise = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((n, n))) * band))
    std = noise.std()
    if std == 0.0:
        raise ValueError("the seeded noise band is empty: geometry.initial_wavelength must be between "
                         "2 cells and the domain size")
    return noise * (rms / std)


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
    switch_proxy: str  # "sky_view" or "openness"
    diffusivity: float  # D [m2 s-1]
    hyperdiffusivity: float  # K [m4 s-1]
    scattered_coefficient: float  # A_B at the reference flux [m s-1]
    scattered_reference_flux: float  # [W m-2]
    azimuths: int
    bounces: int
    max_slope_deg: float
    cfl: float
    snapshots: int


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


def grow_field(h0: np.ndarray, spacing: float, settings: GrowthSettings, rng: np.random.Generator,
               progress: Callable[[int], None] | None = None) -> GrowthResult:
    """Grow a field from ``h0`` over ``settings.days`` days of sun (penitentes.md section 5)."""
    import time

    h = irradiance.check_height_field(h0, "initial height field").copy()
    s = settings
    n = h.shape[0]
    snapshot_every = max(1, int(np.ceil(s.days / max(1, s.snapshots - 1))))
    snapshots, snapshot_days = [h.copy()], [0.0]
    relief = [float(h.std())]
    clamp_sum, clamp_count, max_change = 0.0, 0, 0.0
    timings = {"horizons_s": 0.0, "shadows_s": 0.0, "bounces_s": 0.0, "update_s": 0.0}
    horizons, absorbed, melt = None, np.zeros_like(h), np.zeros_like(h)
    for day in range(s.days):
        sun = sunpath.daily_sun_positions(s.latitude, s.start_day_of_year + day, s.sun_positions_per_day)
        for chunk in np.array_split(np.arange(len(sun.durations)), s.refreshes_per_day):
            if chunk.size == 0:
                continue
            t0 = time.perf_counter()
            horizons = irradiance.compute_horizons(h, spacing, s.azimuths, rotation=rng.uniform(0, 2 * np.pi))
            t1 = time.perf_counter()
            normals = irradiance.unit_normals(h, spacing)
            primary = np.zeros_like(h)  # direct + sky energy per true area [J m-2]
            flux_seconds = 0.0  # time integral of horizontal incident flux / reference [s]
            for j in chunk:
                elevation = float(np.arcsin(sun.vectors[j, 2]))
                s_b, s_d = s.sky.direct_normal(elevation), s.sky.diffuse_horizontal(elevation)
                visible = irradiance.sun_visibility(h, spacing, sun.vectors[j])
                primary += sun.durations[j] * (s_b * np.clip(normals @ sun.vectors[j], 0, None) * visible
                                               + s_d * horizons.sky_view)
                flux_seconds += sun.durations[j] * (s_b * np.sin(elevation) + s_d) / s.scattered_reference_flux
            t2 = time.perf_counter()
            terrain = irradiance.bounce_terrain_light(primary, s.albedo, spacing, horizons, s.bounces)
            absorbed = (1.0 - s.albedo) * (primary + terrain)
            t3 = time.perf_counter()
            melt = (melt_fraction(horizons.sky_view if s.switch_proxy == "sky_view" else horizons.openness, s.switch_centre, s.switch_width)
                    if s.melt_enabled else np.zeros_like(h))
            recession = s.ablation_efficiency * absorbed * inverse_latent_heat(melt) / s.density  # along normal [m]
            h_before = h.copy()
            factor, clamped = godunov_slope_factor(h, spacing, s.max_slope_deg)
            substeps = max(1, int(np.ceil(float(np.max(recession * factor)) / (s.cfl * spacing))))
            for _ in range(substeps):
                factor, clamped = godunov_slope_factor(h, spacing, s.max_slope_deg)
                h -= recession / substeps * factor
                clamp_sum, clamp_count = clamp_sum + clamped, clamp_count + 1
            daylight = float(sun.durations[chunk].sum())
            h = spectral_linear_step(h, spacing, daylight, s.scattered_coefficient * flux_seconds / max(daylight, 1e-9),
                                     s.diffusivity, s.hyperdiffusivity)
            irradiance.check_height_field(h, f"height field after day {day + 1}")
            change = h - h_before
            max_change = max(max_change, float(change.max() - change.min()))
            t4 = time.perf_counter()
            for key, dt in zip(timings, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                timings[key] += dt
        relief.append(float(h.std()))
        if (day + 1) % snapshot_every == 0 or day + 1 == s.days:
            snapshots.append(h.copy())
            snapshot_days.append(float(day + 1))
        if progress is not None:
            progress(1)
    if horizons is None:
        horizons = irradiance.compute_horizons(h, spacing, s.azimuths)
    return GrowthResult(
        height=h, spacing=spacing, snapshots=np.array(snapshots), snapshot_days=np.array(snapshot_days),
        relief_history=np.array(relief), sky_view=horizons.sky_view, melt=melt, daily_absorbed=absorbed,
        clamp_fraction=clamp_sum / max(clamp_count, 1), max_daily_change=max_change, timings=timings,
    )


def settings_from_config(cfg) -> GrowthSettings:
    """GrowthSettings from a GeometryConfig (pipeline.schema.geometry)."""
    return GrowthSettings(
        latitude=cfg.latitude, start_day_of_year=cfg.start_day_of_year, days=cfg.days,
        sun_positions_per_day=cfg.sun_positions_per_day, refreshes_per_day=cfg.horizon_refreshes_per_day,
        sky=Sky(cfg.direct_normal_irradiance, cfg.optical_depth, cfg.diffuse_fraction),
        albedo=cfg.albedo, density=cfg.density, ablation_efficiency=cfg.ablation_efficiency,
        melt_enabled=cfg.melt_enabled, switch_centre=cfg.switch_centre, switch_width=cfg.switch_width,
        switch_proxy=cfg.switch_proxy, diffusivity=cfg.diffusivity, hyperdiffusivity=cfg.hyperdiffusivity,
        scattered_coefficient=cfg.scattered_light_coefficient,
        scattered_reference_flux=cfg.scattered_light_reference_flux, azimuths=cfg.azimuths,
        bounces=cfg.bounces, max_slope_deg=cfg.max_slope_deg, cfl=cfg.cfl, snapshots=cfg.snapshots,
    )
