"""Compare our render with the reference: a table (Markdown, CSV), error-against-time plots and the
run report. relMSE and RMSE are against the Mitsuba steady image and the mitransient frames."""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.atomic import write_text_atomic
from render.output.agreement import agreement
from render.output.figures import error_curves
from render.output.files import RenderOutputs
from render.output.metrics import mean_radiance, relmse, rmse

log = logging.getLogger(__name__)

COLUMNS = [
    "renderer",
    "quantity",
    "seconds",
    "iterations_or_spp",
    "relmse",
    "rmse",
    "mean_r",
    "mean_g",
    "mean_b",
    "peak_memory_mib",
    "agreement",
]


def _row(renderer, quantity, seconds, count, image, reference, memory) -> dict[str, Any]:
    means = mean_radiance(image)
    row = {
        "renderer": renderer,
        "quantity": quantity,
        "seconds": seconds,
        "iterations_or_spp": count,
        "mean_r": means[0],
        "mean_g": means[1],
        "mean_b": means[2],
        "peak_memory_mib": memory,
        "relmse": None,
        "rmse": None,
        "agreement": None,
        "disagrees": False,
    }
    if reference is not None and reference.shape == image.shape:
        row["relmse"] = relmse(image, reference)
        row["rmse"] = rmse(image, reference)
        verdict = agreement(image, reference)
        row["agreement"], row["disagrees"] = verdict.text(), verdict.disagrees
        if verdict.disagrees:
            log.warning("compare: %s %s %s", renderer, quantity, verdict.text())
    return row


def _fmt(value) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def write_table(rows: list[dict[str, Any]], out_dir: Path, stem: str = "comparison") -> None:
    md = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    md += [
        "| " + " | ".join(f"**{_fmt(r[c])}**" if r.get("disagrees") else _fmt(r[c]) for c in COLUMNS) + " |"
        for r in rows
    ]
    write_text_atomic(out_dir / f"{stem}.md", "\n".join(md) + "\n")
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    writer.writerows([["" if r[c] is None else r[c] for c in COLUMNS] for r in rows])
    write_text_atomic(out_dir / f"{stem}.csv", buffer.getvalue())


def compare_renders(ours_dir: Path | None, reference_dir: Path | None, out_dir: Path) -> dict[str, Any]:
    ours = RenderOutputs.read(ours_dir) if ours_dir else None
    reference = RenderOutputs.read(reference_dir) if reference_dir else None
    ours_stats = ours.stats if ours else {}
    ref_timing = reference.stats if reference else {}
    rows: list[dict[str, Any]] = []
    steady_ref = reference.steady() if reference else None
    frames_ref = reference.frames() if reference else None
    steady_ours = ours.steady() if ours else None
    frames_ours = ours.frames_as_bins() if ours else None
    ours_seconds = ours_stats.get("seconds") or ours_stats.get("time_total_s")
    ours_iterations = ours_stats.get("iterations")
    ours_memory = ours_stats.get("peak_memory_mib")
    if steady_ours is not None:
        rows.append(_row("ours (PTPB)", "steady", ours_seconds, ours_iterations, steady_ours, steady_ref, ours_memory))
    if frames_ours is not None and ours is not None and ours.axis is not None:
        rows.append(
            _row(
                "ours (PTPB)",
                f"frames ({ours.axis.frame_mode})",
                ours_seconds,
                ours_iterations,
                frames_ours,
                frames_ref,
                ours_memory,
            )
        )
    for renderer, quantity, image, part in (
        ("Mitsuba volpath", "steady", steady_ref, "steady"),
        ("mitransient", "frames (bins)", frames_ref, "transient"),
    ):
        if image is not None:
            timing = ref_timing.get(part) or {}
            memory = timing.get("peak_memory_mib")
            rows.append(_row(renderer, quantity, timing.get("seconds"), timing.get("spp"), image, None, memory))
    if not rows:
        raise FileNotFoundError("compare found neither our render nor a reference to tabulate")
    write_table(rows, out_dir)
    series = {}
    snapshots = ours_dir / "snapshots.npz" if ours_dir else None
    if steady_ref is not None and snapshots is not None and snapshots.exists():
        with np.load(snapshots) as z:
            series["ours (PTPB), steady"] = [
                {"seconds": float(t), "iterations": int(i), "relmse": relmse(image, steady_ref)}
                for i, t, image in zip(z["iterations"], z["seconds"], z["steady"])
            ]
    if series:
        error_curves(series, out_dir / "error_vs_time.png")
    return {"rows": rows, "error_curves": {k: v for k, v in series.items()}}


HEADINGS = {
    "renderer": "renderer",
    "quantity": "quantity",
    "seconds": "time [s]",
    "iterations_or_spp": "iterations or spp",
    "relmse": "relMSE vs reference",
    "rmse": "RMSE vs reference",
    "mean_r": "mean R",
    "mean_g": "mean G",
    "mean_b": "mean B",
    "peak_memory_mib": "peak memory [MiB]",
    "agreement": "agreement with the reference",
}


def _ratio_text(ours: dict[str, Any], reference: dict[str, Any]) -> str:
    """Per-channel ours / reference; ∞ where the reference is black and ours is not (a delta light behind a
    dielectric in Mitsuba), nan where both are."""

    def one(c: str) -> str:
        if reference[c]:
            return f"{ours[c] / reference[c]:.3f}"
        return "∞" if ours[c] else "nan"

    return " / ".join(one(c) for c in ("mean_r", "mean_g", "mean_b"))


def key_results(rows: list[dict[str, Any]]) -> list[str]:
    """The comparison in plain sentences with units, for the top of the report."""
    by = {(r["renderer"].split(" ")[0], r["quantity"].split(" ")[0]): r for r in rows}
    lines = []
    ours, ref = by.get(("ours", "steady")), by.get(("Mitsuba", "steady"))
    if ours and ref:
        lines.append(
            f"Our steady image's mean radiance is {_ratio_text(ours, ref)} (R / G / B) of Mitsuba volpath's; "
            f"relMSE {_fmt(ours['relmse'])}."
        )
    ours, ref = by.get(("ours", "frames")), by.get(("mitransient", "frames"))
    if ours and ref:
        lines.append(
            f"Our frames carry {_ratio_text(ours, ref)} (R / G / B) of mitransient's energy, compared as bins; "
            f"relMSE {_fmt(ours['relmse'])}."
        )
    for row in rows:
        if row["quantity"] == "steady" or row["renderer"] == "mitransient":
            count = "iterations" if row["renderer"].startswith("ours") else "spp"
            memory = f", peak memory {row['peak_memory_mib']:.0f} MiB" if row.get("peak_memory_mib") else ""
            seconds = f"{row['seconds']:.1f} s" if row.get("seconds") is not None else "an unknown time"
            lines.append(f"{row['renderer']}: {_fmt(row['iterations_or_spp'])} {count} in {seconds}{memory}.")
    return lines


def report_lead(rows: list[dict[str, Any]]) -> str:
    """HTML for the report's first screen: the key results, then the table with units and a caption."""
    import html

    items = "".join(f"<li>{html.escape(line)}</li>" for line in key_results(rows))
    items += "".join(
        f"<li class='disagrees'>Warning: ours and the reference disagree, {html.escape(r['quantity'])}: "
        f"{html.escape(r['agreement'])}. The images are not the same light transport; see "
        "render/core/DESIGN.md §12 (dense media).</li>"
        for r in rows
        if r.get("disagrees")
    )
    head = "".join(f"<th>{html.escape(HEADINGS[c])}</th>" for c in COLUMNS)
    body = "".join(
        ("<tr class='disagrees'>" if r.get("disagrees") else "<tr>")
        + "".join(f"<td>{html.escape(_fmt(r[c]))}</td>" for c in COLUMNS)
        + "</tr>"
        for r in rows
    )
    caption = (
        "Mean radiance in W m⁻² sr⁻¹ (frames: per bin, summed over the frames' mean); relMSE = mean of "
        "(x − r)² / (r² + 0.01) against Mitsuba volpath (steady) or mitransient (frames); peak memory is the "
        "resident size of the process while that renderer ran (pipeline/memory.py), Python and libraries included."
    )
    return (
        f"<h2>Results</h2><ul>{items}</ul><table><caption>{html.escape(caption)}</caption><tr>{head}</tr>{body}</table>"
    )


def run_compare_stage(
    run_root: Path, ours_dir: Path | None, reference_dir: Path | None, out_dir: Path, stage_names, title: str
) -> dict:
    """The `compare` stage: the table, the error plot and ``report.html`` linking every stage's files."""
    from render.output.report import write_report

    result = compare_renders(ours_dir, reference_dir, out_dir)
    write_report(
        out_dir / "report.html",
        run_root,
        [n for n in stage_names if n != "compare"],
        title,
        lead_html=report_lead(result["rows"]),
    )
    return {"rows": [{k: r[k] for k in ("renderer", "quantity", "seconds", "relmse")} for r in result["rows"]]}
