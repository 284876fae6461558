"""Pulses, range estimators and reference heights for a lidar waveform (LIDAR.md §1, §4).

A waveform is an array over the bins of a film axis (``start_opl``, ``bin_width_opl``; bin k covers
[start + k w, start + (k + 1) w) and has its centre at start + (k + ½) w, render/output/files.py ``FrameAxis``).
OPL is the round trip measured from the reference plane z = z_ref of the instrument, so a range is OPL/2 and the
range to a surface at height h is z_ref − h. A bias is an estimated range minus the range to a reference height:
positive means the estimator puts the surface too low (the light came back late).

    gaussian_pulse(start, w, bins, fwhm_ns)       a unit-energy Gaussian pulse as bin integrals
    convolve_pulse(impulse, w, fwhm_ns)           an impulse response seen through a pulse (one render, any pulse)
    surface_impulse(heights, weights, z_ref, ...)  the impulse response of a bare surface (no penetration)
    first_return_range, peak_range, centroid_range, median_range, gaussian_fit_range
    estimate_ranges(waveform, start, w)           all of them, as a RangeEstimates
    reference_heights(heights, spacing, D, centre) footprint mean, highest point, flat-surface equivalent
    bias_table(estimates, references, z_ref)      estimated range minus the range to each reference
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import convolve1d
from scipy.optimize import curve_fit
from scipy.special import ndtr

from common.units import NS_PER_M_OPL

SIGMA_PER_FWHM = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))
KERNEL_HALF_WIDTH_SIGMAS = 8.0  # the pulse's tail beyond 8 sigma carries 1e-15 of its energy
DEFAULT_THRESHOLD = 0.5
ESTIMATORS = ("first_return", "peak", "centroid", "median", "gaussian_fit")
REFERENCES = ("footprint_mean", "highest", "flat_equivalent")


class RangeEstimationError(ValueError):
    """An estimator cannot give a range for this waveform; the message says why and what to change."""


# ---------------------------------------------------------------- pulses


def pulse_sigma_opl(fwhm_ns: float) -> float:
    """Standard deviation of a Gaussian pulse of FWHM ``fwhm_ns`` nanoseconds, in metres of OPL (c·τ)."""
    if not (math.isfinite(fwhm_ns) and fwhm_ns >= 0):
        raise ValueError(f"fwhm_ns must be a non-negative pulse width in nanoseconds, got {fwhm_ns}")
    return fwhm_ns / NS_PER_M_OPL * SIGMA_PER_FWHM


def _check_axis(start_opl: float, bin_width_opl: float) -> None:
    if not math.isfinite(start_opl):
        raise ValueError(f"start_opl must be finite (m of OPL), got {start_opl}")
    if not (math.isfinite(bin_width_opl) and bin_width_opl > 0):
        raise ValueError(f"bin_width_opl must be positive (m of OPL), got {bin_width_opl}")


def gaussian_pulse(
    start_opl: float, bin_width_opl: float, temporal_bins: int, fwhm_ns: float, centre_opl: float = 0.0
) -> np.ndarray:
    """A unit-energy Gaussian pulse centred at ``centre_opl`` [m], as its integral over each bin (LIDAR.md §4.1).

    The FWHM in time τ is c·τ in OPL (the axis is the round trip, so the pulse is cτ/2 wide in range). The sum is
    1 when the pulse lies inside the axis. A zero width gives all the energy to the bin holding ``centre_opl``.
    """
    _check_axis(start_opl, bin_width_opl)
    if temporal_bins < 1:
        raise ValueError(f"temporal_bins must be at least 1, got {temporal_bins}")
    sigma = pulse_sigma_opl(fwhm_ns)
    edges = start_opl + bin_width_opl * np.arange(temporal_bins + 1)
    if sigma == 0:
        return np.diff((edges > centre_opl).astype(np.float64))
    lower, upper = (edges[:-1] - centre_opl) / sigma, (edges[1:] - centre_opl) / sigma
    # Φ(b) − Φ(a) = Φ(−a) − Φ(−b): take the form without cancellation on each side of the centre.
    return np.where(lower > 0, ndtr(-lower) - ndtr(-upper), ndtr(upper) - ndtr(lower))


def pulse_kernel(bin_width_opl: float, fwhm_ns: float) -> np.ndarray:
    """The pulse on bins of width ``bin_width_opl``, centred on the middle bin of an odd-length array, summing to 1.

    It reaches ±8σ (at least one bin each side); ``len(kernel) // 2`` is how many bins the pulse spreads
    energy beyond an impulse.
    """
    _check_axis(0.0, bin_width_opl)
    sigma = pulse_sigma_opl(fwhm_ns)
    half = max(1, math.ceil(KERNEL_HALF_WIDTH_SIGMAS * sigma / bin_width_opl))
    leading = gaussian_pulse(-(half + 0.5) * bin_width_opl, bin_width_opl, half + 1, fwhm_ns)
    # Mirrored, so the kernel is exactly symmetric and a symmetric estimator sees no shift.
    kernel = np.concatenate((leading, leading[-2::-1]))
    return kernel / kernel.sum()


def convolve_pulse(impulse, bin_width_opl: float, fwhm_ns: float, *, axis: int = 0) -> np.ndarray:
    """An impulse response (bins along ``axis``) convolved with a Gaussian pulse of FWHM ``fwhm_ns`` (LIDAR.md §4.1).

    Transport is linear, so one fine render serves every pulse width. The kernel is the pulse integrated over
    each bin, centred (no shift) and summing to 1, so energy is conserved exactly for light that arrives at
    least ``len(pulse_kernel(...)) // 2`` bins (8σ) from both ends of the axis. Edges: the axis is treated as
    zero outside its bins, and the part of the pulse that would fall before the first or after the last bin is
    dropped; the output has the input's shape. Give the film a margin of 8σ, or pad it, when energy matters.
    For a film (T, H, W, 3) use ``axis=0`` and, when it is large, call it on windows of pixels.
    """
    values = np.asarray(impulse)
    if fwhm_ns == 0:
        return values.astype(np.result_type(values.dtype, np.float32), copy=True)
    kernel = pulse_kernel(bin_width_opl, fwhm_ns)
    return convolve1d(
        values, kernel, axis=axis, mode="constant", cval=0.0, output=np.result_type(values.dtype, np.float32)
    )


def surface_impulse(
    heights, weights, z_ref: float, start_opl: float, bin_width_opl: float, temporal_bins: int
) -> np.ndarray:
    """The impulse response of a bare surface (no penetration): each height's weight into the bin of its round
    trip OPL 2(z_ref − h), as the renderer's bins mode does (k = ⌊(OPL − start)/w⌋; outside the axis: dropped)."""
    _check_axis(start_opl, bin_width_opl)
    h = np.asarray(heights, dtype=np.float64).ravel()
    wt = np.broadcast_to(np.asarray(weights, dtype=np.float64), np.shape(heights)).ravel()
    index = np.floor((2.0 * (z_ref - h) - start_opl) / bin_width_opl).astype(np.int64)
    inside = (index >= 0) & (index < temporal_bins)
    return np.bincount(index[inside], weights=wt[inside], minlength=temporal_bins)


# ---------------------------------------------------------------- estimators (LIDAR.md §4.2)


def _waveform(waveform, start_opl: float, bin_width_opl: float) -> np.ndarray:
    _check_axis(start_opl, bin_width_opl)
    y = np.asarray(waveform, dtype=np.float64)
    if y.ndim != 1 or y.size < 3:
        raise RangeEstimationError(f"a waveform is a 1-D array of at least 3 bins, got shape {y.shape}")
    if not np.all(np.isfinite(y)):
        raise RangeEstimationError("the waveform has NaN or inf values; check the film and the pixel range")
    if y.sum() <= 0 or y.max() <= 0:
        raise RangeEstimationError("the waveform holds no energy (sum <= 0): no return in this axis window")
    return y


def _centres(y: np.ndarray, start_opl: float, bin_width_opl: float) -> np.ndarray:
    return start_opl + (np.arange(y.size) + 0.5) * bin_width_opl


def _leading_crossing_opl(y: np.ndarray, start_opl: float, bin_width_opl: float, threshold: float) -> float:
    level = threshold * y.max()
    k = int(np.argmax(y >= level))
    if k == 0:
        raise RangeEstimationError(
            "the waveform is above the threshold in its first bin, so the leading edge is not in the window; "
            "start the axis earlier (smaller start_opl)"
        )
    fraction = (level - y[k - 1]) / (y[k] - y[k - 1])
    return float(start_opl + (k - 0.5 + fraction) * bin_width_opl)


def first_return_range(
    waveform,
    start_opl: float,
    bin_width_opl: float,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    pulse_fwhm_ns: float | None = None,
) -> float:
    """Range [m] where the waveform first rises through ``threshold`` × its highest bin (leading edge).

    The crossing is interpolated linearly between the centres of the two bins around it. The default, 0.5 (half
    maximum), sits on the steep part of the edge, where noise moves the crossing least, and still responds to
    the first surface the pulse meets. Given ``pulse_fwhm_ns``, the estimate is calibrated as an altimeter is on
    a hard flat target: the lead of the transmitted pulse's own crossing (on the same bins, ≈ FWHM/2 at 0.5) is
    added back, so a bare flat surface gives zero bias. Without it the raw crossing is returned.
    """
    if not 0 < threshold < 1:
        raise ValueError(f"threshold is a fraction of the peak in (0, 1), got {threshold}")
    y = _waveform(waveform, start_opl, bin_width_opl)
    opl = _leading_crossing_opl(y, start_opl, bin_width_opl, threshold)
    if pulse_fwhm_ns is not None:
        kernel = pulse_kernel(bin_width_opl, pulse_fwhm_ns)
        half = kernel.size // 2
        # The kernel's centre is OPL 0 on an axis starting at -(half + 1/2) w: its crossing is minus the lead.
        opl -= _leading_crossing_opl(kernel, -(half + 0.5) * bin_width_opl, bin_width_opl, threshold)
    return 0.5 * opl


def peak_range(waveform, start_opl: float, bin_width_opl: float) -> float:
    """Range [m] of the waveform's maximum, refined by the parabola through the highest bin and its neighbours
    (at the first or last bin: that bin's centre)."""
    y = _waveform(waveform, start_opl, bin_width_opl)
    k = int(np.argmax(y))
    offset = 0.0
    if 0 < k < y.size - 1:
        curvature = y[k - 1] - 2.0 * y[k] + y[k + 1]
        if curvature < 0:
            offset = 0.5 * (y[k - 1] - y[k + 1]) / curvature
    return float(0.5 * (start_opl + (k + 0.5 + offset) * bin_width_opl))


def centroid_range(waveform, start_opl: float, bin_width_opl: float) -> float:
    """Range [m] of the waveform's centre of mass, Σ y_k τ_k / Σ y_k over bin centres τ_k, halved."""
    y = _waveform(waveform, start_opl, bin_width_opl)
    return 0.5 * float(np.sum(y * _centres(y, start_opl, bin_width_opl)) / y.sum())


def rms_width_range(waveform, start_opl: float, bin_width_opl: float) -> float:
    """Square root of the waveform's second central moment over bin centres, in range [m] (OPL/2)."""
    y = _waveform(waveform, start_opl, bin_width_opl)
    tau = _centres(y, start_opl, bin_width_opl)
    mean = np.sum(y * tau) / y.sum()
    return 0.5 * math.sqrt(max(float(np.sum(y * (tau - mean) ** 2) / y.sum()), 0.0))


def median_range(waveform, start_opl: float, bin_width_opl: float) -> float:
    """Range [m] by which half of the energy has returned: the cumulative energy, taken linear within each bin
    (energy spread evenly over the bin), reaches half the total."""
    y = _waveform(waveform, start_opl, bin_width_opl)
    cumulative = np.cumsum(y)
    half = 0.5 * cumulative[-1]
    k = int(np.argmax(cumulative >= half))
    before = cumulative[k - 1] if k > 0 else 0.0
    fraction = (half - before) / y[k] if y[k] > 0 else 0.0
    return float(0.5 * (start_opl + (k + fraction) * bin_width_opl))


def _gaussian(x, amplitude, centre, sigma):
    return amplitude * np.exp(-0.5 * ((x - centre) / sigma) ** 2)


def gaussian_fit_range(waveform, start_opl: float, bin_width_opl: float) -> tuple[float, float]:
    """(range of the centre, σ in range) [m] of a least-squares Gaussian a·exp(−(τ − μ)²/(2s²)) through the bins
    (scipy.optimize.curve_fit, no background term), started from the centroid and RMS width.

    Raises RangeEstimationError when the fit does not converge or lands outside the window.
    """
    y = _waveform(waveform, start_opl, bin_width_opl)
    tau = _centres(y, start_opl, bin_width_opl)
    mean = float(np.sum(y * tau) / y.sum())
    spread = math.sqrt(max(float(np.sum(y * (tau - mean) ** 2) / y.sum()), (0.5 * bin_width_opl) ** 2))
    try:
        params, _ = curve_fit(_gaussian, tau, y, p0=(float(y.max()), mean, spread), maxfev=2000)
    except (RuntimeError, ValueError) as exc:
        raise RangeEstimationError(
            f"the Gaussian fit did not converge ({exc}); the waveform may be far from one pulse: "
            "use the median or centroid, or widen the axis window around the return"
        ) from None
    amplitude, centre, sigma = (float(p) for p in params)
    if not (amplitude > 0 and math.isfinite(centre) and tau[0] <= centre <= tau[-1]):
        raise RangeEstimationError(
            f"the Gaussian fit ended outside the window (centre {centre:.6g} m of OPL, amplitude {amplitude:.3g}); "
            "use the median or centroid, or widen the axis window around the return"
        )
    return 0.5 * centre, 0.5 * abs(sigma)


@dataclass(frozen=True)
class RangeEstimates:
    """Ranges [m] from one waveform by every estimator (LIDAR.md §4.2); NaN where one failed (see ``failures``)."""

    first_return: float
    peak: float
    centroid: float
    median: float
    gaussian_fit: float
    gaussian_fit_sigma: float  # σ of the fitted Gaussian, in range [m]
    rms_width: float  # √(second central moment), in range [m]
    threshold: float  # the first-return threshold, a fraction of the peak
    calibrated: bool  # whether the first return was referred to the pulse centre (pulse_fwhm_ns given)
    failures: tuple[tuple[str, str], ...] = ()  # (estimator, why)

    def ranges(self) -> dict[str, float]:
        """Estimator name → range [m], in ESTIMATORS order."""
        return {name: getattr(self, name) for name in ESTIMATORS}

    def to_dict(self) -> dict:
        return asdict(self)


def estimate_ranges(
    waveform,
    start_opl: float,
    bin_width_opl: float,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    pulse_fwhm_ns: float | None = None,
    strict: bool = False,
) -> RangeEstimates:
    """Every estimator on one waveform. A failed estimator gives NaN and its reason in ``failures``;
    ``strict=True`` raises instead. A waveform without energy always raises."""
    _waveform(waveform, start_opl, bin_width_opl)
    failures: list[tuple[str, str]] = []

    def attempt(name: str, compute, default):
        try:
            return compute()
        except RangeEstimationError as exc:
            if strict:
                raise
            failures.append((name, str(exc)))
            return default

    first = attempt(
        "first_return",
        lambda: first_return_range(
            waveform, start_opl, bin_width_opl, threshold=threshold, pulse_fwhm_ns=pulse_fwhm_ns
        ),
        math.nan,
    )
    fit_centre, fit_sigma = attempt(
        "gaussian_fit", lambda: gaussian_fit_range(waveform, start_opl, bin_width_opl), (math.nan, math.nan)
    )
    return RangeEstimates(
        first_return=first,
        peak=peak_range(waveform, start_opl, bin_width_opl),
        centroid=centroid_range(waveform, start_opl, bin_width_opl),
        median=median_range(waveform, start_opl, bin_width_opl),
        gaussian_fit=fit_centre,
        gaussian_fit_sigma=fit_sigma,
        rms_width=rms_width_range(waveform, start_opl, bin_width_opl),
        threshold=threshold,
        calibrated=pulse_fwhm_ns is not None,
        failures=tuple(failures),
    )


# ---------------------------------------------------------------- reference heights (LIDAR.md §4.3)


@dataclass(frozen=True)
class ReferenceHeights:
    """Heights [m] a range can be referred to, for one footprint."""

    footprint_mean: float  # Σ G h / Σ G, G the footprint intensity exp(−2r²/w²), field tiled periodically
    highest: float  # the highest sample within the 1/e² diameter
    flat_equivalent: float  # mean of the whole periodic field: the flat surface holding the same snow

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


def _wrapped_offsets(count: int, spacing: float, centre: float, images: int) -> np.ndarray:
    """x_j + m L − x0 for the samples j and the periodic images m = −images … images, shape (2·images + 1, count)."""
    period = count * spacing
    x = np.arange(count) * spacing - centre
    return x[None, :] + period * np.arange(-images, images + 1)[:, None]


def footprint_weights(
    shape: tuple[int, int], spacing: float, footprint_diameter: float, centre=(0.0, 0.0)
) -> np.ndarray:
    """Footprint intensity on a periodic grid (rows y, columns x, sample [i, j] at (j·spacing, i·spacing)),
    summed over every periodic image of the field and normalised to sum 1.

    The Gaussian exp(−2r²/w²), w = D/2, is separable, so each axis sums its images out to 6w (weight e⁻⁷²):
    a footprint wider than the field wraps onto it (the field is tiled) instead of being cut.
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise ValueError(f"spacing (grid step of the height field) must be positive in metres, got {spacing}")
    if not (math.isfinite(footprint_diameter) and footprint_diameter > 0):
        raise ValueError(f"footprint_diameter (1/e^2 diameter) must be positive in metres, got {footprint_diameter}")
    radius = 0.5 * footprint_diameter
    x0, y0 = (float(c) for c in centre)
    axes = []
    for count, c in ((shape[1], x0), (shape[0], y0)):
        images = math.ceil(6.0 * radius / (count * spacing)) + 1
        offsets = _wrapped_offsets(count, spacing, c, images)
        axes.append(np.exp(-2.0 * offsets**2 / radius**2).sum(axis=0))
    weights = axes[1][:, None] * axes[0][None, :]
    return weights / weights.sum()


def reference_heights(heights, spacing: float, footprint_diameter: float, centre=(0.0, 0.0)) -> ReferenceHeights:
    """Reference heights of a periodic height field [m] under a Gaussian footprint of 1/e² diameter D centred at
    ``centre`` = (x0, y0) [m] (LIDAR.md §4.3). ``heights`` is (ny, nx), sample [i, j] at (j·spacing, i·spacing),
    periodic in x and y (as geometry/ builds it; note heightfield_solid meshes h − mean(h)).

    - footprint_mean: the footprint-weighted mean height, the field tiled under a footprint wider than it;
    - highest: the highest sample whose nearest periodic image lies within D/2 of the centre;
    - flat_equivalent: the mean height of the whole periodic field, i.e. the flat surface holding the same
      snow; it does not depend on the footprint.
    """
    h = np.asarray(heights, dtype=np.float64)
    if h.ndim != 2 or min(h.shape) < 1:
        raise ValueError(f"heights must be a 2-D array (ny, nx) of heights in metres, got shape {h.shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError("heights has NaN or inf values; fill or crop the height field first")
    weights = footprint_weights(h.shape, spacing, footprint_diameter, centre)
    ny, nx = h.shape
    x0, y0 = (float(c) for c in centre)

    def nearest(count: int, c: float) -> np.ndarray:
        period = count * spacing
        return (np.arange(count) * spacing - c + 0.5 * period) % period - 0.5 * period

    r2 = nearest(ny, y0)[:, None] ** 2 + nearest(nx, x0)[None, :] ** 2
    inside = r2 <= (0.5 * footprint_diameter) ** 2 * (1.0 + 1e-12)
    if not inside.any():
        raise ValueError(
            f"no height sample lies within the footprint's 1/e^2 diameter {footprint_diameter} m of {centre} "
            f"(grid spacing {spacing} m); use a finer height field or a wider footprint"
        )
    return ReferenceHeights(
        footprint_mean=float(np.sum(weights * h)),
        highest=float(h[inside].max()),
        flat_equivalent=float(h.mean()),
    )


def bias_table(
    estimates: RangeEstimates | Mapping[str, float],
    references: ReferenceHeights | Mapping[str, float],
    z_ref: float,
) -> dict[str, dict[str, float]]:
    """bias[estimator][reference] = estimated range − (z_ref − reference height) [m] (LIDAR.md §1).

    Positive: the estimator places the surface lower than that reference (the return came late, as light that
    wandered in the snow does). ``z_ref`` is the height of the plane OPL is measured from.
    """
    ranges = estimates.ranges() if isinstance(estimates, RangeEstimates) else dict(estimates)
    heights = references.to_dict() if isinstance(references, ReferenceHeights) else dict(references)
    return {name: {ref: value - (z_ref - h) for ref, h in heights.items()} for name, value in ranges.items()}


__all__ = [
    "DEFAULT_THRESHOLD",
    "ESTIMATORS",
    "REFERENCES",
    "RangeEstimates",
    "RangeEstimationError",
    "ReferenceHeights",
    "bias_table",
    "centroid_range",
    "convolve_pulse",
    "estimate_ranges",
    "first_return_range",
    "footprint_weights",
    "gaussian_fit_range",
    "gaussian_pulse",
    "median_range",
    "peak_range",
    "pulse_kernel",
    "pulse_sigma_opl",
    "reference_heights",
    "rms_width_range",
    "surface_impulse",
]
