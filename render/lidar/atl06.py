"""An ATL06-like land-ice surface finder for photon events, and a track simulator (LIDAR.md §9.3).

Follows the ATL06 ATBD (Smith et al., land ice along-track height) as its author's reference code implements it
(SmithB/IS2_land_ice_ATBD: ATLAS_L3a_proc_ATBD.m, fpb_corr.m), with the procedure numbers of its §5.5, §5.7 and
§5.9 as SlideRule's implementation cites them, and Smith et al. 2019 (RSE 233, 111352) for the first-photon-bias
correction (LIDAR.md §9.3). Per 40 m segment (two 20 m halves, one every 20 m):

1. initial selection: the photons within ``initial_window``/2 of the densest 1 m of height (stands in for
   ATL03's signal classification, which this model does not have);
2. iterate: fit h = h_mean + slope·(x − x_c) to the selected photons by least squares; take the residuals of
   all the segment's photons; the robust spread σ_r of the selected ones with the background removed (§5.9);
   the window H = max(H_min, 6σ_expected, 6σ_r), at least 0.75 of the previous one (§5.5 p4e, §5.7 p2e);
   select |r| < H/2; stop when the selection does not change or after ``max_iterations``; a selection of fewer
   than ``min_photons`` or spanning less than ``min_spread`` is not taken (the last usable one stays);
3. the background-corrected median of the residuals (med_r_fit) and the first-photon-bias corrections from the
   dead time and the received photon rate (``first_photon_bias``);
4. h_li = h_mean + med_r_fit + fpb_med_corr, the reference code's h_mean + (its) fpb_med_corr: the median of the
   gain-corrected residuals. The transmit-pulse-shape correction is zero here because the model's pulse is a
   symmetric Gaussian.

Pure numpy, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from common.units import SPEED_OF_LIGHT
from render.lidar.photons import Beam, LinkBudget, PhotonEvents, draw_shots
from render.lidar.waveform import pulse_sigma_opl

RDE_SCALE = 1.349  # interquartile range of a unit Gaussian: σ_r = (r75 − r25)/1.349


@dataclass(frozen=True)
class SegmentSettings:
    """The surface finder's constants [m unless noted] (ATBD values where it gives them, LIDAR.md §9.3)."""

    length: float = 40.0  # a segment: two 20 m halves
    step: float = 20.0  # segment centres every 20 m
    window_min: float = 3.0  # H_win_min
    max_robust_spread: float = 5.0  # σ_r is capped here before the window is set
    min_photons: int = 10  # [-]
    min_spread: float = 20.0  # along track
    max_iterations: int = 20  # [-]
    initial_window: float = 10.0  # the stand-in for ATL03's signal selection


@dataclass(frozen=True)
class Segment:
    """One segment's result; heights [m] in the impulse response's frame, NaN where the segment failed."""

    x: float  # along-track centre [m]
    h_li: float  # h_mean + med_r_fit + fpb_med_corr
    h_mean: float  # least-squares height at the centre
    h_sigma: float  # its standard error: RMS residual × √((GᵀG)⁻¹₀₀)
    slope: float  # dh/dx along track [-]
    n_photons: int  # photons in the final window [-]
    window: float  # final window height H
    med_r_fit: float  # background-corrected median of the residuals
    fpb_med_corr: float  # first-photon-bias correction of the median
    fpb_mean_corr: float  # of the mean
    iterations: int  # [-]
    valid: bool


def robust_spread(residuals, lower: float, upper: float, background_per_m: float) -> float:
    """σ_r of sorted ``residuals`` in the window [lower, upper] with ``background_per_m`` noise photons per metre
    of height removed (ATBD §5.9): where the signal's cumulative count, C(r) − b(r − lower), passes a quarter and
    three quarters of the signal count N − b(upper − lower), their distance over 1.349. With at most one signal
    photon: (upper − lower)/N."""
    r = np.asarray(residuals, dtype=np.float64)
    n_signal = r.size - background_per_m * (upper - lower)
    if n_signal <= 1:
        return (upper - lower) / max(r.size, 1)
    lo, hi = _signal_quantiles(r, lower, background_per_m, n_signal, (0.25, 0.75))
    return (hi - lo) / RDE_SCALE


def _signal_quantiles(r, lower: float, background_per_m: float, n_signal: float, levels) -> list[float]:
    # Photon k holds the cumulative count k + ½ (mid-step), so the quantiles interpolate between photons.
    signal_count = np.maximum.accumulate(np.arange(r.size) + 0.5 - background_per_m * (r - lower))
    return [float(np.interp(level * n_signal, signal_count, r)) for level in levels]


def first_photon_bias(
    residuals,
    window: float,
    n_pulses: int,
    channels: int,
    dead_time_height: float,
    background_per_m: float,
) -> tuple[float, float]:
    """(median, mean) first-photon-bias corrections [m] of residual heights inside |r| < window/2 (Smith et al.
    2019; the ATBD reference code's ``fpb_corr.m``, read-ICESat-2's ``calc_first_photon_bias``).

    The detected photons per pulse and channel give the probability that a channel is dead at r: it recorded a
    photon less than a dead time earlier, i.e. higher by at most ``dead_time_height`` = cτ/2, P(r) = (photons in
    (r, r + cτ/2]) / (pulses · channels), exact for a non-paralysable channel. It records photons in proportion to
    its live time, so each detected photon stands for 1/(1 − P) received ones. The corrections are the (median,
    mean) of the received signal minus those of the detected signal, the background (``background_per_m`` photons
    per metre, all pulses) taken off both (off the detected one thinned by the live fraction). Both medians are
    read between photons, as ``med_r_fit`` is (``_signal_quantiles``): a median binned finer than the photons
    are spaced reads a sparse weak beam's correction 1–2 mm short at night (LIDAR.md §9.4).
    """
    if dead_time_height <= 0:
        return 0.0, 0.0
    half = 0.5 * window
    r = np.sort(np.asarray(residuals, dtype=np.float64))
    r = r[np.abs(r) < half]
    if r.size < 2:
        return 0.0, 0.0
    per_channel = 1.0 / (n_pulses * channels)
    higher = np.searchsorted(r, r + dead_time_height, side="right") - np.searchsorted(r, r, side="right")
    weight = 1.0 / np.clip(1.0 - per_channel * higher, 1e-3, 1.0)
    # Where a photon at r_j leaves its channel dead: [r_j − cτ/2, r_j) inside the window.
    dead_from = np.maximum(r - dead_time_height, -half)
    ends = np.append(r, half)
    dead_below = per_channel * np.clip(np.minimum(ends[:, None], r[None, :]) - dead_from[None, :], 0.0, None).sum(1)
    received_background = background_per_m * (ends + half)  # its cumulative count from the window's bottom
    detected_background = received_background - background_per_m * dead_below
    median = _weighted_median(r, weight, received_background) - _weighted_median(
        r, np.ones(r.size), detected_background
    )
    received = weight.sum() - received_background[-1]
    detected = r.size - detected_background[-1]
    if not (received > 0 and detected > 0):
        return median, 0.0
    dead_moment = per_channel * np.sum(r**2 - dead_from**2) / 2  # ∫ r P(r) dr
    mean = np.dot(weight, r) / received - (r.sum() + background_per_m * dead_moment) / detected
    return median, float(mean)


def _weighted_median(r: np.ndarray, weights: np.ndarray, background: np.ndarray) -> float:
    """The median of sorted photons ``r`` of ``weights`` less a background of cumulative count ``background`` (at
    each photon, then at the window's top): photon k holds the cumulative weight up to half its own, as in
    ``_signal_quantiles``. 0 when the background leaves no signal."""
    total = weights.sum() - background[-1]
    if not total > 0:
        return 0.0
    cumulative = np.maximum.accumulate(np.cumsum(weights) - 0.5 * weights - background[:-1])
    return float(np.interp(0.5 * total, cumulative, r))


def _line_fit(dx: np.ndarray, h: np.ndarray) -> tuple[float, float, float]:
    """(intercept, slope, √((GᵀG)⁻¹₀₀)) of h = a + b·dx by least squares."""
    n, sx, sxx = dx.size, dx.sum(), np.dot(dx, dx)
    det = n * sxx - sx * sx
    if det <= 0:
        return float(np.mean(h)), 0.0, 1.0 / math.sqrt(n)
    sh, sxh = h.sum(), np.dot(dx, h)
    return float((sxx * sh - sx * sxh) / det), float((n * sxh - sx * sh) / det), math.sqrt(sxx / det)


def fit_segment(
    x,
    h,
    x_centre: float,
    n_pulses: int,
    beam: Beam,
    *,
    background_per_m: float,
    sigma_pulse: float,
    dead_time_height: float,
    sigma_beam: float,
    settings: SegmentSettings = SegmentSettings(),
) -> Segment:
    """The ATL06-like height of one segment from its photons' along-track ``x`` and height ``h`` [m] (module
    docstring, steps 1–4). ``background_per_m``: expected noise photons per metre of height in the segment (all
    its pulses); ``sigma_pulse``: the pulse's σ in height; ``sigma_beam``: the footprint's σ on the ground;
    ``dead_time_height``: cτ/2 of the channels (0: no first-photon-bias correction)."""
    x = np.asarray(x, dtype=np.float64)
    h = np.asarray(h, dtype=np.float64)
    nan = math.nan
    failed = Segment(x_centre, nan, nan, nan, nan, 0, nan, nan, nan, nan, 0, False)
    if h.size < settings.min_photons:
        return failed
    dx = x - x_centre
    density, edges = np.histogram(h, bins=max(1, math.ceil(np.ptp(h) / 1.0)))
    mode = 0.5 * (edges[np.argmax(density)] + edges[np.argmax(density) + 1])
    selected = np.abs(h - mode) <= 0.5 * settings.initial_window

    def usable(chosen: np.ndarray) -> bool:
        return bool(chosen.sum() >= settings.min_photons and np.ptp(x[chosen]) >= settings.min_spread)

    if not usable(selected):
        return failed
    window = math.nan  # the last window computed
    chosen_by = settings.initial_window  # the window that made the current selection
    iterations = 0
    while iterations < settings.max_iterations:
        iterations += 1
        h_mean, slope, scale = _line_fit(dx[selected], h[selected])
        residuals = h - h_mean - slope * dx
        chosen = np.sort(residuals[selected])
        if math.isnan(window):
            lower, upper = float(chosen[0]), float(chosen[-1])  # §5.5 p4c: the initial selection's spread
            window = upper - lower
        else:
            lower, upper = -0.5 * window, 0.5 * window
        spread = min(robust_spread(chosen, lower, upper, background_per_m), settings.max_robust_spread)
        expected = math.hypot(sigma_pulse, sigma_beam * slope)
        window = max(settings.window_min, 6.0 * expected, 6.0 * spread, 0.75 * window)
        now = np.abs(residuals) < 0.5 * window
        if not usable(now):
            break  # keep the last usable selection and its window, as the ATBD's reference code does
        chosen_by = window
        if np.array_equal(now, selected):
            break
        selected = now
    window = chosen_by
    h_mean, slope, scale = _line_fit(dx[selected], h[selected])
    residuals = h - h_mean - slope * dx
    inside = np.sort(residuals[selected])
    n_signal = inside.size - background_per_m * window
    median = _signal_quantiles(inside, -0.5 * window, background_per_m, n_signal, (0.5,))[0] if n_signal > 1 else 0.0
    fpb_median, fpb_mean = first_photon_bias(
        inside, window, n_pulses, beam.channels, dead_time_height, background_per_m
    )
    misfit = math.sqrt(float(np.mean(inside**2)))
    return Segment(
        x=x_centre,
        h_li=h_mean + median + fpb_median,
        h_mean=h_mean,
        h_sigma=misfit * scale,
        slope=slope,
        n_photons=int(inside.size),
        window=window,
        med_r_fit=median,
        fpb_med_corr=fpb_median,
        fpb_mean_corr=fpb_mean,
        iterations=iterations,
        valid=True,
    )


@dataclass(frozen=True)
class Track:
    """Per-segment results of a simulated track (arrays over segments, named as ``Segment``'s fields), the
    surface offset at each centre [m] and the photon count of the whole track."""

    segments: dict[str, np.ndarray]
    surface_offset: np.ndarray
    photons: int
    shots: int


def track(
    impulses,
    bin_width_opl: float,
    reference_height: float,
    length: float,
    beam: Beam,
    *,
    seed: int,
    budget: LinkBudget = LinkBudget(),
    background_hz: float = 0.0,
    dead_time: bool = True,
    window: tuple[float, float] = (-15.0, 15.0),
    slope: float = 0.0,
    impulse_spacing: float | None = None,
    footprint_diameter: float = 11.0,
    settings: SegmentSettings = SegmentSettings(),
) -> Track:
    """Simulate ``length`` metres of track (a shot every ``budget.shot_spacing``) over a surface given by its
    impulse response(s) (``draw_shots``) tilted by ``slope`` along track, and find its surface per segment.

    With several impulse responses (n, bins), the shot at x sees number ⌊x/impulse_spacing⌋ mod n: footprints
    rendered at successive positions along the track. The true surface of a segment is the impulse response's
    reference surface plus ``surface_offset`` (slope × centre).
    """
    shots = np.arange(int(math.floor(length / budget.shot_spacing)) + 1)
    along = shots * budget.shot_spacing
    table = np.atleast_2d(np.asarray(impulses, dtype=np.float64))
    which = None
    if table.shape[0] > 1:
        if impulse_spacing is None:
            raise ValueError("several impulse responses need impulse_spacing, the distance between their footprints")
        which = np.floor(along / impulse_spacing).astype(np.int64) % table.shape[0]
    events: PhotonEvents = draw_shots(
        shots,
        table,
        bin_width_opl,
        reference_height,
        beam,
        seed=seed,
        budget=budget,
        background_hz=background_hz,
        window=window,
        surface_offset=slope * along,
        impulse_index=which,
        dead_time=dead_time,
    )
    x = events.shot * budget.shot_spacing
    background_per_m = background_hz * 2.0 / SPEED_OF_LIGHT  # per pulse and metre of height
    sigma_pulse = 0.5 * pulse_sigma_opl(budget.pulse_fwhm_ns)
    centres = np.arange(settings.step, length - 0.5 * settings.length + 1e-9, settings.step)
    results = []
    for centre in centres:
        bounds = (centre - 0.5 * settings.length, centre + 0.5 * settings.length)  # [low, high) along track
        start, stop = np.searchsorted(x, bounds)
        first_shot, end_shot = np.searchsorted(along, bounds)
        pulses = int(end_shot - first_shot)
        results.append(
            fit_segment(
                x[start:stop],
                events.height[start:stop],
                float(centre),
                pulses,
                beam,
                background_per_m=background_per_m * pulses,
                sigma_pulse=sigma_pulse,
                sigma_beam=footprint_diameter / 4.0,
                dead_time_height=0.5 * beam.dead_time_opl if dead_time else 0.0,
                settings=settings,
            )
        )
    names = [f.name for f in fields(Segment)]
    segments = {name: np.array([getattr(r, name) for r in results]) for name in names}
    return Track(segments, slope * centres, len(events), int(shots.size))


__all__ = ["Segment", "SegmentSettings", "Track", "first_photon_bias", "fit_segment", "robust_spread", "track"]
