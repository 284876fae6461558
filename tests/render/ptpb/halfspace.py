"""Exact diffuse reflection of a semi-infinite, index-matched medium with isotropic scattering
(Chandrasekhar 1960, Radiative Transfer, ch. IV): the closed-form reference of the dense-media tests
(render/core/DESIGN.md §12, "An exact check").

Under a collimated beam of irradiance E (on a plane facing it) arriving at μ0 = cos θ0, the radiance
leaving the surface at μ = cos θ, all orders of scattering included, is

    L(μ; μ0) = E ω μ0 / (4π (μ + μ0)) · H(μ) H(μ0),

with H Chandrasekhar's H-function of the single-scattering albedo ω. It depends on neither σ_t nor the
time axis, so one value checks a renderer at any density."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np


@lru_cache(maxsize=8)
def chandrasekhar_h(albedo: float, nodes: int = 400):
    """H(μ) for isotropic scattering of single-scattering albedo ``albedo`` < 1, from the fixed point
    1/H(μ) = √(1 − ω) + (ω/2) ∫₀¹ μ' H(μ') / (μ + μ') dμ' on Gauss–Legendre nodes (this form
    converges where the textbook one stalls as ω → 1). Returns a function of μ (array-like)."""
    if not 0 < albedo < 1:
        raise ValueError(f"albedo must lie in (0, 1), got {albedo}")
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu, w = 0.5 * (x + 1), 0.5 * w
    root = math.sqrt(1 - albedo)

    def inverse(at: np.ndarray, h: np.ndarray) -> np.ndarray:
        return root + 0.5 * albedo * ((w * mu * h)[None, :] / (at[:, None] + mu[None, :])).sum(axis=1)

    h = np.ones(nodes)
    for _ in range(100_000):
        new = 1.0 / inverse(mu, h)
        if np.max(np.abs(new - h)) < 1e-13:
            h = new
            break
        h = new
    else:
        raise RuntimeError(f"H-function iteration did not converge for albedo {albedo}")

    def H(at):
        at = np.asarray(at, dtype=np.float64)
        return (1.0 / inverse(at.reshape(-1), h)).reshape(at.shape)

    return H


def sky_reflected_radiance(albedo: float, mu):
    """Radiance leaving the surface at ``mu`` under a uniform sky of unit radiance: by reciprocity the
    albedo for incidence at μ, 1 − H(μ) √(1 − ω) (Chandrasekhar ch. IV; equal to 2π ∫ L(μ; μ0) dμ0 with
    L from ``reflected_radiance``, to 1e-13)."""
    return 1.0 - chandrasekhar_h(albedo)(np.asarray(mu, dtype=np.float64)) * math.sqrt(1 - albedo)


def reflected_radiance(albedo: float, mu, mu0: float, irradiance: float = 1.0):
    """L(μ; μ0) above, for an array of view cosines ``mu``."""
    H = chandrasekhar_h(albedo)
    mu = np.asarray(mu, dtype=np.float64)
    return irradiance * albedo * mu0 / (4 * math.pi * (mu + mu0)) * H(mu) * H(np.array(mu0))
