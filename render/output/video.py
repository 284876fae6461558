"""H.264 videos of transient frames, with a burned-in time stamp, an optional title and scale bar."""

from __future__ import annotations

from collections.abc import Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from types import TracebackType
from typing import Any

import av
import numpy as np
from av.video.reformatter import ColorRange, Colorspace
from PIL import Image, ImageDraw, ImageFont

from common.atomic import atomic_path
from common.units import PS_PER_M_OPL


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


# The cuts of a clip (render/output/LOOK.md): pixel format, codec profile and file tags, after the ASWF
# encoding guidelines. Both are BT.709 primaries, transfer and matrix in TV (limited) range.
@dataclass(frozen=True)
class Cut:
    pix_fmt: str
    profile: str  # x264's profile name
    crf: int


CUTS = {"web": Cut("yuv420p", "high", 18), "archival": Cut("yuv420p10le", "high10", 12)}
RC_LOOKAHEAD = 10  # frames x264 looks ahead for rate control (its medium preset: 40)
BT709 = 1  # the ITU-T H.273 code of BT.709 for color_primaries, color_trc and colorspace
RANGE_TV = 1  # AVCOL_RANGE_MPEG: limited ("tv") range


class Mp4Writer:
    """A streaming H.264 MP4 encoder: ``with Mp4Writer(path, fps) as video: video.write(frame)`` for each
    (H, W, 3) display frame, as it is made. Encoded atomically (the file appears on a clean exit only),
    tagged BT.709 in TV range with the index up front (``+faststart``). ``cut`` "web": uint8 frames,
    yuv420p, CRF 18; "archival": uint16 frames (display values x 65535), yuv420p10le (High 10). Odd sizes
    are padded by edge replication. The encoder holds its look-ahead, ``RC_LOOKAHEAD`` frames and its
    threads' frames in YUV."""

    def __init__(self, path: str | Path, fps: float, crf: int | None = None, cut: str = "web") -> None:
        if cut not in CUTS:
            raise ValueError(f"unknown cut '{cut}': use {' or '.join(CUTS)}")
        if not fps > 0:
            raise ValueError(f"frame rate must be positive, got {fps}")
        self.path, self.fps, self.cut, self.spec = Path(path), fps, cut, CUTS[cut]
        self.crf = self.spec.crf if crf is None else crf
        self.dtype = np.uint16 if cut == "archival" else np.uint8
        self.frames = 0
        self._files = ExitStack()
        self._container: Any = None
        self._stream: Any = None
        self._shape: tuple[int, ...] = ()

    def __enter__(self) -> Mp4Writer:
        tmp = self._files.enter_context(atomic_path(self.path))
        self._container = self._files.enter_context(
            av.open(str(tmp), mode="w", format="mp4", options={"movflags": "+faststart"})
        )
        return self

    def _open_stream(self, height: int, width: int) -> None:
        stream = self._container.add_stream("libx264", rate=Fraction(self.fps).limit_denominator(1000))
        stream.width, stream.height = width + width % 2, height + height % 2
        stream.pix_fmt = self.spec.pix_fmt
        context = stream.codec_context
        context.color_primaries = BT709
        context.color_trc = BT709
        context.colorspace = BT709
        context.color_range = RANGE_TV
        stream.options = {
            "crf": str(self.crf),
            "preset": "medium",
            # Ten frames of rate-control look-ahead instead of medium's 40: each 1080p encoder then holds
            # 180 MiB (web) or 330 MiB (10-bit) instead of 380 and 700, which keeps the composite of a full
            # video within 2 GiB (render/output/LOOK.md, "Memory").
            "rc-lookahead": str(RC_LOOKAHEAD),
            "profile": self.spec.profile,
            "x264-params": "colorprim=bt709:transfer=bt709:colormatrix=bt709",
        }
        self._stream = stream

    def write(self, frame: np.ndarray) -> None:
        """Encode one (H, W, 3) frame; every frame of a video has the first one's size."""
        frame = np.asarray(frame)
        if frame.ndim != 3 or frame.shape[-1] != 3 or frame.dtype != self.dtype:
            raise ValueError(
                f"{self.cut} video frames must be {np.dtype(self.dtype)} (H, W, 3), got {frame.dtype} {frame.shape}"
            )
        if self._container is None:
            raise RuntimeError("Mp4Writer.write outside its with block")
        if self._stream is None:
            self._shape = frame.shape
            self._open_stream(*frame.shape[:2])
        elif frame.shape != self._shape:
            raise ValueError(f"{self.path.name}: frame {self.frames} is {frame.shape}, the first was {self._shape}")
        pad_h, pad_w = frame.shape[0] % 2, frame.shape[1] % 2  # 4:2:0 needs even sizes
        if pad_h or pad_w:
            frame = np.pad(frame, ((0, pad_h), (0, pad_w), (0, 0)), mode="edge")
        source_format = "rgb48le" if self.cut == "archival" else "rgb24"
        rgb = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format=source_format)
        # The RGB -> YUV matrix must be BT.709 to match the tags (swscale's default is BT.601).
        yuv = rgb.reformat(format=self.spec.pix_fmt, dst_colorspace=Colorspace.ITU709, dst_color_range=ColorRange.MPEG)
        for packet in self._stream.encode(yuv):
            self._container.mux(packet)
        self.frames += 1

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        if kind is None:
            try:
                if self._stream is None:
                    raise ValueError(f"{self.path}: a video needs at least one frame")
                for packet in self._stream.encode():  # flush the look-ahead
                    self._container.mux(packet)
            except BaseException as failure:  # the temporary file goes, nothing is published
                self._files.__exit__(type(failure), failure, failure.__traceback__)
                raise
        self._files.__exit__(kind, error, trace)


def write_mp4(path: str | Path, frames: np.ndarray, fps: float, crf: int | None = None, cut: str = "web") -> Path:
    """Encode a (T, H, W, 3) stack of display frames with ``Mp4Writer`` (a short clip already in memory)."""
    frames = np.asarray(frames)
    if frames.ndim != 4 or len(frames) == 0:
        raise ValueError(f"a video needs a (T, H, W, 3) stack of at least one frame, got shape {frames.shape}")
    with Mp4Writer(path, fps, crf, cut) as video:
        for frame in frames:
            video.write(frame)
    return Path(path)


def probe_mp4(path: str | Path) -> dict:
    """Decode a video fully; return its codec, profile, pixel format, colour tags, frame count and size
    (used by tests and reports; PyAV's stream info, as ffprobe would print it)."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        context = stream.codec_context
        count = 0
        width = height = 0
        for frame in container.decode(stream):
            count += 1
            width, height = frame.width, frame.height
        return {
            "codec": context.name,
            "profile": context.profile,
            "pix_fmt": context.pix_fmt,
            "color_primaries": int(context.color_primaries),
            "color_trc": int(context.color_trc),
            "colorspace": int(context.colorspace),
            "color_range": int(context.color_range),
            "frames": count,
            "width": width,
            "height": height,
        }


def moov_before_mdat(path: str | Path) -> bool:
    """Whether the MP4's index (moov) comes before its media (mdat): ``+faststart``, playable while loading."""
    data = Path(path).read_bytes()
    boxes, position = [], 0
    while position + 8 <= len(data):  # the top-level boxes: 32-bit size (1: 64-bit follows, 0: to the end), type
        size = int.from_bytes(data[position : position + 4], "big")
        if size == 1:
            size = int.from_bytes(data[position + 8 : position + 16], "big")
        boxes.append(data[position + 4 : position + 8])
        position += size if size >= 8 else len(data)
    return b"moov" in boxes and b"mdat" in boxes and boxes.index(b"moov") < boxes.index(b"mdat")
