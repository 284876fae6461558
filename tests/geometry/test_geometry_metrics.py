"""V3 spacing and height metrics (geometry/DESIGN.md 7) on fields whose answer is known by construction."""

import numpy as np
import pytest

from geometry import metrics

N, L = 64, 4.0
SPACING = L / N
Y = np.arange(N) * SPACING


def _rows(profile: np.ndarray) -> np.ndarray:
    """East-west rows: the same north-south profile in every column."""
    return np.repeat(profile[:, None], N, axis=1)


def test_sinusoidal_rows_on_a_domain_scale_undulation():
    """0.8 m rows of 0.3 m amplitude on a 5 cm undulation of the domain scale: lambda_dom is the rows',
    H is 2 x amplitude (within the sampling of the crests), as 2 sqrt 2 RMS is for a sinusoid."""
    h = _rows(0.3 * np.cos(2 * np.pi * Y / 0.8) + 0.05 * np.cos(2 * np.pi * Y / L))
    assert metrics.row_spacing(h, SPACING) == pytest.approx(0.8, rel=0.01)
    assert metrics.crest_to_trough(h) == pytest.approx(0.6, rel=0.02)
    assert metrics.relief(h)["relief_m"] == pytest.approx(0.6, rel=0.02)


def test_thin_blades_keep_their_height():
    """One-cell blades 1 m tall every 8 cells (0.5 m) on flat troughs: H is the blade height, where
    2 sqrt 2 RMS falls short, and the spacing is the blades'."""
    profile = np.zeros(N)
    profile[::8] = 1.0
    h = _rows(profile)
    assert metrics.crest_to_trough(h) == pytest.approx(1.0)
    assert metrics.relief(h)["relief_m"] < 0.95
    assert metrics.row_spacing(h, SPACING) == pytest.approx(0.5, rel=0.01)
    assert metrics.morphology(h, SPACING)["spacing_to_height"] == pytest.approx(0.5, rel=0.01)


def test_north_south_rows_have_no_height_across_east_west_rows():
    """Ridges running north-south leave every north-south transect flat: no E-W rows to measure."""
    h = _rows(np.zeros(N)) + 0.3 * np.cos(2 * np.pi * Y / 0.8)[None, :]
    assert metrics.crest_to_trough(h, axis=0) == 0.0
    assert metrics.crest_to_trough(h, axis=1) == pytest.approx(0.6, rel=0.02)


def test_transect_spectrum_sums_to_the_transect_variance():
    h = np.random.default_rng(3).standard_normal((N, N))
    _, power = metrics.transect_power_spectrum(h, SPACING)
    assert power.sum() == pytest.approx(h.var(axis=0).mean(), rel=1e-12)


def test_crest_spacing_counts_the_blades():
    profile = np.zeros(N)
    profile[::8] = 1.0
    assert metrics.crest_spacing(_rows(profile), SPACING) == pytest.approx(0.5)
    assert metrics.crest_spacing(_rows(np.cos(2 * np.pi * Y / 0.8)), SPACING) == pytest.approx(0.8)
    assert metrics.crest_spacing(np.ones((N, N)), SPACING) == float("inf")


def test_crest_density_counts_isolated_peaks():
    """Peaks every 8 cells both ways (0.5 m x 0.5 m) give 4 crests per m^2; E-W rows of equal height
    have no strict maxima along them."""
    x = np.arange(N) * SPACING
    bumps = np.cos(2 * np.pi * Y / 0.5)[:, None] + np.cos(2 * np.pi * x / 0.5)[None, :]
    assert metrics.crest_density(bumps, SPACING) == pytest.approx(4.0)
    assert metrics.crest_density(_rows(np.cos(2 * np.pi * Y / 0.5)), SPACING) == 0.0


def test_crest_radius_counts_a_form_once_whatever_the_grid():
    """Peaks 0.5 m apart carrying a 12.5 cm ripple: counted per cell, the ripple's crests add to the forms'
    once a grid resolves them (4 per m^2 on 6.25 cm cells, 12 on 3.1 cm); counted once within pi l (l = 6 cm:
    0.19 m), only the forms count, 4 per m^2 on both grids, and the 0.5 m forms themselves stay separate."""
    per_cell = {}
    for n in (64, 128):
        spacing = L / n
        coords = np.arange(n) * spacing
        y, x = np.meshgrid(coords, coords, indexing="ij")
        forms = np.cos(2 * np.pi * y / 0.5) + np.cos(2 * np.pi * x / 0.5)
        ripple = 0.1 * np.cos(2 * np.pi * x / 0.125) * np.cos(2 * np.pi * y / 0.125)
        assert metrics.crest_density(forms + ripple, spacing, metrics.crest_radius(0.06)) == pytest.approx(4.0)
        per_cell[n] = metrics.crest_density(forms + ripple, spacing)
    assert per_cell == {64: pytest.approx(4.0), 128: pytest.approx(12.0)}
    assert metrics.crest_radius(0.06) == pytest.approx(np.pi * 0.06)


def test_dominant_wavelength_is_never_the_domain():
    """A field whose strongest mode is the domain's fundamental has no repeat inside the domain:
    the answer is the strongest wavelength of L/2 or shorter, here the 0.8 m rows."""
    h = _rows(1.0 * np.cos(2 * np.pi * Y / L) + 0.3 * np.cos(2 * np.pi * Y / 0.8))
    assert metrics.dominant_wavelength(h, SPACING) == pytest.approx(0.8, rel=0.05)


def test_axis_lean_reads_the_crest_offset():
    """Rows whose crests stand 0.1 m north of the midpoint between their troughs, 0.4 m above them
    (a skewed saw-tooth, 0.8 m period): the lean is atan(0.1 / 0.4) = 14 deg north, within the grid's
    sampling of the troughs; symmetric rows do not lean."""
    skewed = np.interp(Y % 0.8, [0.0, 0.5, 0.8], [0.0, 0.4, 0.0])
    assert metrics.axis_lean(_rows(skewed), SPACING) == pytest.approx(14.0, abs=3.0)
    assert metrics.axis_lean(_rows(skewed[::-1]), SPACING) < -10.0
    assert metrics.axis_lean(_rows(np.cos(2 * np.pi * Y / 0.8)), SPACING) == pytest.approx(0.0, abs=1e-9)


def test_gain_spectrum_is_the_log_power_ratio_of_each_mode():
    """A field that grew by exp(sigma(k) t) mode by mode reads 2 sigma(k) t in every bin, whatever the start."""
    h0 = np.random.default_rng(2).standard_normal((N, N))
    kx = 2 * np.pi * np.fft.fftfreq(N, d=SPACING)
    k = np.hypot(*np.meshgrid(kx, kx, indexing="ij"))
    rate = k * np.exp(-k / 8.0)  # peaks at |k| = 8 rad/m, i.e. 0.785 m
    h = np.real(np.fft.ifft2(np.fft.fft2(h0) * np.exp(rate)))
    bins, gain = metrics.gain_spectrum(h, h0, SPACING)
    expected = 2 * bins * np.exp(-bins / 8.0)
    # Bins hold |k| within half a fundamental of their centre, so the curved rate averages a little off near k = 0.
    np.testing.assert_allclose(gain[2:], expected[2:], rtol=0.06)
    assert metrics.fastest_growing_wavelength(h, h0, SPACING) == pytest.approx(2 * np.pi / 8.0, rel=0.05)
