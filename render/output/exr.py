"""OpenEXR images through OpenImageIO, written atomically: float32 RGB (H, W, 3) arrays."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from common.atomic import atomic_path
from render.output.files import frame_windows


def write_exr(
    path: str | os.PathLike[str],
    array: np.ndarray,
    *,
    channels: tuple[str, ...] | None = None,
    attributes: Mapping[str, str | float | int] | None = None,
) -> Path:
    """Write an (H, W) or (H, W, C) array as a float32 EXR (ZIP compression); RGB(A) names by default.
    ``attributes`` go into the header as they are (e.g. ``penitentes:opl_m`` of a transient frame)."""
    image = np.asarray(array, dtype=np.float32)
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3:
        raise ValueError(f"write_exr needs an (H, W) or (H, W, C) array, got shape {image.shape}")
    height, width, nchannels = image.shape
    names = channels or {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}.get(
        nchannels, tuple(f"C{i}" for i in range(nchannels))
    )
    spec = oiio.ImageSpec(width, height, nchannels, oiio.FLOAT)
    spec.channelnames = tuple(names)
    spec.attribute("compression", "zip")
    for name, value in (attributes or {}).items():
        spec.attribute(name, value)
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise RuntimeError(f"OpenImageIO cannot create {path}: {oiio.geterror()}")
        try:
            if not out.open(str(tmp), spec) or not out.write_image(np.ascontiguousarray(image)):
                raise RuntimeError(f"cannot write {path}: {out.geterror()}")
        finally:
            out.close()
    return Path(path)


def exr_frame_path(folder: str | os.PathLike[str], k: int) -> Path:
    return Path(folder) / f"frame_{k:04d}.exr"


def exr_frame_header(
    axis: Any, k: int, attributes: Mapping[str, str | float | int] | None = None
) -> dict[str, str | float | int]:
    """The header of frame ``k``: its OPL, its time in ns since first light, the bin width, the frame mode
    and unit (``axis``: a render.output.files FrameAxis) and ``attributes`` (e.g. the clip exposure and
    the render's config hash)."""
    described = axis.describe(k + 1)
    return {
        "penitentes:opl_m": described["frame_centres_opl_m"][k],
        "penitentes:time_ns_since_first_light": described["frame_centres_ns_since_first_light"][k],
        "penitentes:bin_width_opl_m": axis.bin_width_opl,
        "penitentes:frame_mode": axis.frame_mode,
        "penitentes:unit": described["unit"],
        **(attributes or {}),
    }


def write_exr_frames(
    folder: str | os.PathLike[str],
    frames: np.ndarray,
    axis: Any,
    attributes: Mapping[str, str | float | int] | None = None,
) -> list[Path]:
    """Write a (T, H, W, 3) stack as ``folder/frame_NNNN.exr``, a window of frames at a time (the stack may
    be memory-mapped), each with ``exr_frame_header``."""
    paths = []
    for first, window in frame_windows(frames):
        for k, frame in enumerate(window, start=first):
            paths.append(write_exr(exr_frame_path(folder, k), frame, attributes=exr_frame_header(axis, k, attributes)))
    return paths


def read_exr(path: str | os.PathLike[str]) -> np.ndarray:
    """Read an EXR (or any OpenImageIO image) as float32 (H, W, C)."""
    source = oiio.ImageInput.open(str(path))
    if source is None:
        raise FileNotFoundError(f"cannot open {path}: {oiio.geterror()}")
    try:
        pixels = source.read_image(oiio.FLOAT)
    finally:
        source.close()
    if pixels is None:
        raise RuntimeError(f"cannot read {path}")
    pixels = np.asarray(pixels, dtype=np.float32)
    return pixels if pixels.ndim == 3 else pixels[..., None]


__all__ = ["exr_frame_header", "exr_frame_path", "read_exr", "write_exr", "write_exr_frames"]
