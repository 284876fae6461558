"""The results files of the benchmark scripts: where a figure the project reports lives (issue 50).

Each script writes its tables once, through ``write_results``, to ``benchmarks/results/<name>.md`` (and its rows
to ``<name>.csv``), under a header that says what made them: the command, the commit, the machine, the UTC date,
the wall time and the load average at the start and at the end, so that a reader can tell an old commit or a
loaded machine. The files are kept in git and the site includes them (docs/benchmarks/index.md); prose points to
them instead of copying a figure.

A run with other arguments than the script's standard ones writes to ``benchmarks/results/local/`` instead
(git-ignored), so a trial never replaces the table the site shows::

    run = start()
    ...
    write_results("walk_model", table, run, rows=rows, standard=is_standard(parser, args))
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import shlex
import subprocess
import sys
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from common.atomic import atomic_path, write_text_atomic

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
LOCAL = RESULTS / "local"
# What the scripts write themselves: rewriting a results file is not a change to the code that made it. The
# README holds atl06_track.py's table between markers and steers no result.
WRITTEN_BY_SCRIPTS = ("benchmarks/results", "docs/lidar", "README.md")


@dataclass(frozen=True)
class Start:
    """When a script started, on what load, and from which commit (``start()``)."""

    clock: float  # time.perf_counter() [s]
    load: tuple[float, float, float]  # 1, 5 and 15 min load averages
    commit: str


def start() -> Start:
    """Call first thing in a script: its wall time, starting load and commit go into the results' header."""
    return Start(time.perf_counter(), os.getloadavg(), commit())


def commit() -> str:
    """``git rev-parse HEAD``, with "+ uncommitted changes" when a tracked file other than a results file differs
    from it (pipeline.manifest.git_revision counts the results too, so a second script of ``make bench`` would
    always read as changed)."""
    exclude = [f":(exclude){path}" for path in WRITTEN_BY_SCRIPTS]
    try:
        head = _git("rev-parse", "HEAD")
        changed = _git("status", "--porcelain", "--untracked-files=no", "--", ".", *exclude)
    except (OSError, subprocess.SubprocessError):
        return "unknown (not a git checkout)"
    return head + (" + uncommitted changes" if changed else "")


def _git(*args: str) -> str:
    return subprocess.run(
        ["git", *args], cwd=REPO, capture_output=True, text=True, timeout=30, check=True
    ).stdout.strip()


def machine() -> str:
    """CPU model, logical cores, memory and operating system, in one line."""
    cpu = _first_value(Path("/proc/cpuinfo"), "model name") or platform.processor() or "unknown CPU"
    memory_kib = _first_value(Path("/proc/meminfo"), "MemTotal")
    memory = f"{int(memory_kib.split()[0]) / 2**20:.1f} GiB memory" if memory_kib else "memory unknown"
    system = (_first_value(Path("/etc/os-release"), "PRETTY_NAME", "=") or platform.system()).strip('"')
    return f"{cpu}, {os.cpu_count()} logical cores, {memory}, {system} ({platform.system()} {platform.release()})"


def _first_value(path: Path, key: str, separator: str = ":") -> str | None:
    """The value of the first ``key<separator>value`` line of a /proc or /etc file, or None."""
    try:
        lines = path.read_text().splitlines()
    except OSError:
        return None
    for line in lines:
        name, sep, value = line.partition(separator)
        if sep and name.strip() == key:
            return value.strip()
    return None


def load_average(load: tuple[float, float, float] | None = None) -> str:
    """The 1, 5 and 15 min load averages (now, unless given) as "1.02 / 0.87 / 0.55"."""
    return " / ".join(f"{x:.2f}" for x in (load or os.getloadavg()))


def is_standard(parser: argparse.ArgumentParser, args: argparse.Namespace, ignore: Iterable[str] = ()) -> bool:
    """Whether every argument has its default, but those in ``ignore`` (arguments that change no figure, such
    as a job count, or that the results' name carries)."""
    skipped = set(ignore)
    return all(value == parser.get_default(key) for key, value in vars(args).items() if key not in skipped)


def script() -> str:
    """The running script, relative to the repository when it lies inside it."""
    path = Path(sys.argv[0]).resolve()
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else sys.argv[0]


def command() -> str:
    """This process's command line."""
    return shlex.join(["python", script(), *sys.argv[1:]])


def header(run: Start, csv_name: str | None = None) -> str:
    """The Markdown lines above a results file's tables."""
    seconds = time.perf_counter() - run.clock
    wall = f"{seconds:.0f} s" + (f" ({seconds / 60:.0f} min)" if seconds >= 120 else "")
    lines = [
        f"<!-- Written by {script()}: run it again rather than edit this file (benchmarks/README.md). -->",
        "",
        f"- Command: `{command()}`",
        f"- Commit: {run.commit}",
        f"- Machine: {machine()}",
        f"- Finished: {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, after {wall}",
        f"- Load average (1 / 5 / 15 min): {load_average(run.load)} at the start, {load_average()} at the end",
    ]
    if csv_name:
        lines.append(f"- Rows also in `{csv_name}`")
    return "\n".join(lines) + "\n\n"


def write_results(
    name: str,
    body: str,
    run: Start,
    *,
    rows: Sequence[Mapping[str, object]] = (),
    standard: bool = True,
    folder: Path | None = None,
) -> Path:
    """Write ``body`` (Markdown tables and the sentences that read them) under the header to ``<name>.md``, and
    ``rows`` to ``<name>.csv``, atomically, in ``folder`` (default: benchmarks/results, or results/local/ for a
    run that is not ``standard``). Returns the Markdown file's path."""
    folder = folder or (RESULTS if standard else LOCAL)
    csv_name = f"{name}.csv" if rows else None
    if rows:
        columns = list(dict.fromkeys(key for row in rows for key in row))
        with atomic_path(folder / f"{name}.csv") as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
            writer = csv.DictWriter(f, columns)
            writer.writeheader()
            writer.writerows(rows)
    path = write_text_atomic(folder / f"{name}.md", header(run, csv_name) + body.strip("\n") + "\n")
    print(f"wrote {path.relative_to(REPO) if path.is_relative_to(REPO) else path}", flush=True)
    return path
