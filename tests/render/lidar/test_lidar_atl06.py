"""The ATL06-like surface finder (render/lidar/atl06.py, LIDAR.md §9.3) on simulated tracks over a bare
Lambertian plane, whose true height is known: unbiased without dead time and background, the first-photon-bias
correction against a dead-time bias it can be seen to remove, and the window against daylight background; the
correction of a sparse weak beam against its known shift, why the weak beam reads lower by day, and the README's
copy of the ATL06-like table.

Standard errors of a track's mean height come from every other segment (segments overlap by half)."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np

from render.lidar.atl06 import first_photon_bias, robust_spread, track
from render.lidar.photons import STRONG, WEAK, Beam, PhotonEvents, apply_dead_time, background_rate, draw_shots
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


def test_the_first_photon_bias_of_a_sparse_weak_beam():
    """The weak beam at night over a snow-like return (the pulse, σ 9.5 cm in height, on an exponential delay of
    3 cm): 0.2 photons a channel and pulse, 4 channels, 57 pulses a segment, so about 45 photons 6 mm apart at the
    median. Over 3000 segments the correction matches the dead time's true shift of the median (received photons'
    median minus detected photons', known here) within 3 standard errors and 0.5 mm. Medians read on a 2.5 mm
    histogram, as before, fell 0.8–1.3 mm short (LIDAR.md §9.4)."""
    rng = np.random.default_rng(8)
    segments, pulses, channels = 3000, 57, 4
    counts = rng.poisson(0.2, size=segments * pulses * channels)
    channel_pulse = np.repeat(np.arange(counts.size), counts)  # (segment, pulse, channel), flattened
    height = 0.095 * rng.standard_normal(channel_pulse.size) - rng.exponential(0.03, channel_pulse.size)
    channel = (channel_pulse % channels).astype(np.int16)
    received = PhotonEvents(channel_pulse // channels, height, channel, np.ones(height.size, bool))
    detected = apply_dead_time(received, WEAK.dead_time_opl)
    starts = np.arange(pulses, segments * pulses, pulses)
    errors = []
    for every, kept in zip(
        np.split(received.height, np.searchsorted(received.shot, starts)),
        np.split(detected.height, np.searchsorted(detected.shot, starts)),
        strict=True,
    ):
        correction, _ = first_photon_bias(kept, 3.0, pulses, channels, 0.5 * WEAK.dead_time_opl, 0.0)
        errors.append(correction - (np.median(every) - np.median(kept)))
    bias, error = float(np.mean(errors)), float(np.std(errors, ddof=1) / math.sqrt(segments))
    assert error < 2e-4
    assert abs(bias) < 3 * error and abs(bias) < 5e-4, (bias, error)


def test_day_background_doubles_the_weak_beams_slope_error():
    """Why the weak beam reads lower by day (LIDAR.md §9.4): ATL06's median is taken about a line fitted to the
    same photons, and by day the few background photons in its window make the weak beam's along-track slope
    over 2.5 times as uncertain (4 km of a skewed return, sun 30° up), the strong beam's under 2.5 times. The
    residuals are smeared by the slope's error, and a smeared skewed return's median moves toward its mean."""
    k = np.arange(400)
    impulse = np.exp(-k * BIN / 0.06)
    impulse *= (ALBEDO / math.pi) / impulse.sum()
    rate = background_rate(ALBEDO, 30.0)
    growth = {}
    for beam in (WEAK, STRONG):
        night, day = (
            track(impulse, BIN, Z_REF, 4000.0, beam, seed=41, background_hz=hz, dead_time=False).segments["slope"]
            for hz in (0.0, rate)
        )
        growth[beam.name] = float(np.std(day) / np.std(night))
    assert growth["weak"] > 2.5 > growth["strong"], growth


def test_the_readme_shows_the_atl06_table(monkeypatch):
    """The README's lidar section holds the ATL06-like table for snow and penitentes (issue 51), exactly as
    benchmarks/atl06_track.py writes it from benchmarks/results/atl06.csv, so it cannot go stale unnoticed."""
    benchmarks = Path(__file__).resolve().parents[3] / "benchmarks"
    monkeypatch.syspath_prepend(str(benchmarks))  # the script imports its sibling _results
    spec = importlib.util.spec_from_file_location("atl06_track", benchmarks / "atl06_track.py")
    assert spec is not None and spec.loader is not None
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    rows = script.csv_rows()
    assert {"flat", "penitentes"} <= {row["surface"].split(",")[0].split(" ")[0] for row in rows}
    readme = script.README.read_text(encoding="utf-8")
    assert script.readme_with_table(readme, rows) == readme, (
        "README.md's ATL06 table differs from benchmarks/results/atl06.csv: run "
        "`python benchmarks/atl06_track.py --readme`"
    )
