"""The validation report (tests/validation_report.py) on a small test file run by pytester: the rows of passed and
failed tests arrive from pytest-xdist's workers, skipped tests add none, and nothing is written without the option."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from validation_report import format_figure

TESTS = Path(__file__).resolve().parent

SAMPLE = """
import numpy as np
import pytest


def test_ratio_passes(validation):
    validation.record("half-space: ours / exact", np.float64(0.998123), reference=1.0, tolerance="±1.5 %",
                      against="Chandrasekhar's H-function")
    validation.record("frames | steady", [1.0, 1.25, 0.5, 2.0, 0.75], reference="the steady image",
                      tolerance="rtol 1e-4", against="the same run")


def test_onset_fails(validation):
    validation.record("first arrival [frame]", 1003, reference=1000, tolerance="±2 frames", against="n·D / Δ")
    assert 1003 - 1000 <= 2


def test_skipped_adds_nothing(validation):
    validation.record("never shown", 1.0, reference=1.0, tolerance="exact", against="nothing")
    pytest.skip("not this time")
"""


@pytest.fixture
def sample(pytester: pytest.Pytester, monkeypatch: pytest.MonkeyPatch) -> pytest.Pytester:
    pytester.makepyfile(test_sample=SAMPLE)
    # The subprocess imports the plugin from tests/, as tests/conftest.py does in the project.
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    return pytester


def table_rows(text: str) -> list[list[str]]:
    lines = [line for line in text.splitlines() if line.startswith("| ")]
    return [[cell.strip() for cell in line.strip("|").split(" | ")] for line in lines[1:]]  # after the header


def test_workers_records_reach_the_table(sample: pytest.Pytester):
    result = sample.runpytest_subprocess(
        "-p", "validation_report", "-p", "xdist", "-n", "2", "--validation-report", "out/validation.md"
    )
    result.assert_outcomes(passed=1, failed=1, skipped=1)
    text = (sample.path / "out" / "validation.md").read_text()
    assert "- Machine: " in text and "logical cores" in text and " UTC, after " in text
    assert "- Commit: " in text and "- Load average (1 / 5 / 15 min): " in text
    # pytester puts its own --basetemp first.
    assert "-p validation_report -p xdist -n 2 --validation-report out/validation.md`" in text
    assert "- Figures: 3 from 2 tests, 1 of them from failed tests" in text
    rows = table_rows(text)
    assert [row[0] for row in rows] == ["first arrival [frame]", "half-space: ours / exact", "frames \\| steady"]
    onset, ratio, frames = rows
    assert onset == [
        "first arrival [frame]",
        "n·D / Δ",
        "1003",
        "1000",
        "±2 frames",
        "failed",
        "`test_sample.py::test_onset_fails`",
    ]
    assert ratio[1:6] == ["Chandrasekhar's H-function", "0.9981", "1.000", "±1.5 %", "passed"]
    assert frames[2:4] == ["0.5000 to 2.000 (5 values)", "the steady image"]
    assert "never shown" not in text


def test_without_the_option_nothing_is_written(sample: pytest.Pytester):
    result = sample.runpytest_subprocess("-p", "validation_report")
    result.assert_outcomes(passed=1, failed=1, skipped=1)
    written = [path for path in sample.path.rglob("*.md") if ".pytest_cache" not in path.parts]  # its README
    assert written == []


def test_figures_are_numbers_or_text():
    assert format_figure(np.float32(2.5)) == "2.500"
    assert format_figure(1.00004) == "1.000"  # a ratio keeps its four digits
    assert format_figure(2128.3) == "2128"
    assert format_figure(8.381e-8) == "8.381e-08"
    assert format_figure(np.int64(7)) == "7"
    assert format_figure(np.array([0.25, 0.5])) == "0.2500, 0.5000"
    assert format_figure(True) == "yes"
    assert format_figure("byte-identical") == "byte-identical"
    with pytest.raises(TypeError, match="flat sequence"):
        format_figure([[1.0, 2.0]])
    with pytest.raises(TypeError, match="flat sequence"):
        format_figure(None)
