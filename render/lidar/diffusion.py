"""Time-resolved diffusion theory of a half-space lit by a laser pulse (LIDAR.md §3).

A pencil beam (or a Gaussian footprint) falls at normal incidence on a semi-infinite, index-matched medium.
Photons start as an isotropic point source at depth z0 = 1/σ_s′ (one transport mean free path); an image
source of opposite sign at −(z0 + 2 z_b) makes the fluence vanish on the extrapolated boundary z = −z_b
(z_b = 0: the zero boundary of Patterson, Chance & Wilson 1989; z_b = 2AD: Contini, Martelli & Zaccanti 1997,
Kienle & Patterson 1997, the m = 0 term). D = 1/(3σ_s′) (Contini's convention).

Time is path length. Snow is grains of ice in air with index-matched boundaries, so light moves at c and a
photon that has travelled L metres in the snow is L metres of OPL late. Every quantity here is a function of
L and a density per metre of path, for one unit of incident energy:

    reflectance(medium, rho, L)        R(ρ, L) = J(ρ, z=0, L), the outward flux  [m⁻² per m of path]
    fluence(medium, rho, L, depth)     φ(ρ, z, L)                                 [m⁻² per m of path]
    radiance(medium, rho, L, cos)      P1 radiance φ/(4π) + 3 J cosθ/(4π)          [m⁻² sr⁻¹ per m of path]
    total_reflectance(medium, L)       ∫ R dA, closed form                         [per m of path]
    total_fluence(medium, L)           ∫ φ(z=0) dA, closed form                    [per m of path]
    reflectance_time_integral(medium)  ∫ R(L) dL                                   [-]
    mean_path_length(medium)           ⟨L⟩ of the reflected light                  [m]
    mode_path_length(medium)           where R(L) peaks                            [m]
    late_time_log_slope(medium, L)     d ln R/dL → −3/(2L) − σ_a                   [m⁻¹]
    bin_average(function, axis...)     the mean of any of these over the bins of a film axis

``beam_radius`` (the 1/e² intensity radius w of a Gaussian footprint, exp(−2r²/w²)) turns the pencil-beam
quantities into footprint averages in closed form: the only ρ-dependence is the Gaussian exp(−ρ²/(4DL)), and
a Gaussian convolved with a Gaussian is a Gaussian (LIDAR.md §3.4).

Diffusion is wrong within a few ℓ* of the entry point and for L below a few ℓ*; compare renders past that.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import brentq

Boundary = Literal["zero", "extrapolated"]
BOUNDARIES = ("zero", "extrapolated")


@dataclass(frozen=True)
class DiffusionMedium:
    """A homogeneous, index-matched half-space in the diffusion approximation (LIDAR.md §3.1).

    ``reduced_scattering`` σ_s′ and ``absorption`` σ_a are in m⁻¹. ``boundary`` is ``zero`` (φ = 0 on the
    surface) or ``extrapolated`` (φ = 0 at z = −z_b, z_b = 2AD); ``boundary_coefficient`` is A, 1 for snow
    (grains in air: no interface to reflect light back in).
    """

    reduced_scattering: float
    absorption: float
    boundary: Boundary = "extrapolated"
    boundary_coefficient: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.reduced_scattering) and self.reduced_scattering > 0):
            raise ValueError(
                f"reduced_scattering must be a positive number of m^-1, got {self.reduced_scattering}; "
                "take sigma_s' from render.lidar.optics.snow_coefficients"
            )
        if not (math.isfinite(self.absorption) and self.absorption >= 0):
            raise ValueError(f"absorption must be a non-negative number of m^-1, got {self.absorption}")
        if self.boundary not in BOUNDARIES:
            raise ValueError(f"boundary must be 'zero' or 'extrapolated', got {self.boundary!r}")
        if not (math.isfinite(self.boundary_coefficient) and self.boundary_coefficient > 0):
            raise ValueError(
                f"boundary_coefficient A must be positive (1 for an index-matched surface), got {self.boundary_coefficient}"
            )

    @property
    def diffusion_coefficient(self) -> float:
        """D = 1/(3σ_s′) [m] (Contini's convention: without σ_a)."""
        return 1.0 / (3.0 * self.reduced_scattering)

    @property
    def source_depth(self) -> float:
        """z0 = 1/σ_s′ = ℓ* [m], the depth of the equivalent isotropic source."""
        return 1.0 / self.reduced_scattering

    @property
    def extrapolation_length(self) -> float:
        """z_b = 2AD for the extrapolated boundary, 0 for the zero boundary [m]."""
        if self.boundary == "zero":
            return 0.0
        return 2.0 * self.boundary_coefficient * self.diffusion_coefficient

    @property
    def image_depth(self) -> float:
        """z0 + 2z_b [m]: the image source sits at −(z0 + 2z_b)."""
        return self.source_depth + 2.0 * self.extrapolation_length

    @property
    def effective_attenuation(self) -> float:
        """μ_eff = √(σ_a/D) = √(3σ_aσ_s′) [m⁻¹]."""
        return math.sqrt(self.absorption / self.diffusion_coefficient)


def _positive_paths(path_length) -> tuple[np.ndarray, np.ndarray]:
    """(L with non-positive entries replaced by 1, mask of positive entries): light has not arrived at L ≤ 0."""
    path = np.asarray(path_length, dtype=np.float64)
    arrived = path > 0
    return np.where(arrived, path, 1.0), arrived


def _lateral_gaussian(rho, spread: np.ndarray, beam_radius: float) -> np.ndarray:
    """exp(−ρ²/s) for a pencil beam, or its convolution with the normalised footprint (2/(πw²)) exp(−2r²/w²):
    (s/(s + w²/2)) exp(−ρ²/(s + w²/2)), s = 4DL (LIDAR.md §3.4)."""
    if not (math.isfinite(beam_radius) and beam_radius >= 0):
        raise ValueError(f"beam_radius (1/e^2 intensity radius) must be >= 0 m, got {beam_radius}")
    widened = spread + 0.5 * beam_radius**2
    rho = np.asarray(rho, dtype=np.float64)
    return spread / widened * np.exp(-(rho**2) / widened)


def fluence(medium: DiffusionMedium, rho, path_length, depth=0.0, *, beam_radius: float = 0.0) -> np.ndarray:
    """φ(ρ, z, L) of the dipole at depth ``depth`` z [m] (positive into the snow), per metre of path [m⁻³].

    φ = (4πDL)^(−3/2) e^(−σ_a L) [exp(−(z − z0)²/(4DL)) − exp(−(z + z0 + 2z_b)²/(4DL))] · exp(−ρ²/(4DL)),
    zero for L ≤ 0. With ``beam_radius`` > 0 the last factor is the footprint average (module docstring).
    """
    path, arrived = _positive_paths(path_length)
    d = medium.diffusion_coefficient
    spread = 4.0 * d * path
    z = np.asarray(depth, dtype=np.float64)
    dipole = np.exp(-((z - medium.source_depth) ** 2) / spread) - np.exp(-((z + medium.image_depth) ** 2) / spread)
    value = (
        (np.pi * spread) ** -1.5
        * np.exp(-medium.absorption * path)
        * dipole
        * _lateral_gaussian(rho, spread, beam_radius)
    )
    return np.where(arrived, value, 0.0)


def reflectance(medium: DiffusionMedium, rho, path_length, *, beam_radius: float = 0.0) -> np.ndarray:
    """R(ρ, L) = J = D ∂φ/∂z at z = 0, the flux leaving the surface per metre of path [m⁻³] (LIDAR.md §3.2).

    R = ½ (4πD)^(−3/2) L^(−5/2) e^(−σ_a L) [z0 exp(−r1²/(4DL)) + (z0 + 2z_b) exp(−r2²/(4DL))],
    r1² = ρ² + z0², r2² = ρ² + (z0 + 2z_b)²; with z_b = 0 it is Patterson's (4πD)^(−3/2) z0 L^(−5/2) ….
    In seconds: R_t = c R evaluated at L = ct.
    """
    path, arrived = _positive_paths(path_length)
    d = medium.diffusion_coefficient
    spread = 4.0 * d * path
    z0, z2 = medium.source_depth, medium.image_depth
    dipole = z0 * np.exp(-(z0**2) / spread) + z2 * np.exp(-(z2**2) / spread)
    value = (
        0.5
        * (4.0 * np.pi * d) ** -1.5
        * path**-2.5
        * np.exp(-medium.absorption * path)
        * dipole
        * _lateral_gaussian(rho, spread, beam_radius)
    )
    return np.where(arrived, value, 0.0)


def radiance(medium: DiffusionMedium, rho, path_length, cos_theta=1.0, *, beam_radius: float = 0.0) -> np.ndarray:
    """Radiance leaving the surface at cos θ from the normal, P1 approximation [m⁻³ sr⁻¹] (LIDAR.md §3.3).

    L(θ) = φ(ρ, 0, L)/(4π) + 3 J cos θ/(4π): what a camera looking straight down (cos θ = 1) sees.
    """
    cos_theta = np.asarray(cos_theta, dtype=np.float64)
    if np.any((cos_theta < 0) | (cos_theta > 1)):
        raise ValueError("cos_theta must lie in [0, 1] (directions leaving the surface)")
    phi = fluence(medium, rho, path_length, 0.0, beam_radius=beam_radius)
    flux = reflectance(medium, rho, path_length, beam_radius=beam_radius)
    return phi / (4.0 * np.pi) + 3.0 * flux * cos_theta / (4.0 * np.pi)


def total_reflectance(medium: DiffusionMedium, path_length) -> np.ndarray:
    """R(L) = ∫ R(ρ, L) 2πρ dρ per metre of path [m⁻¹], the same for any footprint (LIDAR.md §3.5).

    R(L) = ½ (4πD)^(−1/2) L^(−3/2) e^(−σ_a L) [z0 exp(−z0²/(4DL)) + (z0 + 2z_b) exp(−(z0 + 2z_b)²/(4DL))].
    """
    path, arrived = _positive_paths(path_length)
    d = medium.diffusion_coefficient
    spread = 4.0 * d * path
    z0, z2 = medium.source_depth, medium.image_depth
    dipole = z0 * np.exp(-(z0**2) / spread) + z2 * np.exp(-(z2**2) / spread)
    value = 0.5 * (4.0 * np.pi * d) ** -0.5 * path**-1.5 * np.exp(-medium.absorption * path) * dipole
    return np.where(arrived, value, 0.0)


def total_fluence(medium: DiffusionMedium, path_length) -> np.ndarray:
    """∫ φ(ρ, 0, L) 2πρ dρ per metre of path [m⁻¹]: (4πDL)^(−1/2) e^(−σ_a L) [e^(−z0²/(4DL)) − e^(−z2²/(4DL))]."""
    path, arrived = _positive_paths(path_length)
    spread = 4.0 * medium.diffusion_coefficient * path
    z0, z2 = medium.source_depth, medium.image_depth
    value = (
        (np.pi * spread) ** -0.5
        * np.exp(-medium.absorption * path)
        * (np.exp(-(z0**2) / spread) - np.exp(-(z2**2) / spread))
    )
    return np.where(arrived, value, 0.0)


def late_time_log_slope(medium: DiffusionMedium, path_length) -> np.ndarray:
    """The asymptote of d ln R(L)/dL, −3/(2L) − σ_a [m⁻¹]; the exact slope adds O(z²/(DL²)) (LIDAR.md §3.5)."""
    path = np.asarray(path_length, dtype=np.float64)
    if np.any(path <= 0):
        raise ValueError("path_length must be positive for the late-time slope")
    return -1.5 / path - medium.absorption


def _dipole_weights(medium: DiffusionMedium) -> tuple[float, float, float, float]:
    """(z0, z2, e^(−μ z0), e^(−μ z2)) with μ = μ_eff."""
    mu = medium.effective_attenuation
    z0, z2 = medium.source_depth, medium.image_depth
    return z0, z2, math.exp(-mu * z0), math.exp(-mu * z2)


def reflectance_time_integral(medium: DiffusionMedium) -> float:
    """∫ R(L) dL [-], the steady diffuse reflectance of the beam (LIDAR.md §3.6).

    Zero boundary e^(−μ_eff z0); extrapolated ½ [e^(−μ_eff z0) + e^(−μ_eff (z0 + 2z_b))]; 1 without absorption.
    """
    _, _, e0, e2 = _dipole_weights(medium)
    return 0.5 * (e0 + e2)


def mean_path_length(medium: DiffusionMedium) -> float:
    """⟨L⟩ = ∫ L R dL / ∫ R dL [m] (LIDAR.md §3.6); range bias of a mean (centroid) estimator is ⟨L⟩/2.

    ⟨L⟩ = [z0 e^(−μ z0) + z2 e^(−μ z2)] / (2Dμ [e^(−μ z0) + e^(−μ z2)]), μ = μ_eff, z2 = z0 + 2z_b;
    zero boundary z0/(2Dμ) = 3/(2μ_eff); extrapolated → (3 + 2A)/(2μ_eff) as σ_a → 0.
    """
    if medium.absorption <= 0:
        raise ValueError("the mean path length is infinite without absorption; give absorption > 0 (m^-1)")
    z0, z2, e0, e2 = _dipole_weights(medium)
    mu = medium.effective_attenuation
    return (z0 * e0 + z2 * e2) / (2.0 * medium.diffusion_coefficient * mu * (e0 + e2))


def mode_path_length(medium: DiffusionMedium) -> float:
    """The path length at which R(L) peaks [m] (LIDAR.md §3.7); ≈ ℓ*/2 for the zero boundary.

    Zero boundary, closed form: σ_a L² + 3L/2 − z0²/(4D) = 0. Extrapolated: the root of d ln R/dL (brentq).
    Diffusion is not accurate this early (L ~ ℓ*): read it as an order of magnitude.
    """
    d = medium.diffusion_coefficient
    b0 = medium.source_depth**2 / (4.0 * d)
    zero_mode = 2.0 * b0 / (1.5 + math.sqrt(2.25 + 4.0 * medium.absorption * b0))
    if medium.boundary == "zero":
        return zero_mode
    z0, z2 = medium.source_depth, medium.image_depth
    b2 = z2**2 / (4.0 * d)

    def slope(path: float) -> float:
        # d ln R/dL, with the two exponentials scaled by the larger one (no underflow at small L).
        w0 = z0
        w2 = z2 * math.exp(-(b2 - b0) / path)
        return -1.5 / path - medium.absorption + (w0 * b0 + w2 * b2) / (path**2 * (w0 + w2))

    upper = 2.0 * b2 / 1.5
    return float(brentq(slope, 0.5 * zero_mode, upper, xtol=1e-15, rtol=1e-12))


def bin_average(
    function: Callable[[np.ndarray], np.ndarray],
    start_opl: float,
    bin_width_opl: float,
    temporal_bins: int,
    *,
    surface_opl: float = 0.0,
    nodes: int = 16,
) -> np.ndarray:
    """The mean of ``function(L)`` over each bin of a film axis, L = OPL − ``surface_opl`` (LIDAR.md §3.8).

    Bin k covers [start_opl + k w, start_opl + (k + 1) w); the mean is (1/w) ∫ over the bin, by Gauss–Legendre
    quadrature with ``nodes`` points per bin (the functions here are smooth, 0 before arrival). Multiply by w
    for mitransient-style bins (integrals over each bin, render/output/files.py ``FrameAxis``). ``function``
    maps an array of path lengths [m] to an array of the same shape; extra trailing axes are kept, so
    ``lambda L: reflectance(medium, rho[None, :], L[..., None])`` gives an array (temporal_bins, len(rho)).
    """
    if not (math.isfinite(bin_width_opl) and bin_width_opl > 0):
        raise ValueError(f"bin_width_opl must be positive (m of OPL), got {bin_width_opl}")
    if temporal_bins < 1:
        raise ValueError(f"temporal_bins must be at least 1, got {temporal_bins}")
    if nodes < 1:
        raise ValueError(f"nodes (quadrature points per bin) must be at least 1, got {nodes}")
    x, weights = np.polynomial.legendre.leggauss(nodes)
    edges = start_opl + bin_width_opl * np.arange(temporal_bins)
    opl = edges[:, None] + 0.5 * bin_width_opl * (x[None, :] + 1.0)
    values = np.asarray(function(opl - surface_opl), dtype=np.float64)
    if values.shape[:2] != opl.shape:
        raise ValueError(
            f"function must return an array shaped like its argument {opl.shape} (plus trailing axes), got {values.shape}"
        )
    extra = (1,) * (values.ndim - 2)
    return 0.5 * np.sum(values * weights.reshape((1, nodes) + extra), axis=1)


__all__ = [
    "BOUNDARIES",
    "DiffusionMedium",
    "bin_average",
    "fluence",
    "late_time_log_slope",
    "mean_path_length",
    "mode_path_length",
    "radiance",
    "reflectance",
    "reflectance_time_integral",
    "total_fluence",
    "total_reflectance",
]
