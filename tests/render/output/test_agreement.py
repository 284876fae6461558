"""The disagreement guard: the noise of the ours/reference ratio from a tile jackknife, and a flag only
beyond both 3σ and 3 %. Tested on synthetic renders with known noise and deliberate biases, and
through the compare stage and the sweep summary."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from render.output.agreement import agreement


def noisy(truth, rel_noise, rng):
    return truth * (1 + rel_noise * rng.standard_normal(truth.shape))


@pytest.fixture
def truth():
    y, x = np.mgrid[0:48, 0:64]
    image = 1.0 + 0.8 * np.sin(x / 9.0)[..., None] * np.cos(y / 7.0)[..., None]  # structure the ratio must ignore
    return np.repeat(image, 3, axis=-1) * np.array([1.0, 0.7, 0.4])


def test_the_jackknife_error_matches_the_spread_over_repeated_renders(truth, validation):
    rng = np.random.default_rng(5)
    results = [agreement(noisy(truth, 0.3, rng), noisy(truth, 0.1, rng)) for _ in range(60)]
    ratios = np.array([r.ratio for r in results])
    sigmas = np.array([r.sigma for r in results])
    validation.record(
        "agreement guard: spread of ours / reference over 60 synthetic renders, per channel",
        np.std(ratios, axis=0),
        reference=np.mean(sigmas, axis=0),
        tolerance="±35 %",
        against="the guard's tile-jackknife σ of the ratio, mean over the renders",
    )
    assert np.std(ratios, axis=0) == pytest.approx(np.mean(sigmas, axis=0), rel=0.35)
    assert not any(r.disagrees for r in results)  # unbiased, only noise


@pytest.mark.parametrize(
    ("bias", "noise", "flagged"),
    [
        (0.90, 0.05, True),  # 10 % low, far beyond the noise: a wrong renderer
        (0.98, 0.001, False),  # beyond 3σ but under 3 %: too small to matter
        (0.95, 3.0, False),  # 5 % low but within the noise of a short render
        (1.00, 0.05, False),
        (0.43, 0.2, True),  # the dense-snow case of issue 16
    ],
)
def test_a_channel_is_flagged_only_beyond_3_sigma_and_3_percent(truth, bias, noise, flagged):
    rng = np.random.default_rng(11)
    verdict = agreement(noisy(truth, noise, rng) * bias, truth)
    assert verdict.disagrees is flagged, verdict.text()
    assert verdict.ratio[0] == pytest.approx(bias, abs=max(0.01, 4 * verdict.sigma[0]))


def test_a_black_reference_is_flagged_not_passed(truth):
    """Mitsuba renders a delta sun behind a dielectric black (configs/showcase/bubbly_ice_sun.yaml): the ratio
    is infinite, which must read as a disagreement, while two black images are no disagreement."""
    verdict = agreement(truth, np.zeros_like(truth))
    assert verdict.reference_black and verdict.disagrees
    assert "reference is black" in verdict.text()
    both_black = agreement(np.zeros_like(truth), np.zeros_like(truth))
    assert not both_black.reference_black and not both_black.disagrees


def test_the_compare_stage_flags_a_biased_render_loudly(tmp_path, caplog):
    from render.output.compare import run_compare_stage

    run = tmp_path / "run"
    ours, ref = run / "render", run / "reference"
    ours.mkdir(parents=True)
    ref.mkdir()
    rng = np.random.default_rng(2)
    steady = np.full((32, 40, 3), 2.0, np.float32)
    np.save(ours / "steady.npy", (noisy(steady, 0.05, rng) * 0.8).astype(np.float32))  # 20 % low
    (ours / "stats.json").write_text(json.dumps({"frame_mode": "steady", "iterations": 8, "time_total_s": 1.0}))
    np.save(ref / "steady.npy", noisy(steady, 0.05, rng).astype(np.float32))
    (ref / "timing.json").write_text(json.dumps({"steady": {"seconds": 2.0, "spp": 64}}))
    with caplog.at_level("WARNING"):
        run_compare_stage(run, ours, ref, run / "compare", ["reference", "render"], "biased run")
    assert "DISAGREES" in caplog.text
    table = (run / "compare" / "comparison.md").read_text()
    assert re.search(r"\*\*DISAGREES: ours / reference 0\.(79|80)\d", table), table
    page = (run / "compare" / "report.html").read_text()
    assert "<tr class='disagrees'>" in page and "Warning: ours and the reference disagree" in page
    csv_text = (run / "compare" / "comparison.csv").read_text()
    assert "DISAGREES" in csv_text.splitlines()[1]


def test_the_sweep_summary_flags_a_point_whose_compare_stage_disagreed(tmp_path, caplog):
    from render.output.summary import _compare_errors, _PointFiles

    compare = tmp_path / "compare"
    compare.mkdir()
    header = "renderer,quantity,relmse,agreement\n"
    (compare / "comparison.csv").write_text(
        header + "ours (PTPB),steady,0.5,DISAGREES: ours / reference 0.43 ± 0.01\nMitsuba volpath,steady,,\n"
    )
    with caplog.at_level("WARNING"):
        errors = _compare_errors(_PointFiles("dense", tmp_path, {"compare"}))
    assert errors["disagrees_with_reference"] is True and errors["relmse_steady"] == 0.5
    assert "point 'dense': ours disagrees with its reference" in caplog.text
    (compare / "comparison.csv").write_text(header + "ours (PTPB),steady,0.001,agrees: ours / reference 1.00 ± 0.01\n")
    assert _compare_errors(_PointFiles("thin", tmp_path, {"compare"}))["disagrees_with_reference"] is False
