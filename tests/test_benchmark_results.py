"""The benchmarks' results files (benchmarks/_results.py): each one says what made it, and the site shows each one.

- ``write_results`` heads a table with the command, the commit, the machine, the date, the wall time and the load
  average, writes its rows as CSV, and sends a run with other than the standard arguments to results/local/.
- Every committed results file carries that header, and docs/benchmarks/index.md (docs/validation.md for the
  validation table) includes every one of them; a file a page names but git lacks fails the strict site build.
"""

from __future__ import annotations

import argparse
import csv
import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
INDEX = ROOT / "docs" / "benchmarks" / "index.md"
# The validation figures that make test records (tests/validation_report.py) have a page of their own.
VALIDATION = ROOT / "docs" / "validation.md"
HEADER_KEYS = ("Command", "Commit", "Machine", "Finished", "Load average")


@pytest.fixture
def results(tmp_path, monkeypatch):
    """benchmarks/_results.py (a script's module, not a package's) writing into tmp_path instead of
    benchmarks/results/."""
    spec = importlib.util.spec_from_file_location("_results", ROOT / "benchmarks" / "_results.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "_results", module)  # its dataclass looks itself up there
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "RESULTS", tmp_path)
    monkeypatch.setattr(module, "LOCAL", tmp_path / "local")
    monkeypatch.setattr(sys, "argv", [str(ROOT / "benchmarks" / "walk_model.py"), "--paths", "2000"])
    return module


def committed_results() -> list[str]:
    try:
        out = subprocess.run(
            ["git", "ls-files", "benchmarks/results/*.md"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout: the committed results are read from git")
    return [line for line in out.splitlines() if line]


def header_keys(text: str) -> list[str]:
    """The keys of the ``- Key: value`` lines above a results file's first table or paragraph."""
    return re.findall(r"^- ([A-Z][a-z ]*[a-z])(?: \([^)]*\))?:", text.split("\n\n", 2)[1], flags=re.MULTILINE)


def test_a_results_file_says_what_made_it(results, tmp_path):
    run = results.start()
    rows = [{"variant": "core", "ratio": 1.0}, {"variant": "guided", "ratio": 0.7, "note": "new column"}]
    path = results.write_results("walk_model", "| variant |\n|---|\n| core |", run, rows=rows)

    assert path == tmp_path / "walk_model.md"
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<!-- Written by benchmarks/walk_model.py")
    assert header_keys(text) == list(HEADER_KEYS)
    assert "- Rows also in `walk_model.csv`" in text
    assert "- Command: `python benchmarks/walk_model.py --paths 2000`" in text
    commit = re.search(r"^- Commit: (.*)$", text, flags=re.MULTILINE)[1]
    assert re.fullmatch(r"[0-9a-f]{40}( \+ uncommitted changes)?|unknown \(not a git checkout\)", commit), commit
    assert "logical cores" in text and "GiB memory" in text
    assert re.search(r"^- Finished: \d{4}-\d\d-\d\d \d\d:\d\d UTC, after \d+ s$", text, flags=re.MULTILINE)
    assert text.rstrip().endswith("| core |")

    with open(tmp_path / "walk_model.csv", newline="", encoding="utf-8") as f:
        read = list(csv.DictReader(f))
    assert [r["variant"] for r in read] == ["core", "guided"]
    assert read[1]["note"] == "new column" and read[0]["note"] == ""
    assert not list(tmp_path.glob(".*tmp*")), "the atomic writer left a temporary file behind"


def test_a_trial_run_writes_apart_from_the_committed_table(results, tmp_path):
    path = results.write_results("walk_model", "trial", results.start(), standard=False)
    assert path == tmp_path / "local" / "walk_model.md"
    assert not (tmp_path / "walk_model.md").exists()
    assert not (tmp_path / "local" / "walk_model.csv").exists(), "no rows, no CSV"


def test_standard_means_every_argument_at_its_default(results):
    parser = argparse.ArgumentParser()
    parser.add_argument("--paths", type=int, default=200_000)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--jobs", type=int, default=2)
    assert results.is_standard(parser, parser.parse_args([]))
    assert results.is_standard(parser, parser.parse_args(["--seeds", "1", "2", "--paths", "200000"]))
    assert not results.is_standard(parser, parser.parse_args(["--seeds", "1"]))
    assert not results.is_standard(parser, parser.parse_args(["--jobs", "1"]))
    assert results.is_standard(parser, parser.parse_args(["--jobs", "1"]), ignore=("jobs",))


def test_every_committed_results_file_says_what_made_it():
    missing = {
        path: [key for key in HEADER_KEYS if key not in header_keys((ROOT / path).read_text(encoding="utf-8"))]
        for path in committed_results()
    }
    missing = {path: keys for path, keys in missing.items() if keys}
    assert not missing, f"results files without their header lines (run the script again): {missing}"


def test_the_site_includes_every_committed_results_file():
    pages = INDEX.read_text() + "\n" + VALIDATION.read_text()
    included = set(re.findall(r'^--8<-- "(benchmarks/results/[^"]+\.md)"', pages, flags=re.MULTILINE))
    tables = set(committed_results())
    assert tables <= included, f"add a section to {INDEX.relative_to(ROOT)} for: {sorted(tables - included)}"
