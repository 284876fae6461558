"""What two known variance reductions would gain on the dense cube's near-surface light, found on a model
before building them in the core (issue 28, render/core/DESIGN.md §12, *Near the lit face*).

The dense cube's error (bench_dense.py) is that of its bright early frames, light that enters the lit face and
comes back within a few tens of collisions, where no hop fits. The model is the cube's top face seen from its
camera: an isotropic half-space z < 0 in units of the mean free path (sigma_t = 1), albedo 0.9995, lit from
the zenith by a directional light (the cube's 0.5 m quad 1 m above its face subtends at most 20 degrees), and
a camera ray entering at the cube's cosine 0.61. A camera walk makes next-event estimates, each landing in the
time bin of its path length (bins of the cube's 0.0816 m, 32.6 mean free paths), with Russian roulette from
the 5th collision at a survival capped at 0.999 as the core's, and ends at the film's end. Each variant's
efficiency per bin is 1 / (relative variance x cost), the cost being the vertices made (each a flight and an
estimate); the table gives its relative variance x cost over that of the walk as the core makes it, averaged
over the frames holding over 1 % of the energy, in the first of them and over the late third of the film, and
the relative variance alone over the lit frames. The model makes every collision one by one: the core hops
across the balls that fit deep in the snow (render/core/DESIGN.md §12, *Hops*), so a gain that comes from
making fewer deep vertices is one the core has mostly taken already.

- ``dwivedi``: directions drawn from a mixture of the phase function and Dwivedi's guided density toward the
  lit face, p(mu) = 1 / (ln((nu + 1) / (nu - 1)) (nu - mu)) with nu the diffusion eigenvalue of the albedo,
  and flights stretched to sigma_t (1 - mu / nu) (Krivanek and d'Eon 2014), weighted by the mixture's pdf.
- ``ray_nee``: the estimate along the whole ray of a flight instead of at its collision (the expected value
  of the collision estimate), with its point drawn in proportion to the ray's transmittance times the light's
  (zero variance for the ray's integral under the zenith light of the model).
- both together.

Every variant is unbiased: the script prints each one's largest deviation from the core's walk per lit frame
in standard errors.

    python benchmarks/walk_model.py [--paths 200000] [--seeds 1 2]

Writes benchmarks/results/walk_model.md and .csv (results/local/ with other arguments than these defaults).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np
from _results import is_standard, start, write_results

ALBEDO = 0.9995
BIN_WIDTH = 32.6  # the cube's 0.0816 m of OPL in mean free paths (sigma_t = 400 per m)
BINS = 32
MU_IN = 0.61  # cosine of the cube camera's ray with the top face's normal
RR_DEPTH = 5
MAX_SURVIVAL = 0.999


def diffusion_eigenvalue(albedo: float) -> float:
    """nu0 > 1 with albedo nu0 atanh(1 / nu0) = 1: the decay of the deep field, exp(-z / nu0) for isotropic
    scattering."""
    lo, hi = 1.0 + 1e-12, 1e8
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if albedo * mid * math.atanh(1.0 / mid) > 1.0:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


@dataclass(frozen=True)
class Variant:
    name: str
    guide: float  # probability of drawing a direction from Dwivedi's density
    ray_nee: bool


VARIANTS = (
    Variant("core (phase sampling, estimate at each collision)", 0.0, False),
    Variant("dwivedi, mixture 0.5", 0.5, False),
    Variant("dwivedi, mixture 0.9", 0.9, False),
    Variant("ray_nee", 0.0, True),
    Variant("dwivedi 0.9 + ray_nee", 0.9, True),
)


def walk(variant: Variant, paths: int, seed: int, offset: float) -> tuple[np.ndarray, int]:
    """Per-path, per-bin scores (paths x BINS) and the vertices made. ``offset``: the path length the camera
    ray has within its first bin when it reaches the face."""
    rng = np.random.default_rng(seed)
    nu = diffusion_eigenvalue(ALBEDO)
    log_ratio = math.log((nu + 1.0) / (nu - 1.0))
    scores = np.zeros((paths, BINS))
    z = np.zeros(paths)
    t = np.full(paths, offset)
    weight = np.ones(paths)
    mu = np.full(paths, -MU_IN)  # cosine of the flight with +z (out of the snow, toward the light)
    collisions = np.zeros(paths, dtype=np.int64)
    alive = np.ones(paths, dtype=bool)
    index = np.arange(paths)
    cost = 0
    first = True

    def score(i: np.ndarray, value: np.ndarray, path_length: np.ndarray) -> None:
        b = np.floor(path_length / BIN_WIDTH).astype(np.int64)
        ok = b < BINS
        np.add.at(scores, (i[ok], b[ok]), value[ok])

    while alive.any():
        i = index[alive]
        if not variant.ray_nee and not first:
            score(i, weight[i] * np.exp(z[i]) / (4 * np.pi), t[i] - z[i])
            cost += i.size
        ended = t[i] >= BINS * BIN_WIDTH
        alive[i[ended]] = False
        i = i[~ended]
        if i.size == 0:
            break
        # The next flight's direction and length, and phase x transmittance over their pdf: over the direction's
        # marginal pdf (for an estimate along the ray) and over the joint one (for the walk).
        if first:
            s = rng.exponential(1.0, i.size)
            marginal_ratio = np.ones(i.size)
            joint_ratio = np.ones(i.size)
        else:
            guided = rng.random(i.size) < variant.guide
            mu_guided = nu - (nu + 1.0) * ((nu - 1.0) / (nu + 1.0)) ** rng.random(i.size)
            mu[i] = np.where(guided, mu_guided, 2.0 * rng.random(i.size) - 1.0)
            stretched = 1.0 - mu[i] / nu  # the guided flight's extinction
            s = rng.exponential(1.0, i.size) / np.where(guided, stretched, 1.0)
            guided_pdf = 1.0 / (log_ratio * (nu - mu[i]))
            marginal_ratio = 0.5 / ((1.0 - variant.guide) * 0.5 + variant.guide * guided_pdf)
            pdf = (1.0 - variant.guide) * 0.5 * np.exp(-s) + variant.guide * guided_pdf * stretched * np.exp(
                -stretched * s
            )
            joint_ratio = 0.5 * np.exp(-s) / pdf
        first = False
        # The estimate along the ray about to be flown: sigma_s T(u) exp(z + mu u) / 4 pi over u in [0, d).
        if variant.ray_nee:
            m = mu[i]
            rate = 1.0 - m
            d = np.where(m > 0, -z[i] / np.where(m > 0, m, 1.0), np.inf)
            mass = -np.expm1(-rate * d)  # of the density rate exp(-rate u) on [0, d)
            u = -np.log1p(-rng.random(i.size) * mass) / rate
            value = weight[i] * marginal_ratio * ALBEDO / (4 * np.pi) * np.exp(z[i]) * mass / rate
            score(i, value, t[i] + u - (z[i] + m * u))
            cost += i.size
        z_new = z[i] + mu[i] * s
        weight[i] *= ALBEDO * joint_ratio
        z[i] = z_new
        t[i] += s
        escaped = z_new > 0
        alive[i[escaped]] = False
        i = i[~escaped]
        collisions[i] += 1
        j = i[collisions[i] >= RR_DEPTH]
        q = np.minimum(MAX_SURVIVAL, weight[j])
        survive = rng.random(j.size) < q
        weight[j[survive]] /= q[survive]
        alive[j[~survive]] = False
    return scores, cost


@dataclass(frozen=True)
class Moments:
    """What the table needs of a variant's walks: per bin, the mean and the variance of one walk's score."""

    mean: np.ndarray
    variance: np.ndarray
    cost: float  # vertices a walk


def moments(variant: Variant, paths: int, seed: int, offset: float) -> Moments:
    scores, cost = walk(variant, paths, seed, offset)
    return Moments(scores.mean(axis=0), scores.var(axis=0), cost / paths)


def relative_variance(m: Moments, core: Moments, frames: np.ndarray, with_cost: bool = True) -> float:
    """The variant's relative variance (x cost) over the core walk's, averaged over ``frames``."""
    ratio = float(np.mean((m.variance / core.mean**2)[frames]) / np.mean((core.variance / core.mean**2)[frames]))
    return ratio * m.cost / core.cost if with_cost else ratio


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--paths", type=int, default=200_000, help="camera walks per variant, seed and offset")
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    if args.paths < 1000:
        raise SystemExit(f"--paths {args.paths}: at least 1000 walks, or the variances mean nothing")

    lines = [
        "| variant | seed | arrival in its bin [mfp] | relvar x cost / core's: lit frames | first lit frame | late third "
        "| relvar / core's, lit frames | vertices a walk | largest deviation [std. errors] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for seed in args.seeds:
        for offset in (0.0, BIN_WIDTH / 2):
            runs = [moments(v, args.paths, seed * 1000 + k, offset) for k, v in enumerate(VARIANTS)]
            core = runs[0]
            lit = core.mean > 0.01 * core.mean.sum()
            first_lit = np.zeros(BINS, dtype=bool)
            first_lit[np.argmax(lit)] = True
            late = np.zeros(BINS, dtype=bool)
            late[2 * BINS // 3 :] = True
            for variant, m in zip(VARIANTS, runs, strict=True):
                ratios = [relative_variance(m, core, frames) for frames in (lit, first_lit, late)]
                error = np.sqrt((core.variance + m.variance) / args.paths)
                deviation = np.max(np.abs(m.mean - core.mean)[lit] / error[lit])
                relvar = relative_variance(m, core, lit, with_cost=False)
                lines.append(
                    f"| {variant.name} | {seed} | {offset:.1f} | {ratios[0]:.3f} | {ratios[1]:.3f} | {ratios[2]:.3f} "
                    f"| {relvar:.3f} | {m.cost:.1f} | {deviation:.1f} |"
                )
                rows.append(
                    {
                        "variant": variant.name,
                        "seed": seed,
                        "arrival_mfp": offset,
                        "relvar_cost_lit": ratios[0],
                        "relvar_cost_first_lit": ratios[1],
                        "relvar_cost_late_third": ratios[2],
                        "relvar_lit": relvar,
                        "vertices_per_walk": m.cost,
                        "largest_deviation_std_errors": float(deviation),
                    }
                )
                print(lines[-1], flush=True)
    intro = (
        f"Near-surface walk model: {args.paths} walks a variant, seed and arrival; albedo {ALBEDO}, bins of "
        f"{BIN_WIDTH} mean free paths. Ratios are against the core's walk (the first row of each seed and arrival).\n\n"
    )
    write_results("walk_model", intro + "\n".join(lines), run, rows=rows, standard=is_standard(parser, args))


if __name__ == "__main__":
    main()
