"""The rules the project's prose keeps (issue 50): figures regenerate, prose does not carry them.

- Hand-written prose (the README, the CHANGELOG, the design notes and the site's own pages) stays within a word
  budget, half of what it had grown to, so that a newcomer can read it in order.
- No prose, comment or config carries a dated measurement: the figures live in the results files that the
  benchmark scripts and ``make test`` write (benchmarks/results/), each with the commit and machine that made it,
  and history stays in git and the CHANGELOG.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Half of the 66 000 words that issue 50 counted.
PROSE_WORD_BUDGET = 33_000

# Markdown that a program writes: results of scripts and tests, and the generated config reference.
GENERATED = ("benchmarks/results/", "docs/config-reference.md", "docs/lidar/biases.md")

# Spelled in two pieces so that this file does not match itself.
DATED = re.compile("|".join(["Dec" + " 2026", "measured" + " on"]), re.IGNORECASE)
DATED_ALLOWED = ("benchmarks/results/", "CHANGELOG.md")


def tracked(pattern: str = "") -> list[str]:
    try:
        out = subprocess.run(
            ["git", "ls-files", *([pattern] if pattern else [])], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the prose rules read the tracked files")
    return [line for line in out.splitlines() if line]


def hand_written_prose() -> list[str]:
    return [p for p in tracked("*.md") if not p.startswith(GENERATED)]


def words(path: str) -> int:
    return len((ROOT / path).read_text(encoding="utf-8").split())


def test_the_walk_finds_the_prose():
    prose = set(hand_written_prose())
    assert {"README.md", "CHANGELOG.md", "geometry/DESIGN.md", "render/core/DESIGN.md"} <= prose
    assert not any(p.startswith("benchmarks/results/") for p in prose)


def test_hand_written_prose_stays_within_its_budget():
    counts = sorted(((words(p), p) for p in hand_written_prose()), reverse=True)
    total = sum(n for n, _ in counts)
    largest = ", ".join(f"{p} {n}" for n, p in counts[:6])
    assert total <= PROSE_WORD_BUDGET, (
        f"hand-written prose has {total} words, over the budget of {PROSE_WORD_BUDGET} (largest: {largest}). "
        "Keep rules, reasons and caveats; move figures into a results file that a script writes."
    )


def test_no_dated_measurement_outside_the_results_and_the_changelog():
    found = []
    for path in tracked():
        if path.startswith(DATED_ALLOWED) or path == "tests/test_docs_rules.py":
            continue
        file = ROOT / path
        try:
            text = file.read_text(encoding="utf-8")
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue
        found += [f"{path}:{n}: {line.strip()}" for n, line in enumerate(text.splitlines(), 1) if DATED.search(line)]
    assert not found, "dated measurements belong in benchmarks/results/ or the CHANGELOG:\n" + "\n".join(found)


@pytest.mark.parametrize(
    ("line", "dated"),
    [
        ("took 8 min on 5 " + "Dec 2026", True),
        ("as " + "measured on the demo", True),
        ("values observed at Guanaco Glacier", False),
        ("the season starts on 1 Oct", False),
    ],
)
def test_the_dated_pattern_tells_a_measurement_log(line, dated):
    assert bool(DATED.search(line)) is dated
