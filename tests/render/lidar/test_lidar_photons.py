"""Photon counting (render/lidar/photons.py, LIDAR.md §9.2): per-shot counts against the link budget and
Poisson, the background against its rate, the arrival times against the pulse, the dead time against the
first-arrival law, and streams that do not depend on how the shots are chunked."""

from __future__ import annotations

import math

import numpy as np

from render.lidar.photons import (
    STRONG,
    WEAK,
    Beam,
    LinkBudget,
    background_rate,
    draw_shots,
    signal_photons_per_shot,
)
from render.lidar.waveform import pulse_sigma_opl, surface_impulse

BIN = 0.005  # OPL [m]
Z_REF = 0.5  # the reference plane stands 0.5 m above the plane z = 0
ALBEDO = 0.9


def plane(albedo: float = ALBEDO) -> np.ndarray:
    """A bare Lambertian plane at z = 0 seen from z_ref: one bin holding albedo/π [sr⁻¹]."""
    return surface_impulse(0.0, albedo / math.pi, Z_REF, 0.0, BIN, 400)


def test_the_link_budget_is_the_radar_equation():
    """N̄ = N_tx·share · (a/π) · (πD²/4)/R² · T² η_opt η_det, written out with the preset's numbers: 2.80 photons a
    shot for the strong beam over a plane of albedo 0.9, a quarter of that for the weak beam."""
    photons_strong = 300e12 * 4 / 15
    expected = photons_strong * (ALBEDO / math.pi) * (math.pi * 0.4**2) / (500e3) ** 2 * 0.9**2 * 0.5 * 0.15
    assert math.isclose(signal_photons_per_shot(plane(), STRONG), expected, rel_tol=1e-12)
    assert math.isclose(expected, 2.799, rel_tol=1e-3)
    assert math.isclose(signal_photons_per_shot(plane(), WEAK), expected / 4, rel_tol=1e-12)


def test_signal_counts_per_shot_are_poisson_with_the_link_budget_mean():
    """6000 strong-beam shots, no dead time, no background: the mean count is N̄ within 4 standard errors
    (√(N̄/n)), and the sample variance is N̄ within 4 of its standard errors (√((N̄ + 2N̄²)/n), Poisson's fourth
    moment), so counts are Poisson, not merely of the right mean."""
    shots = 6000
    events = draw_shots(np.arange(shots), plane(), BIN, Z_REF, STRONG, seed=11, dead_time=False)
    counts = np.bincount(events.shot, minlength=shots)
    mean = signal_photons_per_shot(plane(), STRONG)
    assert abs(counts.mean() - mean) < 4 * math.sqrt(mean / shots)
    assert abs(counts.var(ddof=1) - mean) < 4 * math.sqrt((mean + 2 * mean**2) / shots)
    assert events.signal.all()


def test_background_counts_follow_the_rate_and_fill_the_window_evenly():
    """Day background over snow (sun 30° up): R = E sin e Δλ T (a/π) Ω A T η / (hν) ≈ 3.5 MHz; over a 30 m window
    (200 ns) that is 0.70 photons a shot, Poisson, uniform in height (mean at the window's centre within 4 SE)."""
    rate = background_rate(ALBEDO, 30.0)
    assert 3.0e6 < rate < 4.0e6
    assert background_rate(ALBEDO, None) == 0.0
    shots = 4000
    window = (-10.0, 20.0)
    events = draw_shots(
        np.arange(shots), plane(), BIN, Z_REF, STRONG, seed=5, background_hz=rate, window=window, dead_time=False
    )
    noise = ~events.signal
    counts = np.bincount(events.shot[noise], minlength=shots)
    mean = rate * 2 * 30.0 / 299_792_458.0
    assert abs(counts.mean() - mean) < 4 * math.sqrt(mean / shots)
    heights = events.height[noise]
    assert abs(heights.mean() - 5.0) < 4 * 30.0 / math.sqrt(12 * heights.size)


def test_signal_heights_spread_as_the_pulse():
    """Photons off a bare plane land at its bin's centre with the pulse's spread in range: σ² = (σ_pulse/2)² plus
    a bin's uniform (w/2)²/12 (σ_pulse the pulse's σ in OPL); mean and σ within 4 standard errors."""
    events = draw_shots(np.arange(3000), plane(), BIN, Z_REF, STRONG, seed=2, dead_time=False)
    sigma = math.sqrt((0.5 * pulse_sigma_opl(1.5)) ** 2 + (BIN / 2) ** 2 / 12)
    k = int(np.flatnonzero(plane())[0])
    centre = Z_REF - 0.5 * (k + 0.5) * BIN  # within a bin (w/2 of range) of the plane z = 0
    assert abs(centre) <= BIN / 2
    assert abs(events.height.mean() - centre) < 4 * sigma / math.sqrt(events.height.size)
    assert abs(events.height.std() / sigma - 1) < 4 / math.sqrt(2 * events.height.size)


def test_dead_time_keeps_one_photon_per_channel_for_a_pulse_shorter_than_it():
    """A 1.5 ns pulse is shorter than the 3.2 ns dead time, so a channel records the first of its photons and no
    other within the pulse: the recorded count per shot is n(1 − e^(−m/n)) with m photons over n channels (4 SE),
    and no channel records two photons within the dead time (cτ/2 = 48 cm of height apart at least)."""
    bright = Beam("bright", STRONG.energy_share * 4, 16, 3.2)
    shots = 3000
    events = draw_shots(np.arange(shots), plane(), BIN, Z_REF, bright, seed=9, dead_time=True)
    m = signal_photons_per_shot(plane(), bright)
    expected = 16 * (1 - math.exp(-m / 16))
    counts = np.bincount(events.shot, minlength=shots)
    assert m > 10
    assert abs(counts.mean() - expected) < 4 * math.sqrt(expected / shots)
    order = np.lexsort((-events.height, events.shot * 16 + events.channel))
    key, height = (events.shot * 16 + events.channel)[order], events.height[order]
    same = key[1:] == key[:-1]
    assert np.all(height[:-1][same] - height[1:][same] >= 0.5 * bright.dead_time_opl)
    assert same.sum() < 0.01 * key.size  # two photons 48 cm apart in one shot: the pulse's far tails only


def test_a_shot_draws_the_same_photons_in_any_chunk():
    """Streams are keyed by (seed, shot index): shots 40–79 drawn alone equal the same shots drawn among 0–79,
    dead time and background included; another seed draws other photons."""
    rate = background_rate(ALBEDO, 30.0)
    whole = draw_shots(np.arange(80), plane(), BIN, Z_REF, STRONG, seed=3, background_hz=rate)
    part = draw_shots(np.arange(40, 80), plane(), BIN, Z_REF, STRONG, seed=3, background_hz=rate)
    later = whole.shot >= 40
    assert np.array_equal(whole.height[later], part.height)
    assert np.array_equal(whole.channel[later], part.channel)
    other = draw_shots(np.arange(40, 80), plane(), BIN, Z_REF, STRONG, seed=4, background_hz=rate)
    assert not np.array_equal(other.height[: min(len(other), len(part))], part.height[: min(len(other), len(part))])


def test_the_preset_says_where_its_numbers_come_from():
    """The strong and weak beams: 16 and 4 channels, 3.2 ns dead time, 4:1 in energy; the pulse leaves 300 trillion
    photons; the telescope is 0.8 m at 500 km (LIDAR.md §9.1 cites each)."""
    budget = LinkBudget()
    assert (STRONG.channels, WEAK.channels) == (16, 4)
    assert STRONG.energy_share / WEAK.energy_share == 4
    assert 3 * (STRONG.energy_share + WEAK.energy_share) == 1
    assert (budget.photons_per_pulse, budget.telescope_diameter, budget.altitude) == (300e12, 0.8, 500e3)
    assert math.isclose(STRONG.dead_time_opl, 0.9593, rel_tol=1e-3)
