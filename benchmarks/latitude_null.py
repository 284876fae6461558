"""The latitude null against the start's roughness (issue 49; geometry/DESIGN.md 7 V3, 8).

V3's reduced run (128^2 over 4 m) of the Tapado preset and of its 65 S control (high_latitude_65s.yaml, the same
air and season at 65 S), from starts of different RMS roughness: the RMS relief each grows (final RMS minus start
RMS) after 60 days and over the preset's whole season, and 65 S over Tapado. Penitentes should not grow at 65 S,
so a start that lets 65 S grow as much as Tapado is one the model's latitude null cannot carry.

Run: .venv/bin/python benchmarks/latitude_null.py [--rms 0.03 0.045] [--seeds 7 8] [--demo-grid]
--demo-grid grows on the demo's grid (256^2 over 8 m, whose box holds five or six mature rows where V3's holds two
or three) from the preset's start (3 cm), seeds 1 and 2, and writes latitude_null_demo_grid.
Prints the table and writes benchmarks/results/latitude_null.md and .csv (results/local/ with other arguments).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _results import is_standard, start, write_results  # noqa: E402

from geometry import ablation  # noqa: E402
from pipeline.config import load_config, load_raw  # noqa: E402
from pipeline.schema.geometry import GeometryConfig  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SITES = ROOT / "configs" / "presets" / "sites"
REDUCED = {"grid_cells": 128, "domain_size": 4.0}  # V3's reduced run (tests/geometry/test_geometry_morphology.py)
EARLY = 60  # [days]


def relief_growth(preset: str, rms: float, seed: int, grid: dict) -> np.ndarray:
    """RMS relief grown (RMS minus the start's) [m] on each day of the preset's season, day 0 first, on ``grid``
    (grid_cells and domain_size)."""
    raw = load_raw(SITES / preset)["geometry"]
    days = int(raw["days"])
    cfg = GeometryConfig(**{**raw, **grid, "initial_roughness_rms": rms, "snapshots": days + 1})
    rng = np.random.default_rng(seed)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    if grown.snapshot_days.tolist() != list(range(days + 1)):
        raise RuntimeError(f"{preset}: expected a snapshot on every day of the {days}-day season")
    return grown.snapshots.reshape(days + 1, -1).std(axis=1) - h0.std()


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--rms", type=float, nargs="+", help="start RMS [m] (default 0.03 0.045; 0.03 on the demo grid)"
    )
    parser.add_argument("--seeds", type=int, nargs="+", help="default 7 8; 1 2 on the demo grid")
    parser.add_argument("--demo-grid", action="store_true", help="256^2 over 8 m instead of V3's 128^2 over 4 m")
    args = parser.parse_args()
    if args.demo_grid:
        demo = load_config(ROOT / "configs" / "demo.yaml").geometry
        grid = {"grid_cells": demo.grid_cells, "domain_size": demo.domain_size}
    else:
        grid = REDUCED
    rms_list = args.rms or ([0.03] if args.demo_grid else [0.03, 0.045])
    seeds = args.seeds or ([1, 2] if args.demo_grid else [7, 8])
    lines = [
        "| start RMS [m] | seed | Tapado, day 60 [m] | 65°S, day 60 [m] | 65°S / Tapado, day 60 | Tapado, season [m] "
        "| 65°S, season [m] | 65°S / Tapado, season | 65°S / Tapado, largest from day 60 (day) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for rms in rms_list:
        for seed in seeds:
            tapado = relief_growth("tapado.yaml", rms, seed, grid)
            polar = relief_growth("high_latitude_65s.yaml", rms, seed, grid)
            days = tapado.size - 1
            t60, tend, h60, hend = tapado[EARLY], tapado[-1], polar[EARLY], polar[-1]
            ratio = polar[EARLY:] / tapado[EARLY:]
            worst = int(np.argmax(ratio))
            lines.append(
                f"| {rms:g} | {seed} | {t60:.3f} | {h60:.3f} | {h60 / t60:.0%} | {tend:.3f} | {hend:.3f} | "
                f"{hend / tend:.0%} | {ratio[worst]:.0%} ({EARLY + worst}) |"
            )
            print(lines[-1], flush=True)
            rows.append(
                {
                    "start_rms_m": rms,
                    "seed": seed,
                    "tapado_day60_m": t60,
                    "s65_day60_m": h60,
                    "tapado_season_m": tend,
                    "s65_season_m": hend,
                    "largest_ratio_from_day60": float(ratio[worst]),
                    "largest_ratio_day": EARLY + worst,
                }
            )
    text = (
        f"RMS relief grown (final minus start) on {grid['grid_cells']}² over {grid['domain_size']:g} m; the season is the "
        f"preset's {days} days.\n\n" + "\n".join(lines) + "\n"
    )
    print(text)
    name = "latitude_null_demo_grid" if args.demo_grid else "latitude_null"
    write_results(name, text, run, rows=rows, standard=is_standard(parser, args, ignore=("demo_grid",)))


if __name__ == "__main__":
    main()
