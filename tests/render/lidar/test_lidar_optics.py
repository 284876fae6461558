"""Single-wavelength snow optics of render/lidar/optics.py against hand calculations (LIDAR.md §5).

The hand numbers: ρ_ice = 917 kg/m³; W&B 2008 k(530) = 1.409e-9, k(540) = 1.813e-9 and k(1060) = 1.96e-6,
k(1070) = 1.81e-6; Picard 2016 γ(530) = 0.047081, γ(535) = 0.050671 m⁻¹ (ghislainp/tartes,
tartes/refractive_index.py).
"""

from __future__ import annotations

import math

import pytest

from render.lidar.optics import (
    _PICARD_2016_GAMMA,
    _WARREN_BRANDT_2008_K,
    ice_absorption_coefficient,
    ice_imaginary_index,
    snow_optics,
)
from render.scene.optics import RHO_ICE, derive_snow


def test_the_stored_table_rows_match_snow_optics_md():
    """snow_optics.md section 2 quotes, at 530 nm, W&B 2008 0.0334 and Picard 2016 0.0471 m-1: our copied rows agree."""
    assert 4 * math.pi * _WARREN_BRANDT_2008_K[530.0] / 530e-9 == pytest.approx(0.0334, abs=5e-5)
    assert _PICARD_2016_GAMMA[530.0] == pytest.approx(0.0471, abs=5e-5)


def test_ice_absorption_at_the_laser_lines_by_hand():
    # Linear in ln k: 532 nm is 0.2 of the way from 530 to 540 nm, 1064 nm 0.4 of the way from 1060 to 1070 nm.
    k532 = 1.409e-9 * (1.813 / 1.409) ** 0.2
    assert ice_imaginary_index(532) == pytest.approx(k532, rel=1e-12)
    assert ice_absorption_coefficient(532) == pytest.approx(4 * math.pi * k532 / 532e-9, rel=1e-12)
    assert ice_absorption_coefficient(532) == pytest.approx(0.035003, rel=1e-4)
    k1064 = 1.96e-6 * (1.81 / 1.96) ** 0.4
    assert ice_absorption_coefficient(1064) == pytest.approx(4 * math.pi * k1064 / 1064e-9, rel=1e-12)
    assert ice_absorption_coefficient(1064) == pytest.approx(22.423, rel=1e-4)
    k530 = 0.047080833955 * 530e-9 / (4 * math.pi)
    k535 = 0.050671292623 * 535e-9 / (4 * math.pi)
    picard = 4 * math.pi * (k530 * (k535 / k530) ** 0.4) / 532e-9
    assert ice_absorption_coefficient(532, "picard_2016") == pytest.approx(picard, rel=1e-10)
    assert ice_absorption_coefficient(532, "picard_2016") == pytest.approx(0.048485, rel=1e-4)


def test_snow_coefficients_at_532_nm_by_hand():
    """ρ = 300 kg/m³, d = 0.5 mm: σ_e = 3ρ/(ρ_ice d) = 1962.92 m⁻¹, σ_a = 1.6 γ ρ/ρ_ice, σ_s′ = (σ_e − σ_a)(1 − g)."""
    snow = snow_optics(300.0, 0.5e-3, 532.0)
    gamma = 4 * math.pi * 1.409e-9 * (1.813 / 1.409) ** 0.2 / 532e-9
    extinction = 3 * 300 / (917 * 0.5e-3)
    absorption = 1.6 * gamma * 300 / 917
    assert snow.extinction == pytest.approx(extinction, rel=1e-12)
    assert snow.extinction == pytest.approx(1962.92, rel=1e-5)
    assert snow.specific_surface_area == pytest.approx(6 / (917 * 0.5e-3), rel=1e-12)
    assert snow.extinction == pytest.approx(300 * snow.specific_surface_area / 2, rel=1e-12)
    assert snow.absorption == pytest.approx(absorption, rel=1e-12)
    assert snow.absorption == pytest.approx(0.018322, rel=1e-4)
    assert snow.scattering == pytest.approx(extinction - absorption, rel=1e-12)
    assert snow.asymmetry == 0.86
    assert snow.reduced_scattering == pytest.approx((extinction - absorption) * 0.14, rel=1e-12)
    assert snow.transport_mean_free_path == pytest.approx(3.6389e-3, rel=1e-4)
    medium = snow.diffusion_medium("zero")
    assert medium.reduced_scattering == snow.reduced_scattering and medium.absorption == snow.absorption
    picard = snow_optics(300.0, 0.5e-3, 532.0, ice_data_set="picard_2016")
    assert picard.absorption / snow.absorption == pytest.approx(0.048485 / 0.035003, rel=1e-4)


@pytest.mark.parametrize(
    ("wavelength", "tolerance", "scattering_tolerance"), [(532.0, 1e-4, 1e-6), (1064.0, 1e-2, 1e-4)]
)
def test_agrees_with_the_projects_kokhanovsky_zege_form_in_the_weak_absorption_limit(
    wavelength, tolerance, scattering_tolerance
):
    """derive_snow (render/scene/optics.py) with the same α_ice in every channel: σ_t is the same formula; σ_a and
    σ_s differ by the second order of the KZ expansion, a relative (1/3) B c/(1 − W) with c = 2 γ r_opt
    (1e-5 at 532 nm, 6e-3 at 1064 nm for these grains): hence tolerances of 1e-4 and 1e-2 on σ_a, and that
    difference over σ_s/σ_a (1e-6, 1e-4) on σ_s."""
    ours = snow_optics(300.0, 0.5e-3, wavelength)
    gamma = ours.ice_absorption
    theirs = derive_snow(300.0, optical_radius=0.25e-3, alpha_ice=(gamma, gamma, gamma))
    green = 1
    assert ours.extinction == pytest.approx(theirs.sigma_t[green], rel=1e-12)
    assert ours.absorption == pytest.approx(theirs.sigma_a[green], rel=tolerance)
    assert ours.scattering == pytest.approx(theirs.sigma_s[green], rel=scattering_tolerance)
    c = 2 * gamma * 0.25e-3
    w = 0.0611 + 0.17 * (theirs.ior[green] - 1.3)
    predicted = 1.6 * c / (3 * (1 - w))  # leading relative difference of the two absorption forms
    assert 1 - theirs.sigma_a[green] / ours.absorption == pytest.approx(predicted, rel=0.02)
    same_g = snow_optics(300.0, 0.5e-3, wavelength, asymmetry=theirs.g[green])
    assert same_g.reduced_scattering == pytest.approx(
        theirs.sigma_s[green] * (1 - theirs.g[green]), rel=scattering_tolerance
    )


def test_bad_inputs_are_refused_with_the_argument_and_the_fix():
    with pytest.raises(ValueError, match="density must lie in"):
        snow_optics(-1.0, 0.5e-3)
    with pytest.raises(ValueError, match="density must lie in"):
        snow_optics(RHO_ICE, 0.5e-3)
    with pytest.raises(ValueError, match="density must lie in"):
        snow_optics(950.0, 0.5e-3)
    with pytest.raises(ValueError, match="grain_diameter"):
        snow_optics(300.0, 0.0)
    with pytest.raises(ValueError, match="wavelength_nm must be one of the laser lines"):
        snow_optics(300.0, 0.5e-3, 530.0)
    with pytest.raises(ValueError, match="data_set must be one of"):
        snow_optics(300.0, 0.5e-3, ice_data_set="warren_1984")
    with pytest.raises(ValueError, match="picard_2016' covers 320-600 nm only.*use 'warren_brandt_2008'"):
        snow_optics(300.0, 0.5e-3, 1064.0, ice_data_set="picard_2016")
    with pytest.raises(ValueError, match="asymmetry"):
        snow_optics(300.0, 0.5e-3, asymmetry=1.0)
    with pytest.raises(ValueError, match="absorption_enhancement"):
        snow_optics(300.0, 0.5e-3, absorption_enhancement=0.0)
