"""Pictures of a grown field: hillshade map, metrics plot, pyvista render with the sun drawn in,
and a time-lapse MP4 of the growth. All files are written atomically."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from common.atomic import atomic_path
from geometry import irradiance, metrics, morphology
from geometry.mesh import TriangleMesh


def hillshade(
    h: np.ndarray, spacing: float, sun_azimuth_deg: float = 315.0, sun_elevation_deg: float = 35.0
) -> np.ndarray:
    """Shaded relief in [0, 1]: cosine of the angle between the normal and a light direction (no shadows)."""
    az, el = np.radians(sun_azimuth_deg), np.radians(sun_elevation_deg)
    light = np.array([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    return np.clip(irradiance.unit_normals(h, spacing) @ light, 0.0, 1.0)


def _figure_to_file(fig, path: Path, dpi: int) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)


def save_hillshade(path: Path, h: np.ndarray, spacing: float, width_px: int, title: str) -> None:
    """Hillshade map with the height as colour, north up, axes in metres."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    extent = (0, h.shape[1] * spacing, 0, h.shape[0] * spacing)
    fig, ax = plt.subplots(figsize=(8, 7))
    ax.imshow(hillshade(h, spacing), cmap="gray", origin="lower", extent=extent, vmin=0, vmax=1)
    im = ax.imshow(h - h.mean(), cmap="terrain", origin="lower", extent=extent, alpha=0.35)
    fig.colorbar(im, ax=ax, label="height above mean [m]", shrink=0.8)
    ax.set_xlabel("x, east [m]")
    ax.set_ylabel("y, north [m]")
    ax.set_title(title)
    fig.tight_layout()
    _figure_to_file(fig, path, dpi=max(50, width_px // 8))
    plt.close(fig)


def save_metrics_plot(
    path: Path, h: np.ndarray, spacing: float, relief_history: np.ndarray, summary: dict, history: dict
) -> None:
    """Four panels: the season (relief, crest spacing and crest count against time), N-S and radial
    spectra, aspect rose of steep facets, slope histogram. history: metrics.season_history plus "day"."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker
    from matplotlib.projections.polar import PolarAxes

    fig = plt.figure(figsize=(11, 8))
    ax = fig.add_subplot(2, 2, 1)
    ax.plot(np.arange(len(relief_history)), 2 * np.sqrt(2) * relief_history, label="relief 2√2·RMS")
    ax.plot(history["day"], history["crest_to_trough_m"], label="crest to trough H")
    ax.plot(history["day"], history["crest_spacing_m"], label="crest spacing λ_dom")
    ax.set_xlabel("day")
    ax.set_ylabel("[m]")
    density = ax.twinx()
    density.plot(history["day"], history["crest_density_per_m2"], color="k", ls=":", label="crests per m²")
    density.set_ylabel("crests per m² (dotted)")
    _shade_stages(ax, history)
    ax.legend(loc="upper left", fontsize="small")
    ax.set_title("the season: forms coarsen and deepen; shaded: the stage")
    ax = fig.add_subplot(2, 2, 2)
    k, power = metrics.transect_power_spectrum(h, spacing, axis=0)
    ax.loglog(2 * np.pi / k[1:], power[1:], label="N–S transects")
    k, power = metrics.radial_power_spectrum(h, spacing)
    ax.loglog(2 * np.pi / k[1:], power[1:], color="0.6", label="radial average")
    ax.axvline(summary["crest_spacing_m"], color="r", ls="--", label=f"λ_dom = {summary['crest_spacing_m']:.2f} m")
    ax.axvline(summary["onset_wavelength_m"], color="g", ls=":", label=f"2πl = {summary['onset_wavelength_m']:.2f} m")
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # labels on every minor tick overlap
    ax.set_xlabel("wavelength [m]")
    ax.set_ylabel("power per bin [m²]")
    ax.legend()
    ax.set_title(
        f"power spectrum: λ_dom / H = {summary['spacing_to_height']:.2f} (H {summary['crest_to_trough_m']:.2f} m)"
    )
    polar = fig.add_subplot(2, 2, 3, projection="polar")
    if not isinstance(polar, PolarAxes):  # matplotlib types add_subplot as returning plain Axes
        raise TypeError("matplotlib did not make a polar axes")
    edges, frac = metrics.aspect_histogram(h, spacing)
    polar.set_theta_zero_location("N")
    polar.set_theta_direction(-1)
    ax = polar
    ax.bar(np.radians(edges[:-1] + 5), frac, width=np.radians(10), alpha=0.7)
    ax.set_title("aspect of steep (>30°) facets", pad=15)
    ax = fig.add_subplot(2, 2, 4)
    p, q = irradiance.gradient(h, spacing)
    ax.hist(np.degrees(np.arctan(np.hypot(p, q))).ravel(), bins=45, range=(0, 90))
    ax.set_xlabel("slope [deg]")
    ax.set_ylabel("cells")
    ax.set_title(
        f"ridges {summary['ridge_deviation_from_east_west_deg']:.0f}° from E-W, lean {summary['lean_north_deg']:.1f}° N"
    )
    fig.tight_layout()
    _figure_to_file(fig, path, dpi=90)
    plt.close(fig)


STAGE_COLOURS = dict(zip(morphology.STAGES, ("0.85", "#f3d9a4", "#a9c8ec")))  # pitted, suncups, penitentes


def _shade_stages(ax, history: dict) -> None:
    """Shade each snapshot's day, from halfway to the one before to halfway to the one after, by its stage
    (morphology.stage_label)."""
    days, stages = np.asarray(history["day"], float), history.get("stage", [])
    if len(days) < 2 or len(stages) != len(days):
        return
    edges = np.concatenate(([days[0]], 0.5 * (days[:-1] + days[1:]), [days[-1]]))
    for start, end, stage in zip(edges[:-1], edges[1:], stages):
        ax.axvspan(start, end, color=STAGE_COLOURS.get(stage, "w"), alpha=0.6, lw=0, zorder=0)
    for stage, colour in STAGE_COLOURS.items():
        if stage in stages:
            ax.axvspan(0, 0, color=colour, alpha=0.6, lw=0, label=stage)


def render_preview(path: Path, mesh: TriangleMesh, sun: np.ndarray, width_px: int, title: str) -> None:
    """Off-screen pyvista render of the mesh lit from the sun, with an arrow toward the sun."""
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista as pv

    pv.OFF_SCREEN = True
    faces = np.column_stack((np.full(len(mesh.faces), 3), mesh.faces)).ravel()
    surface = pv.PolyData(np.asarray(mesh.vertices, float), faces)
    surface["height [m]"] = surface.points[:, 2]
    bounds = surface.bounds
    size = max(bounds[1] - bounds[0], bounds[3] - bounds[2])
    centre = np.array([(bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2, bounds[5]])
    sun = np.asarray(sun, float) / np.linalg.norm(sun)
    plotter = pv.Plotter(off_screen=True, window_size=[width_px, int(width_px * 0.7)], lighting="none")
    plotter.set_background("#bcd3ea", top="#5d86b5")  # type: ignore[arg-type]  # pyvista's wraps() hides the signature
    plotter.add_mesh(surface, color="#f4f7fb", smooth_shading=False, specular=0.1, ambient=0.25, diffuse=0.8)
    plotter.add_light(
        pv.Light(position=tuple(centre + sun * size * 10), focal_point=tuple(centre), light_type="scene light")
    )
    start = centre + sun * size * 0.15
    plotter.add_mesh(pv.Arrow(start=start, direction=sun, scale=size * 0.45), color="orange", ambient=1.0, diffuse=0.0)
    plotter.add_text(title, font_size=10)
    plotter.add_axes(xlabel="E", ylabel="N", zlabel="up")  # type: ignore[call-arg]  # pyvista's wraps() hides the signature
    # Look from the south-east and above so north-leaning blades show their lean.
    plotter.camera_position = [
        tuple(centre + np.array([0.9, -1.3, 0.9]) * size),
        tuple(centre - [0, 0, size * 0.1]),
        (0, 0, 1),
    ]
    with atomic_path(path) as tmp:
        plotter.screenshot(str(tmp))
    plotter.close()


def save_timelapse(
    path: Path,
    snapshots: np.ndarray,
    snapshot_days: np.ndarray,
    spacing: float,
    fps: int,
    width_px: int = 640,
    stages: Sequence[str] | None = None,
) -> None:
    """H.264 MP4 of the field growing: hillshade + height colour per snapshot, with the day and, if given, the
    stage of each snapshot (morphology.stage_label) burned in."""
    import av
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lo = float(min(s.min() - s.mean() for s in snapshots))
    hi = float(max(s.max() - s.mean() for s in snapshots))
    size_in = 6.4
    fig, ax = plt.subplots(figsize=(size_in, size_in))
    extent = (0, snapshots.shape[2] * spacing, 0, snapshots.shape[1] * spacing)
    with atomic_path(path) as tmp:
        container = av.open(str(tmp), mode="w")
        stream = container.add_stream("libx264", rate=fps)
        stream.pix_fmt = "yuv420p"
        stream.options = {"crf": "23"}
        dpi = width_px / size_in
        frames = []
        for i, (h, day) in enumerate(zip(snapshots, snapshot_days)):
            ax.clear()
            ax.imshow(hillshade(h, spacing), cmap="gray", origin="lower", extent=extent, vmin=0, vmax=1)
            ax.imshow(h - h.mean(), cmap="terrain", origin="lower", extent=extent, alpha=0.35, vmin=lo, vmax=hi)
            stage = f"   {stages[i]}" if stages is not None else ""
            ax.set_title(f"day {day:.0f}   relief {2 * np.sqrt(2) * h.std():.2f} m{stage}")
            ax.set_xlabel("x, east [m]")
            ax.set_ylabel("y, north [m]")
            fig.set_dpi(dpi)
            fig.canvas.draw()
            canvas = fig.canvas
            if not isinstance(canvas, FigureCanvasAgg):  # the Agg backend, chosen above
                raise TypeError("the time-lapse needs matplotlib's Agg backend")
            image = np.array(canvas.buffer_rgba())[:, :, :3]  # a copy: the canvas buffer is reused by the next draw
            image = image[: image.shape[0] // 2 * 2, : image.shape[1] // 2 * 2]
            frames.append(image)
        stream.width, stream.height = frames[0].shape[1], frames[0].shape[0]
        for image in frames + [frames[-1]] * fps:  # hold the last frame for a second
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
        container.close()
    plt.close(fig)
