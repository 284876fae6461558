"""One table of range biases from lidar runs (render/lidar/LIDAR.md §7.4): every run folder's
``lidar/summary.json`` (with the lidar section it ran), a row per run, channel and estimator.

    python -m render.lidar.table runs/lidar_icesat2 runs/lidar_airborne ... --out runs/lidar_table

writes ``biases.csv`` and ``biases.md`` (cm, against the footprint mean, the highest point and the flat
equivalent) in ``--out``.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

from pipeline.atomic import atomic_path

COLUMNS = ("run", "target", "density", "grain_mm", "footprint_m", "channel", "estimator")


def rows_of(run: Path) -> list[dict]:
    """The bias rows of one run folder (``run/lidar/summary.json``, which holds the lidar section it ran)."""
    summary_path = run / "lidar" / "summary.json"
    if not summary_path.is_file():
        raise FileNotFoundError(f"{summary_path} is missing: run the lidar stage of {run.name} first")
    summary = json.loads(summary_path.read_text())
    lidar = summary["config"]
    rows = []
    for channel in summary["channels"]:
        for estimator, by_reference in channel["bias_m"].items():
            rows.append(
                {
                    "run": run.name,
                    "target": summary["target"],
                    "density": lidar["density"],
                    "grain_mm": 1000 * lidar["optical_diameter"],
                    "footprint_m": lidar["footprint_diameter"],
                    "channel": channel["label"],
                    "estimator": estimator,
                    **{f"bias_{k}_cm": 100 * v for k, v in by_reference.items()},
                }
            )
    return rows


def write_table(rows: list[dict], out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0])
    with atomic_path(out / "biases.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append(
            "| "
            + " | ".join(
                f"{v:+.1f}" if isinstance(v, float) and k.startswith("bias") else str(v) for k, v in row.items()
            )
            + " |"
        )
    with atomic_path(out / "biases.md") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run folders (runs/<name>) with a lidar stage")
    parser.add_argument("--out", type=Path, required=True, help="folder for biases.csv and biases.md")
    args = parser.parse_args()
    rows = [row for run in args.runs for row in rows_of(run)]
    write_table(rows, args.out)
    print(f"{len(rows)} rows from {len(args.runs)} runs -> {args.out}/biases.csv, biases.md")


if __name__ == "__main__":
    main()
