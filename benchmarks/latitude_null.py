"""The latitude null against the start's roughness (issue 49; geometry/DESIGN.md 7 V3, 8).

V3's reduced run (128^2 over 4 m) of the Tapado preset and of its 65 S control (high_latitude_65s.yaml, the same
air and season at 65 S), from starts of different RMS roughness: the RMS relief each grows (final RMS minus start
RMS) after 60 days and over the preset's whole season, and 65 S over Tapado. Penitentes should not grow at 65 S,
so a start that lets 65 S grow as much as Tapado is one the model's latitude null cannot carry.

Run: .venv/bin/python benchmarks/latitude_null.py [--rms 0.03 0.045] [--seeds 7 8]
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
from pipeline.config import load_raw  # noqa: E402
from pipeline.schema.geometry import GeometryConfig  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SITES = ROOT / "configs" / "presets" / "sites"
REDUCED = {"grid_cells": 128, "domain_size": 4.0}  # V3's reduced run (tests/geometry/test_geometry_morphology.py)
EARLY = 60  # [days]


def relief_growth(preset: str, rms: float, seed: int) -> tuple[float, float, int]:
    """RMS relief grown by day EARLY and by the season's end [m], and the season's length [days]."""
    raw = load_raw(SITES / preset)["geometry"]
    days = int(raw["days"])
    cfg = GeometryConfig(**{**raw, **REDUCED, "initial_roughness_rms": rms, "snapshots": days + 1})
    rng = np.random.default_rng(seed)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    day = grown.snapshot_days.tolist()
    start = h0.std()
    return float(grown.snapshots[day.index(EARLY)].std() - start), float(grown.height.std() - start), days


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rms", type=float, nargs="+", default=[0.03, 0.045])
    parser.add_argument("--seeds", type=int, nargs="+", default=[7, 8])
    args = parser.parse_args()
    lines = [
        "| start RMS [m] | seed | Tapado, day 60 [m] | 65°S, day 60 [m] | 65°S / Tapado, day 60 | Tapado, season [m] "
        "| 65°S, season [m] | 65°S / Tapado, season |",
        "|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for rms in args.rms:
        for seed in args.seeds:
            t60, tend, days = relief_growth("tapado.yaml", rms, seed)
            h60, hend, _ = relief_growth("high_latitude_65s.yaml", rms, seed)
            lines.append(
                f"| {rms:g} | {seed} | {t60:.3f} | {h60:.3f} | {h60 / t60:.0%} | {tend:.3f} | {hend:.3f} | "
                f"{hend / tend:.0%} |"
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
                }
            )
    text = (
        f"RMS relief grown (final minus start) on 128² over 4 m; the season is the preset's {days} days.\n\n"
        + "\n".join(lines)
        + "\n"
    )
    print(text)
    write_results("latitude_null", text, run, rows=rows, standard=is_standard(parser, args))


if __name__ == "__main__":
    main()
