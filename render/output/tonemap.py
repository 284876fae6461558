"""From linear radiance to display pixels: one exposure for a whole clip, a tone curve, sRGB.

The default exposure is global: one scale for every frame, chosen so that a high percentile of
the luminance over all frames maps to ``key``. Brightness therefore evolves as the light does,
and a frame holding more energy is never shown darker (the mapping is monotonic per pixel).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

ToneCurve = Literal["reinhard", "filmic", "linear"]
REC709_LUMA = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, dtype=np.float64) @ REC709_LUMA


def exposure_scale(frames: np.ndarray, percentile: float = 99.5, key: float = 1.0) -> float:
    """Scale that maps the ``percentile`` of the positive luminance values to ``key``."""
    lum = luminance(frames)
    positive = lum[lum > 0]
    if positive.size == 0:
        return 1.0
    level = float(np.percentile(positive, percentile))
    return key / level if level > 0 else 1.0


def tone_curve(x: np.ndarray, curve: ToneCurve) -> np.ndarray:
    x = np.maximum(x, 0.0)
    if curve == "linear":
        return np.minimum(x, 1.0)
    if curve == "reinhard":
        # Luminance-based Reinhard keeps hues; the white point is the exposure key's 4x.
        lum = x @ REC709_LUMA
        white2 = 16.0
        mapped = lum * (1 + lum / white2) / (1 + lum)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(lum > 0, mapped / lum, 0.0)
        return np.minimum(x * ratio[..., None], 1.0)
    if curve == "filmic":
        # Narkowicz's fit of the ACES filmic curve, per channel.
        y = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
        return np.clip(y, 0.0, 1.0)
    raise ValueError(f"unknown tone curve '{curve}': use reinhard, filmic or linear")


def srgb_encode(linear: np.ndarray) -> np.ndarray:
    linear = np.clip(linear, 0.0, 1.0)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.power(linear, 1 / 2.4) - 0.055)


def display_values(frames: np.ndarray, scale: float | np.ndarray, curve: ToneCurve = "reinhard") -> np.ndarray:
    """Linear RGB (..., 3) times ``scale`` -> tone curve -> sRGB encoding, as floats in [0, 1]."""
    x = np.asarray(frames, dtype=np.float64) * np.asarray(scale, dtype=np.float64)
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
