"""Grid convergence of the grown field (issue 27; geometry/DESIGN.md 7, *Grid convergence*).

Grows one config's season on grids that each halve the cell, for several seeds, and tables its numbers
(crest spacing, crest-to-trough height H, relief, crest density, spacing/H, the field albedo drop, the lean)
per grid, with the Richardson extrapolation from the three finest grids and each grid's error against it.

Run: .venv/bin/python benchmarks/grid_convergence.py [--grids 128 256 512] [--seeds 1 2 3] [--jobs 2]
     [--config configs/demo.yaml] [--set geometry.days=60 ...]
Writes benchmarks/results/grid_convergence/<grid>_<seed>.json and .npz (the numbers and the final field
of one run, reused unless --force; git-ignored) and the table to benchmarks/results/grid_convergence.md and .csv
(results/local/<name>.md with other arguments than the defaults, --jobs and --force aside). On 2 cores the default study (128^2, 256^2, 512^2 over 8 m, seeds
1-3) takes about 10 minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _results import is_standard, start, write_results  # noqa: E402

from common.atomic import write_json_atomic  # noqa: E402
from geometry import ablation, convergence, stage  # noqa: E402
from pipeline.config import load_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"

# (key in a run's JSON, column title, format)
QUANTITIES = [
    ("crest_spacing_m", "crest spacing [m]", "{:.3f}"),
    ("crest_to_trough_m", "H [m]", "{:.3f}"),
    ("relief_m", "relief 2√2 RMS [m]", "{:.3f}"),
    ("crest_density_per_m2", "crests per m²", "{:.2f}"),
    ("spacing_to_height", "λ_dom/H", "{:.2f}"),
    ("albedo_difference", "field albedo − flat", "{:.3f}"),
    ("lean_toward_equator_deg", "lean [°]", "{:.1f}"),
]
# The quantities issue 27's convergence criterion names (the lean is reported, judged by V3 instead).
JUDGED = QUANTITIES[:6]


def grow_and_measure(config: str, overrides: list[str], grid: int, seed: int) -> dict:
    """One season on one grid: the numbers of the geometry stage's metrics.json that the study tables."""
    cfg = load_config(config, [*overrides, f"geometry.grid_cells={grid}", f"seed={seed}"]).geometry
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    growth_s = time.perf_counter() - t0
    shape = stage.field_metrics(grown, cfg)
    keys = [k for k, _, _ in QUANTITIES] + ["axis_lean_toward_equator_deg", "ridge_deviation_from_east_west_deg"]
    return {
        "grid": grid,
        "seed": seed,
        "cell_m": cfg.spacing,
        "domain_m": cfg.domain_size,
        "days": cfg.days,
        "growth_s": growth_s,
        **{k: shape[k] for k in [*keys, "noon_zenith_growth_weighted_deg"]},
        "relief_history_m": (2 * np.sqrt(2) * grown.relief_history).tolist(),
        "height": grown.height,
    }


def _task(args: tuple[str, list[str], int, int, Path]) -> dict:
    config, overrides, grid, seed, path = args
    row = grow_and_measure(config, overrides, grid, seed)
    np.savez_compressed(path.with_suffix(".npz"), height=row.pop("height"), cell_m=row["cell_m"])
    write_json_atomic(path, row)
    print(f"{grid}^2 seed {seed}: grown in {row['growth_s']:.0f} s", flush=True)
    return row


def table(rows: list[dict], grids: list[int], seeds: list[int], title: str) -> list[str]:
    """Markdown: per-seed and seed-mean values per grid, Richardson from the three finest, errors."""
    by = {(r["grid"], r["seed"]): r for r in rows}
    lines = [f"{title}.", ""]
    header = "| grid (cell) | " + " | ".join(t for _, t, _ in QUANTITIES) + " | growth [s] |"
    lines += [header, "|" + "---|" * (len(QUANTITIES) + 2)]
    means = {}
    for g in grids:
        runs = [by[(g, s)] for s in seeds]
        means[g] = {k: float(np.mean([r[k] for r in runs])) for k, _, _ in QUANTITIES}
        cell = 100 * runs[0]["cell_m"]
        cells = " | ".join(
            fmt.format(means[g][k]) + " (" + ", ".join(fmt.format(r[k]) for r in runs) + ")" for k, _, fmt in QUANTITIES
        )
        lines.append(f"| {g}² ({cell:.3g} cm) | {cells} | {np.mean([r['growth_s'] for r in runs]):.0f} |")
    lines += ["", "Seed means first, each seed in brackets (seeds " + ", ".join(map(str, seeds)) + ").", ""]
    if len(grids) >= 3:
        coarse, medium, fine = grids[-3:]
        lines += [
            f"Richardson extrapolation from {coarse}², {medium}², {fine}² (seed means); error of each grid against it; "
            f"'finest two' is |f({medium}²) − f({fine}²)| / f({fine}²), 'next coarser' |f({coarse}²) − f({fine}²)| / "
            f"f({fine}²).",
            "",
            "| quantity | extrapolated | order | "
            + " | ".join(f"error {g}²" for g in grids)
            + " | finest two | next coarser |",
            "|" + "---|" * (len(grids) + 5),
        ]
        for key, title_, fmt in QUANTITIES:
            est = convergence.richardson(means[coarse][key], means[medium][key], means[fine][key])
            errors = " | ".join(
                f"{100 * convergence.relative_error(means[g][key], est.extrapolated):.1f} %" for g in grids
            )
            two = convergence.relative_error(means[medium][key], means[fine][key])
            next_ = convergence.relative_error(means[coarse][key], means[fine][key])
            order = f"{est.order:.2f}" if est.order_measured else f"{est.order:.0f} (assumed)"
            lines.append(
                f"| {title_} | {fmt.format(est.extrapolated)} | {order} | {errors} | {100 * two:.1f} % | "
                f"{100 * next_:.1f} % |"
            )
    return lines


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "configs" / "demo.yaml"))
    parser.add_argument("--grids", type=int, nargs="+", default=[128, 256, 512])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--name", default="grid_convergence", help="results name under benchmarks/results")
    parser.add_argument("--force", action="store_true", help="re-grow runs whose JSON exists")
    args = parser.parse_args()
    folder = OUT / args.name
    folder.mkdir(parents=True, exist_ok=True)
    tasks, rows = [], []
    # Largest grids first, so the two processes finish together.
    for grid in sorted(args.grids, reverse=True):
        for seed in args.seeds:
            path = folder / f"{grid}_{seed}.json"
            if path.exists() and not args.force:
                rows.append(json.loads(path.read_text()))
            else:
                tasks.append((args.config, args.overrides, grid, seed, path))
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        rows += list(pool.map(_task, tasks))
    title = f"Grid convergence: {Path(args.config).name}" + (
        f" with {', '.join(args.overrides)}" if args.overrides else ""
    )
    lines = table(rows, sorted(args.grids), args.seeds, title)
    print("\n".join(lines))
    csv_rows = [{k: v for k, v in row.items() if k != "relief_history_m"} for row in rows]
    standard = is_standard(parser, args, ignore=("jobs", "force"))
    write_results(args.name, "\n".join(lines), run, rows=csv_rows, standard=standard)


if __name__ == "__main__":
    main()
