"""From linear radiance to display pixels: one exposure for a whole clip, a tone curve, sRGB.

The default exposure is global: one scale for every frame, chosen so that a high percentile of
the luminance over all frames maps to ``key``. Brightness therefore evolves as the light does,
and a frame holding more energy is never shown darker (the mapping is monotonic per pixel).

The percentile comes from a histogram of log2 luminance (``LuminanceHistogram``), filled a frame at a
time, never from a sort of every pixel: a 1080p film of 240 frames has 500 million of them. The bins
are 1/256 of an octave wide and cover every positive float32 luminance, so the level it returns lies
within a factor 2^(1/512) of numpy's linearly interpolated percentile: ``PERCENTILE_RELATIVE_ERROR``,
0.14 %, and so does the exposure.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

ToneCurve = Literal["reinhard", "filmic", "linear"]
REC709_LUMA = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, dtype=np.float64) @ REC709_LUMA


BINS_PER_OCTAVE = 256
LOG2_LUMINANCE_RANGE = (-160, 130)  # every positive luminance of float32 RGB: 2^-149 * 0.0722 .. 2^128
PERCENTILE_RELATIVE_ERROR = 2 ** (1 / (2 * BINS_PER_OCTAVE)) - 1  # half a bin: 0.135 %


class LuminanceHistogram:
    """Counts of positive luminance in bins of 1/``BINS_PER_OCTAVE`` octave, filled image by image.

    ``percentile`` reads numpy's percentile (linear interpolation between the two order statistics around
    the rank) off the counts: each order statistic is known to its bin, [lo, lo·2^w) with w one bin in
    octaves, and the interpolation of two such intervals is again [L, L·2^w); the answer, taken at the
    bins' geometric centres, is L·2^(w/2), within a factor 2^(w/2) of the exact value
    (``PERCENTILE_RELATIVE_ERROR``)."""

    bins = (LOG2_LUMINANCE_RANGE[1] - LOG2_LUMINANCE_RANGE[0]) * BINS_PER_OCTAVE

    def __init__(self) -> None:
        self.counts = np.zeros(self.bins, np.int64)

    @classmethod
    def of(cls, rgb: np.ndarray) -> LuminanceHistogram:
        """The histogram of an (..., 3) image or stack (a stack frame by frame: it may be memory-mapped)."""
        histogram = cls()
        rgb = np.asanyarray(rgb)
        for image in rgb if rgb.ndim == 4 else (rgb,):
            histogram.add_luminance(luminance(image))
        return histogram

    def add_luminance(self, lum: np.ndarray) -> None:
        positive = lum[lum > 0]
        if positive.size == 0:
            return
        index = np.floor((np.log2(positive) - LOG2_LUMINANCE_RANGE[0]) * BINS_PER_OCTAVE).astype(np.int64)
        np.clip(index, 0, self.bins - 1, out=index)
        self.counts += np.bincount(index, minlength=self.bins)

    def __iadd__(self, other: LuminanceHistogram) -> LuminanceHistogram:
        self.counts += other.counts
        return self

    @property
    def total(self) -> int:
        return int(self.counts.sum())

    def percentile(self, percentile: float) -> float | None:
        """The ``percentile`` of the counted luminances (None when nothing positive was counted)."""
        count = self.total
        if count == 0:
            return None
        rank = (count - 1) * percentile / 100.0
        below = int(np.floor(rank))
        cumulative = np.cumsum(self.counts)
        low, high = np.searchsorted(cumulative, [below, min(below + 1, count - 1)], side="right")
        centres = 2.0 ** (LOG2_LUMINANCE_RANGE[0] + (np.array([low, high]) + 0.5) / BINS_PER_OCTAVE)
        return float(centres[0] + (rank - below) * (centres[1] - centres[0]))

    def exposure(self, percentile: float = 99.5, key: float = 1.0) -> float:
        """Scale that maps the ``percentile`` to ``key`` (1 when nothing positive was counted)."""
        level = self.percentile(percentile)
        return key / level if level else 1.0


def exposure_scale(frames: np.ndarray, percentile: float = 99.5, key: float = 1.0) -> float:
    """Scale that maps the ``percentile`` of the positive luminance values to ``key`` (an image, or a stack
    read a frame at a time; within ``PERCENTILE_RELATIVE_ERROR`` of the sorted values' percentile)."""
    return LuminanceHistogram.of(frames).exposure(percentile, key)


def tone_curve(x: np.ndarray, curve: ToneCurve) -> np.ndarray:
    """The curve on linear RGB (..., 3), in the input's floating type (``display_values`` passes float32)."""
    # Above 1e18 every curve shows white; the clip keeps float32's squares below its overflow (3e38).
    x = np.clip(x, 0, x.dtype.type(1e18))
    one = x.dtype.type(1)
    if curve == "linear":
        return np.minimum(x, one)
    if curve == "reinhard":
        # Luminance-based Reinhard keeps hues; the white point is the exposure key's 4x.
        lum = x @ REC709_LUMA.astype(x.dtype)
        white2 = x.dtype.type(16)
        mapped = lum * (one + lum / white2) / (one + lum)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(lum > 0, mapped / lum, x.dtype.type(0))
        return np.minimum(x * ratio[..., None], one)
    if curve == "filmic":
        # Narkowicz's fit of the ACES filmic curve, per channel.
        c = x.dtype.type
        y = (x * (c(2.51) * x + c(0.03))) / (x * (c(2.43) * x + c(0.59)) + c(0.14))
        return np.clip(y, 0, one)
    raise ValueError(f"unknown tone curve '{curve}': use reinhard, filmic or linear")


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on values clipped to [0, 1], in the input's floating type."""
    c = linear.dtype.type
    linear = np.clip(linear, 0, c(1))
    return np.where(linear <= c(0.0031308), c(12.92) * linear, c(1.055) * np.power(linear, c(1 / 2.4)) - c(0.055))


def display_values(frames: np.ndarray, scale: float | np.ndarray, curve: ToneCurve = "reinhard") -> np.ndarray:
    """Linear RGB (..., 3) times ``scale`` -> tone curve -> sRGB encoding, as float32 in [0, 1].

    Float32 throughout: its rounding (6e-8 relative) is 1/60000 of an 8-bit step and 1/250 of a 16-bit one,
    and a 1080p frame costs half the float64 computation (render/output/LOOK.md, *Float32 display values*)."""
    x = np.asarray(frames, dtype=np.float32) * np.asarray(scale, dtype=np.float32)
    return srgb_encode(tone_curve(x, curve))


def to_display(
    frames: np.ndarray,
    scale: float | np.ndarray,
    curve: ToneCurve = "reinhard",
    bits: int = 8,
) -> np.ndarray:
    """Linear RGB (..., 3) times ``scale`` -> tone curve -> sRGB -> uint8 (``bits`` 16: uint16, for the
    10-bit archival cut)."""
    top = 255.0 if bits == 8 else 65535.0
    return np.round(display_values(frames, scale, curve) * top).astype(np.uint8 if bits == 8 else np.uint16)


def display_frames(
    frames: np.ndarray,
    curve: ToneCurve = "reinhard",
    percentile: float = 99.5,
    per_frame: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Tone-map a (T, H, W, 3) stack; returns uint8 frames and the scale used for each frame."""
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"frames must have shape (T, H, W, 3), got {frames.shape}")
    if not np.all(np.isfinite(frames)):
        raise ValueError("frames contain NaN or infinite values")
    if per_frame:
        scales = np.array([exposure_scale(f, percentile) for f in frames])
    else:
        scales = np.full(len(frames), exposure_scale(frames, percentile))
    out = np.stack([to_display(f, s, curve) for f, s in zip(frames, scales)])
    return out, scales
