"""The season's coarsening (geometry/DESIGN.md 3.9 and 7, V5 and V6) on reduced grids.

The mechanism test grows east-west rows 0.5 m apart whose every other crest stands 12 cm lower
(a 13 deg rise to its neighbours, above the 1-in-6 wake slope), Tapado, 128^2 cells over 4 m, 60 days:
with the shelter switch the lower blade melts and is consumed, so the spacing doubles (DESIGN.md 7, V5).
"""

from pathlib import Path

import numpy as np
import pytest

from geometry import ablation, metrics, sunpath
from pipeline.config import load_raw
from pipeline.schema.geometry import GeometryConfig

SITES = Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites"
N, L, ROW = 128, 4.0, 0.5


def _alternate_rows() -> np.ndarray:
    y = (np.arange(N) + 0.5) * L / N
    profile = 0.1 * np.cos(2 * np.pi * y / ROW) + 0.06 * np.cos(np.pi * y / ROW)
    return np.repeat(profile[:, None], N, axis=1)


def _grow_rows(**overrides) -> tuple[np.ndarray, float]:
    site = load_raw(SITES / "tapado.yaml")["geometry"]
    cfg = GeometryConfig(**{**site, "grid_cells": N, "domain_size": L, "snapshots": 2, **overrides})
    settings = ablation.settings_from_config(cfg)
    grown = ablation.grow_field(_alternate_rows(), cfg.spacing, settings, np.random.default_rng(0))
    return grown.height, cfg.spacing


def test_a_lower_blade_between_taller_ones_is_consumed(validation):
    """The lower crest is no crest any more (the spacing doubles) and where it stood the surface is well
    below the taller crests (measured 0.06 m below the mean against 0.45 m above it; the spacing is 1.0 m by day 40)."""
    h, spacing = _grow_rows(days=60)
    validation.record(
        "V5 mechanism: crest spacing of rows 0.5 m apart with every other crest 12 cm lower, day 60 [m]",
        metrics.crest_spacing(h, spacing),
        reference=2 * ROW,
        tolerance="±5 %",
        against="the lower blade consumed: twice the row spacing",
    )
    assert metrics.crest_spacing(h, spacing) == pytest.approx(2 * ROW, rel=0.05)
    profile = h.mean(axis=1) - h.mean()
    short_crest = profile[int(ROW / (L / N))]  # where the lower crest stood
    assert short_crest < 0.5 * profile.max()


def _season(seed: int) -> dict:
    """The demo's 60-day Tapado season at its converged cell (256^2 over 8 m, 3.1 cm): morphology and the
    growth-weighted noon zenith angle the lean is judged against."""
    cfg = GeometryConfig(
        **{
            **load_raw(SITES / "tapado.yaml")["geometry"],
            "grid_cells": 256,
            "domain_size": 8.0,
            "days": 60,
            "snapshots": 2,
        }
    )
    rng = np.random.default_rng(seed)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    shape = metrics.morphology(grown.height, cfg.spacing)
    target = sunpath.growth_weighted_noon_zenith(cfg.latitude, cfg.start_day_of_year, grown.relief_history)
    return shape | {"lean_target_deg": float(np.degrees(target))}


@pytest.fixture(scope="module")
def six_seasons():
    return [_season(seed) for seed in range(1, 7)]


@pytest.mark.slow
def test_final_spacing_does_not_depend_on_the_seed(six_seasons, validation):
    """V6: six seeds end within +-20 % of their mean crest spacing, each with spacing / height in 0.5-2 (the
    reference's V3 bound; 60-day Tapado season, 256^2 over 8 m as the demo; ~10 min with the lean test).
    Measured with the net-gain gate: 1.03-1.22 m (-8.1 % ... +8.5 %), spacing/H 1.23-1.37."""
    spacings = np.array([s["crest_spacing_m"] for s in six_seasons])
    ratios = np.array([s["spacing_to_height"] for s in six_seasons])
    validation.record(
        "V6 six seeds, demo's 256² over 8 m: final crest spacing / the seeds' mean",
        spacings / spacings.mean(),
        reference=1.0,
        tolerance="±20 % each",
        against="the other seeds",
    )
    assert np.all(np.abs(spacings / spacings.mean() - 1) <= 0.2), spacings
    assert np.all((ratios >= 0.5) & (ratios <= 2.0)), ratios


@pytest.mark.slow
def test_every_seed_leans_within_5_deg_of_the_noon_zenith(six_seasons, validation):
    """V3's lean for the six V6 seeds, each against its growth-weighted noon zenith angle, within 5 deg.
    Measured: 3.4-4.4 deg toward the equator against 7.78-7.87 deg, 3.4-4.4 deg short (DESIGN.md 7, V3)."""
    leans = np.array([s["lean_north_deg"] for s in six_seasons])  # at 30 S the equator is north
    targets = np.array([s["lean_target_deg"] for s in six_seasons])
    validation.record(
        "V3 lean, six seeds: lean toward the equator − growth-weighted noon zenith angle [°]",
        leans - targets,
        reference=0,
        tolerance="±5°",
        against="Warren 2023 and the reference's V3: the forms lean toward the noon sun",
    )
    assert np.all(np.abs(leans - targets) <= 5.0), (leans, targets)
