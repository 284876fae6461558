"""The sweep summary: one table row per point (CSV, Markdown, HTML), the poster grid of our steady
renders, the error-against-time plot and ``report.html``, read from the points' stage outputs.

It reads only files: ``workflow.yaml`` (written by ``python -m pipeline sweep``, which resolves each
point's overrides, inputs and enabled stages) and the stage folders of every point's run. The workflow's
summary rule (``python -m pipeline.sweep``) calls it for every sweep but a lidar one, whose table of range
biases render/lidar/table.py writes.
"""

from __future__ import annotations

import csv
import html
import io
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from common.atomic import write_text_atomic
from render.output.compare import likely_dark
from render.output.figures import error_curves, poster_grid
from render.output.files import RenderOutputs
from render.output.metrics import relmse
from render.output.report import html_page, markdown_table_to_html

log = logging.getLogger(__name__)


@dataclass
class _PointFiles:
    """Reads a point's stage outputs; a missing file of an enabled stage logs a warning and gives None."""

    name: str
    run_dir: Path
    enabled: set[str]

    def path(self, stage: str, name: str) -> Path | None:
        if stage not in self.enabled:
            return None
        path = self.run_dir / stage / name
        if not path.is_file():
            log.warning("sweep summary: point '%s': %s is missing; its cells stay empty", self.name, path)
            return None
        return path

    def read_json(self, stage: str, name: str) -> dict:
        path = self.path(stage, name)
        if path is None:
            return {}
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            log.warning("sweep summary: point '%s': cannot read %s (%s); its cells stay empty", self.name, path, exc)
            return {}

    def read_array(self, stage: str, name: str):

        path = self.path(stage, name)
        if path is None:
            return None
        try:
            return np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            log.warning("sweep summary: point '%s': cannot read %s (%s)", self.name, path, exc)
            return None


def _number(value: Any) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if number == number and abs(number) != float("inf") else None


def _compare_errors(files: _PointFiles) -> dict[str, Any]:
    """relMSE of ours (steady, frames) against the point's own reference, from compare/comparison.csv."""
    errors: dict[str, Any] = {"relmse_steady": None, "relmse_frames": None, "disagrees_with_reference": None}
    path = files.path("compare", "comparison.csv")
    if path is None:
        return errors
    with open(path, newline="", encoding="utf-8") as handle:
        for row in csv.DictReader(handle):
            if not row.get("renderer", "").startswith("ours"):
                continue
            key = "relmse_steady" if row.get("quantity") == "steady" else "relmse_frames"
            errors[key] = _number(row.get("relmse"))
            if row.get("agreement"):  # the compare stage's guard (render/output/agreement.py)
                flagged = row["agreement"].startswith("DISAGREES")
                errors["disagrees_with_reference"] = bool(errors["disagrees_with_reference"]) or flagged
    if errors["disagrees_with_reference"]:
        log.warning("sweep summary: point '%s': ours disagrees with its reference (compare/comparison.md)", files.name)
    return errors


def _relmse(estimate, reference, what: str, point: str) -> float | None:
    if estimate is None or reference is None:
        return None
    if estimate.shape != reference.shape:
        log.warning(
            "sweep summary: point '%s': %s has shape %s, the ground truth %s; no error computed",
            point,
            what,
            estimate.shape,
            reference.shape,
        )
        return None
    return relmse(estimate, reference)


def _triple_columns(prefix: str, values) -> dict[str, float | None]:
    values = values if isinstance(values, (list, tuple)) and len(values) == 3 else [None] * 3
    return {f"{prefix}_{channel}": _number(v) for channel, v in zip("rgb", values)}


def _point_row(
    spec: dict, name: str, input_keys: list[str], truth: dict | None
) -> tuple[dict[str, Any], _PointFiles, dict]:
    """One row: the point's inputs (every key some point overrides), times, errors, albedo, optics."""
    point = spec["points"][name]
    run_dir = Path(spec["runs_dir"]) / f"{spec['sweep']}-{name}"
    enabled = set(point["stages"])
    files = _PointFiles(name, run_dir, enabled)
    row: dict[str, Any] = {"point": name, **{key: point["inputs"].get(key) for key in input_keys}}
    stats = files.read_json("render", "stats.json")
    timing = files.read_json("reference", "timing.json")
    steady_timing, transient_timing = timing.get("steady") or {}, timing.get("transient") or {}
    row.update(
        {
            "frame_mode": stats.get("frame_mode"),
            "render_s": _number(stats.get("time_total_s", stats.get("seconds"))),
            "iterations": stats.get("iterations"),
        }
    )
    extras = {"steady_timing": steady_timing, "transient_timing": transient_timing}
    row["reference_steady_s"] = _number(steady_timing.get("seconds"))
    row["reference_transient_s"] = _number(transient_timing.get("seconds"))
    # The share of light the reference's roulette is expected to leave out (render/scene/roulette.py).
    roulette = timing.get("roulette") or {}
    row["reference_rr_depth"] = roulette.get("rr_depth")
    row["reference_missed_share"] = _number(roulette.get("missed"))
    dark = likely_dark(timing)
    if dark:
        log.warning("sweep summary: point '%s': its %s", name, dark)
    if truth is None:
        row.update(_compare_errors(files))
    else:
        ours_steady, ours_frames = files.read_array("render", "steady.npy"), files.read_array("render", "frames.npy")
        row["relmse_steady"] = _relmse(ours_steady, truth["steady"], "render/steady.npy", name)
        axis = RenderOutputs.read(files.run_dir / "render").axis if stats else None
        as_bins = axis.as_bins(ours_frames) if axis is not None and ours_frames is not None else ours_frames
        row["relmse_frames"] = _relmse(as_bins, truth["frames"], "render/frames.npy", name)
        row["reference_relmse_steady"] = row["reference_relmse_frames"] = None
        if name != spec["ground_truth"]:
            own_steady = files.read_array("reference", "steady.npy") if steady_timing else None
            own_frames = files.read_array("reference", "frames.npy") if transient_timing else None
            row["reference_relmse_steady"] = _relmse(own_steady, truth["steady"], "reference/steady.npy", name)
            row["reference_relmse_frames"] = _relmse(own_frames, truth["frames"], "reference/frames.npy", name)
    metrics = files.read_json("geometry", "metrics.json").get("metrics", {})
    row["field_albedo"] = _number(metrics.get("field_albedo"))
    for medium, entry in files.read_json("scene", "optics.json").items():
        derived = entry.get("derived", {}) if isinstance(entry, dict) else {}
        row.update(_triple_columns(f"{medium}_diffuse_albedo", derived.get("diffuse_albedo")))
        row.update(_triple_columns(f"{medium}_efolding_depth_m", derived.get("efolding_depth")))
    return row, files, extras


def _format_cell(value: Any, markdown: bool) -> str:
    if value is None:
        return ""
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    return text.replace("|", "/") if markdown else text


def write_table(rows: list[dict[str, Any]], folder: Path, title: str) -> dict[str, Path]:
    """summary.csv, summary.md and summary.html: one row per point, the union of the rows' columns."""
    columns: list[str] = []
    for row in rows:
        columns += [c for c in row if c not in columns]
    md_lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    md_lines += ["| " + " | ".join(_format_cell(r.get(c), True) for c in columns) + " |" for r in rows]
    markdown = "\n".join(md_lines) + "\n"
    paths = {"md": folder / "summary.md", "csv": folder / "summary.csv", "html": folder / "summary.html"}
    write_text_atomic(paths["md"], markdown)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    # Full precision in the CSV; four digits for people in Markdown and HTML.
    writer.writerows(
        [["" if r.get(c) is None else repr(r[c]) if isinstance(r[c], float) else r[c] for c in columns] for r in rows]
    )
    write_text_atomic(paths["csv"], buffer.getvalue())
    write_text_atomic(paths["html"], html_page(title, markdown_table_to_html(markdown)))
    return paths


def _sigma_label(key: str, entry: dict) -> str:
    """One poster line per medium: its rendered sigma_s and sigma_a (R, G, B) in 1/m."""
    medium = entry.get("medium", {})
    if "sigma_s" not in medium:
        return ""
    triple = lambda values: "/".join(f"{v:.3g}" for v in values)  # noqa: E731
    return f"\n{key} σs {triple(medium['sigma_s'])} /m\nσa {triple(medium['sigma_a'])} /m"


def write_poster(points: list[tuple[str, Any, str]], path: Path, title: str) -> None:
    """The poster grid of our steady renders; points whose image shape differs from the first are left out."""
    images = [(name, image, label) for name, image, label in points if image is not None]
    if images:
        shape = images[0][1].shape
        for name, image, _ in images:
            if image.shape != shape:
                log.warning(
                    "sweep summary: point '%s': its render is %s, not %s; left out of the poster",
                    name,
                    image.shape,
                    shape,
                )
        images = [item for item in images if item[1].shape == shape]
    if not images:
        log.warning("sweep summary: no steady render found; the poster is a placeholder")
        import matplotlib.pyplot as plt

        from common.atomic import atomic_path

        fig = plt.figure(figsize=(4, 1))
        fig.text(0.5, 0.5, "no steady render found", ha="center", va="center")
        for target in (path, path.with_suffix(".pdf")):
            with atomic_path(target) as tmp:
                fig.savefig(tmp)
        plt.close(fig)
        return
    poster_grid(
        [i for _, i, _ in images], [label for _, _, label in images], path, columns=min(4, len(images)), title=title
    )


def _error_series(
    spec: dict, rows: list[dict], extras: dict[str, dict], files: dict[str, _PointFiles], truth: dict | None
) -> dict[str, list[dict[str, float]]]:
    """With a ground truth: one line per method across points; without: each point's convergence
    (its steady snapshots against its own steady reference)."""

    series: dict[str, list[dict[str, float]]] = {}

    def add(label, seconds, count, error):
        if seconds and count and error:
            series.setdefault(label, []).append({"seconds": seconds, "iterations": count, "relmse": error})

    if truth is not None:
        for row in rows:
            extra = extras[row["point"]]
            if row["point"] == spec["ground_truth"]:
                continue
            if extra["steady_timing"] or extra["transient_timing"]:
                # A point that renders its own reference measures the reference renderer.
                add(
                    "mitransient, frames",
                    row.get("reference_transient_s"),
                    extra["transient_timing"].get("spp"),
                    row.get("reference_relmse_frames"),
                )
                add(
                    "Mitsuba volpath, steady",
                    row.get("reference_steady_s"),
                    extra["steady_timing"].get("spp"),
                    row.get("reference_relmse_steady"),
                )
                continue
            mode = row.get("frame_mode") or "?"
            add(f"ours ({mode}), frames", row.get("render_s"), row.get("iterations"), row.get("relmse_frames"))
            add(f"ours ({mode}), steady", row.get("render_s"), row.get("iterations"), row.get("relmse_steady"))
        for points in series.values():
            points.sort(key=lambda p: p["seconds"])
        return series
    for row in rows:
        point_files = files[row["point"]]
        reference = point_files.read_array("reference", "steady.npy") if extras[row["point"]]["steady_timing"] else None
        snapshots = point_files.run_dir / "render" / "snapshots.npz"
        if reference is None or not snapshots.is_file():
            continue
        with np.load(snapshots) as z:
            for iterations, seconds, image in zip(z["iterations"], z["seconds"], z["steady"]):
                if image.shape == reference.shape:
                    add(row["point"], float(seconds), int(iterations), relmse(image, reference))
    return series


def _report(spec: dict, rows: list[dict], table_md: Path, folder: Path, has_error_plot: bool) -> str:
    rel = lambda p: html.escape(os.path.relpath(p, folder))  # noqa: E731
    truth = spec.get("ground_truth")
    against = f"the reference renders of point '{truth}'" if truth else "each point's own reference"
    parts = []
    if spec.get("description"):
        parts.append(f"<p>{html.escape(spec['description'])}</p>")
    parts.append(
        f"<p>Sweep file <code>{html.escape(spec['sweep_file'])}</code>; {len(rows)} points; "
        f"errors (relMSE) are against {html.escape(against)}. "
        f"Regenerate with <code>python -m pipeline sweep {html.escape(spec['sweep_file'])}</code>.</p>"
    )
    if spec.get("common"):
        parts.append(
            "<p>Every point sets: "
            + ", ".join(f"<code>{html.escape(key)}={html.escape(value)}</code>" for key, value in spec["common_pairs"])
            + "</p>"
        )
    parts.append(
        "<h2>Summary</h2><div style='overflow-x: auto'>"
        + markdown_table_to_html(table_md.read_text(encoding="utf-8"))
        + "</div>"
    )
    parts.append(
        "<p>" + " · ".join(f'<a href="{n}">{n}</a>' for n in ("summary.csv", "summary.md", "summary.html")) + "</p>"
    )
    parts.append(
        '<h2>Poster</h2><figure><a href="poster.pdf"><img src="poster.png" alt="poster grid"></a>'
        "<figcaption>ours, steady, one exposure for all points</figcaption></figure>"
    )
    if has_error_plot:
        parts.append(
            '<h2>Error against time</h2><figure><a href="error_vs_time.pdf">'
            '<img src="error_vs_time.png" alt="error against time"></a></figure>'
        )
    items = []
    for row in rows:
        name = row["point"]
        run = Path(spec["runs_dir"]) / f"{spec['sweep']}-{name}"
        links = [
            f'<a href="{rel(run / "compare" / "report.html")}">run report</a>',
            f'<a href="{rel(folder / "points" / f"{name}.yaml")}">config</a>',
            f'<a href="{rel(folder / "logs" / f"{name}.log")}">log</a>',
        ]
        overrides = ", ".join(
            f"<code>{html.escape(key)}={html.escape(value)}</code>"
            for key, value in spec["points"][name]["override_pairs"]
        )
        description = html.escape(spec["points"][name].get("description") or "")
        items.append(f"<li><b>{html.escape(name)}</b> {description} {overrides} — {' · '.join(links)}</li>")
    parts.append("<h2>Points</h2><ul>" + "".join(items) + "</ul>")
    return html_page(f"Sweep '{spec['sweep']}'", "\n".join(parts))


def write_summary(workflow_yaml: str | Path) -> dict[str, Path]:
    """The sweep summary from the points' stage outputs; missing files give empty cells and warnings."""
    spec = yaml.safe_load(Path(workflow_yaml).read_text(encoding="utf-8"))
    folder = Path(spec["folder"])
    truth = None
    if spec.get("ground_truth"):
        name = spec["ground_truth"]
        truth_files = _PointFiles(name, Path(spec["runs_dir"]) / f"{spec['sweep']}-{name}", {"reference"})
        truth = {
            "steady": truth_files.read_array("reference", "steady.npy"),
            "frames": truth_files.read_array("reference", "frames.npy"),
        }
    input_keys = list(dict.fromkeys(key for point in spec["points"].values() for key, _ in point["override_pairs"]))
    rows, extras, files, images = [], {}, {}, []
    for name in spec["points"]:
        row, point_files, extra = _point_row(spec, name, input_keys, truth)
        rows.append(row)
        extras[name], files[name] = extra, point_files
        label = name + "".join(
            f"\n{key.split('.')[-1]}={value}" for key, value in spec["points"][name]["override_pairs"] if value != name
        )
        label += "".join(
            _sigma_label(key, medium) for key, medium in point_files.read_json("scene", "optics.json").items()
        )
        images.append((name, point_files.read_array("render", "steady.npy"), label))
    title = f"Sweep '{spec['sweep']}'"
    paths = write_table(rows, folder, title)
    write_poster(images, folder / "poster.png", f"{title}: ours, steady")
    paths["poster"] = folder / "poster.png"
    series = _error_series(spec, rows, extras, files, truth)
    error_plot = folder / "error_vs_time.png"
    if series:
        error_curves(series, error_plot)
        paths["error_plot"] = error_plot
    else:
        log.warning("sweep summary: no errors against a reference to plot; no error_vs_time.png")
        for stale in (error_plot, error_plot.with_suffix(".pdf")):
            stale.unlink(missing_ok=True)
    paths["report"] = write_text_atomic(folder / "report.html", _report(spec, rows, paths["md"], folder, bool(series)))
    return paths
