"""Compare our render with the reference: a table (Markdown, CSV), error-against-time plots and the
run report. relMSE and RMSE are against the Mitsuba steady image and the mitransient frames."""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path
from typing import Any

import numpy as np

from common.atomic import write_text_atomic
from render.output.agreement import agreement
from render.output.figures import error_curves
from render.output.files import RenderOutputs
from render.output.metrics import RELMSE_EPSILON, box_downsample, downsample_factor, relmse
from render.scene.roulette import RouletteDepth, dark_reference

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


def measure(image: np.ndarray, reference: np.ndarray | None = None, to_bins=None) -> dict[str, Any]:
    """Per-channel means of an image or (T, H, W, 3) stack and, against a reference of its shape, relMSE, RMSE
    and the agreement, a window of frames at a time (``to_bins``: the image's FrameAxis, converting gate
    frames window by window); the stacks may be memory-mapped films. A reference rendered k times coarser in
    both axes (``reference.downsample``) is measured against the image box-averaged over k x k pixels, which is
    what the same camera records on the coarser film; ``downsample`` in the result says by how much."""
    from itertools import repeat

    from render.output.files import frame_windows

    stack = image if image.ndim == 4 else image[None]
    references: Any = repeat(None)
    factor = downsample_factor(image.shape, reference.shape) if reference is not None else None
    if reference is not None and factor is None:
        log.warning("compare: reference shape %s does not match %s by an integer factor", reference.shape, image.shape)
    if reference is not None and factor is not None:
        references = frame_windows(reference if reference.ndim == 4 else reference[None])
    sums, count = np.zeros(3), 0
    squared = relative = 0.0
    image_sum = reference_sum = None
    for (_, window), pair in zip(frame_windows(stack), references):
        x = np.asarray(to_bins.as_bins(window) if to_bins is not None else window, np.float64)
        if not np.isfinite(x).all():
            raise ValueError("render or reference contains NaN or infinite values")
        sums += x.reshape(-1, 3).sum(axis=0)
        count += x.size // 3
        if pair is not None:
            x = box_downsample(x, factor or 1)
            r = np.asarray(pair[1], np.float64)
            if not np.isfinite(r).all():
                raise ValueError("render or reference contains NaN or infinite values")
            error = (x - r) ** 2
            squared += float(error.sum())
            relative += float((error / (r**2 + RELMSE_EPSILON)).sum())
            image_sum = x.sum(axis=0) if image_sum is None else image_sum + x.sum(axis=0)
            reference_sum = r.sum(axis=0) if reference_sum is None else reference_sum + r.sum(axis=0)
    measured: dict[str, Any] = {"means": [float(v) for v in sums / max(1, count)]}
    if image_sum is not None and reference_sum is not None:
        values = count * 3 // (factor or 1) ** 2
        measured["downsample"] = factor
        measured.update(relmse=relative / values, rmse=float(np.sqrt(squared / values)))
        measured["agreement"] = agreement(image_sum, reference_sum)  # its tiles sum the frames first
    return measured


def _row(renderer, quantity, seconds, count, image, reference, memory, to_bins=None) -> dict[str, Any]:
    measured = measure(image, reference, to_bins)
    means = measured["means"]
    row = {
        "renderer": renderer,
        "quantity": quantity,
        "seconds": seconds,
        "iterations_or_spp": count,
        "mean_r": means[0],
        "mean_g": means[1],
        "mean_b": means[2],
        "peak_memory_mib": memory,
        "relmse": measured.get("relmse"),
        "rmse": measured.get("rmse"),
        "agreement": None,
        "disagrees": False,
        "downsample": measured.get("downsample"),
    }
    if "agreement" in measured:
        verdict = measured["agreement"]
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


def likely_dark(reference_timing: dict[str, Any]) -> str | None:
    """``dark_reference`` of the depth a reference's timing.json records (``roulette``), or None."""
    roulette = reference_timing.get("roulette")
    if not roulette:
        return None
    return dark_reference(RouletteDepth(roulette["rr_depth"], roulette["missed"], roulette["medium"]))


def compare_renders(ours_dir: Path | None, reference_dir: Path | None, out_dir: Path) -> dict[str, Any]:
    ours = RenderOutputs.read(ours_dir) if ours_dir else None
    reference = RenderOutputs.read(reference_dir) if reference_dir else None
    ours_stats = ours.stats if ours else {}
    ref_timing = reference.stats if reference else {}
    rows: list[dict[str, Any]] = []
    steady_ref = reference.steady() if reference else None
    frames_ref = reference.frames(memory_mapped=True) if reference else None
    steady_ours = ours.steady() if ours else None
    frames_ours = ours.frames(memory_mapped=True) if ours else None
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
                to_bins=ours.axis,
            )
        )
    dark = likely_dark(ref_timing)
    if dark:
        log.warning("compare: %s", dark)
        for row in rows:
            if row["agreement"] is not None:
                row["agreement"] += f"; {dark}"
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
            factor = downsample_factor(z["steady"].shape[1:], steady_ref.shape)
            if factor is not None:
                series["ours (PTPB), steady"] = [
                    {
                        "seconds": float(t),
                        "iterations": int(i),
                        "relmse": relmse(box_downsample(image, factor), steady_ref),
                    }
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
    factor = next((r["downsample"] for r in rows if r.get("downsample", 1) not in (None, 1)), None)
    if factor:
        lines.append(
            f"The references ran on a film {factor}× coarser in each axis (reference.downsample); every comparison "
            f"reads our frames box-averaged over {factor} × {factor} pixels, what the same camera records there."
        )
    for row in rows:
        if row["quantity"] == "steady" or row["renderer"] == "mitransient":
            count = "iterations" if row["renderer"].startswith("ours") else "spp"
            memory = f", peak memory {row['peak_memory_mib']:.0f} MiB" if row.get("peak_memory_mib") else ""
            seconds = f"{row['seconds']:.1f} s" if row.get("seconds") is not None else "an unknown time"
            lines.append(f"{row['renderer']}: {_fmt(row['iterations_or_spp'])} {count} in {seconds}{memory}.")
    return lines


def report_lead(rows: list[dict[str, Any]], stages: dict[str, dict[str, Any]] | None = None) -> str:
    """HTML for the report's first screen: the key results (and the stages' own peak memory), then the table
    with units and a caption."""
    import html

    lines = key_results(rows)
    if stages:
        lines.append(
            "Stage peak memory (resident, common/memory.py): "
            + "; ".join(
                f"{name} {record['peak_memory_mib']:.0f} MiB ({record['peak_memory_added_mib']:.0f} MiB above its start)"
                for name, record in stages.items()
            )
            + "."
        )
    items = "".join(f"<li>{html.escape(line)}</li>" for line in lines)
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
        "resident size of the process while that renderer ran (common/memory.py), Python and libraries included."
    )
    return (
        f"<h2>Results</h2><ul>{items}</ul><table><caption>{html.escape(caption)}</caption><tr>{head}</tr>{body}</table>"
    )


def run_compare_stage(
    run_root: Path, ours_dir: Path | None, reference_dir: Path | None, out_dir: Path, stage_names, title: str
) -> dict:
    """The `compare` stage: the table, the error plot and ``report.html`` linking every stage's files."""
    from common.memory import PeakMemory
    from render.output.report import write_report

    with PeakMemory() as memory:  # the stage's own peak (common/memory.py), reported beside the composite's
        result = compare_renders(ours_dir, reference_dir, out_dir)
    write_report(
        out_dir / "report.html",
        run_root,
        [n for n in stage_names if n != "compare"],
        title,
        lead_html=report_lead(result["rows"], stage_memory(run_root, memory.record())),
    )
    rows = [{k: r[k] for k in ("renderer", "quantity", "seconds", "relmse")} for r in result["rows"]]
    return {"rows": rows, **memory.record()}


def stage_memory(run_root: Path, compare: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The peak memory of the composite stage (from its manifest's summary) and of this compare."""
    import json

    stages = {}
    manifest = run_root / "composite" / "manifest.json"
    if manifest.is_file():
        summary = json.loads(manifest.read_text(encoding="utf-8")).get("summary") or {}
        if "peak_memory_mib" in summary:
            stages["composite"] = summary
    stages["compare"] = compare
    return stages
