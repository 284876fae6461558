"""Validation figures written by the tests that assert them (docs/validation.md).

A test takes the ``validation`` fixture and hands it the figure it is about to assert, with what the figure
is compared against and the tolerance::

    validation.record("single scattering: ours / quadrature", ratio, reference=1.0, tolerance="±2 %",
                      against="closed-form single-scattering integral")

With ``--validation-report PATH`` the session ends by writing every figure recorded by a test that passed or
failed as a Markdown table, under the header every results file carries (benchmarks/_results.py: the command,
the commit, the machine, the UTC date and wall time, the load average). Without the option nothing is written and
a record costs nothing but a list entry.

A record rides in the test item's ``user_properties``, which pytest-xdist sends with each report from its
workers to the controller; the controller alone collects the records (``pytest_runtest_logreport``) and writes
the file, so ``make test``'s ``-n 2 --dist loadfile`` gives the same table as a run in one process.
"""

from __future__ import annotations

import shlex
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import pytest

from common.atomic import write_text_atomic

# The results files' own header helpers, from the benchmarks' script folder (no package).
sys.path.append(str(Path(__file__).resolve().parents[1] / "benchmarks"))
from _results import load_average, machine, start  # noqa: E402

RECORD_KEY = "validation"
OPTION = "--validation-report"
# A sequence longer than this is written as its range and its length, not value by value.
LISTED_VALUES = 4


def format_figure(value: object) -> str:
    """A figure as the table shows it: four significant digits, integers whole, a long sequence as its range."""
    if hasattr(value, "tolist"):  # numpy scalars and arrays become Python numbers and lists
        value = value.tolist()
    if isinstance(value, str):
        return value
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        # Four significant digits, kept when they are zeros (a ratio reads 1.000, not 1).
        return f"{value:#.4g}".replace(".e", "e").removesuffix(".")
    if isinstance(value, list | tuple) and value and all(isinstance(v, int | float) for v in value):
        if len(value) <= LISTED_VALUES:
            return ", ".join(format_figure(v) for v in value)
        return f"{format_figure(min(value))} to {format_figure(max(value))} ({len(value)} values)"
    raise TypeError(f"a figure is a number, a flat sequence of numbers or text, not {value!r}")


@dataclass(frozen=True)
class Row:
    """One recorded figure as the controller received it."""

    check: str
    against: str
    measured: str
    reference: str
    tolerance: str
    outcome: str
    nodeid: str


class Validation:
    """What the ``validation`` fixture gives a test: ``record`` files one figure with the test's report."""

    def __init__(self, item: pytest.Item) -> None:
        self._item = item

    def record(self, check: str, measured: object, *, reference: object, tolerance: str, against: str) -> None:
        """Record ``measured`` (what the test asserts) for the check named ``check``, compared with ``reference``
        (a number or words) within ``tolerance`` (words, with units: "±1.5 %", "≤ 5°"), the reference being
        ``against`` (a closed form, a renderer, a paper). Call it before the assert, so a failure still reports
        its figure."""
        for name, text in (("check", check), ("tolerance", tolerance), ("against", against)):
            if not isinstance(text, str) or not text.strip():
                raise TypeError(f"validation.record: {name} must be non-empty text, got {text!r}")
        entry = {
            "check": check,
            "against": against,
            "measured": format_figure(measured),
            "reference": format_figure(reference),
            "tolerance": tolerance,
        }
        self._item.user_properties.append((RECORD_KEY, entry))


@pytest.fixture
def validation(request: pytest.FixtureRequest) -> Validation:
    """Records the figures this test asserts for ``--validation-report`` (tests/validation_report.py)."""
    return Validation(request.node)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.getgroup("validation").addoption(
        OPTION,
        metavar="PATH",
        default=None,
        help="write the validation figures the tests record (the validation fixture) as a Markdown table to PATH",
    )


def pytest_configure(config: pytest.Config) -> None:
    path = config.getoption("validation_report")
    # An xdist worker sends its reports to the controller, which writes the one table.
    if path and not hasattr(config, "workerinput"):
        target = Path(config.invocation_params.dir) / path
        config.pluginmanager.register(ValidationReport(config, target), "validation-report")


class ValidationReport:
    """The controller's side: collects the records of passed and failed calls and writes the table at the end."""

    def __init__(self, config: pytest.Config, path: Path) -> None:
        self.config = config
        self.path = path
        self.rows: list[Row] = []
        self.run = start()  # the commit, the clock and the load average as the session starts

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when != "call" or report.outcome not in ("passed", "failed"):
            return
        for name, entry in report.user_properties:
            if name == RECORD_KEY:
                self.rows.append(Row(**entry, outcome=report.outcome, nodeid=report.nodeid))

    @pytest.hookimpl(trylast=True)
    def pytest_sessionfinish(self, session: pytest.Session, exitstatus: int) -> None:
        write_text_atomic(self.path, self.markdown())

    def markdown(self) -> str:
        rows = sorted(self.rows, key=lambda row: row.nodeid)  # stable: a test's records keep their order
        failed = sum(row.outcome == "failed" for row in rows)
        seconds = time.perf_counter() - self.run.clock
        lines = [
            "<!-- Written by tests/validation_report.py (pytest --validation-report): run the tests again rather than "
            "edit this file (docs/validation.md). -->",
            "",
            f"- Command: `{shlex.join(['pytest', *self.config.invocation_params.args])}`",
            f"- Commit: {self.run.commit}",
            f"- Machine: {machine()}",
            f"- Finished: {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, after {wall_time(seconds)}",
            f"- Load average (1 / 5 / 15 min): {load_average(self.run.load)} at the start, {load_average()} at the end",
            f"- Figures: {len(rows)} from {len({row.nodeid for row in rows})} tests, {failed} of them from failed tests",
            "",
            "| check | compared against | measured | reference | tolerance | result | test |",
            "|---|---|---|---|---|---|---|",
        ]
        for row in rows:
            cells = [row.check, row.against, row.measured, row.reference, row.tolerance, row.outcome]
            lines.append("| " + " | ".join(_cell(c) for c in cells) + f" | `{_cell(row.nodeid)}` |")
        return "\n".join(lines) + "\n"


def wall_time(seconds: float) -> str:
    """As benchmarks/_results.py writes it: seconds, and minutes past two of them."""
    return f"{seconds:.0f} s" + (f" ({seconds / 60:.0f} min)" if seconds >= 120 else "")


def _cell(text: str) -> str:
    """Text that stays inside one Markdown table cell."""
    return " ".join(text.split()).replace("|", "\\|")
