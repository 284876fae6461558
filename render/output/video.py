"""H.264 videos of transient frames, with a burned-in time stamp, an optional title and scale bar."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import av
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from pipeline.atomic import atomic_path
from pipeline.units import PS_PER_M_OPL


def opl_to_ps(opl_m: np.ndarray | float) -> np.ndarray | float:
    return np.asarray(opl_m, dtype=np.float64) * PS_PER_M_OPL


def format_time(opl_m: float, unit: str = "ps") -> str:
    """A burned-in time stamp for ``opl_m`` metres of optical path (callers pass the OPL since first light)."""
    ps = float(opl_to_ps(opl_m))
    if unit == "ns":
        return f"t = {ps / 1000:8.3f} ns"
    return f"t = {ps:8.1f} ps"


def upscale(image: np.ndarray, min_height: int) -> np.ndarray:
    """Nearest-neighbour integer upscaling so small renders stay crisp in a player."""
    factor = max(1, int(np.ceil(min_height / image.shape[-3])))
    if factor == 1:
        return image
    return image.repeat(factor, axis=-3).repeat(factor, axis=-2)


def annotate(
    image: np.ndarray,
    lines_top_left: Sequence[str] = (),
    title: str | None = None,
    scale_bar_px: float | None = None,
    scale_bar_label: str | None = None,
) -> np.ndarray:
    """Draw text (white on a dark box) and a scale bar onto a uint8 (H, W, 3) image."""
    pil = Image.fromarray(image)
    draw = ImageDraw.Draw(pil)
    size = max(10, image.shape[0] // 28)
    font = ImageFont.load_default(size=size)
    y: float = 4  # textbbox gives float coordinates
    for text in ([title] if title else []) + list(lines_top_left):
        box = draw.textbbox((6, y), text, font=font)
        draw.rectangle((box[0] - 3, box[1] - 2, box[2] + 3, box[3] + 2), fill=(0, 0, 0))
        draw.text((6, y), text, fill=(255, 255, 255), font=font)
        y = box[3] + 6
    if scale_bar_px and scale_bar_px >= 2:
        h, w = image.shape[:2]
        x1 = w - 12
        x0 = max(4, int(round(x1 - scale_bar_px)))
        yb = h - 14
        draw.rectangle((x0, yb - 3, x1, yb), fill=(255, 255, 255))
        if scale_bar_label:
            box = draw.textbbox((0, 0), scale_bar_label, font=font)
            draw.text(
                (x1 - (box[2] - box[0]), yb - 6 - (box[3] - box[1]) - 4),
                scale_bar_label,
                fill=(255, 255, 255),
                font=font,
            )
    return np.asarray(pil)


def write_mp4(path: str | Path, frames: np.ndarray, fps: float, crf: int = 18) -> Path:
    """Encode uint8 (T, H, W, 3) frames as H.264 (yuv420p) MP4, atomically."""
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise ValueError(f"video frames must be uint8 (T, H, W, 3), got {frames.dtype} {frames.shape}")
    if len(frames) == 0:
        raise ValueError("a video needs at least one frame")
    if not fps > 0:
        raise ValueError(f"frame rate must be positive, got {fps}")
    # yuv420p needs even sizes: pad by edge replication.
    pad_h, pad_w = frames.shape[1] % 2, frames.shape[2] % 2
    if pad_h or pad_w:
        frames = np.pad(frames, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    from fractions import Fraction

    with atomic_path(path) as tmp:
        with av.open(str(tmp), mode="w", format="mp4") as container:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1000))
            stream.width, stream.height = frames.shape[2], frames.shape[1]
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": str(crf), "preset": "medium"}
            for frame in frames:
                for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
                    container.mux(packet)
            for packet in stream.encode():
                container.mux(packet)
    return Path(path)


def probe_mp4(path: str | Path) -> dict:
    """Decode a video fully; return its codec, frame count and size (used by tests and reports)."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        count = 0
        width = height = 0
        for frame in container.decode(stream):
            count += 1
            width, height = frame.width, frame.height
        return {"codec": stream.codec_context.name, "frames": count, "width": width, "height": height}
