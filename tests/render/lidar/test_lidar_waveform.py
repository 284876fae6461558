"""Pulses, range estimators and reference heights of render/lidar/waveform.py (LIDAR.md §4).

Axes are in metres of round-trip OPL; ranges come back as OPL/2.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest

from common.units import NS_PER_M_OPL
from render.lidar.diffusion import DiffusionMedium, bin_average, mean_path_length, total_reflectance
from render.lidar.waveform import (
    ESTIMATORS,
    RangeEstimationError,
    bias_table,
    centroid_range,
    convolve_pulse,
    estimate_ranges,
    first_return_range,
    footprint_weights,
    gaussian_fit_range,
    gaussian_pulse,
    median_range,
    peak_range,
    pulse_kernel,
    pulse_sigma_opl,
    reference_heights,
    rms_width_range,
    surface_impulse,
)

WIDTH = 5e-3  # bin width, m of OPL
FWHM_NS = 1.0  # sigma = 0.1273 m of OPL, 25 bins


def _delta(bins: int, at: int) -> np.ndarray:
    impulse = np.zeros(bins)
    impulse[at] = 1.0
    return impulse


def test_pulse_width_and_energy():
    sigma = pulse_sigma_opl(FWHM_NS)
    assert sigma == pytest.approx(1e-9 * 299_792_458.0 / (2 * math.sqrt(2 * math.log(2))), rel=1e-12)
    pulse = gaussian_pulse(-2.0, WIDTH, 800, FWHM_NS, centre_opl=0.0123)
    assert pulse.sum() == pytest.approx(1.0, abs=1e-14)
    centres = -2.0 + (np.arange(800) + 0.5) * WIDTH
    mean = np.sum(pulse * centres)
    assert mean == pytest.approx(0.0123, abs=1e-12)
    # Sheppard: bin integrals of a Gaussian have variance sigma^2 + w^2/12 about bin centres.
    assert np.sum(pulse * (centres - mean) ** 2) == pytest.approx(sigma**2 + WIDTH**2 / 12, rel=1e-9)
    kernel = pulse_kernel(WIDTH, FWHM_NS)
    assert kernel.size % 2 == 1 and kernel.sum() == pytest.approx(1.0, abs=1e-15)
    assert kernel.size // 2 == math.ceil(8 * sigma / WIDTH)
    np.testing.assert_array_equal(kernel, kernel[::-1])
    assert gaussian_pulse(0.0, 1.0, 4, 0.0, centre_opl=2.5).tolist() == [0.0, 0.0, 1.0, 0.0]


def test_convolution_conserves_energy_and_says_what_the_edges_lose():
    half = pulse_kernel(WIDTH, FWHM_NS).size // 2
    rng = np.random.default_rng(3)
    bins = 1200
    impulse = np.zeros((bins, 2, 3))
    impulse[half : bins - half] = rng.random((bins - 2 * half, 2, 3))
    out = convolve_pulse(impulse, WIDTH, FWHM_NS)
    assert out.shape == impulse.shape and out.dtype == np.float64
    np.testing.assert_allclose(out.sum(axis=0), impulse.sum(axis=0), rtol=1e-12)
    # An impulse in the first bin keeps only the half of the pulse that falls inside the axis.
    edge = convolve_pulse(_delta(bins, 0), WIDTH, FWHM_NS)
    kernel = pulse_kernel(WIDTH, FWHM_NS)
    assert edge.sum() == pytest.approx(kernel[half:].sum(), rel=1e-12)
    # float32 films stay float32; a zero width returns the impulse unchanged.
    assert convolve_pulse(impulse.astype(np.float32), WIDTH, FWHM_NS).dtype == np.float32
    np.testing.assert_array_equal(convolve_pulse(impulse, WIDTH, 0.0), impulse)
    # The pulse on any axis: time last gives the same numbers.
    moved = convolve_pulse(np.moveaxis(impulse, 0, -1), WIDTH, FWHM_NS, axis=-1)
    np.testing.assert_allclose(np.moveaxis(moved, -1, 0), out, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("fwhm_ns", [FWHM_NS, 0.01])
def test_a_delta_through_a_pulse_has_zero_bias_for_every_estimator_and_shifts_exactly(fwhm_ns):
    """A bare flat surface (one delta) seen through the pulse: every estimator returns its range; moving the
    delta by k bins moves every estimate by k w/2. fwhm 0.01 ns is 3 mm of OPL, narrower than a bin."""
    start, bins, at = 10.0, 1000, 500
    surface_range = 0.5 * (start + (at + 0.5) * WIDTH)
    for shift in (0, 7, -123):
        waveform = convolve_pulse(_delta(bins, at + shift), WIDTH, fwhm_ns)
        estimates = estimate_ranges(waveform, start, WIDTH, pulse_fwhm_ns=fwhm_ns, strict=True)
        expected = surface_range + 0.5 * shift * WIDTH
        for name, value in estimates.ranges().items():
            assert value == pytest.approx(expected, abs=1e-9), name
    # Uncalibrated, the leading edge is early by the pulse's own lead: HWHM in OPL, HWHM/2 in range.
    waveform = convolve_pulse(_delta(bins, at), WIDTH, FWHM_NS)
    raw = first_return_range(waveform, start, WIDTH)
    hwhm_range = 0.5 * (0.5 * FWHM_NS / NS_PER_M_OPL)
    assert surface_range - raw == pytest.approx(hwhm_range, rel=2e-3)


def test_second_moments_of_pulse_and_surface_spread_add():
    """A tilted flat surface spreads the heights under the footprint; the waveform's variance is the pulse's plus
    the spread's. Exact for a discrete uniform spread of heights on bin centres; for a tilted plane under a
    Gaussian footprint, σ_h = slope·D/4 and the histogram adds w²/12 in OPL (Sheppard)."""
    start, bins, z_ref = 0.0, 3000, 10.0
    kernel = pulse_kernel(WIDTH, FWHM_NS)
    pulse_rms = rms_width_range(np.pad(kernel, 10), 0.0, WIDTH)
    # Uniform heights: 101 levels one bin (w/2 in height) apart, centred on OPL bin 1500.
    levels = np.arange(-50, 51)
    heights = z_ref - 0.5 * (start + (1500 + levels + 0.5) * WIDTH)
    impulse = surface_impulse(heights, 1.0, z_ref, start, WIDTH, bins)
    assert impulse.sum() == 101 and impulse.max() == 1
    spread = 0.5 * WIDTH * math.sqrt((101**2 - 1) / 12)
    assert rms_width_range(impulse, start, WIDTH) == pytest.approx(spread, rel=1e-12)
    waveform = convolve_pulse(impulse, WIDTH, FWHM_NS)
    assert rms_width_range(waveform, start, WIDTH) ** 2 == pytest.approx(pulse_rms**2 + spread**2, rel=1e-10)
    # Tilted plane h = z0 + s x on a fine grid under a Gaussian footprint of 1/e^2 diameter D.
    slope, diameter, spacing = 0.2, 4.0, 0.01
    n = 1600  # 16 m: the footprint's images are e^-32 down
    x = np.arange(n) * spacing
    plane = 5.0 + slope * (x - 8.0)[None, :] * np.ones((n, 1))
    weights = footprint_weights(plane.shape, spacing, diameter, (8.0, 8.0))
    impulse = surface_impulse(plane, weights, z_ref, start, WIDTH, bins)
    sigma_h = slope * diameter / 4
    expected_spread2 = sigma_h**2 + (0.5 * WIDTH) ** 2 / 12
    assert rms_width_range(impulse, start, WIDTH) ** 2 == pytest.approx(expected_spread2, rel=2e-3)
    waveform = convolve_pulse(impulse, WIDTH, FWHM_NS)
    assert rms_width_range(waveform, start, WIDTH) ** 2 == pytest.approx(pulse_rms**2 + expected_spread2, rel=2e-3)


def test_gaussian_fit_recovers_a_noisy_gaussian():
    """Photon counts (Poisson) of a Gaussian of σ = 20 bins and 4·10⁴ expected photons: the centre's standard
    error is σ/√N ≈ 0.1 bin and the width's σ/√(2N) ≈ 0.07 bin; we allow 5 standard errors."""
    rng = np.random.default_rng(2029)
    bins, start = 400, 3.0
    centre, sigma, photons = 3.0 + 187.3 * WIDTH, 20 * WIDTH, 4e4
    expected = photons * gaussian_pulse(start, WIDTH, bins, sigma / pulse_sigma_opl(1.0), centre)
    counts = rng.poisson(expected).astype(float)
    fit_centre, fit_sigma = gaussian_fit_range(counts, start, WIDTH)
    n = counts.sum()
    # The fit sees bin integrals: their width is √(σ² + w²/12).
    assert abs(2 * fit_centre - centre) <= 5 * sigma / math.sqrt(n)
    assert abs(2 * fit_sigma - math.sqrt(sigma**2 + WIDTH**2 / 12)) <= 5 * sigma / math.sqrt(2 * n)
    estimates = estimate_ranges(counts, start, WIDTH)
    assert estimates.gaussian_fit == fit_centre and not estimates.failures


def test_a_fit_that_fails_is_reported_not_hidden():
    ramp = np.linspace(0.0, 1.0, 50)  # still rising at the end of the window: no Gaussian inside it
    with pytest.raises(RangeEstimationError, match="Gaussian fit"):
        gaussian_fit_range(ramp, 0.0, WIDTH)
    estimates = estimate_ranges(ramp, 0.0, WIDTH)
    assert math.isnan(estimates.gaussian_fit)
    assert estimates.failures and estimates.failures[0][0] == "gaussian_fit"
    assert "median or centroid" in estimates.failures[0][1]
    with pytest.raises(RangeEstimationError):
        estimate_ranges(ramp, 0.0, WIDTH, strict=True)
    with pytest.raises(RangeEstimationError, match="start the axis earlier"):
        first_return_range(ramp[::-1], 0.0, WIDTH)
    with pytest.raises(RangeEstimationError, match="no energy"):
        estimate_ranges(np.zeros(10), 0.0, WIDTH)
    with pytest.raises(ValueError, match="threshold"):
        first_return_range(ramp, 0.0, WIDTH, threshold=1.5)
    with pytest.raises(ValueError, match="bin_width_opl"):
        peak_range(ramp, 0.0, -1.0)


def test_estimators_on_hand_made_waveforms():
    # Three bins 1, 3, 2: parabola vertex at +0.5·(1 − 2)/(1 − 6 + 2) = +1/6 bin from the middle one.
    y = np.array([0.0, 1.0, 3.0, 2.0, 0.0])
    assert peak_range(y, 0.0, 1.0) == pytest.approx(0.5 * (2.5 + 1 / 6))
    assert centroid_range(y, 0.0, 1.0) == pytest.approx(0.5 * (1.5 * 1 + 2.5 * 3 + 3.5 * 2) / 6)
    # Half of 6 is reached inside bin 2 (edges 2..3): 1 before it, 2 of its 3 needed.
    assert median_range(y, 0.0, 1.0) == pytest.approx(0.5 * (2 + 2 / 3))
    # Threshold 0.5 of 3 = 1.5, crossed between centres 1.5 (1.0) and 2.5 (3.0): at 1.75.
    assert first_return_range(y, 0.0, 1.0) == pytest.approx(0.5 * 1.75)
    assert first_return_range(y, 0.0, 1.0, threshold=0.25) == pytest.approx(0.5 * (0.5 + 0.75))


def test_centroid_bias_of_a_diffuse_return_is_half_the_mean_path():
    """The diffusion impulse response of a half-space through a pulse: the centroid lies ⟨L⟩/2 below the
    surface (LIDAR.md §4.2), for both boundaries. An absorbing medium keeps the tail inside 40 m of OPL."""
    surface_opl, width, bins = 2.0, 1e-3, 42000
    start = surface_opl - 1.0
    for medium in (DiffusionMedium(100.0, 1.0, "zero"), DiffusionMedium(100.0, 1.0, "extrapolated")):
        impulse = width * bin_average(partial(total_reflectance, medium), start, width, bins, surface_opl=surface_opl)
        waveform = convolve_pulse(impulse, width, 1.5)
        bias = centroid_range(waveform, start, width) - 0.5 * surface_opl
        assert bias == pytest.approx(0.5 * mean_path_length(medium), rel=1e-4)
        estimates = estimate_ranges(waveform, start, width, pulse_fwhm_ns=1.5)
        # The tail pulls the later estimators further down.
        assert estimates.first_return < estimates.peak < estimates.median < estimates.centroid


def test_reference_heights_on_a_tilted_plane():
    spacing, n = 0.05, 400  # 20 m field; footprint of 2 m at its middle, images e^-50 down
    x = np.arange(n) * spacing
    plane = 1.0 + 0.3 * x[None, :] * np.ones((n, 1))
    centre = (10.0, 7.5)
    refs = reference_heights(plane, spacing, 2.0, centre)
    assert refs.footprint_mean == pytest.approx(1.0 + 0.3 * 10.0, abs=1e-12)
    assert refs.highest == pytest.approx(1.0 + 0.3 * (10.0 + 1.0), abs=1e-12)  # the sample at +D/2 is inside
    assert refs.flat_equivalent == pytest.approx(plane.mean(), abs=1e-12)
    off_grid = reference_heights(plane, spacing, 1.98, (10.0, 7.5))
    assert off_grid.highest == pytest.approx(1.0 + 0.3 * (10.0 + 0.95), abs=1e-12)


@pytest.mark.parametrize("diameter", [0.4, 2.0, 6.0, 30.0])
def test_reference_heights_of_a_periodic_field_narrower_and_wider_than_the_footprint(diameter):
    """h = h0 + a cos(2πx/P) + b cos(2πy/P) on one period P = 2 m: the wrapped Gaussian of σ = D/4 averages each
    cosine to e^(−2π²σ²/P²) of itself (Poisson summation), whether the footprint is narrower or wider than the
    field; the highest sample within D/2 is the crest once the disc covers a whole period."""
    period, n = 2.0, 64
    spacing = period / n
    coords = np.arange(n) * spacing
    h0, a, b = 0.4, 0.3, 0.1
    field = h0 + a * np.cos(2 * np.pi * coords / period)[None, :] + b * np.cos(2 * np.pi * coords / period)[:, None]
    x0, y0 = 0.3125, 1.5
    refs = reference_heights(field, spacing, diameter, (x0, y0))
    damping = math.exp(-2 * math.pi**2 * (diameter / 4) ** 2 / period**2)
    expected = h0 + damping * (a * math.cos(2 * math.pi * x0 / period) + b * math.cos(2 * math.pi * y0 / period))
    assert refs.footprint_mean == pytest.approx(expected, abs=1e-12)
    assert refs.flat_equivalent == pytest.approx(h0, abs=1e-12)
    # The highest sample inside the disc, by brute force over every periodic image that can reach it.
    k = math.ceil(diameter / period) + 1
    shifts = period * np.arange(-k, k + 1)
    dx = coords[None, :] + shifts[:, None] - x0  # (image, j)
    dy = coords[None, :] + shifts[:, None] - y0  # (image, i)
    d2 = dy[:, None, :, None] ** 2 + dx[None, :, None, :] ** 2  # (image y, image x, i, j)
    inside = (d2 <= (diameter / 2) ** 2).any(axis=(0, 1))
    assert refs.highest == field[inside].max()
    if diameter > math.sqrt(2) * period:
        assert refs.highest == pytest.approx(field.max())


def test_footprint_weights_and_bad_inputs():
    weights = footprint_weights((32, 48), 0.1, 20.0, (1.0, 2.0))
    assert weights.sum() == pytest.approx(1.0) and weights.shape == (32, 48)
    # 20 m over a 4.8 x 3.2 m field: nearly uniform; the wrapped Gaussian ripples by 2 exp(-2 pi^2 sigma^2 / P^2)
    # per axis (Poisson summation), sigma = D/4: 1.0e-9 along x (P = 4.8 m), 8e-22 along y.
    ripple = 2 * math.exp(-2 * math.pi**2 * 5.0**2 / 4.8**2)
    deviation = np.abs(weights / weights.mean() - 1).max()
    assert 0.5 * ripple < deviation <= 1.01 * ripple
    with pytest.raises(ValueError, match="spacing"):
        reference_heights(np.zeros((4, 4)), 0.0, 1.0)
    with pytest.raises(ValueError, match="footprint_diameter"):
        reference_heights(np.zeros((4, 4)), 0.1, -1.0)
    with pytest.raises(ValueError, match="2-D array"):
        reference_heights(np.zeros(4), 0.1, 1.0)
    with pytest.raises(ValueError, match="finer height field or a wider footprint"):
        reference_heights(np.zeros((4, 4)), 1.0, 0.2, (0.5, 0.5))


def test_bias_table_signs():
    """A surface at h = 1 m under a plane at z_ref = 10 m is 9 m away (18 m of OPL). A return 4 cm of OPL late
    reads 2 cm low: bias +0.02 m against the surface, and 0.02 + 0.1 against a crest 0.1 m higher."""
    start, bins = 17.0, 800
    late_bin = int(round((18.04 - start) / WIDTH - 0.5))
    waveform = convolve_pulse(_delta(bins, late_bin), WIDTH, FWHM_NS)
    estimates = estimate_ranges(waveform, start, WIDTH, pulse_fwhm_ns=FWHM_NS)
    refs = {"footprint_mean": 1.0, "highest": 1.1, "flat_equivalent": 0.95}
    table = bias_table(estimates, refs, z_ref=10.0)
    assert set(table) == set(ESTIMATORS)
    true_range = 0.5 * (start + (late_bin + 0.5) * WIDTH)
    for name in ESTIMATORS:
        assert table[name]["footprint_mean"] == pytest.approx(true_range - 9.0, abs=1e-9)
        assert table[name]["footprint_mean"] == pytest.approx(0.02, abs=0.5 * WIDTH)
        assert table[name]["highest"] == pytest.approx(table[name]["footprint_mean"] + 0.1, abs=1e-12)
        assert table[name]["flat_equivalent"] == pytest.approx(table[name]["footprint_mean"] - 0.05, abs=1e-12)
