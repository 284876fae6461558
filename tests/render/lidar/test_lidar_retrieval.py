"""Grain size read back from an ATM-like waveform (render/lidar/retrieval.py, LIDAR.md §11).

- The scaling law: flat snow's response in transport lengths depends on α = σ_a/σ_s′ alone, and α on grain size
  alone, so two densities of one grain size render one curve.
- A noisy waveform of the model reads back within three of its stated standard deviations, and a waveform
  rendered apart from the table (another ℓ*, seed and binning) within the issue's 15 %.
- What the fit refuses: a bare surface (the fit runs to the table's bound), noise beyond the stated model (χ²),
  and a range gate deeper than the table.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from render.lidar.optics import snow_group_index, snow_optics
from render.lidar.retrieval import (
    AtmInstrument,
    RetrievalError,
    absorption_ratio,
    flat_impulse,
    observe,
    render_table,
    retrieve_grain_size,
)

DENSITY = 300.0
INSTRUMENT = AtmInstrument()


@pytest.fixture(scope="module")
def table():
    """f(x; α) to x = 2048 ℓ*, enough for the range gate over 0.3–1 mm grains at 300 kg/m3."""
    return render_table(bins=1024, pixels=16, iterations=64, seed=5)


def bands(energy: np.ndarray, bin_width: float, marks=(2, 20, 200, 2000)) -> np.ndarray:
    """The share of the energy returned before x = each mark (transport lengths)."""
    cumulative = np.cumsum(energy) / energy.sum()
    return np.array([cumulative[round(m / bin_width) - 1] for m in marks])


def test_the_absorption_ratio_is_set_by_grain_size_alone():
    light, dense = snow_optics(300.0, 5e-4), snow_optics(550.0, 5e-4)
    assert absorption_ratio(light) == pytest.approx(absorption_ratio(dense), rel=1e-4)
    assert light.transport_mean_free_path / dense.transport_mean_free_path == pytest.approx(550 / 300, rel=1e-4)
    assert absorption_ratio(snow_optics(300.0, 1e-3)) == pytest.approx(2 * absorption_ratio(light), rel=1e-4)


def test_two_densities_of_one_grain_size_render_one_response_in_transport_lengths():
    renders = []
    for density, seed in ((300.0, 1), (550.0, 2)):
        snow = snow_optics(density, 5e-4)
        alpha = absorption_ratio(snow)
        renders.append(
            render_table(
                alphas=(alpha, alpha, alpha),
                transport_length=snow.transport_mean_free_path,
                bins=1024,
                pixels=16,
                iterations=32,
                seed=seed,
            )
        )
    light, dense = renders
    # Physical scales 3.6 and 2.0 mm, yet the same shares of light by 2, 20, 200 and 2000 transport lengths
    # (within the renders' noise, about 1 %) and the same albedo.
    np.testing.assert_allclose(bands(light.energy[:, 0], 2.0), bands(dense.energy[:, 0], 2.0), rtol=0.03)
    assert light.energy[:, 0].sum() == pytest.approx(dense.energy[:, 0].sum(), rel=0.02)


def test_a_noisy_waveform_of_the_model_reads_back_within_its_uncertainty(table):
    truth = 7e-4
    snow = snow_optics(DENSITY, truth)
    edges = np.arange(0.0, 4.0, 0.005)
    energy = flat_impulse(table, snow, snow_group_index(DENSITY), edges)
    centres = 1.0 + 0.5 * (edges[:-1] + edges[1:])  # the surface 0.5 m below the reference plane
    observation = observe(centres, energy, INSTRUMENT, np.random.default_rng(3), phase=0.4)
    fit = retrieve_grain_size(observation, table, INSTRUMENT, density=DENSITY)
    assert 0 < fit.grain_sigma < 0.1 * truth
    assert abs(fit.grain_diameter - truth) < 3 * fit.grain_sigma
    assert fit.surface_opl == pytest.approx(1.0, abs=0.02)


def test_a_separate_render_reads_back_within_fifteen_percent(table):
    """Flat snow rendered at its own scale (ℓ* = 3.6 mm), seed and bins, its clock applied as the stage does."""
    truth = 5e-4
    snow = snow_optics(DENSITY, truth)
    alpha = absorption_ratio(snow)
    ell = snow.transport_mean_free_path
    render = render_table(alphas=(alpha,) * 3, transport_length=ell, bins=700, bin_width=3.0, iterations=64, seed=11)
    path = (np.arange(render.energy.shape[0]) + 0.5) * render.bin_width * ell
    centres = 0.8 + snow_group_index(DENSITY) * path
    observation = observe(centres, render.energy[:, 0], INSTRUMENT, np.random.default_rng(4))
    fit = retrieve_grain_size(observation, table, INSTRUMENT, density=DENSITY)
    assert fit.grain_diameter == pytest.approx(truth, rel=0.15)


def test_a_bare_surface_runs_the_fit_to_the_table_bound(table):
    observation = observe(np.array([1.0]), np.array([1.0]), INSTRUMENT, np.random.default_rng(5))
    with pytest.raises(RetrievalError, match="table's bound"):
        retrieve_grain_size(observation, table, INSTRUMENT, density=DENSITY)


def test_noise_beyond_the_stated_model_is_detected(table):
    snow = snow_optics(DENSITY, 7e-4)
    edges = np.arange(0.0, 4.0, 0.005)
    energy = flat_impulse(table, snow, snow_group_index(DENSITY), edges)
    noisy = replace(INSTRUMENT, digitiser_noise=5 * INSTRUMENT.digitiser_noise)
    observation = observe(1.0 + edges[:-1], energy, noisy, np.random.default_rng(6))
    with pytest.raises(RetrievalError, match="noise model"):
        retrieve_grain_size(observation, table, INSTRUMENT, density=DENSITY)
    fit = retrieve_grain_size(observation, table, noisy, density=DENSITY)  # the right model passes
    assert fit.p_value > 1e-3


def test_a_gate_deeper_than_the_table_is_refused(table):
    short = replace(table, energy=table.energy[:64])
    snow = snow_optics(DENSITY, 5e-4)
    with pytest.raises(RetrievalError, match="beyond the table"):
        flat_impulse(short, snow, 1.0, np.array([0.0, 1.0]))
    assert math.isclose(short.x_max, 128.0)
