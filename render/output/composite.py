"""Transient frames -> videos (light in flight, and light filling the scene), streak images and
side-by-side comparisons. Pure array work plus the writers in render.output.video and render.output.figures.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from render.output.figures import relative_difference, side_by_side_still, streak_image
from render.output.files import FrameAxis, RenderOutputs
from render.output.tonemap import display_frames, exposure_scale, to_display
from render.output.video import annotate, format_time, upscale, write_mp4

log = logging.getLogger(__name__)


def check_frames(frames: np.ndarray, name: str = "frames") -> np.ndarray:
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (T, H, W, 3), got {frames.shape}")
    if not np.all(np.isfinite(frames)):
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
    display, _ = display_frames(frames, cfg.tone_curve, cfg.exposure_percentile, cfg.per_frame_exposure)
    exposure = "per-frame exposure" if cfg.per_frame_exposure else "one exposure for the clip"
    video = _annotated_video(display, film, cfg, exposure, metres_per_pixel)
    paths = {"video": write_mp4(out_dir / f"{stem}.mp4", video, fps)}
    # Light filling the scene: the running sum; its last frame is the (windowed) steady image.
    cumulative = np.cumsum(frames.astype(np.float64), axis=0)
    scale = exposure_scale(cumulative[-1], cfg.exposure_percentile)
    display_cum = np.stack([to_display(f, scale, cfg.tone_curve) for f in cumulative])
    video_cum = _annotated_video(display_cum, film, cfg, "cumulative", metres_per_pixel)
    paths["cumulative_video"] = write_mp4(out_dir / f"{stem}_cumulative.mp4", video_cum, fps)
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
    scale = exposure_scale(b_frames, cfg.exposure_percentile)
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
        exposure_scale(b_frames.sum(axis=0), cfg.exposure_percentile),
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
    frames = ours.frames()
    if frames is None:
        raise FileNotFoundError(f"{render_dir}: frames.npy is missing; run the render stage again (--force)")
    written = transient_videos(frames, film, cfg, out_dir, metres_per_pixel=metres_per_pixel)
    written.update(streak_images(frames, film, cfg, out_dir))
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
