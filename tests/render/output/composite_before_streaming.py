"""The composite as it was before it streamed (issue 32), kept only as the tests' oracle: every output held
as a whole stack, and the exposure from a sort of every pixel (numpy's percentile). ``composite_outputs``
returns what the old code handed to its writers: the encoders' frames, the streak slabs and exposure, the
arrival times, the PNG images and the EXR frames with their exposure, keyed as the new path's files.

``exposures`` overrides the exposures (keys clip, cumulative, streak, steady): given the new path's, the
old code must produce the new path's outputs bit for bit; without, it gives the old outputs, which differ
from the new only as far as the exposure moves within the histogram's error."""

from __future__ import annotations

import numpy as np

from common.units import NS_PER_M_OPL
from render.output.files import FrameAxis
from render.output.tonemap import display_values, luminance, to_display
from render.output.video import annotate, format_time, upscale


def sorted_exposure(frames: np.ndarray, percentile: float) -> float:
    """The old exposure: the percentile of every positive luminance, by numpy's sort."""
    lum = luminance(frames)
    positive = lum[lum > 0]
    if positive.size == 0:
        return 1.0
    level = float(np.percentile(positive, percentile))
    return 1.0 / level if level > 0 else 1.0


def old_exposures(frames: np.ndarray, steady: np.ndarray, cfg) -> dict[str, float]:
    stride = max(1, int(np.ceil(len(frames) / 64)))
    return {
        "clip": sorted_exposure(frames[::stride], cfg.exposure_percentile),
        "cumulative": sorted_exposure(frames.astype(np.float64).sum(axis=0), cfg.exposure_percentile),
        "streak": sorted_exposure(frames, cfg.exposure_percentile),
        "steady": sorted_exposure(steady, cfg.exposure_percentile),
    }


def _annotated_video(display, film: FrameAxis, cfg, caption, metres_per_pixel):
    out = []
    factor = max(1, int(np.ceil(cfg.video_min_height / display.shape[1])))
    bar_px = bar_label = None
    if cfg.scale_bar_m and metres_per_pixel:
        bar_px = cfg.scale_bar_m / metres_per_pixel * factor
        bar_label = f"{cfg.scale_bar_m:g} m"
    for k, frame in enumerate(display):
        big = upscale(frame, cfg.video_min_height)
        time = format_time(film.centre(k) - film.start_opl, cfg.time_unit)
        out.append(annotate(big, [time, caption], cfg.title, bar_px, bar_label))
    return np.stack(out)


def composite_outputs(frames, steady, film: FrameAxis, cfg, metres_per_pixel=None, exposures=None) -> dict:
    frames = np.asarray(frames)
    scales = exposures or old_exposures(frames, steady, cfg)
    clip, curve = scales["clip"], cfg.tone_curve
    out: dict = {"exposures": scales}
    display = np.stack([to_display(frame, clip, curve) for frame in frames])
    out["transient.mp4"] = _annotated_video(display, film, cfg, "one exposure for the clip", metres_per_pixel)
    archival = []
    for k, frame in enumerate(frames):
        image = to_display(upscale(frame, cfg.video_min_height), clip, curve, bits=16)
        label = annotate(
            np.zeros((*image.shape[:2], 3), np.uint8), [format_time(film.centre(k) - film.start_opl, cfg.time_unit)]
        )
        text = label.any(axis=-1)
        image[text] = label[text].astype(np.uint16) * 257
        archival.append(image)
    out["transient_10bit.mp4"] = np.stack(archival)
    running = np.zeros(frames.shape[1:])
    cumulative = np.empty_like(display)
    for k, frame in enumerate(frames):
        running += frame
        cumulative[k] = to_display(running, scales["cumulative"], curve)
    out["transient_cumulative.mp4"] = _annotated_video(cumulative, film, cfg, "cumulative", metres_per_pixel)
    height, width = frames.shape[1:3]
    out["streak_x.png"] = (frames[:, height // 2], scales["streak"])
    out["streak_y.png"] = (frames[:, :, width // 2], scales["streak"])
    steady_display = display_values(steady, scales["steady"], curve)
    background = steady_display * cfg.light_in_flight_dim

    def screened(k):
        return 1 - (1 - background) * (1 - display_values(frames[k], clip, curve))

    composed = np.stack([np.round(screened(k) * 255).astype(np.uint8) for k in range(len(frames))])
    out["light_in_flight.mp4"] = _annotated_video(composed, film, cfg, "light in flight", metres_per_pixel)
    tiles = []
    for k in np.linspace(0, len(frames) - 1, 4).round().astype(int):
        image = screened(int(k))
        if image.shape[0] < 480:
            tile = upscale(np.round(image * 255).astype(np.uint8), 240)
        else:
            h, w = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
            tile = np.round(image[:h, :w].reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3)) * 255).astype(np.uint8)
        tiles.append(annotate(tile, [format_time(film.centre(int(k)) - film.start_opl, cfg.time_unit)]))
    out["light_in_flight_panel.png"] = np.concatenate(
        [np.concatenate(tiles[:2], axis=1), np.concatenate(tiles[2:], axis=1)], axis=0
    )
    out["still.png"] = np.round(steady_display * 255).astype(np.uint8)
    running_lum = np.zeros(frames.shape[1:3])
    for frame in frames:
        running_lum += luminance(frame)
    total = running_lum
    arrival = np.full(total.shape, np.nan)
    running_lum = np.zeros(total.shape)
    for k, frame in enumerate(frames):
        running_lum += luminance(frame)
        reached = np.isnan(arrival) & (total > 0) & (running_lum >= 0.05 * total)
        arrival[reached] = (k + 0.5) * film.bin_width_opl * NS_PER_M_OPL
    out["time_of_arrival.png"] = arrival
    out["exr"] = (frames, clip)
    return out
