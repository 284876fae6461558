"""Matplotlib figures: streak images, side-by-side comparisons, error curves and poster grids.

Every function writes its files atomically and returns the paths it wrote. Figures are saved as
PNG, and as PDF too where they are meant for print (error curves, poster grids).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common.atomic import save_figure_atomic  # noqa: E402
from common.units import PS_PER_M_OPL  # noqa: E402
from render.output.tonemap import ToneCurve, luminance, to_display  # noqa: E402


def _save(fig, path: Path, pdf: bool = False) -> list[Path]:
    written = save_figure_atomic(fig, path, pdf=pdf)
    plt.close(fig)
    return written


def streak_image(
    slab: np.ndarray,
    axis: str,
    index: int,
    start_opl: float,
    bin_width_opl: float,
    scale: float,
    path: Path,
    curve: ToneCurve = "reinhard",
    time_unit: str = "ps",
) -> list[Path]:
    """An x–t slice (axis='x': ``slab`` is image row ``index`` of every frame, (T, W, 3)) or y–t slice
    (axis='y': column ``index``, (T, H, 3)); time counts in ``time_unit`` (ps or ns) from the opening of
    the film window at ``start_opl``, the first light."""
    slab = np.asarray(slab)
    if axis not in ("x", "y"):
        raise ValueError(f"streak axis must be 'x' or 'y', got {axis!r}")
    label = f"x (pixel), row {index}" if axis == "x" else f"y (pixel), column {index}"
    t_count, extent_space = slab.shape[:2]
    per_unit = PS_PER_M_OPL / (1000.0 if time_unit == "ns" else 1.0)
    t_end = t_count * bin_width_opl * per_unit
    fig, ax = plt.subplots(figsize=(6, 4.5))
    ax.imshow(
        to_display(slab, scale, curve),
        aspect="auto",
        origin="lower",
        extent=(0, extent_space, 0.0, t_end),
        interpolation="nearest",
    )
    ax.set_xlabel(label)
    ax.set_ylabel(f"time since first light ({time_unit}), from OPL {start_opl:.3f} m")
    ax.set_title(f"Streak image ({axis}–t)")
    return _save(fig, path)


def relative_difference(a: np.ndarray, b: np.ndarray, floor: float | None = None) -> np.ndarray:
    """|L(a) − L(b)| / max(L(b), floor) on luminance; the floor defaults to 1% of the mean of L(b)."""
    la, lb = luminance(a), luminance(b)
    if floor is None:
        floor = max(1e-12, 0.01 * float(np.mean(np.abs(lb))))
    return np.abs(la - lb) / np.maximum(np.abs(lb), floor)


def side_by_side_still(
    a: np.ndarray,
    b: np.ndarray,
    labels: tuple[str, str],
    scale: float,
    path: Path,
    curve: ToneCurve = "reinhard",
    title: str | None = None,
    vmax: float = 1.0,
) -> list[Path]:
    """Two images and the heat map of their relative difference, with a colour bar."""
    if a.shape != b.shape:
        raise ValueError(f"side-by-side images differ in shape: {a.shape} vs {b.shape}")
    fig, axes = plt.subplots(1, 3, figsize=(12, 4.2))
    for ax, image, label in zip(axes[:2], (a, b), labels):
        ax.imshow(to_display(image, scale, curve), interpolation="nearest")
        ax.set_title(label)
        ax.axis("off")
    diff = relative_difference(a, b)
    im = axes[2].imshow(diff, cmap="inferno", vmin=0, vmax=vmax, interpolation="nearest")
    if np.any(luminance(b) > 0):
        axes[2].set_title(f"relative difference (mean {np.mean(diff):.3g})")
    else:  # a black reference (Mitsuba's delta sun behind a dielectric): no ratio to quote
        axes[2].set_title(f"relative difference ({labels[1]} is black)")
    axes[2].axis("off")
    fig.colorbar(im, ax=axes[2], fraction=0.046, pad=0.04, label="|a − b| / b")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def error_curves(series: Mapping[str, Sequence[Mapping[str, float]]], path: Path, metric: str = "relmse") -> list[Path]:
    """Error against wall time and against iterations (or spp), log–log, one line per renderer.

    ``series[name]`` is a list of points with keys ``seconds``, ``iterations`` and ``metric``.
    """
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, points in series.items():
        pts = [p for p in points if p.get(metric, 0) > 0 and p.get("seconds", 0) > 0]
        if not pts:
            continue
        seconds = [p["seconds"] for p in pts]
        iterations = [p["iterations"] for p in pts]
        errors = [p[metric] for p in pts]
        axes[0].loglog(seconds, errors, "o-", label=name)
        axes[1].loglog(iterations, errors, "o-", label=name)
    axes[0].set_xlabel("wall time (s)")
    axes[1].set_xlabel("iterations / samples per pixel")
    from matplotlib.ticker import NullFormatter

    for ax in axes:
        ax.set_ylabel(metric)
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.set_minor_formatter(NullFormatter())  # labelled minor ticks overlap on short ranges
        ax.legend()
    fig.suptitle(f"{metric} against the reference")
    return _save(fig, path, pdf=True)


def poster_grid(
    images: Sequence[np.ndarray],
    labels: Sequence[str],
    path: Path,
    curve: ToneCurve = "reinhard",
    columns: int = 3,
    title: str | None = None,
    percentile: float = 99.5,
) -> list[Path]:
    """A labelled grid of renders sharing one exposure, so brightness compares across panels."""
    from render.output.tonemap import exposure_scale

    if len(images) != len(labels) or not images:
        raise ValueError("poster grid needs one label per image and at least one image")
    scale = exposure_scale(np.stack([np.asarray(i) for i in images]), percentile)
    rows = int(np.ceil(len(images) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(4 * columns, 4.2 * rows), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, image, label in zip(axes.flat, images, labels):
        ax.imshow(to_display(image, scale, curve), interpolation="nearest")
        ax.set_title(label, fontsize=9)
    if title:
        fig.suptitle(title)
    return _save(fig, path, pdf=True)


def rendered_image(
    image: np.ndarray, path: Path, title: str, curve: ToneCurve = "filmic", percentile: float = 99.5
) -> list[Path]:
    """One tone-mapped render with a title, e.g. a stage's steady image."""
    from render.output.tonemap import exposure_scale

    image = np.asarray(image)
    height, width = image.shape[:2]
    fig, ax = plt.subplots(figsize=(6.0, 6.0 * height / width + 0.5))
    ax.imshow(to_display(image, exposure_scale(image, percentile), curve), interpolation="nearest")
    ax.set_title(title, fontsize=10)
    ax.axis("off")
    return _save(fig, path)


class ArrivalTimes:
    """Per pixel, the time since first light at which its luminance, summed over the frames, first reaches
    ``fraction`` of its total ``total_luminance`` (H, W), in ns; NaN where no light arrives. Fed a frame's
    luminance at a time, in order. A fraction rather than the first non-zero frame keeps one stray early
    photon from setting the time."""

    def __init__(self, total_luminance: np.ndarray, bin_width_opl: float, fraction: float = 0.05) -> None:
        self.total = np.asarray(total_luminance, np.float64)
        self.bin_width_opl, self.fraction = bin_width_opl, fraction
        self.arrival: np.ndarray = np.full(self.total.shape, np.nan)
        self.running = np.zeros(self.total.shape)

    def add(self, k: int, frame_luminance: np.ndarray) -> None:
        from common.units import NS_PER_M_OPL

        self.running += frame_luminance
        reached = np.isnan(self.arrival) & (self.total > 0) & (self.running >= self.fraction * self.total)
        self.arrival[reached] = (k + 0.5) * self.bin_width_opl * NS_PER_M_OPL


def time_of_arrival_map(times: ArrivalTimes, path: Path, title: str) -> list[Path]:
    """The arrival times in a perceptual colour map (viridis); pixels without light are blank."""
    height, width = times.arrival.shape[:2]
    fig, ax = plt.subplots(figsize=(6.5, 6.5 * height / width + 0.5))
    shown = ax.imshow(times.arrival, cmap="viridis", interpolation="nearest")
    label = f"time of arrival ({times.fraction:.0%} of the light), ns since first light"
    fig.colorbar(shown, ax=ax, label=label, shrink=0.8)
    ax.set_title(title, fontsize=10)
    ax.axis("off")
    return _save(fig, path)
