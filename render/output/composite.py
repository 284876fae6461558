"""Transient frames -> videos (light in flight, and light filling the scene), streak images, EXR frames and
side-by-side comparisons. Pure array work plus the writers in render.output.video, render.output.figures and
render.output.exr.

A film is read in two passes, a window of frames at a time (``frame_windows``), so that compositing holds a
few frames and the fixed images (sums, the streak slabs, the arrival map) however long the film is
(render/output/LOOK.md, "Memory"). The first pass measures (``FilmStatistics``: the luminance histograms
that set the exposures, the sum over the frames); the second tone-maps each frame once and hands it to
every output it feeds (``composite_film``): the 8-bit, 10-bit, cumulative and light-in-flight encoders, the
EXR writer, the streak slabs and the arrival times.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from PIL import Image

from common.atomic import atomic_path
from common.memory import PeakMemory
from render.output.denoise import Guides
from render.output.figures import ArrivalTimes, relative_difference, side_by_side_still, streak_image
from render.output.files import FrameAxis, RenderOutputs, frame_windows
from render.output.metrics import box_downsample, downsample_factor
from render.output.tonemap import LuminanceHistogram, display_values, exposure_scale, luminance, to_display
from render.output.video import Mp4Writer, annotate, format_time, upscale

log = logging.getLogger(__name__)

CLIP_EXPOSURE_FRAMES = 64  # the clip's exposure comes from at most this many evenly spaced frames


def check_frames(frames: np.ndarray, name: str = "frames") -> np.ndarray:
    """The shape check; the values are checked for NaN as ``FilmStatistics.measure`` reads them."""
    frames = np.asanyarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (T, H, W, 3), got {frames.shape}")
    if len(frames) == 0:
        raise ValueError(f"{name} hold no frame")
    return frames


def _frame_rate(cfg, film: FrameAxis) -> float:
    fps = cfg.frame_rate(film.bin_width_opl)
    if not 0.1 <= fps <= 240:
        raise ValueError(
            f"composite.slow_motion={cfg.slow_motion} gives {fps:.3g} frames/s for bins of "
            f"{film.bin_width_opl} m; choose a factor that gives 0.1–240 frames/s, or set composite.fps"
        )
    return fps


def clip_stride(frame_count: int) -> int:
    """Every how many frames the clip's exposure looks: at most ``CLIP_EXPOSURE_FRAMES`` evenly spaced."""
    return max(1, int(np.ceil(frame_count / CLIP_EXPOSURE_FRAMES)))


@dataclass
class FilmStatistics:
    """What the first pass over a film measures, a frame at a time."""

    clip: LuminanceHistogram  # every clip_stride-th frame: the clip's exposure (videos, EXR headers)
    every_frame: LuminanceHistogram  # all frames: the streak images' exposure
    total: np.ndarray  # (H, W, 3) float64, the sum of the frames: the cumulative video's last frame
    total_luminance: np.ndarray  # (H, W), the frames' luminance summed: the time-of-arrival map's 100 %

    @classmethod
    def measure(cls, frames: np.ndarray, name: str = "frames", to_bins: FrameAxis | None = None) -> FilmStatistics:
        """Measure ``frames`` (converted window by window with ``to_bins.as_bins`` when given); refuses NaN
        or infinite values."""
        frames = check_frames(frames, name)
        stride = clip_stride(len(frames))
        statistics = cls(
            LuminanceHistogram(), LuminanceHistogram(), np.zeros(frames.shape[1:]), np.zeros(frames.shape[1:3])
        )
        for first, window in frame_windows(frames):
            if not np.isfinite(window).all():
                raise ValueError(f"{name} contain NaN or infinite values (frames {first}–{first + len(window) - 1})")
            if to_bins is not None:
                window = to_bins.as_bins(window)
            for k, frame in enumerate(window, start=first):
                lum = luminance(frame)
                histogram = LuminanceHistogram()
                histogram.add_luminance(lum)
                statistics.every_frame += histogram
                if k % stride == 0:
                    statistics.clip += histogram
                statistics.total += frame
                statistics.total_luminance += lum
        return statistics

    def clip_exposure(self, cfg) -> float:
        """One exposure for the clip (``composite.exposure_percentile`` of the sampled frames)."""
        return self.clip.exposure(cfg.exposure_percentile)


def clip_exposure(frames: np.ndarray, cfg) -> float:
    """The clip's exposure of a stack (a pass over it; ``FilmStatistics`` when the pass measures more)."""
    return FilmStatistics.measure(frames).clip_exposure(cfg)


class _Frame:
    """Frame ``k`` of a pass, with what several outputs share computed once.

    A transient frame is mostly black: light arrives at a pixel in a few of the frames. Every display value
    is a function of its own pixel alone, and a pixel without light shows 0 (each curve maps 0 to 0), so
    the curves run on the lit pixels only (``lit``); the results are the whole-frame computation's, bit for
    bit (render/output/LOOK.md, "Memory")."""

    def __init__(self, k: int, frame: np.ndarray, clip_scale: float, curve) -> None:
        self.k, self.frame, self.clip_scale, self.curve = k, frame, clip_scale, curve

    @cached_property
    def lit(self) -> np.ndarray:
        """Flat indices of the pixels with a non-zero value in any channel."""
        return np.flatnonzero((self.frame != 0).any(axis=-1))

    def scatter(self, values: np.ndarray, dtype) -> np.ndarray:
        """(H, W, 3) of ``dtype``: ``values`` (one row per lit pixel) at the lit pixels, 0 elsewhere."""
        out = np.zeros(self.frame.shape, dtype)
        out.reshape(-1, 3)[self.lit] = values
        return out

    @cached_property
    def clip_display_lit(self) -> np.ndarray:
        """Display values in [0, 1] at the clip's exposure of the lit pixels (float32, (N, 3))."""
        return display_values(self.frame.reshape(-1, 3)[self.lit], self.clip_scale, self.curve)

    def clip_codes(self, top: int, dtype) -> np.ndarray:
        """The clip's display values quantised to 0..``top`` (255 or 65535)."""
        return self.scatter(np.round(self.clip_display_lit * top).astype(dtype), dtype)

    @cached_property
    def luminance(self) -> np.ndarray:
        return luminance(self.frame)


class _Labels:
    """The burned-in labels of a clip's frames: time, caption, title and scale bar (upscaled frames)."""

    def __init__(self, film: FrameAxis, cfg, height: int, metres_per_pixel: float | None) -> None:
        self.film, self.cfg = film, cfg
        factor = max(1, int(np.ceil(cfg.video_min_height / height)))
        self.bar_px = cfg.scale_bar_m / metres_per_pixel * factor if cfg.scale_bar_m and metres_per_pixel else None
        self.bar_label = f"{cfg.scale_bar_m:g} m" if self.bar_px is not None else None

    def time(self, k: int) -> str:
        return format_time(self.film.centre(k) - self.film.start_opl, self.cfg.time_unit)

    def video_frame(self, k: int, display: np.ndarray, caption: str) -> np.ndarray:
        big = upscale(display, self.cfg.video_min_height)
        return annotate(big, [self.time(k), caption], self.cfg.title, self.bar_px, self.bar_label)


class _TransientVideos:
    """``<stem>.mp4`` (frame by frame), ``<stem>_10bit.mp4`` (``archival_cut``) and ``<stem>_cumulative.mp4``
    (the running sum; its last frame is the windowed steady image)."""

    def __init__(self, files: ExitStack, out_dir: Path, stem: str, fps: float, labels: _Labels, cfg, cumulative_scale):
        self.cfg, self.labels, self.cumulative_scale = cfg, labels, cumulative_scale
        self.paths = {"video": out_dir / f"{stem}.mp4", "cumulative_video": out_dir / f"{stem}_cumulative.mp4"}
        if cfg.archival_cut:
            self.paths["archival_video"] = out_dir / f"{stem}_10bit.mp4"
        self.video = files.enter_context(Mp4Writer(self.paths["video"], fps))
        self.cumulative = files.enter_context(Mp4Writer(self.paths["cumulative_video"], fps))
        self.archival = (
            files.enter_context(Mp4Writer(self.paths["archival_video"], fps, cut="archival"))
            if (cfg.archival_cut)
            else None
        )
        self.caption = "per-frame exposure" if cfg.per_frame_exposure else "one exposure for the clip"
        self.running: np.ndarray | None = None
        self.running_display = np.zeros(0, np.uint8)

    def add(self, view: _Frame) -> None:
        cfg, k = self.cfg, view.k
        if cfg.per_frame_exposure:
            display = to_display(view.frame, exposure_scale(view.frame, cfg.exposure_percentile), cfg.tone_curve)
        else:
            display = view.clip_codes(255, np.uint8)
        self.video.write(self.labels.video_frame(k, display, self.caption))
        if self.archival is not None:
            self.archival.write(self._archival_frame(view))
        if self.running is None:
            self.running = np.zeros(view.frame.shape)
            self.running_display = np.zeros(view.frame.shape, np.uint8)
        # The running sum changes at this frame's lit pixels only, and so does its display.
        running, shown = self.running.reshape(-1, 3), self.running_display.reshape(-1, 3)
        running[view.lit] += view.frame.reshape(-1, 3)[view.lit]
        shown[view.lit] = to_display(running[view.lit], self.cumulative_scale, cfg.tone_curve)
        self.cumulative.write(self.labels.video_frame(k, self.running_display, "cumulative"))

    def _archival_frame(self, view: _Frame) -> np.ndarray:
        """The 10-bit cut: the web cut's exposure and curve, quantised to 16 bits before the encoder's 10,
        with the time label burned in (render/output/LOOK.md)."""
        cfg = self.cfg
        if view.frame.shape[0] >= cfg.video_min_height:  # not upscaled: the values the other outputs use
            display = view.clip_codes(65535, np.uint16)
        else:
            display = to_display(upscale(view.frame, cfg.video_min_height), view.clip_scale, cfg.tone_curve, bits=16)
        label = annotate(np.zeros((*display.shape[:2], 3), np.uint8), [self.labels.time(view.k)])
        text = label.any(axis=-1)  # the label's box and glyphs, drawn over the 16-bit frame
        display[text] = label[text].astype(np.uint16) * 257
        return display

    def finish(self) -> dict[str, Path]:
        return dict(self.paths)


class _Streaks:
    """``streak_x.png`` / ``streak_y.png``: the x–t slice at ``streak_row`` and the y–t slice at
    ``streak_column`` (the middle by default), at the exposure of all the frames."""

    def __init__(self, shape: tuple[int, ...], film: FrameAxis, cfg, out_dir: Path, stem: str, scale: float) -> None:
        count, height, width = shape[:3]
        self.row = height // 2 if cfg.streak_row is None else cfg.streak_row
        self.column = width // 2 if cfg.streak_column is None else cfg.streak_column
        if self.row >= height:
            raise ValueError(f"composite.streak_row={self.row} is outside the image of height {height}")
        if self.column >= width:
            raise ValueError(f"composite.streak_column={self.column} is outside the image of width {width}")
        self.film, self.cfg, self.out_dir, self.stem, self.scale = film, cfg, out_dir, stem, scale
        self.x_slab = np.empty((count, width, 3), np.float32)
        self.y_slab = np.empty((count, height, 3), np.float32)

    def add(self, view: _Frame) -> None:
        self.x_slab[view.k] = view.frame[self.row]
        self.y_slab[view.k] = view.frame[:, self.column]

    def finish(self) -> dict[str, Path]:
        paths = {"streak_x": self.out_dir / f"{self.stem}_x.png", "streak_y": self.out_dir / f"{self.stem}_y.png"}
        film, cfg = self.film, self.cfg
        for axis, index, slab, key in (
            ("x", self.row, self.x_slab, "streak_x"),
            ("y", self.column, self.y_slab, "streak_y"),
        ):
            streak_image(
                slab,
                axis,
                index,
                film.start_opl,
                film.bin_width_opl,
                self.scale,
                paths[key],
                cfg.tone_curve,
                cfg.time_unit,
            )
        return paths


class _LightInFlight:
    """Each frame's light over the dimmed steady image, as in femto-photography videos: the steady image at
    ``light_in_flight_dim`` of its brightness, the frame's light screened over it with the clip's exposure.
    Writes light_in_flight.mp4, a 2 x 2 panel of four moments (the size of the still; larger for small
    renders), still.png (the steady image at full size, unlabelled) and the time-of-arrival map."""

    def __init__(
        self,
        files: ExitStack,
        steady: np.ndarray,
        statistics: FilmStatistics,
        count: int,
        film: FrameAxis,
        cfg,
        out_dir: Path,
        fps: float,
        labels: _Labels,
    ) -> None:
        self.cfg, self.out_dir, self.labels = cfg, out_dir, labels
        self.steady_display = display_values(steady, exposure_scale(steady, cfg.exposure_percentile), cfg.tone_curve)
        self.background = self.steady_display * cfg.light_in_flight_dim
        # The screen blend where a frame has no light: the dimmed still, through the same expression.
        self.unlit = 1 - (1 - self.background) * (1 - np.zeros_like(self.background))
        self.unlit_codes = np.round(self.unlit * 255).astype(np.uint8)
        self.video_path = out_dir / "light_in_flight.mp4"
        self.video = files.enter_context(Mp4Writer(self.video_path, fps))
        self.moments = [int(k) for k in np.linspace(0, count - 1, 4).round().astype(int)]
        self.tiles: dict[int, np.ndarray] = {}
        self.arrival = ArrivalTimes(statistics.total_luminance, film.bin_width_opl)

    def add(self, view: _Frame) -> None:
        background = self.background.reshape(-1, 3)[view.lit]
        screened = 1 - (1 - background) * (1 - view.clip_display_lit)
        composed = self.unlit_codes.copy()
        composed.reshape(-1, 3)[view.lit] = np.round(screened * 255).astype(np.uint8)
        self.video.write(self.labels.video_frame(view.k, composed, "light in flight"))
        if view.k in self.moments:
            image = self.unlit.copy()
            image.reshape(-1, 3)[view.lit] = screened
            self.tiles[view.k] = annotate(self._tile(image), [self.labels.time(view.k)])
        self.arrival.add(view.k, view.luminance)

    @staticmethod
    def _tile(image: np.ndarray) -> np.ndarray:
        """A 2 x 2 box average, so that four moments make a panel of the still's size; below 480 rows the
        frame at full size, enlarged to at least 240 rows, so that the panel and its labels stay legible."""
        if image.shape[0] < 480:
            return upscale(np.round(image * 255).astype(np.uint8), 240)
        height, width = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
        blocks = image[:height, :width].reshape(height // 2, 2, width // 2, 2, 3)
        return np.round(blocks.mean(axis=(1, 3)) * 255).astype(np.uint8)

    def finish(self) -> dict[str, Path]:
        from render.output.figures import time_of_arrival_map

        tiles = [self.tiles[k] for k in self.moments]
        panel = np.concatenate([np.concatenate(tiles[:2], axis=1), np.concatenate(tiles[2:], axis=1)], axis=0)
        paths = {
            "light_in_flight": self.video_path,
            "light_in_flight_panel": self.out_dir / "light_in_flight_panel.png",
        }
        with atomic_path(paths["light_in_flight_panel"]) as tmp:
            Image.fromarray(panel).save(tmp)
        # The still at the render's full size, without labels: the poster's main image.
        paths["still"] = self.out_dir / "still.png"
        with atomic_path(paths["still"]) as tmp:
            Image.fromarray(np.round(self.steady_display * 255).astype(np.uint8)).save(tmp)
        paths["time_of_arrival"] = self.out_dir / "time_of_arrival.png"
        time_of_arrival_map(self.arrival, paths["time_of_arrival"], "Time of arrival")
        return paths


class _ExrFrames:
    """``exr/frame_NNNN.exr``: the linear frames with render.output.exr's headers, written as they stream."""

    def __init__(self, folder: Path, film: FrameAxis, attributes: dict) -> None:
        self.folder, self.film, self.attributes = folder, film, attributes

    def add(self, view: _Frame) -> None:
        from render.output.exr import exr_frame_header, exr_frame_path, write_exr

        write_exr(
            exr_frame_path(self.folder, view.k),
            view.frame,
            attributes=exr_frame_header(self.film, view.k, self.attributes),
        )

    def finish(self) -> dict[str, Path]:
        return {"exr_frames": self.folder}


def composite_film(
    frames: np.ndarray,
    film: FrameAxis,
    cfg,
    out_dir: Path,
    *,
    stem: str = "transient",
    videos: bool = True,
    streaks: bool = False,
    steady: np.ndarray | None = None,
    exr_attributes: dict | None = None,
    exr_folder: str = "exr",
    metres_per_pixel: float | None = None,
) -> tuple[dict[str, Path], dict[str, float]]:
    """Composite a (T, H, W, 3) stack (in memory or memory-mapped) in two passes over it: the videos
    (``videos``), the streak images (``streaks``), light in flight (given the ``steady`` image) and the EXR
    frames (given their header's ``exr_attributes``: the clip exposure is added) into ``out_dir/exr_folder``.
    Returns the paths written and the exposures used (clip, cumulative, streak, steady)."""
    statistics = FilmStatistics.measure(frames)
    fps = _frame_rate(cfg, film)
    count, height = frames.shape[0], frames.shape[1]
    exposures = {"clip": statistics.clip_exposure(cfg)}
    if videos:
        exposures["cumulative"] = exposure_scale(statistics.total, cfg.exposure_percentile)
    if streaks:
        exposures["streak"] = statistics.every_frame.exposure(cfg.exposure_percentile)
    if steady is not None:
        exposures["steady"] = exposure_scale(steady, cfg.exposure_percentile)
    labels = _Labels(film, cfg, height, metres_per_pixel)
    with ExitStack() as files:  # an error leaves no half-written video behind
        outputs: list = []
        if videos:
            outputs.append(_TransientVideos(files, out_dir, stem, fps, labels, cfg, exposures["cumulative"]))
        if streaks:
            outputs.append(_Streaks(frames.shape, film, cfg, out_dir, stem="streak", scale=exposures["streak"]))
        if steady is not None:
            outputs.append(_LightInFlight(files, steady, statistics, count, film, cfg, out_dir, fps, labels))
        if exr_attributes is not None:
            outputs.append(
                _ExrFrames(out_dir / exr_folder, film, {"penitentes:exposure": exposures["clip"], **exr_attributes})
            )
        for first, window in frame_windows(frames):
            for k, frame in enumerate(window, start=first):
                view = _Frame(k, frame, exposures["clip"], cfg.tone_curve)
                for output in outputs:
                    output.add(view)
        written: dict[str, Path] = {}
        for output in outputs:
            written.update(output.finish())
    return written, exposures


def transient_videos(
    frames: np.ndarray,
    film: FrameAxis,
    cfg,
    out_dir: Path,
    stem: str = "transient",
    metres_per_pixel: float | None = None,
) -> dict[str, Path]:
    """Write ``<stem>.mp4`` (frame by frame), ``<stem>_cumulative.mp4`` (running sum) and, with
    ``archival_cut``, ``<stem>_10bit.mp4``."""
    return composite_film(frames, film, cfg, out_dir, stem=stem, metres_per_pixel=metres_per_pixel)[0]


def streak_images(frames: np.ndarray, film: FrameAxis, cfg, out_dir: Path) -> dict[str, Path]:
    """Write ``streak_x.png`` and ``streak_y.png``."""
    return composite_film(frames, film, cfg, out_dir, videos=False, streaks=True)[0]


def light_in_flight(
    frames: np.ndarray, steady: np.ndarray, film: FrameAxis, cfg, out_dir: Path, metres_per_pixel: float | None = None
) -> dict[str, Path]:
    """Write light_in_flight.mp4, light_in_flight_panel.png, still.png and time_of_arrival.png."""
    return composite_film(frames, film, cfg, out_dir, videos=False, steady=steady, metres_per_pixel=metres_per_pixel)[0]


SIDE_BY_SIDE_PANEL_WIDTH = 1280  # px: three panels of a 4K film would make an 11520-wide clip few players open


def panel_factor(height: int, width: int) -> int:
    """The box factor that brings a side-by-side panel to SIDE_BY_SIDE_PANEL_WIDTH pixels or fewer: the
    smallest that divides both sides (1 where none does, or none is needed)."""
    for factor in range(1, width + 1):
        if width % factor == 0 and height % factor == 0 and width // factor <= SIDE_BY_SIDE_PANEL_WIDTH:
            return factor
    return 1


def side_by_side(
    a_frames: np.ndarray,
    b_frames: np.ndarray,
    labels: tuple[str, str],
    film: FrameAxis,
    cfg,
    out_dir: Path,
    stem: str = "side_by_side",
    a_film: FrameAxis | None = None,
) -> dict[str, Path]:
    """Video and still of two frame stacks with a relative-difference heat-map panel, streamed a window at a
    time; ``a_film`` converts ``a`` to bins window by window (our gate frames against mitransient's bins).
    Films wider than SIDE_BY_SIDE_PANEL_WIDTH are box-averaged for the clip (``panel_factor``) and not
    enlarged: the full video's raw and denoised clip was 5760 x 1080, wider than many players open."""
    import matplotlib

    a_frames = check_frames(a_frames, labels[0])
    b_frames = check_frames(b_frames, labels[1])
    if a_frames.shape != b_frames.shape:
        raise ValueError(f"cannot compare {labels[0]} {a_frames.shape} with {labels[1]} {b_frames.shape}")
    a_stats = FilmStatistics.measure(a_frames, labels[0], to_bins=a_film)
    b_stats = FilmStatistics.measure(b_frames, labels[1])
    # One exposure for both, from both: from the reference alone a black one (Mitsuba's delta sun behind a
    # dielectric) would blow ours out to white.
    both = LuminanceHistogram()
    both += a_stats.every_frame
    both += b_stats.every_frame
    scale = both.exposure(cfg.exposure_percentile)
    floor = 0.01 * float(b_stats.total.mean()) / len(b_frames) + 1e-12  # 1 % of the reference's mean
    colormap = matplotlib.colormaps["inferno"]
    shrink = panel_factor(a_frames.shape[1], a_frames.shape[2])
    text = _Labels(film, cfg, a_frames.shape[1] // shrink, None)
    convert: Callable[[np.ndarray], np.ndarray] = a_film.as_bins if a_film is not None else (lambda window: window)
    path = out_dir / f"{stem}.mp4"
    with Mp4Writer(path, _frame_rate(cfg, film)) as video:
        for (first, a_window), (_, b_window) in zip(frame_windows(a_frames), frame_windows(b_frames)):
            a_window, b_window = box_downsample(convert(a_window), shrink), box_downsample(b_window, shrink)
            for k, (a_frame, b_frame) in enumerate(zip(a_window, b_window), start=first):
                a = to_display(a_frame, scale, cfg.tone_curve)
                b = to_display(b_frame, scale, cfg.tone_curve)
                diff = relative_difference(a_frame, b_frame, floor=floor)
                heat = (colormap(np.clip(diff / cfg.difference_vmax, 0, 1))[..., :3] * 255).astype(np.uint8)
                # Small films are enlarged for players; shrunk ones are large already.
                panels = (a, b, heat) if shrink > 1 else [upscale(p, cfg.video_min_height // 2) for p in (a, b, heat)]
                row = np.concatenate(panels, axis=1)
                caption = f"{labels[0]} | {labels[1]} | rel. diff 0 to {cfg.difference_vmax:g}"
                video.write(annotate(row, [caption, text.time(k)]))
    still = out_dir / f"{stem}.png"
    side_by_side_still(
        a_stats.total,
        b_stats.total,
        labels,
        exposure_scale(np.stack([a_stats.total, b_stats.total]), cfg.exposure_percentile),
        still,
        cfg.tone_curve,
        title="Sum over all frames",
        vmax=cfg.difference_vmax,
    )
    return {"side_by_side_video": path, "side_by_side_still": still}


def run_composite_stage(
    render_dir: Path, reference_dir: Path | None, scene_dir: Path, cfg, out_dir: Path, guides: Guides | None = None
) -> dict:
    """The `composite` stage: videos and streak images of our frames, and ours against the reference.

    Reads ``render_dir/frames.npy`` (memory-mapped, a window at a time) and ``stats.json`` (the film),
    ``reference_dir/frames.npy`` when a transient reference exists, and the camera from
    ``scene_dir/scene.json`` for the scale bar. With ``cfg.denoise`` the videos show denoised frames, guided by
    ``guides`` (render.output.denoise.Guides, which render.output.guides traces). The summary carries the
    exposures and the stage's own peak memory (common/memory.py).
    """
    with PeakMemory() as memory:
        summary = _composite(render_dir, reference_dir, scene_dir, cfg, out_dir, guides)
    return {**summary, **memory.record()}


def _downsampled(frames: np.ndarray, factor: int) -> np.ndarray:
    """A film box-averaged over factor x factor pixels, a window of frames at a time (files.frame_windows)."""
    t, h, w, c = frames.shape
    out = np.empty((t, h // factor, w // factor, c), np.float32)
    for first, window in frame_windows(frames):
        out[first : first + len(window)] = box_downsample(window, factor)
    return out


def _composite(
    render_dir: Path, reference_dir: Path | None, scene_dir: Path, cfg, out_dir: Path, guides: Guides | None
) -> dict:
    from render.scene.model import Scene, pixel_footprint

    ours = RenderOutputs.read(render_dir)
    film = ours.axis
    if film is None or film.frame_mode == "steady":
        return {"skipped": "the render is steady; there are no frames to composite"}
    scene = Scene.load(scene_dir / "scene.json")
    camera = scene.camera
    distance = float(np.linalg.norm(np.subtract(camera.target, camera.origin)))
    metres_per_pixel = pixel_footprint(camera, distance)
    frames = ours.frames(memory_mapped=True)
    if frames is None:
        raise FileNotFoundError(f"{render_dir}: frames.npy is missing; run the render stage again (--force)")
    steady = ours.steady() if cfg.light_in_flight else None
    exr_attributes = None
    if cfg.exr_frames:
        manifest = render_dir / "manifest.json"
        config_hash = json.loads(manifest.read_text())["config_hash"] if manifest.is_file() else "unknown"
        exr_attributes = {"penitentes:config_hash": config_hash, "penitentes:frames": "raw"}
    shown, denoised, delivered = frames, None, "raw"
    if cfg.denoise:
        if guides is None:
            raise ValueError("composite.denoise needs the scene's guide buffers (render.output.guides.guide_buffers)")
        shown, denoised, delivered = *_denoise(frames, film, cfg, guides, out_dir, exr_attributes), "denoised"
        if steady is not None:
            steady = _denoise_still(steady, cfg, guides, out_dir, denoised)
    written, exposures = composite_film(
        shown,
        film,
        cfg,
        out_dir,
        streaks=True,
        steady=steady,
        exr_attributes=None if exr_attributes is None else {**exr_attributes, "penitentes:frames": delivered},
        exr_folder="exr_denoised" if cfg.denoise else "exr",
        metres_per_pixel=metres_per_pixel,
    )
    if denoised is not None:
        written.update(denoised.pop("files"))
    reference_frames = RenderOutputs.read(reference_dir).frames(memory_mapped=True) if reference_dir else None
    factor = downsample_factor(frames.shape, reference_frames.shape) if reference_frames is not None else None
    if reference_frames is not None and factor is not None:
        # mitransient's frames are bin integrals; gate frames are densities per metre (render/core/DESIGN.md §2).
        # A reference on a film k times coarser (reference.downsample) faces ours box-averaged over k x k pixels.
        bins_film = film.in_bins()
        ours_shown = frames if factor == 1 else _downsampled(frames, factor)
        label = "ours (PTPB)" if factor == 1 else f"ours (PTPB), {factor}×{factor} box"
        written.update(
            side_by_side(ours_shown, reference_frames, (label, "mitransient"), bins_film, cfg, out_dir, a_film=film)
        )
        reference_videos = transient_videos(
            reference_frames,
            bins_film,
            cfg,
            out_dir,
            stem="reference_transient",
            metres_per_pixel=metres_per_pixel * factor,
        )
        written.update({f"reference_{k}": v for k, v in reference_videos.items()})
    elif reference_frames is not None:
        log.warning(
            "reference frames %s do not match ours %s by an integer factor; no side-by-side",
            reference_frames.shape,
            frames.shape,
        )
    return {
        "files": sorted(p.name for p in written.values()),
        "frames": int(frames.shape[0]),
        "frame_mode": film.frame_mode,
        "exposures": exposures,
        **({"denoise": denoised} if denoised is not None else {}),
    }


def _denoise_still(steady: np.ndarray, cfg, guides: Guides, out_dir: Path, denoised: dict) -> np.ndarray:
    """The still (the steady image under the light in flight, and the poster's main image) denoised with the
    frames' guides and kept at its raw sum, as each frame is (render/output/LOOK.md, *Denoised delivery*).
    The raw still goes beside it as still_raw.png, at the denoised still's exposure so the two compare, and
    the denoised steady image as steady_denoised.exr; the render's steady.exr stays raw."""
    import time

    from render.output import denoise
    from render.output.exr import write_exr

    start = time.perf_counter()
    delivered = denoise.denoise_frame(steady, guides, cfg.denoise_quality, cfg.denoise_refine)
    denoised["still_seconds"] = time.perf_counter() - start
    raw_sum = np.asarray(steady, np.float64).sum()
    denoised["still_sum_change"] = float(abs(delivered.sum(dtype=np.float64) / raw_sum - 1)) if raw_sum > 0 else 0.0
    files = denoised["files"]
    files["still_raw"] = out_dir / "still_raw.png"
    scale = exposure_scale(delivered, cfg.exposure_percentile)
    with atomic_path(files["still_raw"]) as tmp:
        Image.fromarray(np.round(display_values(steady, scale, cfg.tone_curve) * 255).astype(np.uint8)).save(tmp)
    files["steady_denoised"] = write_exr(
        out_dir / "steady_denoised.exr", delivered, attributes={"penitentes:frames": "denoised"}
    )
    return delivered


def _denoise(
    frames: np.ndarray, film: FrameAxis, cfg, guides: Guides, out_dir: Path, exr_attributes: dict | None
) -> tuple[np.ndarray, dict]:
    """The denoised delivery (render/output/LOOK.md, *Denoised delivery*): frames_denoised.npy, the raw frames'
    EXRs in ``exr/`` (the caller writes the delivered ones to ``exr_denoised/``), raw and denoised side by side,
    the guides as a picture, and the flicker of both stacks."""
    import time

    from render.output import denoise

    start = time.perf_counter()
    film_out = denoise.denoise_film(
        frames,
        guides,
        out_dir / "frames_denoised.npy",
        cfg.denoise_quality,
        arrival_band=cfg.denoise_arrival_band,
        refine=cfg.denoise_refine,
    )
    seconds = time.perf_counter() - start
    files: dict[str, Path] = {"frames_denoised": out_dir / "frames_denoised.npy"}
    files["denoise_guides"] = denoise.save_guides(guides, out_dir / "denoise_guides.png")
    if exr_attributes is not None:
        raw_exr = composite_film(frames, film, cfg, out_dir, videos=False, exr_attributes=exr_attributes)[0]
        files.update({f"raw_{k}": v for k, v in raw_exr.items()})
    pair = side_by_side(frames, film_out.frames, ("raw", "denoised"), film, cfg, out_dir, stem="raw_denoised")
    files.update({f"raw_denoised_{k}": v for k, v in pair.items()})
    return film_out.frames, {
        "seconds": seconds,
        "largest_frame_sum_change": film_out.largest_frame_sum_change,
        "temporal_roughness_raw": film_out.temporal_roughness_raw,
        "temporal_roughness_denoised": film_out.temporal_roughness_denoised,
        # The arrival band (render/output/LOOK.md): the raw film's sharpness and whether the band was kept apart.
        "arrival_band": (
            {"sharpness": film_out.arrival.sharpness, "kept_apart": film_out.arrival.used}
            if film_out.arrival is not None
            else None
        ),
        "files": files,
    }
