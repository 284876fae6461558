"""Sensitivity of the grown field to its estimated constants (geometry/DESIGN.md 7, *Sensitivity*).

Grows the Tapado season once as the preset gives it and once per change of one estimated constant (the air
temperature and the wind of the surface energy balance, the shelter angle of full melt, the optical e-folding
depth, the wake slope, the start's correlation length), each at both ends of its plausible range, and tables the final
field: crest-to-trough height H, crest spacing, their ratio, the crest count per m^2 on day 15 and at the end,
the lean toward the equator, the ridges' angle off E-W and the growth of the RMS height.

Run: .venv/bin/python benchmarks/geometry_sensitivity.py [--grid 256] [--domain 4] [--days 60] [--seed 7]
     [--jobs 2]
Writes benchmarks/results/geometry_sensitivity.md and .csv (results/local/ with other arguments, --jobs aside).
The default (256^2 over 4 m: 1.6 cm cells, inside every resolution guard even for l = 3 cm; 13 seasons) takes
about 10 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _results import is_standard, start, write_results  # noqa: E402

from geometry import ablation, metrics, stage  # noqa: E402
from pipeline.config import load_raw  # noqa: E402
from pipeline.schema.geometry import GeometryConfig  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SITE = ROOT / "configs" / "presets" / "sites" / "tapado.yaml"

# (row label, the two changed values); the row's key is the label's first word, a dotted key for a value inside a
# block (meteorology.air_temperature). The preset runs the surface energy balance, so the constant-loss keys
# (sky_loss, turbulent_loss_share, melt_gain_threshold) do not apply; the balance's own estimates vary instead: the
# season's air temperature (an estimate for ~4700 m, +-2 C) and its wind (Guanaco's annual mean, halved and 1.5x).
CHANGES = [
    ("meteorology.air_temperature", (-5.0, -1.0)),
    ("meteorology.wind_speed", (5.0, 15.0)),
    ("shelter_full_melt_deg", (30.0, 60.0)),
    ("optical_efolding_depth", (0.03, 0.12)),
    ("wake_slope", (0.0, 1 / 3)),
    ("initial_correlation_length", (0.075, 0.30)),
]
DAY_EARLY = 15


def grow(overrides: dict, *, grid: int, domain: float, days: int, seed: int) -> dict:
    """One season of the Tapado preset with ``overrides``: the final field's numbers (module docstring)."""
    snapshots = days // 5 + 1  # a snapshot every 5 days, so day 15 is one of them
    raw = {
        **load_raw(SITE)["geometry"],
        "grid_cells": grid,
        "domain_size": domain,
        "days": days,
        "snapshots": snapshots,
    }
    for key, value in overrides.items():
        block, _, name = key.rpartition(".")
        if block:
            raw[block] = {**raw[block], name: value}
        else:
            raw[key] = value
    cfg = GeometryConfig(**raw)
    rng = np.random.default_rng(seed)
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    shape = stage.field_metrics(grown, cfg)
    early = int(np.argmin(np.abs(grown.snapshot_days - DAY_EARLY)))
    radius = metrics.crest_radius(cfg.optical_efolding_depth)  # as field_metrics counts the crests
    return {
        "H": shape["crest_to_trough_m"],
        "spacing": shape["crest_spacing_m"],
        "ratio": shape["spacing_to_height"],
        "density_early": metrics.crest_density(grown.snapshots[early], cfg.spacing, radius),
        "density_end": shape["crest_density_per_m2"],
        "lean": shape["lean_toward_equator_deg"],
        "off_east_west": shape["ridge_deviation_from_east_west_deg"],
        "rms_growth": float(grown.height.std() - h0.std()),
        "warnings": ablation.config_warnings(cfg),
    }


def _cells(runs: list[dict]) -> list[str]:
    def pair(fmt: str, key: str) -> str:
        return " / ".join(fmt.format(r[key]).replace("-", "−") for r in runs)

    density = " / ".join(f"{r['density_early']:.1f} → {r['density_end']:.1f}" for r in runs)
    return [
        pair("{:.2f}", "H"),
        pair("{:.2f}", "spacing"),
        pair("{:.2f}", "ratio"),
        density,
        pair("{:.1f}", "lean"),
        pair("{:.1f}", "off_east_west"),
        pair("{:.3f}", "rms_growth"),
    ]


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=256)
    parser.add_argument("--domain", type=float, default=4.0)
    parser.add_argument("--days", type=int, default=60)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    points: list[dict] = [{}] + [{key: value} for key, values in CHANGES for value in values]
    grow_point = partial(grow, grid=args.grid, domain=args.domain, days=args.days, seed=args.seed)
    with ProcessPoolExecutor(args.jobs) as pool:
        results = list(pool.map(grow_point, points))
    for point, result in zip(points, results):
        for warning in result["warnings"]:
            print(f"warning ({point or 'preset'}): {warning}", file=sys.stderr)
    header = (
        "| change | H [m] | crest spacing [m] | λ_dom/H | crests per m², day "
        f"{DAY_EARLY} → {args.days} | lean [°] | ridges off E–W [°] | RMS growth [m] |\n"
        "|---|---|---|---|---|---|---|---|\n"
    )
    rows = ["| none | " + " | ".join(_cells(results[:1])) + " |"]
    for i, (key, values) in enumerate(CHANGES):
        pair = results[1 + 2 * i : 3 + 2 * i]
        label = f"{key} {' / '.join(f'{v:.3g}' for v in values)}"
        rows.append(f"| {label} | " + " | ".join(_cells(pair)) + " |")
    text = (
        f"Sensitivity of the Tapado season: {args.grid}² over {args.domain:g} m, {args.days} days, seed {args.seed}. "
        "A changed row's cells give the fields grown at its two values, in the order its label lists them.\n\n"
        + header
        + "\n".join(rows)
        + "\n"
    )
    print(text)
    csv_rows = [
        {"change": next(iter(point), "none"), "value": next(iter(point.values()), ""), **result}
        for point, result in zip(points, results)
    ]
    for row in csv_rows:
        del row["warnings"]
    standard = is_standard(parser, args, ignore=("jobs",))
    write_results("geometry_sensitivity", text, run, rows=csv_rows, standard=standard)


if __name__ == "__main__":
    main()
