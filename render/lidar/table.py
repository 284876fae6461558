"""One table of range biases from lidar runs (render/lidar/LIDAR.md §7.4): every run folder's
``lidar/summary.json`` (with the lidar section it ran), a row per run, channel and estimator.

    python -m render.lidar.table runs/lidar_icesat2 runs/lidar_airborne ... --out runs/lidar_table

writes ``biases.csv`` and ``biases.md`` (cm, against the footprint mean, the highest point and the flat
equivalent) in ``--out``. A sweep of lidar runs (``configs/sweeps/lidar_biases.yaml``) gets its summary from
``write_sweep_summary``: the full table, the compact one (docs/benchmarks/lidar.md) and a figure of every point's waveform.
"""

from __future__ import annotations

import argparse
import csv
import html
import json
from pathlib import Path

import numpy as np

from common.atomic import atomic_path, write_text_atomic

COLUMNS = ("run", "target", "density", "grain_mm", "footprint_m", "channel", "estimator")
# The estimators from the leading edge to the tail: the compact table's columns (compact_rows).
ESTIMATOR_COLUMNS = ("first_return", "peak", "gaussian_fit", "median", "centroid")


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


def write_table(rows: list[dict], out: Path, stem: str = "biases") -> tuple[Path, Path]:
    """``rows`` as ``stem``.csv and ``stem``.md in ``out`` (biases with one decimal, in cm); returns both paths."""
    if not rows:
        raise ValueError(f"no bias rows to write to {out}: none of the runs had a lidar summary")
    out.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0])
    with atomic_path(out / f"{stem}.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, keys)
        writer.writeheader()
        writer.writerows(rows)
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append(
            "| "
            + " | ".join(
                f"{v:+.1f}" if isinstance(v, float) and (k.startswith("bias") or k in ESTIMATOR_COLUMNS) else str(v)
                for k, v in row.items()
            )
            + " |"
        )
    with atomic_path(out / f"{stem}.md") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out / f"{stem}.csv", out / f"{stem}.md"


def compact_rows(rows: list[dict], channel: str, reference: str = "flat_equivalent") -> list[dict]:
    """One row per run: its inputs and every estimator's bias [cm] in ``channel`` against ``reference`` (the
    compact table), estimators from the leading edge to the tail."""
    inputs: dict[str, dict] = {}
    biases: dict[str, dict] = {}
    for row in rows:
        if row["channel"] == channel:
            inputs.setdefault(row["run"], {k: row[k] for k in COLUMNS if k not in ("channel", "estimator")})
            biases.setdefault(row["run"], {})[row["estimator"]] = row[f"bias_{reference}_cm"]
    order = [e for e in ESTIMATOR_COLUMNS if any(e in b for b in biases.values())]
    order += [e for b in biases.values() for e in b if e not in order]
    return [{**inputs[run], **{e: biases[run][e] for e in order if e in biases[run]}} for run in inputs]


def write_sweep_summary(spec: dict) -> dict[str, Path]:
    """The summary of a sweep whose points end in the lidar stage (``spec``: the sweep's workflow.yaml):
    ``biases.csv``/``.md`` (every point, channel, estimator and reference), ``summary.csv``/``.md``/``.html``
    (a row per point: 532 nm with Warren & Brandt ice against the flat-equivalent surface), ``poster.png``
    (every point's pulsed waveform) and ``report.html``, in the sweep's folder."""
    from render.output.report import html_page, markdown_table_to_html

    folder = Path(spec["folder"])
    runs = {name: Path(spec["runs_dir"]) / f"{spec['sweep']}-{name}" for name in spec["points"]}
    rows = []
    for name, run in runs.items():
        for row in rows_of(run):
            rows.append({**row, "run": name})
    write_table(rows, folder, "biases")
    channel = rows[0]["channel"]
    csv_path, md_path = write_table(compact_rows(rows, channel), folder, "summary")
    table_html = markdown_table_to_html(md_path.read_text(encoding="utf-8"))
    title = f"Sweep '{spec['sweep']}': lidar range biases"
    write_text_atomic(folder / "summary.html", html_page(title, table_html))
    _plot_sweep_waveforms(runs, folder / "poster.png")
    parts = [f"<p>{html.escape(spec['description'])}</p>"] if spec.get("description") else []
    parts.append(
        f"<p>{len(runs)} points from <code>{html.escape(spec['sweep_file'])}</code>. Bias [cm] = the estimator's "
        f"range minus the range of the flat-equivalent surface, {html.escape(channel)}; positive: the surface "
        "reads low. Every channel and reference height: "
        '<a href="biases.csv">biases.csv</a> · <a href="biases.md">biases.md</a> (render/lidar/LIDAR.md §4).</p>'
    )
    parts.append(f"<div style='overflow-x: auto'>{table_html}</div>")
    parts.append(
        '<figure><img src="poster.png" alt="waveforms" style="max-width: 100%"><figcaption>pulsed waveforms, '
        f"{html.escape(channel)}, each over its peak</figcaption></figure>"
    )
    write_text_atomic(folder / "report.html", html_page(title, "\n".join(parts)))
    return {"csv": csv_path, "md": md_path, "poster": folder / "poster.png", "report": folder / "report.html"}


def normalised_waveform(run: Path, channel: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A run's pulsed waveform in ``channel`` over its peak, against the height of the return above the
    flat-equivalent surface [m] (``run/lidar/waveform.npz``)."""
    with np.load(run / "lidar" / "waveform.npz") as data:
        height = float(data["reference_height"]) - data["range_m"]
        pulsed = np.asarray(data["pulsed"][:, channel], dtype=np.float64)
    return height, pulsed / pulsed.max() if pulsed.max() > 0 else pulsed


def _plot_sweep_waveforms(runs: dict[str, Path], path: Path) -> None:
    """Every point's first-channel pulsed waveform against the height of the return above the flat-equivalent
    surface, one panel per target and footprint."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {}
    for run in runs.values():
        summary = json.loads((run / "lidar" / "summary.json").read_text())
        lidar = summary["config"]
        height, pulsed = normalised_waveform(run)
        key = f"{summary['target']}, {lidar['footprint_diameter']:g} m footprint"
        label = (
            f"albedo {lidar['bare_albedo']:g}"
            if summary["target"] == "bare"
            else f"{lidar['density']:g} kg/m³, {1000 * lidar['optical_diameter']:g} mm"
        )
        panels.setdefault(key, []).append((label, height, pulsed))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), dpi=130, squeeze=False)
    for ax, (key, curves) in zip(axes[0], sorted(panels.items())):
        for label, height, pulsed in curves:
            ax.plot(height, pulsed, lw=1.0, label=label)
        ax.axvline(0.0, color="0.5", ls=":", lw=0.8)
        ax.set_title(key, fontsize=9)
        ax.set_xlabel("height above the flat-equivalent surface [m]")
        ax.set_xlim(-1.5, 1.2)
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("pulsed waveform / its peak")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


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
