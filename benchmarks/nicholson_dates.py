"""The Tapado season on Nicholson et al.'s (2016) survey dates (issue 49; geometry/DESIGN.md 8).

Grows a config's season (the demo's by default) with a snapshot every day and tables, on 25 Nov, 11 Dec,
20 Dec and 3 Jan, what the surveys measured or show: crest spacing, crest-to-trough height H, crests per m²,
the share of cells steeper than 45° (morphology.slope_deg), the ridge azimuth and its coherence, the mean surface lowering since the
start, and the stage (pitted, suncups, penitentes; DESIGN.md 7, *Stages*).

Run: .venv/bin/python benchmarks/nicholson_dates.py [--config configs/demo.yaml] [--seeds 1 2] [--set KEY=VALUE ...]
     [--earlier-start 258]
The second table grows the same season from an earlier start (15 Sep by default), which tells whether the date of
the penitente stage follows the season's length or the calendar.
Prints the table and writes benchmarks/results/nicholson_dates.md and .csv (results/local/ with other arguments).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _results import is_standard, start, write_results  # noqa: E402

from geometry import ablation, metrics, morphology  # noqa: E402
from geometry.sunpath import calendar_day  # noqa: E402
from pipeline.config import load_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
# The survey dates (Nicholson et al. 2016, 2013-14 season) as days of the year.
SURVEYS = [("25 Nov", 329), ("11 Dec", 345), ("20 Dec", 354), ("3 Jan", 3)]


def survey_rows(config: str, overrides: list[str], seed: int) -> tuple[list[dict], str]:
    """One seed's row on each survey date, and the date on which the stage first reads penitentes (and stays so
    to the last survey), or "not by 3 Jan"."""
    base = load_config(config, [*overrides, f"seed={seed}"]).geometry
    offsets = [(day - base.start_day_of_year) % 365 for _, day in SURVEYS]
    cfg = load_config(
        config, [*overrides, f"seed={seed}", f"geometry.days={max(offsets)}", f"geometry.snapshots={max(offsets) + 1}"]
    ).geometry
    rng = np.random.default_rng(seed)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    days = grown.snapshot_days.tolist()
    radius = metrics.crest_radius(cfg.optical_efolding_depth)
    stages = [morphology.stage_metrics(h, cfg.spacing)["stage"] for h in grown.snapshots]
    rows = []
    for (label, _), offset in zip(SURVEYS, offsets, strict=True):
        snapshot = days.index(offset)
        h = grown.snapshots[snapshot]
        shape = metrics.morphology(h, cfg.spacing, radius)
        rows.append(
            {
                "start_day_of_year": cfg.start_day_of_year,
                "date": label,
                "day": offset,
                "spacing": shape["crest_spacing_m"],
                "H": shape["crest_to_trough_m"],
                "density": shape["crest_density_per_m2"],
                "steep": float((morphology.slope_deg(h, cfg.spacing) > 45.0).mean()),
                "azimuth": shape["ridge_azimuth_deg"],
                "coherence": shape["coherence"],
                "lowering": float(h0.mean() - h.mean()),
                "stage": stages[snapshot],
            }
        )
    settled = len(stages)
    while settled > 0 and stages[settled - 1] == "penitentes":
        settled -= 1
    if settled == len(stages):
        return rows, "not by 3 Jan"
    day = int(days[settled])
    return rows, f"{calendar_day(cfg.start_day_of_year + day)} (day {day})"


def table(config: str, overrides: list[str], seeds: list[int]) -> tuple[str, list[dict]]:
    """The Markdown table (seeds side by side in each cell) and its rows, one per seed and date."""
    runs, firsts = zip(*(survey_rows(config, overrides, s) for s in seeds), strict=True)
    shown = Path(config).resolve()
    shown_config = shown.relative_to(ROOT) if shown.is_relative_to(ROOT) else shown
    lines = [
        f"Config {shown_config} {' '.join(overrides)}; seeds {' / '.join(map(str, seeds))}.",
        "",
        "| date (season day) | crest spacing [m] | H [m] | crests per m² | facets > 45° | ridge azimuth [°] (coherence)"
        " | mean lowering [m] | stage |",
        "|---|---|---|---|---|---|---|---|",
    ]

    def cell(key: str, fmt: str) -> str:
        return " / ".join(fmt.format(r[i][key]) for r in runs)

    for i, row in enumerate(runs[0]):
        azimuth = " / ".join(f"{r[i]['azimuth']:.0f} ({r[i]['coherence']:.2f})" for r in runs)
        lines.append(
            f"| {row['date']} ({row['day']}) | {cell('spacing', '{:.2f}')} | {cell('H', '{:.2f}')} | "
            f"{cell('density', '{:.1f}')} | {cell('steep', '{:.0%}')} | {azimuth} | {cell('lowering', '{:.2f}')} | "
            f"{' / '.join(r[i]['stage'] for r in runs)} |"
        )
    lines += ["", f"Penitentes from (to the last survey): {' / '.join(firsts)}."]
    rows = [{"seed": seed, **row} for seed, run in zip(seeds, runs, strict=True) for row in run]
    return "\n".join(lines) + "\n", rows


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", default=str(ROOT / "configs" / "demo.yaml"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--set", dest="overrides", action="append", default=[], help="config override KEY=VALUE")
    parser.add_argument(
        "--earlier-start",
        type=int,
        default=258,
        help="day of year of a second, earlier season start to table beside the config's (258: 15 Sep; 0: none)",
    )
    args = parser.parse_args()
    text, rows = table(args.config, args.overrides, args.seeds)
    if args.earlier_start:
        earlier = [*args.overrides, f"geometry.start_day_of_year={args.earlier_start}"]
        more, more_rows = table(args.config, earlier, args.seeds)
        text += (
            "\nThe same season started earlier: does an older field stand at the penitente stage by the first survey?"
            "\n\n" + more
        )
        rows += more_rows
    print(text)
    write_results("nicholson_dates", text, run, rows=rows, standard=is_standard(parser, args))


if __name__ == "__main__":
    main()
