"""V1 (geometry/DESIGN.md 7): linear dispersion of the Betterton-type kernel with diffusion.

sigma(k) = A_B |k| - D k^2, lambda* = 4 pi D / A_B = 4.40 cm for A_B = 7.14e-7 m/s, D = 2.5e-9 m2/s.
The 1-D run uses the real-space quadrature (not the spectral shortcut), so it tests the kernel.
Reduced grids: 256 cells over 8 lambda* (1-D) and 128^2 over 16 lambda* (2-D); the physics is linear
and scale-free at these amplitudes, so nothing is lost.
"""

import numpy as np
import pytest

from geometry import ablation, metrics

A_B = 7.14e-7  # [m s-1]
D = 2.5e-9  # [m2 s-1]
LAMBDA_STAR = 4 * np.pi * D / A_B
SIGMA_STAR = A_B**2 / (4 * D)


def test_quadrature_reproduces_minus_abs_k_h():
    n, wavelength = 200, 0.05
    spacing = wavelength / 25
    x = np.arange(n) * spacing
    k = 2 * np.pi / wavelength
    h = 1e-5 * np.cos(k * x)
    intensity = ablation.betterton_intensity_1d(h, spacing, periods=8)
    np.testing.assert_allclose(intensity, -k * h, rtol=0, atol=0.01 * k * 1e-5)


def _grow_1d(h, spacing, duration, dt):
    """Strang splitting: exact diffusion half steps around an RK4 step of the quadrature kernel."""
    kx = 2 * np.pi * np.fft.fftfreq(h.size, d=spacing)
    half = np.exp(-D * kx**2 * dt / 2)
    rate = lambda y: -A_B * ablation.betterton_intensity_1d(y, spacing)
    for _ in range(int(round(duration / dt))):
        h = np.real(np.fft.ifft(np.fft.fft(h) * half))
        k1 = rate(h)
        k2 = rate(h + dt / 2 * k1)
        k3 = rate(h + dt / 2 * k2)
        k4 = rate(h + dt * k3)
        h = h + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        h = np.real(np.fft.ifft(np.fft.fft(h) * half))
    return h


def test_growth_rates_fit_dispersion_relation_and_lambda_star(validation):
    n = 256
    length = 8 * LAMBDA_STAR
    spacing = length / n
    x = np.arange(n) * spacing
    modes = np.array([3, 4, 5, 6, 8, 10, 12, 14])  # lambda from 11.7 cm to 2.5 cm (cut-off 2.2 cm)
    rng = np.random.default_rng(0)
    amplitude = 1e-6  # [m], far below 1e-3 lambda
    h = sum(amplitude * np.cos(2 * np.pi * m * x / length + rng.uniform(0, 2 * np.pi)) for m in modes)
    duration, samples = 3.0 / SIGMA_STAR, 4  # three e-folding times of the fastest mode
    times, amplitudes = [0.0], [np.abs(np.fft.rfft(h))[modes]]
    for i in range(samples):
        h = _grow_1d(h, spacing, duration / samples, dt=duration / samples / 24)
        times.append(duration * (i + 1) / samples)
        amplitudes.append(np.abs(np.fft.rfft(h))[modes])
    log_amp = np.log(np.array(amplitudes))
    measured = np.polyfit(np.array(times), log_amp, 1)[0]
    k = 2 * np.pi * modes / length
    expected = ablation.linear_growth_rate(k, A_B, D)
    assert np.all(np.abs(measured - expected) <= 0.05 * SIGMA_STAR), (measured / SIGMA_STAR, expected / SIGMA_STAR)
    fitted_a, fitted_d = np.linalg.lstsq(np.column_stack((k, -(k**2))), measured, rcond=None)[0]
    fitted_lambda = 4 * np.pi * fitted_d / fitted_a
    validation.record(
        "V1 linear dispersion: λ* = 4π D / A_B fitted to measured growth rates [m]",
        fitted_lambda,
        reference=LAMBDA_STAR,
        tolerance="±10 %",
        against="the linear model's σ(k) = A_B |k| − D k²",
    )
    assert abs(fitted_lambda / LAMBDA_STAR - 1) < 0.10, fitted_lambda
    assert abs(fitted_a**2 / (4 * fitted_d) / SIGMA_STAR - 1) < 0.10


@pytest.mark.parametrize("seed", [1, 2])
def test_white_noise_develops_lambda_star(seed):
    n = 128
    spacing = 16 * LAMBDA_STAR / n  # 8 cells per lambda*: the spectral operator is exact at any resolution
    rng = np.random.default_rng(seed)
    h = 1e-6 * rng.standard_normal((n, n))
    h = ablation.spectral_linear_step(h, spacing, 5.0 / SIGMA_STAR, A_B, D, 0.0)
    assert abs(metrics.dominant_wavelength(h, spacing) / LAMBDA_STAR - 1) < 0.15


def test_two_d_growth_is_isotropic():
    """Same sigma along the grid axis and the diagonal (grid-anisotropy check)."""
    n, spacing = 64, LAMBDA_STAR / 8
    y, x = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing, indexing="ij")
    k_axis = 2 * np.pi * 8 / (n * spacing)
    for field, k in ((np.cos(k_axis * x), k_axis), (np.cos(k_axis * (x + y)), k_axis * np.sqrt(2))):
        grown = ablation.spectral_linear_step(1e-6 * field, spacing, 1000.0, A_B, D, 0.0)
        rate = np.log(np.abs(grown).max() / 1e-6) / 1000.0
        assert rate == pytest.approx(float(ablation.linear_growth_rate(k, A_B, D)), rel=1e-6)


# Penetration length (DESIGN.md 3.10, 7 V1 and V7): sigma(k) = A_B |k| / (1 + (k l)^2) peaks at k = 1/l.


def _white_noise_onset(efolding_depth: float, seed: int) -> float:
    """Dominant wavelength [m] of 2-D white noise after five e-folding times of the fastest mode,
    sigma* = A_B / (2 l), on a 256^2 grid holding 32 onset wavelengths."""
    n = 256
    spacing = 32 * 2 * np.pi * efolding_depth / n
    h = 1e-6 * np.random.default_rng(seed).standard_normal((n, n))
    h = ablation.spectral_linear_step(h, spacing, 5.0 * 2 * efolding_depth / A_B, A_B, 0.0, 0.0, efolding_depth)
    return metrics.dominant_wavelength(h, spacing)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_white_noise_peaks_at_two_pi_l(seed, validation):
    """V1: the onset wavelength is 2 pi l (4.4 cm for l = 7 mm), within 20 %."""
    efolding_depth = 0.007
    onset = _white_noise_onset(efolding_depth, seed)
    validation.record(
        f"V1 onset wavelength from white noise, l = 7 mm, seed {seed} [m]",
        onset,
        reference=ablation.onset_wavelength(efolding_depth),
        tolerance="±20 %",
        against="2π l, the linear model's fastest mode",
    )
    assert onset == pytest.approx(ablation.onset_wavelength(efolding_depth), rel=0.2)


def test_doubling_l_doubles_the_onset_wavelength(validation):
    """V7: twice the e-folding depth, twice the onset wavelength, within 20 %."""
    ratio = _white_noise_onset(0.014, 4) / _white_noise_onset(0.007, 5)
    validation.record(
        "V7 onset wavelength at l = 14 mm / at l = 7 mm",
        ratio,
        reference=2.0,
        tolerance="±20 %",
        against="exact scaling with l",
    )
    assert ratio == pytest.approx(2.0, rel=0.2)


def test_growth_rate_peaks_at_one_over_l():
    efolding_depth = 0.06
    k = np.linspace(1.0, 100.0, 20000)
    sigma = ablation.linear_growth_rate(k, A_B, 0.0, 0.0, efolding_depth)
    assert k[np.argmax(sigma)] == pytest.approx(1.0 / efolding_depth, rel=1e-3)
    assert sigma.max() == pytest.approx(A_B / (2 * efolding_depth), rel=1e-6)


# V1 on the Tapado preset (DESIGN.md 7): lone modes below the wake slope, and the first forms of a season.


def test_tapado_has_no_linear_phase_below_the_wake_slope():
    """Why the Tapado onset spectrum is red (DESIGN.md 7, V1): a lone east-west row mode of 1.5 mm (slopes below
    the wake slope) at 2, 1 or 0.5 m does not grow over 10 days (ln gain measured -0.000, -0.001, -0.009), so
    the preset has no linear instability to select 2 pi l; its forms grow only from finite roughness, through
    the shelter index's rectification."""
    from pathlib import Path

    from pipeline.config import load_raw
    from pipeline.schema.geometry import GeometryConfig

    site = load_raw(Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites" / "tapado.yaml")["geometry"]
    cfg = GeometryConfig(**{**site, "grid_cells": 64, "domain_size": 4.0, "days": 10, "snapshots": 2})
    y = (np.arange(cfg.grid_cells) + 0.5) * cfg.spacing
    for wavelength in (2.0, 1.0, 0.5):
        amplitude = 0.0015 * np.sqrt(2)
        h0 = np.repeat(amplitude * np.cos(2 * np.pi * y / wavelength)[:, None], cfg.grid_cells, axis=1)
        grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), np.random.default_rng(0))
        profile = grown.height.mean(axis=1)
        mode = 2 * np.abs(np.fft.rfft(profile - profile.mean()))[round(cfg.domain_size / wavelength)] / cfg.grid_cells
        assert np.log(mode / amplitude) < 0.002, (wavelength, np.log(mode / amplitude))


def test_tapado_first_forms_follow_the_start():
    """V1 as issue 49 decided (DESIGN.md 7): V1 is judged on the lab preset and the linear model (above). At
    Tapado a season grows from finite roughness, and its first forms follow the start: a Gaussian-correlated
    surface crosses its mean every pi lc / sqrt(2) (Rice), so its crests stand pi sqrt(2) lc = 0.67 m apart
    for lc = 0.15 m, and on days 15-18 (128^2 over 4 m, 3.1 cm cells, seed 1) the forms are at least that far
    apart, well past 2 pi l = 0.38 m: the growth coarsens from the start's spacing instead of selecting 2 pi l
    below it. Under the constant loss they kept the start's spacing (0.66-0.68 m); under the surface energy
    balance (DESIGN.md 3.9) only the start's deepest hollows reach still enough air to melt, and the first forms
    stand 1.09-1.24 m apart."""
    from pathlib import Path

    from pipeline.config import load_raw
    from pipeline.schema.geometry import GeometryConfig

    site = load_raw(Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites" / "tapado.yaml")["geometry"]
    cfg = GeometryConfig(**{**site, "grid_cells": 128, "domain_size": 4.0, "days": 18, "snapshots": 7})
    rng = np.random.default_rng(1)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    assert cfg.initial_correlation_length is not None
    rice = np.pi * np.sqrt(2) * cfg.initial_correlation_length
    assert metrics.crest_spacing(h0, cfg.spacing) == pytest.approx(rice, rel=0.1)
    first = grown.snapshot_days >= 15
    spacings = [metrics.crest_spacing(h, cfg.spacing) for h in grown.snapshots[first]]
    assert np.mean(spacings) > 0.9 * rice, spacings
    assert np.mean(spacings) > 1.5 * ablation.onset_wavelength(cfg.optical_efolding_depth), spacings
