"""Diffusion theory of render/lidar/diffusion.py against its own closed forms and numerical integrals (LIDAR.md §3).

Snow of the worked example (ρ = 300 kg/m³, d = 0.5 mm, 532 nm: σ_s′ ≈ 275 m⁻¹, σ_a ≈ 0.018 m⁻¹) and a more
absorbing medium (σ_a/σ_s′ = 10⁻²), so the absorption terms are visible at the lengths integrated.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from render.lidar.diffusion import (
    DiffusionMedium,
    bin_average,
    fluence,
    late_time_log_slope,
    mean_path_length,
    mode_path_length,
    radiance,
    reflectance,
    reflectance_time_integral,
    total_fluence,
    total_reflectance,
)

SNOW = dict(reduced_scattering=275.0, absorption=0.0183)
DARK = dict(reduced_scattering=100.0, absorption=1.0)
MEDIA = [
    DiffusionMedium(**SNOW, boundary="zero"),
    DiffusionMedium(**SNOW, boundary="extrapolated"),
    DiffusionMedium(**DARK, boundary="zero"),
    DiffusionMedium(**DARK, boundary="extrapolated"),
    DiffusionMedium(**DARK, boundary="extrapolated", boundary_coefficient=2.5),
]
IDS = ["snow-zero", "snow-extrapolated", "dark-zero", "dark-extrapolated", "dark-A2.5"]


def _integrate_path(function, medium: DiffusionMedium) -> float:
    """∫₀^∞ function(L) dL, split where R(L) changes scale (mode, a few ℓ*, the absorption length)."""
    ell = medium.source_depth
    cuts = [0.0, 0.5 * ell, 5 * ell, 50 * ell, 20.0 / max(medium.absorption, 1e-9), math.inf]
    cuts = sorted(set(cuts))
    return sum(quad(function, a, b, limit=400, epsabs=0, epsrel=1e-11)[0] for a, b in zip(cuts[:-1], cuts[1:]))


@pytest.mark.parametrize("medium", MEDIA, ids=IDS)
@pytest.mark.parametrize("beam_radius", [0.0, 0.02])
def test_area_integral_of_r_rho_is_the_closed_form(medium, beam_radius):
    for path in (2e-3, 0.05, 1.0):
        spread = math.sqrt(4 * medium.diffusion_coefficient * path + beam_radius**2)
        for local, total in ((reflectance, total_reflectance), (fluence, total_fluence)):
            numeric = quad(
                lambda rho, path=path, local=local: (
                    2 * math.pi * rho * float(local(medium, rho, path, beam_radius=beam_radius))
                ),
                0,
                12 * spread,
                epsabs=0,
                epsrel=1e-11,
                limit=200,
            )[0]
            assert numeric == pytest.approx(float(total(medium, path)), rel=1e-9), local.__name__


@pytest.mark.parametrize("medium", MEDIA, ids=IDS)
def test_time_integral_and_mean_path_match_the_closed_forms(medium):
    total = _integrate_path(lambda L: float(total_reflectance(medium, L)), medium)
    first = _integrate_path(lambda L: L * float(total_reflectance(medium, L)), medium)
    assert total == pytest.approx(reflectance_time_integral(medium), rel=1e-8)
    assert first / total == pytest.approx(mean_path_length(medium), rel=1e-8)


def test_closed_forms_reduce_to_the_textbook_limits():
    zero = DiffusionMedium(**SNOW, boundary="zero")
    mu = math.sqrt(3 * SNOW["absorption"] * SNOW["reduced_scattering"])
    assert reflectance_time_integral(zero) == pytest.approx(math.exp(-mu / SNOW["reduced_scattering"]), rel=1e-12)
    assert mean_path_length(zero) == pytest.approx(3 / (2 * mu), rel=1e-12)
    # No absorption: every photon comes back, through either boundary.
    for boundary in ("zero", "extrapolated"):
        clear = DiffusionMedium(275.0, 0.0, boundary)
        assert reflectance_time_integral(clear) == 1.0
    # Extrapolated boundary, small absorption: <L> -> (3 + 2A)/(2 mu_eff) (LIDAR.md 3.6).
    for a_coef in (1.0, 2.5):
        faint = DiffusionMedium(275.0, 1e-7, "extrapolated", a_coef)
        assert mean_path_length(faint) * 2 * faint.effective_attenuation == pytest.approx(3 + 2 * a_coef, rel=1e-3)


@pytest.mark.parametrize("medium", MEDIA, ids=IDS)
def test_late_time_log_slope(medium):
    """d ln R/dL → −3/(2L) − σ_a; the exact slope of the zero boundary adds z0²/(4DL²)."""
    d = medium.diffusion_coefficient
    for path in (100 * medium.source_depth, 3000 * medium.source_depth):
        step = 1e-4 * path
        numeric = (
            math.log(float(total_reflectance(medium, path + step)))
            - math.log(float(total_reflectance(medium, path - step)))
        ) / (2 * step)
        asymptote = float(late_time_log_slope(medium, path))
        bound = medium.image_depth**2 / (4 * d * path**2)
        assert abs(numeric - asymptote) <= 1.0001 * bound
        if medium.boundary == "zero":
            assert numeric == pytest.approx(asymptote + medium.source_depth**2 / (4 * d * path**2), rel=1e-7)
    far = 3000 * medium.source_depth
    assert abs(bound / float(late_time_log_slope(medium, far))) < 1e-3  # the asymptote is reached


@pytest.mark.parametrize("medium", MEDIA, ids=IDS)
@pytest.mark.parametrize("beam_radius", [0.0, 0.01])
def test_flux_is_minus_d_grad_phi_of_the_dipole(medium, beam_radius):
    """R(ρ, L) is D ∂φ/∂z at z = 0 (the outward flux), checked by a central difference of φ (LIDAR.md §3.2)."""
    d = medium.diffusion_coefficient
    for path in (0.01, 0.3):
        for rho in (0.0, 0.01, 0.05):
            h = 1e-4 * medium.source_depth
            dphi = (
                fluence(medium, rho, path, h, beam_radius=beam_radius)
                - fluence(medium, rho, path, -h, beam_radius=beam_radius)
            ) / (2 * h)
            assert float(d * dphi) == pytest.approx(
                float(reflectance(medium, rho, path, beam_radius=beam_radius)), rel=1e-7
            )


def test_fluence_vanishes_on_the_extrapolated_boundary():
    for medium in MEDIA:
        value = fluence(medium, 0.01, 0.1, -medium.extrapolation_length)
        assert abs(float(value)) <= 1e-12 * float(fluence(medium, 0.01, 0.1, medium.source_depth))


def test_exitance_of_the_p1_radiance_is_the_flux_with_an_index_matched_extrapolated_boundary():
    """∫ L(θ) cos θ dΩ over the outgoing hemisphere = φ/4 + J/2 exactly; with z_b = 2D, φ(0) = 2J up to a relative
    2D/L (LIDAR.md §3.3), so the exitance is J (1 + D/L)."""
    medium = DiffusionMedium(**SNOW, boundary="extrapolated")
    d = medium.diffusion_coefficient
    for path in (0.5, 5.0, 50.0):
        for rho in (0.0, 0.03):
            flux = float(reflectance(medium, rho, path))
            phi = float(fluence(medium, rho, path))
            exitance = (
                2 * math.pi * quad(lambda mu, rho=rho, path=path: float(radiance(medium, rho, path, mu)) * mu, 0, 1)[0]
            )
            assert exitance == pytest.approx(phi / 4 + flux / 2, rel=1e-12)
            # phi / (2J) = 1 + z_b^2/(2DL) + O(1/L^2) = 1 + 2D/L + ...
            assert phi / (2 * flux) - 1 == pytest.approx(2 * d / path, rel=0.01)
            assert exitance / flux - 1 == pytest.approx(d / path, rel=0.01)
    late = 5.0
    assert float(fluence(medium, 0, late)) / (2 * float(reflectance(medium, 0, late))) == pytest.approx(1, abs=1e-3)


@pytest.mark.parametrize("medium", MEDIA[:2], ids=IDS[:2])
def test_gaussian_footprint_matches_a_direct_convolution_and_tends_to_the_pencil_beam(medium):
    beam_radius = 0.01
    path = 0.02
    # Direct 2-D convolution of the pencil beam with (2/(pi w^2)) exp(-2 r^2/w^2), in polar coordinates of the source.
    radii, radial_weights = np.polynomial.legendre.leggauss(60)
    radii = 0.5 * 3.5 * beam_radius * (radii + 1)
    radial_weights = radial_weights * 0.5 * 3.5 * beam_radius
    angles = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    for rho in (0.0, 0.005, 0.02):
        sx = radii[:, None] * np.cos(angles)[None, :]
        sy = radii[:, None] * np.sin(angles)[None, :]
        distance = np.hypot(rho - sx, sy)
        beam = 2 / (np.pi * beam_radius**2) * np.exp(-2 * radii**2 / beam_radius**2)
        integrand = reflectance(medium, distance, path) * (beam * radii * radial_weights)[:, None]
        direct = integrand.sum() * (2 * np.pi / angles.size)
        closed = float(reflectance(medium, rho, path, beam_radius=beam_radius))
        assert direct == pytest.approx(closed, rel=2e-6)
    # w -> 0: the pencil beam, with the first correction −(w²/2)/(4DL) at ρ = 0.
    pencil = float(reflectance(medium, 0.0, path))
    for w in (1e-3, 1e-4):
        narrow = float(reflectance(medium, 0.0, path, beam_radius=w))
        expected = 0.5 * w**2 / (4 * medium.diffusion_coefficient * path)
        assert 1 - narrow / pencil == pytest.approx(expected, rel=1e-2)
    assert float(reflectance(medium, 0.0, path, beam_radius=0.0)) == pencil


def test_mode_of_the_zero_boundary_is_half_a_transport_path():
    """Without absorption the mode of R(L) is z0²/(6D) = ℓ*/2 exactly; check it against a grid search too."""
    clear = DiffusionMedium(275.0, 0.0, "zero")
    assert mode_path_length(clear) == pytest.approx(0.5 / 275.0, rel=1e-12)
    for medium in MEDIA:
        grid = np.linspace(0.2, 3.0, 200001) * mode_path_length(medium)
        best = grid[np.argmax(total_reflectance(medium, grid))]
        assert best == pytest.approx(mode_path_length(medium), rel=1e-4)


@pytest.mark.parametrize("medium", MEDIA[:2], ids=IDS[:2])
def test_bin_averages_integrate_to_the_closed_forms(medium):
    """Bins of 1 mm from before arrival to 30 m: Σ average·w is the time integral, and the bin mean of the
    radiance at ρ = 0 is (1/w) ∫ over the bin."""
    width, start, bins = 1e-3, -0.0105, 30000
    averages = bin_average(lambda L: total_reflectance(medium, L), start, width, bins)
    assert averages[:10].max() == 0.0
    tail = quad(lambda L: float(total_reflectance(medium, L)), start + bins * width, np.inf)[0]
    assert averages.sum() * width + tail == pytest.approx(reflectance_time_integral(medium), rel=3e-8)
    # The quadrature error sits in the first bins, where R rises on the scale z0^2/(4D) ~ 3 mm: more nodes fix it.
    finer = bin_average(lambda L: total_reflectance(medium, L), start, width, bins, nodes=48)
    assert finer.sum() * width + tail == pytest.approx(reflectance_time_integral(medium), rel=1e-11)
    for k in (11, 12, 40, 900):
        lo = start + k * width
        exact = quad(lambda L: float(radiance(medium, 0.0, L)), lo, lo + width, epsabs=0, epsrel=1e-12)[0] / width
        mean = bin_average(lambda L: radiance(medium, 0.0, L), start, width, bins)[k]
        assert mean == pytest.approx(exact, rel=1e-9)
    # Trailing axes: one call for several rho, with a surface delay of 2 m of OPL.
    rho = np.array([0.0, 0.01, 0.05])
    grid = bin_average(lambda L: reflectance(medium, rho, L[..., None]), 2.0, 0.01, 50, surface_opl=2.0)
    assert grid.shape == (50, 3)
    single = bin_average(lambda L: reflectance(medium, 0.01, L), 2.0, 0.01, 50, surface_opl=2.0)
    np.testing.assert_allclose(grid[:, 1], single, rtol=1e-14)


def test_bad_inputs_are_refused_with_the_argument_named():
    with pytest.raises(ValueError, match="reduced_scattering"):
        DiffusionMedium(0.0, 0.01)
    with pytest.raises(ValueError, match="absorption"):
        DiffusionMedium(275.0, -0.01)
    with pytest.raises(ValueError, match="boundary"):
        DiffusionMedium(275.0, 0.01, "robin")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="boundary_coefficient"):
        DiffusionMedium(275.0, 0.01, "extrapolated", 0.0)
    with pytest.raises(ValueError, match="mean path length is infinite"):
        mean_path_length(DiffusionMedium(275.0, 0.0))
    with pytest.raises(ValueError, match="beam_radius"):
        reflectance(DiffusionMedium(275.0, 0.01), 0.0, 0.1, beam_radius=-1.0)
    with pytest.raises(ValueError, match="bin_width_opl"):
        bin_average(lambda L: L, 0.0, 0.0, 10)
    with pytest.raises(ValueError, match="cos_theta"):
        radiance(DiffusionMedium(275.0, 0.01), 0.0, 0.1, 1.5)
    # Before arrival there is no light.
    assert float(reflectance(DiffusionMedium(275.0, 0.01), 0.0, -1.0)) == 0.0
    assert float(total_reflectance(DiffusionMedium(275.0, 0.01), 0.0)) == 0.0
