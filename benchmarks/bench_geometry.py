"""Geometry-stage time against grid size: growth + mesh + metrics.

Run: .venv/bin/python benchmarks/bench_geometry.py  (SEASON=0 skips the 512^2 season, ~10 min)
Writes benchmarks/results/geometry.md and .csv (results/local/ with SEASON=0). The 256^2 row is the demo's grid (the Tapado site
preset over 8 m, 60 days as in configs/demo.yaml: 3.1 cm cells, inside the converged range of
geometry/DESIGN.md 7); the last row is issue 27's target, a 60-day season at that converged cell over
16 m (512^2), which must stay under 15 minutes on 2 cores. Pictures are excluded (~4 s).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _results import start, write_results  # noqa: E402

from geometry import ablation, mesh, metrics  # noqa: E402
from pipeline.config import load_raw  # noqa: E402
from pipeline.schema.geometry import GeometryConfig  # noqa: E402

# (grid cells per side, domain side [m], simulated days)
CASES = [(256, 8.0, 60)] + ([(512, 16.0, 60)] if os.environ.get("SEASON", "1") != "0" else [])
TAPADO = Path(__file__).resolve().parents[1] / "configs" / "presets" / "sites" / "tapado.yaml"


def bench(cells: int, domain: float, days: int) -> dict:
    site = load_raw(TAPADO)["geometry"]
    cfg = GeometryConfig(**{**site, "grid_cells": cells, "domain_size": domain, "days": days, "snapshots": 2})
    rng = np.random.default_rng(1)
    t0 = time.perf_counter()
    h0 = ablation.initial_height_field_from_config(cfg, rng)
    grown = ablation.grow_field(h0, cfg.spacing, ablation.settings_from_config(cfg), rng)
    t1 = time.perf_counter()
    solid = mesh.decimate(mesh.heightfield_solid(grown.height, cfg.spacing, cfg.base_thickness), cfg.max_triangles)
    mesh.manifold_volume(solid)
    t2 = time.perf_counter()
    shape = metrics.morphology(grown.height, cfg.spacing)
    t3 = time.perf_counter()
    return {
        "grid": f"{cells}^2",
        "domain_m": domain,
        "days": days,
        "growth_s": t1 - t0,
        "per_day_s": (t1 - t0) / days,
        "horizons_s": grown.timings["horizons_s"],
        "mesh_s": t2 - t1,
        "metrics_s": t3 - t2,
        "total_s": t3 - t0,
        "triangles": len(solid.faces),
        "crest_spacing_m": shape["crest_spacing_m"],
        "crest_to_trough_m": shape["crest_to_trough_m"],
    }


def main() -> None:
    run = start()
    rows = []
    for cells, domain, days in CASES:
        row = bench(cells, domain, days)
        rows.append(row)
        print(
            f"{row['grid']:>6}  {days:3d} days  growth {row['growth_s']:7.2f} s ({row['per_day_s']:.2f} s/day, "
            f"horizons {row['horizons_s']:.2f} s)  mesh {row['mesh_s']:.2f} s  total {row['total_s']:.2f} s",
            flush=True,
        )
    md = [
        "Geometry stage: time against grid size. Tapado preset from its correlated start; growth + mesh + metrics; "
        "pictures excluded (~4 s, grid-independent).",
        "",
        "| grid | domain [m] | days | growth [s] | per day [s] | horizons [s] | mesh [s] | metrics [s] | total [s] | "
        "triangles | crest spacing [m] | H [m] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    md += [
        f"| {r['grid']} | {r['domain_m']:g} | {r['days']} | {r['growth_s']:.2f} | {r['per_day_s']:.2f} | "
        f"{r['horizons_s']:.2f} | "
        f"{r['mesh_s']:.2f} | {r['metrics_s']:.2f} | {r['total_s']:.2f} | {r['triangles']} | "
        f"{r['crest_spacing_m']:.2f} | {r['crest_to_trough_m']:.2f} |"
        for r in rows
    ]
    print("\n".join(md[2:]))
    write_results("geometry", "\n".join(md), run, rows=rows, standard=os.environ.get("SEASON", "1") != "0")


if __name__ == "__main__":
    main()
