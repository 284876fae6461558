"""Does the mature field remember its start? (issue 49; geometry/DESIGN.md 7, *Sensitivity*).

Grows the demo's season (80 days, 256² over 8 m) from starts whose correlation length lc is the preset's
0.15 m, halved and doubled, for two seeds each, and tables the mature field's numbers per lc with their
change against the preset's start. A start that is forgotten changes them by no more than the seeds do.

Run: .venv/bin/python benchmarks/start_memory.py [--lengths 0.075 0.15 0.3] [--seeds 1 2] [--jobs 2]
Writes benchmarks/results/start_memory/<lc>_<seed>.json (reused unless --force; git-ignored) and the table to
benchmarks/results/start_memory.md and .csv. About 10 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _results import is_standard, start, write_results  # noqa: E402
from grid_convergence import QUANTITIES, grow_and_measure  # noqa: E402

from common.atomic import write_json_atomic  # noqa: E402
from geometry import morphology  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
CONFIG = ROOT / "configs" / "demo.yaml"
PRESET_LC = 0.15  # the Tapado preset's initial_correlation_length [m]


def _task(args: tuple[float, int, int, Path]) -> dict:
    lc, seed, grid, path = args
    row = grow_and_measure(str(CONFIG), [f"geometry.initial_correlation_length={lc}"], grid, seed)
    row["stage"] = morphology.stage_metrics(row.pop("height"), row["cell_m"])["stage"]
    row["lc_m"] = lc
    write_json_atomic(path, row)
    print(f"lc {lc} m seed {seed}: grown in {row['growth_s']:.0f} s", flush=True)
    return row


def table(rows: list[dict], lengths: list[float], seeds: list[int], grid: int) -> list[str]:
    by = {(r["lc_m"], r["seed"]): r for r in rows}
    lines = [
        f"The demo's season ({rows[0]['days']} days, {grid}² over {rows[0]['domain_m']:g} m) from starts of correlation "
        f"length lc; seed means first, each seed in brackets (seeds {', '.join(map(str, seeds))}). Change: the seed "
        f"mean against lc = {PRESET_LC} m; seed spread: half the gap between the seeds at lc = {PRESET_LC} m, as a "
        "fraction of their mean.",
        "",
        "| lc [m] | " + " | ".join(t for _, t, _ in QUANTITIES) + " | stage |",
        "|" + "---|" * (len(QUANTITIES) + 2),
    ]
    means = {}
    for lc in lengths:
        runs = [by[(lc, s)] for s in seeds]
        means[lc] = {k: float(np.mean([r[k] for r in runs])) for k, _, _ in QUANTITIES}
        cells = " | ".join(
            fmt.format(means[lc][k]) + " (" + ", ".join(fmt.format(r[k]) for r in runs) + ")"
            for k, _, fmt in QUANTITIES
        )
        lines.append(f"| {lc:g} | {cells} | {' / '.join(r['stage'] for r in runs)} |")
    if PRESET_LC in lengths:
        base = [by[(PRESET_LC, s)] for s in seeds]
        lines += [
            "",
            "| quantity | seed spread at the preset | "
            + " | ".join(f"change at lc = {lc:g} m" for lc in lengths if lc != PRESET_LC)
            + " |",
        ]
        lines.append("|" + "---|" * (1 + len(lengths)))
        for key, title, _ in QUANTITIES:
            ref = means[PRESET_LC][key]
            spread = abs(base[0][key] - base[-1][key]) / 2 / abs(ref) if ref else float("nan")
            changes = " | ".join(
                f"{100 * (means[lc][key] - ref) / abs(ref):+.1f} %" for lc in lengths if lc != PRESET_LC
            )
            lines.append(f"| {title} | {100 * spread:.1f} % | {changes} |")
    return lines


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--lengths", type=float, nargs="+", default=[0.075, PRESET_LC, 0.3])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--grid", type=int, default=256)
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--force", action="store_true", help="re-grow runs whose JSON exists")
    args = parser.parse_args()
    folder = OUT / "start_memory"
    folder.mkdir(parents=True, exist_ok=True)
    tasks, rows = [], []
    for lc in args.lengths:
        for seed in args.seeds:
            path = folder / f"{lc:g}_{seed}.json"
            if path.exists() and not args.force:
                rows.append(json.loads(path.read_text()))
            else:
                tasks.append((lc, seed, args.grid, path))
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows += list(pool.map(_task, tasks))
    lines = table(rows, args.lengths, args.seeds, args.grid)
    print("\n".join(lines))
    csv_rows = [{k: v for k, v in row.items() if k != "relief_history_m"} for row in rows]
    write_results(
        "start_memory",
        "\n".join(lines),
        run,
        rows=csv_rows,
        standard=is_standard(parser, args, ignore=("jobs", "force")),
    )


if __name__ == "__main__":
    main()
