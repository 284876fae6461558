"""Transient frames -> videos (light in flight, and light filling the scene), streak images and
side-by-side comparisons. Pure array work plus the writers in render.output.video and render.output.figures.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
from PIL import Image

from pipeline.atomic import atomic_path
from render.output.figures import relative_difference, side_by_side_still, streak_image
from render.output.files import FrameAxis, RenderOutputs
from render.output.tonemap import display_frames, display_values, exposure_scale, to_display
from render.output.video import annotate, format_time, upscale, write_mp4

log = logging.getLogger(__name__)


def check_frames(frames: np.ndarray, name: str = "frames") -> np.ndarray:
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (T, H, W, 3), got {frames.shape}")
    if not all(np.isfinite(frame).all() for frame in frames):  # a frame at a time: the stack may be memory-mapped
        raise ValueError(f"{name} contain NaN or infinite values")
    return frames


def _frame_rate(cfg, film: FrameAxis) -> float:
    fps = cfg.frame_rate(film.bin_width_opl)
    if not 0.1 <= fps <= 240:
        raise ValueError(
            f"composite.slow_motion={cfg.slow_motion} gives {fps:.3g} frames/s for bins of "
            f"{film.bin_width_opl} m; choose a factor that gives 0.1–240 frames/s, or set composite.fps"
        )
    return fps


def _annotated_video(
    display: np.ndarray, film: FrameAxis, cfg, caption: str, metres_per_pixel: float | None
) -> np.ndarray:
    out = []
    factor = max(1, int(np.ceil(cfg.video_min_height / display.shape[1])))
    bar_px = None
    bar_label = None
    if cfg.scale_bar_m and metres_per_pixel:
        bar_px = cfg.scale_bar_m / metres_per_pixel * factor
        bar_label = f"{cfg.scale_bar_m:g} m"
    for k, frame in enumerate(display):
        big = upscale(frame, cfg.video_min_height)
        out.append(
            annotate(
                big,
                [format_time(film.centre(k) - film.start_opl, cfg.time_unit), caption],
                cfg.title,
                bar_px,
                bar_label,
            )
        )
    return np.stack(out)


def transient_videos(
    frames: np.ndarray,
    film: FrameAxis,
    cfg,
    out_dir: Path,
    stem: str = "transient",
    metres_per_pixel: float | None = None,
) -> dict[str, Path]:
    """Write ``<stem>.mp4`` (frame by frame) and ``<stem>_cumulative.mp4`` (running sum)."""
    frames = check_frames(frames)
    fps = _frame_rate(cfg, film)
    if cfg.per_frame_exposure:
        display, _ = display_frames(frames, cfg.tone_curve, cfg.exposure_percentile, per_frame=True)
    else:  # frame by frame: the stack may be a memory-mapped film larger than memory allows in float64
        scale = clip_exposure(frames, cfg)
        display = np.stack([to_display(frame, scale, cfg.tone_curve) for frame in frames])
    exposure = "per-frame exposure" if cfg.per_frame_exposure else "one exposure for the clip"
    video = _annotated_video(display, film, cfg, exposure, metres_per_pixel)
    paths = {"video": write_mp4(out_dir / f"{stem}.mp4", video, fps)}
    if getattr(cfg, "archival_cut", False):
        paths["archival_video"] = archival_cut(frames, film, cfg, out_dir / f"{stem}_10bit.mp4", fps)
    # Light filling the scene: the running sum; its last frame is the (windowed) steady image.
    total = np.zeros(frames.shape[1:], np.float64)
    for frame in frames:
        total += frame
    scale = exposure_scale(total, cfg.exposure_percentile)
    running = np.zeros_like(total)
    display_cum = np.empty_like(display)
    for k, frame in enumerate(frames):
        running += frame
        display_cum[k] = to_display(running, scale, cfg.tone_curve)
    video_cum = _annotated_video(display_cum, film, cfg, "cumulative", metres_per_pixel)
    paths["cumulative_video"] = write_mp4(out_dir / f"{stem}_cumulative.mp4", video_cum, fps)
    return paths


def clip_exposure(frames: np.ndarray, cfg, max_frames: int = 64) -> float:
    """One exposure for the clip; a long stack is sampled at most ``max_frames`` evenly spaced frames."""
    stride = max(1, int(np.ceil(len(frames) / max_frames)))
    return exposure_scale(np.asarray(frames[::stride]), cfg.exposure_percentile)


def archival_cut(frames: np.ndarray, film: FrameAxis, cfg, path: Path, fps: float) -> Path:
    """The 10-bit cut: the same exposure and curve as the web cut, quantised to 16 bits before the
    encoder's 10, with the time label burned in (render/output/LOOK.md)."""
    scale = clip_exposure(frames, cfg)
    out = []
    for k, frame in enumerate(frames):
        display = to_display(upscale(np.asarray(frame), cfg.video_min_height), scale, cfg.tone_curve, bits=16)
        label = annotate(
            np.zeros((*display.shape[:2], 3), np.uint8), [format_time(film.centre(k) - film.start_opl, cfg.time_unit)]
        )
        text = label.any(axis=-1)  # the label's box and glyphs, drawn over the 16-bit frame
        display[text] = label[text].astype(np.uint16) * 257
        out.append(display)
    return write_mp4(path, np.stack(out), fps, cut="archival")


def light_in_flight(
    frames: np.ndarray, steady: np.ndarray, film: FrameAxis, cfg, out_dir: Path, metres_per_pixel: float | None = None
) -> dict[str, Path]:
    """Each frame's light over the dimmed steady image, as in femto-photography videos: the steady image at
    ``light_in_flight_dim`` of its brightness, the frame's light screened over it with the clip's exposure.
    Writes light_in_flight.mp4, a 2 x 2 panel of four moments (the size of the still; larger for small
    renders), still.png (the steady
    image at full size, unlabelled) and the time-of-arrival map."""
    from render.output.figures import time_of_arrival_map

    scale = clip_exposure(frames, cfg)
    background = display_values(steady, exposure_scale(steady, cfg.exposure_percentile), cfg.tone_curve)
    background = background * cfg.light_in_flight_dim

    def screened(k: int) -> np.ndarray:
        return 1 - (1 - background) * (1 - display_values(frames[k], scale, cfg.tone_curve))

    def composed(k: int) -> np.ndarray:
        return np.round(screened(k) * 255).astype(np.uint8)

    def tile(k: int) -> np.ndarray:
        """A 2 x 2 box average, so that four moments make a panel of the still's size; below 480 rows the
        frame at full size, enlarged to at least 240 rows, so that the panel and its labels stay legible."""
        image = screened(k)
        if image.shape[0] < 480:
            return upscale(np.round(image * 255).astype(np.uint8), 240)
        height, width = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
        blocks = image[:height, :width].reshape(height // 2, 2, width // 2, 2, 3)
        return np.round(blocks.mean(axis=(1, 3)) * 255).astype(np.uint8)

    fps = _frame_rate(cfg, film)
    video = _annotated_video(
        np.stack([composed(k) for k in range(len(frames))]), film, cfg, "light in flight", metres_per_pixel
    )
    paths = {"light_in_flight": write_mp4(out_dir / "light_in_flight.mp4", video, fps)}
    moments = np.linspace(0, len(frames) - 1, 4).round().astype(int)
    tiles = [
        annotate(tile(int(k)), [format_time(film.centre(int(k)) - film.start_opl, cfg.time_unit)]) for k in moments
    ]
    panel = np.concatenate([np.concatenate(tiles[:2], axis=1), np.concatenate(tiles[2:], axis=1)], axis=0)
    panel_path = out_dir / "light_in_flight_panel.png"
    with atomic_path(panel_path) as tmp:
        Image.fromarray(panel).save(tmp)
    paths["light_in_flight_panel"] = panel_path
    # The still at the render's full size, without labels: the poster's main image.
    still_path = out_dir / "still.png"
    with atomic_path(still_path) as tmp:
        steady_display = display_values(steady, exposure_scale(steady, cfg.exposure_percentile), cfg.tone_curve)
        Image.fromarray(np.round(steady_display * 255).astype(np.uint8)).save(tmp)
    paths["still"] = still_path
    toa = out_dir / "time_of_arrival.png"
    time_of_arrival_map(frames, film.start_opl, film.bin_width_opl, toa, "Time of arrival")
    paths["time_of_arrival"] = toa
    return paths


def streak_images(frames: np.ndarray, film: FrameAxis, cfg, out_dir: Path, stem: str = "streak") -> dict[str, Path]:
    frames = check_frames(frames)
    height, width = frames.shape[1:3]
    row = height // 2 if cfg.streak_row is None else cfg.streak_row
    column = width // 2 if cfg.streak_column is None else cfg.streak_column
    if row >= height:
        raise ValueError(f"composite.streak_row={row} is outside the image of height {height}")
    if column >= width:
        raise ValueError(f"composite.streak_column={column} is outside the image of width {width}")
    scale = exposure_scale(frames, cfg.exposure_percentile)
    x_path = out_dir / f"{stem}_x.png"
    y_path = out_dir / f"{stem}_y.png"
    for axis, index, path in (("x", row, x_path), ("y", column, y_path)):
        streak_image(
            frames, axis, index, film.start_opl, film.bin_width_opl, scale, path, cfg.tone_curve, cfg.time_unit
        )
    return {"streak_x": x_path, "streak_y": y_path}


def side_by_side(
    a_frames: np.ndarray,
    b_frames: np.ndarray,
    labels: tuple[str, str],
    film: FrameAxis,
    cfg,
    out_dir: Path,
    stem: str = "side_by_side",
) -> dict[str, Path]:
    """Video and still of two frame stacks with a relative-difference heat-map panel."""
    import matplotlib

    a_frames = check_frames(a_frames, labels[0])
    b_frames = check_frames(b_frames, labels[1])
    if a_frames.shape != b_frames.shape:
        raise ValueError(f"cannot compare {labels[0]} {a_frames.shape} with {labels[1]} {b_frames.shape}")
    # One exposure for both, from both: from the reference alone a black one (Mitsuba's delta sun behind a
    # dielectric) would blow ours out to white.
    scale = exposure_scale(np.concatenate([a_frames, b_frames]), cfg.exposure_percentile)
    colormap = matplotlib.colormaps["inferno"]
    panels = []
    for k in range(len(a_frames)):
        a = to_display(a_frames[k], scale, cfg.tone_curve)
        b = to_display(b_frames[k], scale, cfg.tone_curve)
        diff = relative_difference(a_frames[k], b_frames[k], floor=0.01 * float(np.mean(b_frames)) + 1e-12)
        heat = (colormap(np.clip(diff / cfg.difference_vmax, 0, 1))[..., :3] * 255).astype(np.uint8)
        row = np.concatenate([upscale(p, cfg.video_min_height // 2) for p in (a, b, heat)], axis=1)
        panels.append(
            annotate(
                row,
                [
                    f"{labels[0]} | {labels[1]} | rel. diff 0 to {cfg.difference_vmax:g}",
                    format_time(film.centre(k) - film.start_opl, cfg.time_unit),
                ],
            )
        )
    paths = {"side_by_side_video": write_mp4(out_dir / f"{stem}.mp4", np.stack(panels), _frame_rate(cfg, film))}
    still = out_dir / f"{stem}.png"
    side_by_side_still(
        a_frames.sum(axis=0),
        b_frames.sum(axis=0),
        labels,
        exposure_scale(np.concatenate([a_frames.sum(axis=0), b_frames.sum(axis=0)]), cfg.exposure_percentile),
        still,
        cfg.tone_curve,
        title="Sum over all frames",
        vmax=cfg.difference_vmax,
    )
    paths["side_by_side_still"] = still
    return paths


def run_composite_stage(render_dir: Path, reference_dir: Path | None, scene_dir: Path, cfg, out_dir: Path) -> dict:
    """The `composite` stage: videos and streak images of our frames, and ours against the reference.

    Reads ``render_dir/frames.npy`` and ``stats.json`` (the film), ``reference_dir/frames.npy`` when a
    transient reference exists, and the camera from ``scene_dir/scene.json`` for the scale bar.
    """
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
    written = transient_videos(frames, film, cfg, out_dir, metres_per_pixel=metres_per_pixel)
    written.update(streak_images(frames, film, cfg, out_dir))
    steady = ours.steady()
    if cfg.light_in_flight and steady is not None:
        written.update(light_in_flight(frames, steady, film, cfg, out_dir, metres_per_pixel))
    if cfg.exr_frames:
        from render.output.exr import write_exr_frames

        manifest = render_dir / "manifest.json"
        config_hash = json.loads(manifest.read_text())["config_hash"] if manifest.is_file() else "unknown"
        exposure = clip_exposure(frames, cfg)
        attributes = {"penitentes:exposure": exposure, "penitentes:config_hash": config_hash}
        written["exr_frames"] = write_exr_frames(out_dir / "exr", frames, film, attributes)[0].parent
    reference_frames = RenderOutputs.read(reference_dir).frames() if reference_dir is not None else None
    if reference_frames is not None and reference_frames.shape == frames.shape:
        # mitransient's frames are bin integrals; gate frames are densities per metre (render/core/DESIGN.md §2).
        ours_as_bins = film.as_bins(frames)
        bins_film = film.in_bins()
        written.update(
            side_by_side(ours_as_bins, reference_frames, ("ours (PTPB)", "mitransient"), bins_film, cfg, out_dir)
        )
        written.update(
            transient_videos(
                reference_frames, bins_film, cfg, out_dir, stem="reference_transient", metres_per_pixel=metres_per_pixel
            )
        )
    elif reference_frames is not None:
        log.warning("reference frames %s do not match ours %s; no side-by-side", reference_frames.shape, frames.shape)
    return {
        "files": sorted(p.name for p in written.values()),
        "frames": int(frames.shape[0]),
        "frame_mode": film.frame_mode,
    }
