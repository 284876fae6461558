"""Snow as grains: a packing of ice spheres traced exactly, against the homogenised medium (LIDAR.md §10).

The C++ core (render/core/src/grains.cpp, ``render._core.grains_*``) traces a nadir beam, photon by photon, through
a periodic packing of dielectric spheres: Fresnel reflection and refraction at every surface, absorption
exp(−γ ℓ) inside ice, time = air length + n_g × ice length. The same source, receivers and estimators run in a
homogeneous Henyey–Greenstein half-space. This module makes the packings, the homogenised presets with the
spheres' own shape factors, and the comparison:

    pack_spheres(φ, d)                     periodic non-overlapping monodisperse spheres up to φ ≈ 0.6
    homogenised_preset(ρ, d, λ, form)      σ_s, σ_a, g of the matching medium (``preset``, ``geometric``, ``isotropic``)
    trace_packing / trace_homogenised      one run each: time histograms, albedo, absorbed energy by depth, paths
    compare(packing, homogenised, ...)     mean delay, R(t) shape, albedo, e-folding depth, path fractions

Sphere shape factors (weak absorption, geometric optics; Bohren & Huffman 1983 §7; Kokhanovsky 2004; Libois et
al. 2014, The Cryosphere 8, 2157): B = n²[1 − (1 − 1/n²)^{3/2}] (1.253 at n = 1.3117), g = 0.89 with diffraction.
Without diffraction (a ray-traced packing has none) a sphere's extinction is half, 3φ/(2d), and its asymmetry
g_geo = 2g − 1 ≈ 0.78, so σ_s(1 − g) is the same.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from scipy.spatial import cKDTree

from render import _core
from render.lidar.optics import (
    ice_absorption_coefficient,
    ice_group_index,
    ice_refractive_index,
    snow_group_index,
)
from render.scene.optics import RHO_ICE

SPHERE_ASYMMETRY = 0.89  # g of a weakly absorbing ice sphere with diffraction (Libois et al. 2014)
PresetForm = Literal["preset", "geometric", "isotropic"]
PRESET_FORMS = ("preset", "geometric", "isotropic")


def sphere_absorption_enhancement(refractive_index: float) -> float:
    """B = n²[1 − (1 − 1/n²)^{3/2}]: a weakly absorbing sphere absorbs B γ V (Bohren & Huffman 1983 §7.2)."""
    n2 = refractive_index * refractive_index
    return n2 * (1.0 - (1.0 - 1.0 / n2) ** 1.5)


def _ice_sphere_enhancement(wavelength_nm: float) -> float:
    """B of an ice sphere at a laser line."""
    return sphere_absorption_enhancement(ice_refractive_index(wavelength_nm))


@dataclass(frozen=True)
class Packing:
    """N monodisperse spheres in a periodic cube of side ``cell_size`` [m]; centres in [0, Lc)³ [m]."""

    centres: np.ndarray
    radius: float
    cell_size: float
    seed: int

    @property
    def count(self) -> int:
        return int(self.centres.shape[0])

    @property
    def volume_fraction(self) -> float:
        return self.count * 4.0 / 3.0 * math.pi * self.radius**3 / self.cell_size**3

    @property
    def density(self) -> float:
        return self.volume_fraction * RHO_ICE

    def min_gap(self) -> float:
        """Smallest surface-to-surface distance over all pairs (periodic) [m]; ≥ 0 means no overlap."""
        tree = cKDTree(self.centres, boxsize=self.cell_size)
        dist, _ = tree.query(self.centres, k=2)
        return float(dist[:, 1].min() - 2.0 * self.radius)


def pack_spheres(
    volume_fraction: float,
    grain_diameter: float,
    count: int = 2000,
    seed: int = 0,
    *,
    max_iterations: int = 20000,
) -> Packing:
    """A random periodic packing of ``count`` spheres of diameter ``grain_diameter`` [m] at ``volume_fraction``.

    Random sequential addition jams near φ ≈ 0.38, so the centres start uniform and overlaps are pushed apart: every
    overlapping pair (cKDTree, periodic) moves apart by half its overlap, at a radius 0.5 % larger than the target
    and grown to it, until no pair overlaps at the target radius (Lubachevsky–Stillinger in spirit, without
    velocities). Deterministic for a seed. Reaches φ = 0.60 (random close packing is ≈ 0.64).
    """
    if not 0.0 < volume_fraction <= 0.62:
        raise ValueError(f"volume_fraction must lie in (0, 0.62] (random close packing ≈ 0.64), got {volume_fraction}")
    if not (grain_diameter > 0 and count >= 8):
        raise ValueError("grain_diameter must be positive and count at least 8")
    radius = 0.5 * grain_diameter
    cell = (count * 4.0 / 3.0 * math.pi * radius**3 / volume_fraction) ** (1.0 / 3.0)
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, cell, size=(count, 3))
    inflated = 2.0 * radius * 1.005
    for _ in range(max_iterations):
        tree = cKDTree(x, boxsize=cell)
        pairs = tree.query_pairs(inflated, output_type="ndarray")
        if pairs.size == 0:
            break
        delta = x[pairs[:, 1]] - x[pairs[:, 0]]
        delta -= cell * np.round(delta / cell)
        dist = np.linalg.norm(delta, axis=1)
        if dist.min() >= 2.0 * radius:
            break
        push = (0.5 * (inflated - dist) / np.maximum(dist, 1e-12 * cell))[:, None] * delta
        move = np.zeros_like(x)
        np.add.at(move, pairs[:, 1], push)
        np.add.at(move, pairs[:, 0], -push)
        x = np.mod(x + move, cell)
    else:
        raise ArithmeticError(
            f"pack_spheres: overlaps remain after {max_iterations} iterations at φ = {volume_fraction}; "
            "lower volume_fraction or raise max_iterations"
        )
    packing = Packing(centres=x, radius=radius, cell_size=cell, seed=seed)
    if packing.min_gap() < 0:
        raise ArithmeticError("pack_spheres: a pair still overlaps")
    return packing


@dataclass(frozen=True)
class HomogenisedSnow:
    """A homogeneous index-matched half-space: coefficients in m⁻¹."""

    scattering: float
    absorption: float
    asymmetry: float
    form: str

    @property
    def reduced_scattering(self) -> float:
        return self.scattering * (1.0 - self.asymmetry)

    @property
    def e_folding_depth(self) -> float:
        """Diffusion's 1/√(3 σ_a σ_s′) [m]."""
        return 1.0 / math.sqrt(3.0 * self.absorption * (self.reduced_scattering + self.absorption))


def homogenised_preset(
    density: float, grain_diameter: float, wavelength_nm: float = 532.0, form: PresetForm = "preset"
) -> HomogenisedSnow:
    """The homogenised medium of spheres of ``grain_diameter`` [m] at ``density`` [kg m⁻³] (module docstring).

    ``preset``: σ_e = 3φ/d and g = 0.89, the presets' form with diffraction; ``geometric``: σ_e = 3φ/(2d) and
    g_geo = 2g − 1, what the ray-traced packing itself scatters; ``isotropic``: σ_s′ of the preset with g = 0.
    σ_a = B γ φ in each, B of the sphere.
    """
    if form not in PRESET_FORMS:
        raise ValueError(f"form must be one of {PRESET_FORMS}, got {form!r}")
    phi = density / RHO_ICE
    b = _ice_sphere_enhancement(wavelength_nm)
    absorption = b * ice_absorption_coefficient(wavelength_nm) * phi
    extinction = 3.0 * phi / grain_diameter
    g = SPHERE_ASYMMETRY
    if form == "geometric":
        extinction, g = 0.5 * extinction, 2.0 * g - 1.0
    scattering = extinction - absorption
    if form == "isotropic":
        scattering, g = scattering * (1.0 - g), 0.0
    return HomogenisedSnow(scattering=scattering, absorption=absorption, asymmetry=g, form=form)


@dataclass(frozen=True)
class TraceSettings:
    """Source, receivers and binning shared by both tracers. OPL in metres, measured from a reflection off the
    plane z = 0 (the packing's plane of equal mass: half the grains' volume lies above it in the top layer)."""

    photons: int = 20000
    seed: int = 0
    start_opl: float = -2e-3
    bin_width_opl: float = 2e-4
    temporal_bins: int = 2000
    cone_half_angle: float = 0.2  # rad
    depth_bin_width: float = 2e-3  # m
    depth_bins: int = 1000
    max_path: float = 2000.0  # m of geometric path; past it a photon is counted as truncated
    threads: int = 1

    def kwargs(self) -> dict[str, Any]:
        return {
            "photons": self.photons,
            "seed": self.seed,
            "start_opl": self.start_opl,
            "bin_width_opl": self.bin_width_opl,
            "temporal_bins": self.temporal_bins,
            "cone_half_angle": self.cone_half_angle,
            "depth_bin_width": self.depth_bin_width,
            "depth_bins": self.depth_bins,
            "max_path": self.max_path,
            "threads": self.threads,
        }


@dataclass(frozen=True)
class Transient:
    """One run's per-photon sums (see render/_core.pyi, grains_trace_packing) and its binning."""

    settings: TraceSettings
    raw: dict[str, Any] = field(repr=False)

    def __getitem__(self, key: str) -> Any:
        return self.raw[key]

    def merged(self, other: Transient) -> Transient:
        """This run and ``other`` (same photon count and binning, another seed) as one: per-photon sums averaged."""
        if replace(self.settings, seed=0) != replace(other.settings, seed=0):
            raise ValueError("merged() takes two runs of the same photon count and binning")
        raw: dict[str, Any] = {}
        for key, value in self.raw.items():
            if key == "photons_done":
                raw[key] = value + other.raw[key]
            elif key == "cancelled":
                raw[key] = value or other.raw[key]
            else:
                raw[key] = (value + other.raw[key]) / 2.0
        return Transient(self.settings, raw)

    @property
    def bin_centres(self) -> np.ndarray:
        s = self.settings
        return s.start_opl + (np.arange(s.temporal_bins) + 0.5) * s.bin_width_opl

    @property
    def depth_centres(self) -> np.ndarray:
        return (np.arange(self.settings.depth_bins) + 0.5) * self.settings.depth_bin_width

    def window(self, end_opl: float) -> np.ndarray:
        """Bins whose centre lies below ``end_opl``."""
        return self.bin_centres < end_opl

    def mean_delay(self, end_opl: float, receiver: str = "flux") -> float:
        """Mean OPL [m] of the exits with OPL in [start_opl, end_opl): ``flux`` (all directions) or ``cone``."""
        w = self.window(end_opl)
        h = self.raw["time_flux" if receiver == "flux" else "time_cone"][w]
        return float(np.sum(h * self.bin_centres[w]) / np.sum(h))

    def cumulative(self, end_opl: float, receiver: str = "flux") -> np.ndarray:
        """The exits' distribution function over the window's bins, normalised within the window."""
        h = self.raw["time_flux" if receiver == "flux" else "time_cone"][self.window(end_opl)]
        return np.cumsum(h) / np.sum(h)

    def ice_per_air(self, end_opl: float | None = None) -> float:
        """Ice path over air path: of every photon (``end_opl`` None) or of the exits within the window."""
        if end_opl is None:
            return float(self.raw["ice_path"] / self.raw["air_path"])
        w = self.window(end_opl)
        return float(np.sum(self.raw["ice_by_bin"][w]) / np.sum(self.raw["air_by_bin"][w]))

    def e_folding_depth(self, fit_from: float, fit_to: float) -> float:
        """1/slope of ln(absorbed energy) against depth, least squares over depths in [fit_from, fit_to] [m]."""
        z = self.depth_centres
        a = self.raw["absorbed_depth"]
        keep = (z >= fit_from) & (z <= fit_to) & (a > 0)
        if keep.sum() < 3:
            raise ValueError(f"fewer than 3 non-empty depth bins in [{fit_from}, {fit_to}] m: widen the fit")
        slope = np.polyfit(z[keep], np.log(a[keep]), 1, w=np.sqrt(a[keep] / a[keep].max()))[0]
        return float(-1.0 / slope)


Progress = Callable[[int, int], bool | None] | None


def trace_packing(
    packing: Packing,
    settings: TraceSettings,
    wavelength_nm: float = 532.0,
    *,
    ice_absorption: float | None = None,
    progress: Progress = None,
) -> Transient:
    """Trace ``settings.photons`` into the packing (ice of ``wavelength_nm``; ``ice_absorption`` γ overrides)."""
    gamma = ice_absorption_coefficient(wavelength_nm) if ice_absorption is None else ice_absorption
    centres = packing.centres - np.array([0.0, 0.0, packing.cell_size])
    raw = _core.grains_trace_packing(
        centres=centres,
        radii=np.full(packing.count, packing.radius),
        cell_size=packing.cell_size,
        ice_index=ice_refractive_index(wavelength_nm),
        ice_group_index=ice_group_index(wavelength_nm),
        ice_absorption=gamma,
        progress=progress,
        **settings.kwargs(),
    )
    return Transient(settings, raw)


def trace_homogenised(
    medium: HomogenisedSnow, settings: TraceSettings, time_index: float = 1.0, *, progress: Progress = None
) -> Transient:
    """The same beam and receivers in ``medium``; OPL = ``time_index`` × path (1: index matched)."""
    raw = _core.grains_trace_homogeneous(
        scattering=medium.scattering,
        absorption=medium.absorption,
        asymmetry=medium.asymmetry,
        time_index=time_index,
        progress=progress,
        **settings.kwargs(),
    )
    return Transient(settings, raw)


def snow_clock(density: float, wavelength_nm: float = 532.0) -> float:
    """n_snow for spheres: render.lidar.optics.snow_group_index with the sphere's B."""
    b = _ice_sphere_enhancement(wavelength_nm)
    return snow_group_index(density, absorption_enhancement=b, wavelength_nm=wavelength_nm)


def compare(
    packing: Transient,
    homogenised: Transient,
    homogenised_clocked: Transient,
    *,
    density: float,
    window_opl: float,
    fit_depths: tuple[float, float],
    wavelength_nm: float = 532.0,
) -> dict[str, float]:
    """Packing against the homogenised medium, index matched and with the snow's clock (``homogenised_clocked``
    ran with time_index = snow_clock). Delays: mean OPL of the flux exits within [start_opl, window_opl);
    R(t) shape: Kolmogorov distance (largest gap between the distribution functions) within the window; e-folding
    depth: fit over ``fit_depths``; paths: ice over air path against B φ/(1 − φ), of all photons and of the exits in
    the window, and all photons' path per metre of homogenised path against 1 − φ + B φ."""
    phi = density / RHO_ICE
    b = _ice_sphere_enhancement(wavelength_nm)
    h_path = homogenised["air_path"]
    out = {
        "volume_fraction": phi,
        "snow_clock": snow_clock(density, wavelength_nm),
        "delay_packing": packing.mean_delay(window_opl),
        "delay_homogenised": homogenised.mean_delay(window_opl),
        "delay_clocked": homogenised_clocked.mean_delay(window_opl),
        "delay_packing_cone": packing.mean_delay(window_opl, "cone"),
        "delay_clocked_cone": homogenised_clocked.mean_delay(window_opl, "cone"),
        "shape_ks_homogenised": float(
            np.max(np.abs(packing.cumulative(window_opl) - homogenised.cumulative(window_opl)))
        ),
        "shape_ks_clocked": float(
            np.max(np.abs(packing.cumulative(window_opl) - homogenised_clocked.cumulative(window_opl)))
        ),
        "albedo_packing": packing["albedo"],
        "albedo_homogenised": homogenised["albedo"],
        "efold_packing": packing.e_folding_depth(*fit_depths),
        "efold_homogenised": homogenised.e_folding_depth(*fit_depths),
        "ice_per_air": packing.ice_per_air(),
        "ice_per_air_window": packing.ice_per_air(window_opl),
        "ice_per_air_expected": b * phi / (1.0 - phi),
        "path_per_path": (packing["air_path"] + packing["ice_path"]) / h_path,
        "path_per_path_expected": 1.0 - phi + b * phi,
        "truncated_packing": packing["truncated"],
    }
    out["delay_ratio_clocked"] = out["delay_packing"] / out["delay_clocked"]
    out["delay_ratio_homogenised"] = out["delay_packing"] / out["delay_homogenised"]
    out["efold_ratio"] = out["efold_packing"] / out["efold_homogenised"]
    return out


__all__ = [
    "PRESET_FORMS",
    "SPHERE_ASYMMETRY",
    "HomogenisedSnow",
    "Packing",
    "TraceSettings",
    "Transient",
    "compare",
    "homogenised_preset",
    "ice_refractive_index",
    "pack_spheres",
    "snow_clock",
    "sphere_absorption_enhancement",
    "trace_homogenised",
    "trace_packing",
]
