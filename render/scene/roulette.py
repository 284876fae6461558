"""How much of the light a snow surface returns comes back late, counted in collisions, and so how deep a
renderer's Russian roulette may start before its estimate turns dark (render/core/DESIGN.md §12, *Roulette
depth from the medium*).

The model is exact transport in an isotropically scattering half-space, lit and seen along the normal:

- a path that returns after n collisions carries p_n ω^n of the light, ω the single-scattering albedo and
  p_n the share in a conservative medium (ω = 1): absorption only weighs each collision;
- the reflection's generating function is ω H(1; ω)² / 2 (Chandrasekhar's H function), and its leading
  singularity, -K √a with a = -ln ω, fixes the tail: p_n ≈ K / (2 √π) n^(-3/2) (a Tauberian argument;
  ``late_coefficient``);
- the share returning after more than N collisions is then K/(2√π) ∫ n^(-3/2) e^(-a n) dn from N + 1/2
  over the whole reflection (``late_share``). Normal light and view weigh late light most (the first
  collisions, which grazing light and views favour, carry the least of it), so other angles leave out less.

A medium with g ≠ 0 is mapped to it by similarity: one collision of the isotropic reduced medium (albedo
σ_s (1 - g) / (σ_s (1 - g) + σ_a)) stands for 1 / (1 - g) collisions of the full one.

A roulette that keeps a path with probability q at every collision from ``rr_depth`` on is unbiased, but a
render of M paths a pixel samples a path of n collisions with chance q^(n - rr_depth): past
n* = rr_depth + ln M / (-ln q) fewer than one path in M gets there, and a finite render misses the light
that returns later (``missed_share``). Mitsuba's volpath caps q at 0.95 (``MITSUBA_SURVIVAL_CAP``);
our path tracer at ``path_max_survival`` (0.999).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import optimize

MITSUBA_SURVIVAL_CAP = 0.95
# The share of light a depth chosen by ``auto_rr_depth`` may leave out: half the share above which a depth
# is reported as likely dark, so that an auto reference stays within 0.5 % of an unbounded one.
AUTO_MISSED_SHARE = 0.0025
DARK_WARNING_SHARE = 0.005
# No depth beyond this: the reference schema's bound.
MAX_RR_DEPTH = 1_000_000

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(200)
_MU = 0.5 * (_NODES + 1.0)  # Gauss-Legendre on [0, 1]
_MU_WEIGHTS = 0.5 * _WEIGHTS


@lru_cache(maxsize=256)
def h_function_at_one(albedo: float) -> float:
    """Chandrasekhar's H(1) for isotropic scattering of single-scattering ``albedo`` in (0, 1]: the equation
    1/H(μ) = √(1 - ω) + (ω/2) ∫ μ' H(μ') / (μ + μ') dμ' on 200 Gauss nodes, solved by Newton's method
    (H(1; 1) = 2.9078, Chandrasekhar 1960, Table XI). Its fixed-point iteration stalls at ω = 1 on a wrong root."""
    if not 0.0 < albedo <= 1.0:
        raise ValueError(f"single-scattering albedo must lie in (0, 1], got {albedo}")
    root = math.sqrt(1.0 - albedo)
    kernel = 0.5 * albedo * (_MU_WEIGHTS * _MU)[None, :] / (_MU[:, None] + _MU[None, :])

    def residual(h: np.ndarray) -> np.ndarray:
        return h * (root + kernel @ h) - 1.0

    def jacobian(h: np.ndarray) -> np.ndarray:
        return np.diag(root + kernel @ h) + h[:, None] * kernel

    h = optimize.fsolve(residual, np.full_like(_MU, 1.5), fprime=jacobian, xtol=1e-12)
    if np.max(np.abs(residual(h))) > 1e-10:
        raise ArithmeticError(f"the H equation did not converge at albedo {albedo}")
    return float(1.0 / (root + 0.5 * albedo * np.sum(_MU_WEIGHTS * _MU * h / (1.0 + _MU))))


def normal_reflection(albedo: float) -> float:
    """Radiance reflected along the normal of an isotropic half-space lit along the normal, per unit of
    the irradiance over π: ω H(1)² / 2 (Chandrasekhar's reflection function at μ = μ0 = 1) [-]."""
    return 0.5 * albedo * h_function_at_one(albedo) ** 2


@lru_cache(maxsize=1)
def late_coefficient() -> float:
    """K / (2 √π): the normal reflection of paths of n collisions in a conservative medium is this times
    n^(-3/2) for large n. K is read off ω H(1)² / 2 = R(1) - K √a + O(a), a = -ln ω, by Richardson on
    a = 10⁻⁶ and 4·10⁻⁶."""
    small = 1e-6
    r1 = normal_reflection(1.0)
    d1 = r1 - normal_reflection(math.exp(-small))
    d2 = r1 - normal_reflection(math.exp(-4 * small))
    k = (4 * d1 - d2) / (2 * math.sqrt(small))
    return k / (2 * math.sqrt(math.pi))


def _tail_integral(start: float, absorption: float) -> float:
    """∫ n^(-3/2) e^(-a n) dn from ``start`` to infinity, a = ``absorption`` ≥ 0."""
    if absorption <= 0.0:
        return 2.0 / math.sqrt(start)
    x = absorption * start
    return 2.0 * math.exp(-x) / math.sqrt(start) - 2.0 * math.sqrt(math.pi * absorption) * math.erfc(math.sqrt(x))


def late_share(collisions: float, albedo: float) -> float:
    """The share of the normal reflection of an isotropic half-space carried by paths of more than
    ``collisions`` collisions, at single-scattering ``albedo`` [-]."""
    if collisions < 0:
        raise ValueError(f"collisions must be >= 0, got {collisions}")
    absorption = -math.log(albedo)
    start = max(collisions, 1.0) + 0.5
    share = late_coefficient() * _tail_integral(start, absorption) / normal_reflection(albedo)
    return min(1.0, share)


@dataclass(frozen=True)
class ReducedChannel:
    """One channel of a medium as the isotropic half-space of the model sees it."""

    albedo: float  # σ_s (1 - g) / (σ_s (1 - g) + σ_a) [-]
    collisions_per_step: float  # collisions of the rendered medium a reduced collision stands for: 1/(1 - g) [-]


def reduced_channels(sigma_s: Iterable[float], sigma_a: Iterable[float], g: Iterable[float]) -> list[ReducedChannel]:
    """Each channel of an HG medium (σ_s, σ_a [1/m], g as rendered), reduced by similarity."""
    out = []
    for s, a, gc in zip(sigma_s, sigma_a, g, strict=True):
        if s < 0 or a < 0 or not -1.0 < gc < 1.0:
            raise ValueError(f"need sigma_s >= 0, sigma_a >= 0 and -1 < g < 1, got {s}, {a}, {gc}")
        scattering = s * (1.0 - gc)
        total = scattering + a
        albedo = scattering / total if total > 0 else 0.0
        out.append(ReducedChannel(albedo=albedo, collisions_per_step=1.0 / (1.0 - gc)))
    return out


def reach(rr_depth: int, survival_cap: float, samples: int) -> float:
    """Collisions past which fewer than one in ``samples`` paths survive a roulette that starts at
    ``rr_depth`` and keeps a path with ``survival_cap`` per collision."""
    if not 0.0 < survival_cap < 1.0:
        raise ValueError(f"survival cap must lie in (0, 1), got {survival_cap}")
    return rr_depth + math.log(max(samples, 1)) / -math.log(survival_cap)


def missed_share(channel: ReducedChannel, rr_depth: int, survival_cap: float, samples: int) -> float:
    """The share of a channel's light that a render of ``samples`` paths a pixel misses with this roulette."""
    if channel.albedo <= 0.0:
        return 0.0
    return late_share(reach(rr_depth, survival_cap, samples) / channel.collisions_per_step, channel.albedo)


@dataclass(frozen=True)
class RouletteDepth:
    """A roulette depth and what it is expected to leave out."""

    rr_depth: int
    missed: float  # the largest expected share of light left out, over the media and channels [-]
    medium: str  # the medium and channel that set it, e.g. "snow (B)"


def worst_missed(
    media: dict[str, list[ReducedChannel]], rr_depth: int, survival_cap: float, samples: int
) -> tuple[float, str]:
    """The largest share any medium's channel misses at this depth, and which one."""
    worst, where = 0.0, ""
    for name, channels in media.items():
        for label, channel in zip("RGB", channels, strict=False):
            share = missed_share(channel, rr_depth, survival_cap, samples)
            if share > worst:
                worst, where = share, f"{name} ({label})"
    return worst, where


def auto_rr_depth(
    media: dict[str, list[ReducedChannel]],
    survival_cap: float = MITSUBA_SURVIVAL_CAP,
    samples: int = 1,
    target: float = AUTO_MISSED_SHARE,
    minimum: int = 5,
) -> RouletteDepth:
    """The smallest depth (two significant figures, at least ``minimum``) at which no medium's channel is
    expected to miss more than ``target`` of its light."""
    lo, hi = minimum, minimum
    while worst_missed(media, hi, survival_cap, samples)[0] > target:
        if hi >= MAX_RR_DEPTH:
            break
        lo, hi = hi, min(2 * hi, MAX_RR_DEPTH)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if worst_missed(media, mid, survival_cap, samples)[0] > target:
            lo = mid
        else:
            hi = mid
    depth = _round_up(hi)
    missed, where = worst_missed(media, depth, survival_cap, samples)
    return RouletteDepth(rr_depth=depth, missed=missed, medium=where)


def dark_reference(roulette: RouletteDepth) -> str | None:
    """The words every stage uses for a reference depth expected to leave out more than
    ``DARK_WARNING_SHARE`` of some light; None when it does not."""
    if roulette.missed <= DARK_WARNING_SHARE:
        return None
    return (
        f"reference is likely {100 * roulette.missed:.1f} % dark (roulette from collision {roulette.rr_depth}): it "
        f"is expected to leave out that share of the light of {roulette.medium}; set reference.rr_depth: auto"
    )


def _round_up(depth: int) -> int:
    """``depth`` rounded up to two significant figures (a depth one can read in a log)."""
    if depth < 100:
        return depth
    step = 10 ** (len(str(depth)) - 2)
    return -(-depth // step) * step
