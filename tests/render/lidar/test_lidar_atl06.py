"""The ATL06-like surface finder (render/lidar/atl06.py, LIDAR.md §9.3) on simulated tracks over a bare
Lambertian plane, whose true height is known: unbiased without dead time and background, the first-photon-bias
correction against a dead-time bias it can be seen to remove, and the window against daylight background.

Standard errors of a track's mean height come from every other segment (segments overlap by half)."""

from __future__ import annotations

import math

import numpy as np

from render.lidar.atl06 import first_photon_bias, robust_spread, track
from render.lidar.photons import STRONG, Beam, background_rate, draw_shots
from render.lidar.waveform import surface_impulse

BIN = 0.005  # OPL [m]
Z_REF = 0.5
ALBEDO = 0.9
IMPULSE = surface_impulse(0.0, ALBEDO / math.pi, Z_REF, 0.0, BIN, 400)
K = int(np.flatnonzero(IMPULSE)[0])
PLANE = Z_REF - 0.5 * (K + 0.5) * BIN  # the bin centre the plane at z = 0 is rendered into (within w/2 of 0)


def mean_and_error(values: np.ndarray) -> tuple[float, float]:
    """Mean of the segments' values and its standard error from non-overlapping segments."""
    independent = values[::2]
    return float(values.mean()), float(independent.std(ddof=1) / math.sqrt(independent.size))


def test_robust_spread_sees_through_uniform_background():
    """2000 Gaussian residuals (σ = 0.1 m) and 3000 uniform over a 10 m window: the background-corrected spread
    is σ within 5 %, where the raw interquartile range/1.349 would read metres."""
    rng = np.random.default_rng(1)
    signal = 0.1 * rng.standard_normal(2000)
    noise = rng.uniform(-5, 5, 3000)
    residuals = np.sort(np.concatenate((signal, noise)))
    spread = robust_spread(residuals, -5.0, 5.0, 3000 / 10.0)
    assert abs(spread / 0.1 - 1) < 0.05
    assert (np.percentile(residuals, 75) - np.percentile(residuals, 25)) / 1.349 > 1.0


def test_no_dead_time_and_no_background_give_zero_bias_within_the_standard_error():
    """A strong beam over 2 km of a bare plane tilted 1 % along track, dead time and background off: 99
    segments, h_li − true height zero within 3 standard errors (about 1.4 mm), the slope within 3·10⁻⁴, the
    first-photon-bias correction exactly 0, and the window at its 3 m floor."""
    result = track(IMPULSE, BIN, Z_REF, 2000.0, STRONG, seed=21, dead_time=False, slope=0.01)
    s = result.segments
    assert s["valid"].all() and s["valid"].size == 99
    bias, error = mean_and_error(s["h_li"] - PLANE - result.surface_offset)
    assert abs(bias) < 3 * error, (bias, error)
    assert error < 0.002
    assert np.all(s["fpb_med_corr"] == 0)
    assert abs(s["slope"].mean() - 0.01) < 3e-4
    assert np.all(s["window"] == 3.0)


def test_first_photon_bias_correction_removes_the_dead_time_bias():
    """A beam of 11 photons a shot over 16 channels with 3.2 ns of dead time (4x the strong beam's energy: the rate
    the ATBD's reference test data give a white surface, 12 over 16 channels): each channel keeps only its first photon, so the heights come out high. Without the correction
    the segments read more than 1 cm high; with it the bias is within 1 cm and within 3 standard errors."""
    bright = Beam("bright", STRONG.energy_share * 4, 16, 3.2)
    result = track(IMPULSE, BIN, Z_REF, 2000.0, bright, seed=22, dead_time=True)
    s = result.segments
    assert s["valid"].all()
    corrected, error = mean_and_error(s["h_li"] - PLANE)
    uncorrected = float(np.mean(s["h_li"] - s["fpb_med_corr"] - PLANE))
    assert uncorrected > 0.01, uncorrected
    assert abs(corrected) < 0.01
    assert abs(corrected) < 3 * error, (corrected, error)
    assert np.all(s["fpb_med_corr"] < 0)


def test_the_window_rejects_day_background():
    """Day background over bright snow (sun 60° up, 5.7 MHz): 1.1 noise photons a shot over a telemetry window
    from 5 m below to 25 m above the plane. The mean of all photons reads metres high (the test can fail), the
    refined window stays within a few metres, and h_li is unbiased within 3 standard errors."""
    rate = background_rate(ALBEDO, 60.0)
    assert rate > 5e6
    window = (-5.0, 25.0)
    result = track(IMPULSE, BIN, Z_REF, 2000.0, STRONG, seed=23, dead_time=False, background_hz=rate, window=window)
    s = result.segments
    assert s["valid"].all()
    photons = draw_shots(
        np.arange(result.shots),
        IMPULSE,
        BIN,
        Z_REF,
        STRONG,
        seed=23,
        dead_time=False,
        background_hz=rate,
        window=window,
    )
    assert result.photons == len(photons)
    assert photons.height.mean() > 2.0  # (1.1 × 10 m + 2.8 × 0 m)/3.9 ≈ 2.9 m: the background's pull
    bias, error = mean_and_error(s["h_li"] - PLANE)
    assert abs(bias) < 3 * error, (bias, error)
    assert np.all(s["window"] < 5.0)


def test_the_first_photon_bias_of_a_known_histogram():
    """Detected photons of a box 0.2 m tall at 0.5 photons a channel and pulse: a channel that fired is dead for
    the 0.45 m below, so with the box shorter than that the detected density falls as 1 − (photons above); the
    correction brings the median back to the box's centre within a bin, lowering it (negative)."""
    rng = np.random.default_rng(4)
    pulses, channels, per_channel = 400, 16, 0.5
    # draw received photons, apply the first-arrival rule per (pulse, channel), keep the recorded heights
    counts = rng.poisson(per_channel, size=(pulses, channels))
    recorded = [rng.uniform(-0.1, 0.1, n).max() for n in counts.ravel() if n > 0]
    median, mean = first_photon_bias(np.array(recorded), 3.0, pulses, channels, 0.45, 0.0)
    assert median < 0 and mean < 0
    assert abs(np.median(recorded) + median) < 0.01
