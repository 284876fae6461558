"""Optical grain size read back from an airborne (ATM-like) waveform over snow (render/lidar/LIDAR.md §11).

The forward model is our renderer's flat-snow impulse response in the isotropic reduced form, which depends on
the snow only through σ_s′ and σ_a. Measured in transport lengths ℓ* = 1/σ_s′ it depends on α = σ_a/σ_s′ alone,
and absorption multiplies a path of length L by e^{-σ_a L} whatever it did (the microscopic Beer–Lambert law):

    I(L; σ_s′, σ_a) dL = f(x; α0) e^{-(α − α0) x} dx,    x = σ_s′ L.

So one render of f(x; α0) at a small α0 (``render_table``), rescaled, is the response of every grain size and
density. The snow's clock stretches a subsurface path L to the delay n_snow L (``optics.snow_group_index``).

    ReducedTable                          f(x; α) in ℓ* units, three absorptions (one render's three channels)
    render_table(...)                     that render
    flat_impulse(table, optics, n, edges) the energy of flat snow in OPL bins behind its surface
    AtmInstrument                         pulse, digitiser sampling, range gate and noise (LIDAR.md §11.1)
    digitise(...)                         an impulse response through the pulse into digitiser samples
    observe(...)                          a noisy waveform, gated around its strongest sample
    retrieve_grain_size(...)              least squares over grain size, surface and amplitude (density, roughness)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import fftconvolve
from scipy.special import ndtr
from scipy.stats import chi2

from common.atomic import atomic_path
from common.units import NS_PER_M_OPL
from render.lidar.optics import SnowOptics, snow_group_index, snow_optics
from render.lidar.waveform import SIGMA_PER_FWHM, pulse_kernel, pulse_sigma_opl

GroupIndex = Callable[[float], float] | float
GRAIN_BOUNDS = (3e-5, 2e-2)  # optical diameters the fit may take [m]
DENSITY_BOUNDS = (100.0, 800.0)  # densities a free-density fit may take [kg m-3]
FINE_OPL = 4e-3  # the model's impulse grid behind the surface, well under the pulse's sigma [m of OPL]
MIN_P_VALUE = 1e-3  # below this the residuals do not follow the stated noise model
MAX_ROUGHNESS = 0.5  # the largest Gaussian height spread a fit with roughness may take [m]


class RetrievalError(ValueError):
    """The waveform cannot be read back with this table and noise model; the message says why and what to do."""


# ---------------------------------------------------------------- the table (f in units of ℓ*)


@dataclass(frozen=True)
class ReducedTable:
    """Flat snow's nadir impulse response in transport lengths: ``energy[k, c]`` is the return per unit incident
    irradiance (sr⁻¹) with x = σ_s′ L in [k w, (k + 1) w), w = ``bin_width``, for absorption ratio
    ``alphas[c]`` = σ_a/σ_s′. The model uses the smallest α and Beer–Lambert; the others check it."""

    bin_width: float
    energy: np.ndarray  # (bins, channels)
    alphas: tuple[float, ...]
    paths: int = 0

    @property
    def x_max(self) -> float:
        return self.bin_width * self.energy.shape[0]

    @property
    def base(self) -> int:
        return int(np.argmin(self.alphas))

    def cumulative(self, alpha: float, x_limit: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(x edges, cumulative energy) at absorption ratio ``alpha`` ≥ the table's smallest, by Beer–Lambert from
        the base channel (the factor taken at each bin's centre), as far as ``x_limit`` (default: all)."""
        alpha0 = self.alphas[self.base]
        if alpha < alpha0 * (1 - 1e-9):
            raise RetrievalError(
                f"absorption ratio {alpha:.3g} lies below the table's {alpha0:.3g}: Beer–Lambert only removes "
                "light; render the table with a smaller alpha (render_table(alphas=...))"
            )
        bins = (
            self.energy.shape[0] if x_limit is None else min(self.energy.shape[0], math.ceil(x_limit / self.bin_width))
        )
        edges = self.bin_width * np.arange(bins + 1)
        centres = 0.5 * (edges[:-1] + edges[1:])
        weights = self.energy[:bins, self.base] * np.exp(-(alpha - alpha0) * centres)
        return edges, np.concatenate(([0.0], np.cumsum(weights)))

    def save(self, path: Path) -> None:
        """Write the table to ``path`` (.npz), atomically."""
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(f, bin_width=self.bin_width, energy=self.energy, alphas=np.array(self.alphas), paths=self.paths)

    @classmethod
    def load(cls, path: Path) -> ReducedTable:
        with np.load(path) as data:
            return cls(
                float(data["bin_width"]),
                np.asarray(data["energy"], np.float64),
                tuple(float(a) for a in data["alphas"]),
                int(data["paths"]),
            )


def render_table(
    *,
    alphas: tuple[float, float, float] = (1e-6, 1e-4, 1e-3),
    transport_length: float = 1e-3,
    bins: int = 16384,
    bin_width: float = 2.0,
    pixels: int = 16,
    iterations: int = 1024,
    seed: int = 1,
    threads: int = 1,
) -> ReducedTable:
    """Render f(x; α) for three α in one render of flat snow with ℓ* = ``transport_length`` [m], the receiver
    ``bins`` × ``bin_width`` ℓ* deep in path (isotropic reduced form, index matched: the clock is applied
    afterwards). The snow is 1500 ℓ* deep and 2000 ℓ* wide, far beyond the √(2x/3) ℓ* that light wanders by
    x = 32768. Any ℓ* gives the same table (the scaling law, tests/render/lidar/test_lidar_retrieval.py)."""
    from render.lidar.scene import Receiver, medium, shot_scene
    from render.ptpb.api import render

    ell = transport_length
    # The reference plane half a bin above the snow: the surface is the edge between bins 0 and 1.
    receiver = Receiver((0.0, 0.0), 1000 * ell, pixels, 0.5 * bin_width * ell, bin_width * ell, bins + 1)
    snow = medium((1 / ell,) * 3, tuple(a / ell for a in alphas), 0.0)
    scene = shot_scene("flat_snow", receiver, snow=snow, depth=1500 * ell)
    settings = {
        "iterations": iterations,
        "frame_mode": "bins",
        "max_depth": -1,
        "seed": seed,
        "threads": threads,
        "medium_estimator": "paths",
        "path_max_survival": 0.9999,
    }
    result = render(scene, settings)
    frames = result.frames.astype(np.float64).mean(axis=(1, 2))
    return ReducedTable(bin_width, frames[1:], tuple(float(a) for a in alphas), pixels * pixels * iterations)


def absorption_ratio(optics: SnowOptics) -> float:
    """α = σ_a/σ_s′ = B γ d / (3 (1 − g)) to first order: set by grain size, not by density."""
    return optics.absorption / optics.reduced_scattering


def _group_index(group_index: GroupIndex, density: float) -> float:
    return float(group_index(density) if callable(group_index) else group_index)


def flat_impulse(table: ReducedTable, optics: SnowOptics, group_index: float, opl_edges: np.ndarray) -> np.ndarray:
    """The energy of flat ``optics`` snow between ``opl_edges`` [m of OPL behind the surface, ≥ 0]: a delay τ is
    a path τ/n in the snow, n = ``group_index``, so x = σ_s′ τ/n. Refuses edges beyond the table."""
    x = optics.reduced_scattering * np.asarray(opl_edges, np.float64) / group_index
    if x[-1] > table.x_max:
        raise RetrievalError(
            f"the waveform reaches {x[-1]:.0f} transport lengths into the snow, beyond the table's {table.x_max:.0f}: "
            "shorten the range gate or render a longer table (render_table(bins=...))"
        )
    edges, cumulative = table.cumulative(absorption_ratio(optics), x[-1])
    return np.diff(np.interp(x, edges, cumulative))


# ---------------------------------------------------------------- the instrument and its noise


@dataclass(frozen=True)
class AtmInstrument:
    """An ATM-like green waveform lidar (LIDAR.md §11.1): a Gaussian pulse, a digitiser sampling every
    ``sample_ns``, a range gate ``gate_before``/``gate_after`` metres of range around the strongest sample, and
    noise: per shot, Poisson photoelectrons with ``peak_photoelectrons`` expected in the strongest sample plus
    Gaussian digitiser noise of ``digitiser_noise`` photoelectrons rms; a waveform is the sum of ``shots`` shots
    over the same snow."""

    pulse_fwhm_ns: float = 1.5
    sample_ns: float = 0.5
    gate_before: float = 0.75
    gate_after: float = 1.5
    peak_photoelectrons: float = 200.0
    digitiser_noise: float = 2.0
    shots: int = 25

    @property
    def peak(self) -> float:
        """Expected photoelectrons in the strongest sample of the summed waveform."""
        return self.peak_photoelectrons * self.shots

    @property
    def sample_opl(self) -> float:
        return self.sample_ns / NS_PER_M_OPL

    @property
    def pulse_sigma_opl(self) -> float:
        return pulse_sigma_opl(self.pulse_fwhm_ns)

    def variance(self, expected: np.ndarray) -> np.ndarray:
        """The noise variance of each sample [photoelectrons²]: shot noise plus the digitiser's."""
        return np.maximum(expected, 0.0) + self.shots * self.digitiser_noise**2

    def noise(self, expected: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A noisy waveform [photoelectrons] around ``expected``."""
        return rng.poisson(np.maximum(expected, 0.0)).astype(np.float64) + rng.normal(
            0.0, self.digitiser_noise * math.sqrt(self.shots), np.shape(expected)
        )


def digitise(opl_centres: np.ndarray, energy: np.ndarray, sample_edges: np.ndarray, sigma_opl: float) -> np.ndarray:
    """Energy arriving at ``opl_centres`` spread by a Gaussian pulse of ``sigma_opl`` and integrated over the
    digitiser's samples between ``sample_edges`` [m of OPL]."""
    z = (np.asarray(sample_edges)[:, None] - np.asarray(opl_centres)[None, :]) / sigma_opl
    return np.diff(ndtr(z), axis=0) @ np.asarray(energy, np.float64)


@dataclass(frozen=True)
class Observation:
    """A gated waveform: ``waveform`` [photoelectrons] in samples between ``sample_edges`` [m of OPL from the
    instrument's reference], ``expected`` its noiseless mean."""

    waveform: np.ndarray
    sample_edges: np.ndarray
    expected: np.ndarray


def observe(
    opl_centres: np.ndarray,
    energy: np.ndarray,
    instrument: AtmInstrument,
    rng: np.random.Generator | None,
    *,
    phase: float = 0.0,
) -> Observation:
    """An impulse response (energy at ``opl_centres``, ascending) as the instrument records it: digitised on samples
    offset by ``phase`` samples, gated around the strongest one (and short of the render's end), scaled to
    ``instrument.peak`` and, given ``rng``, noisy."""
    step = instrument.sample_opl
    sigma = instrument.pulse_sigma_opl
    first = math.floor((opl_centres[0] - 4 * sigma) / step) - 1 + phase
    count = math.ceil((opl_centres[-1] - opl_centres[0] + 8 * sigma) / step) + 2
    edges = (first + np.arange(count + 1)) * step
    full = digitise(opl_centres, energy, edges, sigma)
    peak = int(np.argmax(full))
    lo = max(0, peak - round(2 * instrument.gate_before / step))
    # Samples within 3 sigma of the render's last bin would miss light that came later than the render.
    inside = int(np.searchsorted(edges[1:], opl_centres[-1] - 3 * sigma, side="right"))
    hi = min(full.size, max(inside, peak + 8), peak + round(2 * instrument.gate_after / step) + 1)
    expected = full[lo:hi] * (instrument.peak / full[peak])
    waveform = expected if rng is None else instrument.noise(expected, rng)
    return Observation(waveform, edges[lo : hi + 1], expected)


# ---------------------------------------------------------------- the fit


@dataclass(frozen=True)
class GrainRetrieval:
    """The fit of one waveform. Uncertainties are one standard deviation from the curvature of χ²."""

    grain_diameter: float  # optical diameter d [m]
    grain_sigma: float  # its uncertainty [m]
    density: float  # the density assumed, or fitted [kg m-3]
    density_sigma: float  # 0 when assumed
    correlation: float  # of ln d and ln ρ when both are free, else 0
    roughness: float  # the fitted Gaussian height spread [m] (0 unless fitted)
    surface_opl: float  # the surface's OPL from the reference [m]
    amplitude: float  # photoelectrons per unit of the table's energy
    chi2: float
    dof: int
    p_value: float
    at_bound: bool  # the fit ended at the table's grain-size bound (refused when strict)
    model: np.ndarray = field(repr=False)  # the fitted expected waveform [photoelectrons]


def _fine_kernel(pulse_sigma: float) -> np.ndarray:
    """A Gaussian of ``pulse_sigma`` [m of OPL] integrated over the fine grid's bins, centred, summing to 1."""
    return pulse_kernel(FINE_OPL, pulse_sigma / SIGMA_PER_FWHM * NS_PER_M_OPL)


_pulse_kernel = lru_cache(maxsize=8)(_fine_kernel)


def _model(
    table: ReducedTable,
    density: float,
    grain: float,
    surface_opl: float,
    sample_edges: np.ndarray,
    instrument: AtmInstrument,
    group_index: GroupIndex,
    roughness: float = 0.0,
) -> np.ndarray:
    """The noiseless waveform of flat snow with unit amplitude; ``roughness`` [m] spreads the surface's heights
    as a Gaussian of that standard deviation (2× in OPL), added to the pulse's."""
    sigma = math.hypot(instrument.pulse_sigma_opl, 2.0 * roughness)
    depth = max(0.0, sample_edges[-1] + 6 * sigma - surface_opl)
    fine = np.arange(0.0, depth + FINE_OPL, FINE_OPL)
    energy = flat_impulse(table, snow_optics(density, grain), _group_index(group_index, density), fine)
    # The pulse on the fine grid, then the cumulative energy read at the sample edges: digitise() at a tenth
    # of its cost, the same within the grid's 4 mm (1/50 of the pulse's sigma).
    kernel = _pulse_kernel(sigma) if roughness == 0 else _fine_kernel(sigma)
    cumulative = np.cumsum(fftconvolve(energy, kernel))
    ends = surface_opl + (np.arange(cumulative.size) - kernel.size // 2 + 1) * FINE_OPL
    return np.diff(np.interp(sample_edges, ends, cumulative, left=0.0))


def retrieve_grain_size(
    observation: Observation | tuple[np.ndarray, np.ndarray],
    table: ReducedTable,
    instrument: AtmInstrument,
    *,
    density: float,
    group_index: GroupIndex = snow_group_index,
    fit_density: bool = False,
    fit_roughness: bool = False,
    strict: bool = True,
) -> GrainRetrieval:
    """Least squares of a waveform against flat snow of the table: ln d, the surface's OPL and the amplitude free
    (and ln ρ with ``fit_density``, from ``density``; a Gaussian surface roughness with ``fit_roughness``), each
    sample weighted by the instrument's noise variance at the model (two passes). ``density`` is assumed
    otherwise: at 532 nm the waveform fixes ℓ* n_snow, not d and ρ apart (LIDAR.md §11.3). ``group_index`` is
    the snow's clock, a function of density or a number (1: the index-matched clock).

    With ``strict`` a fit that ends at the table's grain-size bounds, or whose χ² is improbable under the stated
    noise (p < 1e-3), raises RetrievalError."""
    waveform, edges = (
        (observation.waveform, observation.sample_edges) if isinstance(observation, Observation) else observation
    )
    y = np.asarray(waveform, np.float64)
    edges = np.asarray(edges, np.float64)
    if y.ndim != 1 or edges.shape != (y.size + 1,) or y.size < 8:
        raise RetrievalError(f"a waveform of at least 8 samples with one more edge is needed, got {y.shape}")
    if not y.max() > 5 * math.sqrt(instrument.variance(np.zeros(1))[0]):
        raise RetrievalError("the waveform holds no return above the digitiser's noise: nothing to fit")
    sigma = instrument.pulse_sigma_opl
    centres = 0.5 * (edges[:-1] + edges[1:])
    # The surface: the leading edge's half maximum lies near it for every grain size (the return's mode).
    peak = int(np.argmax(y))
    rising = np.nonzero(y[: peak + 1] < 0.5 * y[peak])[0]
    start = centres[rising[-1]] if rising.size else centres[0]
    # The finest grain whose response the table holds down to the gate's end (σ_s′ ∝ 1/d), with a margin.
    densest = DENSITY_BOUNDS[1] if fit_density else density
    reference = snow_optics(densest, 1e-3)
    reach = edges[-1] + 6 * sigma + 2 * MAX_ROUGHNESS - (start - 5 * sigma)
    finest = 1.02e-3 * reference.reduced_scattering * reach / _group_index(group_index, densest) / table.x_max
    log_bounds = [math.log(max(GRAIN_BOUNDS[0], finest)), math.log(GRAIN_BOUNDS[1])]
    if log_bounds[0] >= log_bounds[1] - 1.0:
        raise RetrievalError(
            f"the table reaches {table.x_max:.0f} transport lengths, too few for this range gate: render a longer "
            "table (render_table(bins=...)) or shorten the gate"
        )
    # Parameters: ln d, surface OPL, ln amplitude, then ln ρ and roughness when free.
    slot_density = 3 if fit_density else None
    slot_roughness = 3 + fit_density if fit_roughness else None

    def expected(params: np.ndarray) -> np.ndarray:
        rho = math.exp(params[slot_density]) if slot_density is not None else density
        rough = float(params[slot_roughness]) if slot_roughness is not None else 0.0
        shape = _model(table, rho, math.exp(params[0]), params[1], edges, instrument, group_index, rough)
        return math.exp(params[2]) * shape

    # A coarse grid over grain size and surface, the amplitude solved linearly, starts the fit.
    variance = instrument.variance(y)
    best = (math.inf, 0.0, 0.0, 0.0)
    for log_d in np.linspace(log_bounds[0] + 0.1, log_bounds[1] - 0.1, 9):
        for t0 in start + np.linspace(-1.0, 2.0, 9) * sigma:
            shape = _model(table, density, math.exp(log_d), t0, edges, instrument, group_index)
            a = float(np.sum(shape * y / variance) / np.sum(shape**2 / variance))
            cost = float(np.sum((y - a * shape) ** 2 / variance))
            if a > 0 and cost < best[0]:
                best = (cost, log_d, t0, math.log(a))
    start_values, scale = list(best[1:]), [0.3, 0.3 * sigma, 0.1]
    lower = [log_bounds[0], start_values[1] - 4 * sigma, start_values[2] - 5]
    upper = [log_bounds[1], start_values[1] + 4 * sigma, start_values[2] + 5]
    if fit_density:
        start_values.append(math.log(density))
        lower.append(math.log(DENSITY_BOUNDS[0]))
        upper.append(math.log(DENSITY_BOUNDS[1]))
        scale.append(0.1)
    if fit_roughness:
        start_values.append(0.05)
        lower.append(0.0)
        upper.append(MAX_ROUGHNESS)
        scale.append(0.05)
    params = np.array(start_values)
    for _ in range(2):  # weights from the data, then from the model
        fit = least_squares(
            lambda p, v=variance: (expected(p) - y) / np.sqrt(v),
            params,
            bounds=(lower, upper),
            x_scale=scale,
            diff_step=1e-4,
        )
        params = fit.x
        variance = instrument.variance(expected(params))
    model = expected(params)
    residual = (y - model) / np.sqrt(variance)
    try:
        covariance = np.linalg.inv(fit.jac.T @ fit.jac)
    except np.linalg.LinAlgError:
        covariance = np.full((params.size, params.size), np.nan)
    dof = y.size - params.size
    chi_square = float(residual @ residual)
    p_value = float(chi2.sf(chi_square, dof))
    grain = math.exp(params[0])
    at_bound = min(params[0] - log_bounds[0], log_bounds[1] - params[0]) < 1e-3
    if strict and at_bound:
        raise RetrievalError(
            f"the fit ends at the table's bound (d = {1e3 * grain:.3g} mm, bounds {1e3 * math.exp(log_bounds[0]):.3g}–"
            f"{1e3 * math.exp(log_bounds[1]):.3g} mm): the waveform is not flat snow of this density and clock"
        )
    if strict and p_value < MIN_P_VALUE:
        raise RetrievalError(
            f"χ²/dof = {chi_square / dof:.2f} over {dof} degrees of freedom (p = {p_value:.1e}): the residuals do not "
            "follow the stated noise model; check peak_photoelectrons and digitiser_noise, or the surface is not flat"
        )
    rho = math.exp(params[slot_density]) if slot_density is not None else density
    return GrainRetrieval(
        grain_diameter=grain,
        grain_sigma=grain * math.sqrt(max(covariance[0, 0], 0.0)),
        density=rho,
        density_sigma=rho * math.sqrt(max(covariance[3, 3], 0.0)) if fit_density else 0.0,
        correlation=float(covariance[0, 3] / math.sqrt(covariance[0, 0] * covariance[3, 3])) if fit_density else 0.0,
        roughness=float(params[slot_roughness]) if slot_roughness is not None else 0.0,
        surface_opl=float(params[1]),
        amplitude=math.exp(params[2]),
        chi2=chi_square,
        dof=dof,
        p_value=p_value,
        at_bound=at_bound,
        model=model,
    )


__all__ = [
    "AtmInstrument",
    "GrainRetrieval",
    "Observation",
    "ReducedTable",
    "RetrievalError",
    "absorption_ratio",
    "digitise",
    "flat_impulse",
    "observe",
    "render_table",
    "retrieve_grain_size",
]
