"""Error metrics between a render and a reference, as used in every comparison table."""

from __future__ import annotations

import numpy as np

RELMSE_EPSILON = 1e-2  # render/core/DESIGN.md §10: keeps near-black reference pixels from dominating


def _pair(estimate, reference) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(estimate, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if x.shape != r.shape:
        raise ValueError(f"render and reference shapes differ: {x.shape} vs {r.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(r))):
        raise ValueError("render or reference contains NaN or infinite values")
    return x, r


def relmse(estimate, reference, epsilon: float = RELMSE_EPSILON) -> float:
    """Mean over pixels and channels of (x - r)^2 / (r^2 + epsilon)."""
    x, r = _pair(estimate, reference)
    return float(np.mean((x - r) ** 2 / (r**2 + epsilon)))


def rmse(estimate, reference) -> float:
    """Root of the mean over pixels and channels of (x - r)^2, in the images' units."""
    x, r = _pair(estimate, reference)
    return float(np.sqrt(np.mean((x - r) ** 2)))


def per_frame_relmse(frames, reference_frames, epsilon: float = RELMSE_EPSILON) -> np.ndarray:
    """relMSE of every frame of (T, H, W, 3) stacks, as a (T,) array."""
    x, r = _pair(frames, reference_frames)
    return np.mean((x - r) ** 2 / (r**2 + epsilon), axis=tuple(range(1, x.ndim)))


def mean_radiance(image) -> list[float]:
    """Per-channel mean of an (..., 3) image or frame stack."""
    a = np.asarray(image, dtype=np.float64)
    return [float(v) for v in a.reshape(-1, a.shape[-1]).mean(axis=0)]


def downsample_factor(shape: tuple[int, ...], reference_shape: tuple[int, ...]) -> int | None:
    """The integer k by which an (..., H, W, 3) render is larger than a reference of the same frame count and
    channels in both image axes (1 for equal shapes), or None when no such k exists: the references may be
    rendered at the film's size over k (``reference.downsample``)."""
    if len(shape) != len(reference_shape) or len(shape) < 3 or shape[:-3] != reference_shape[:-3]:
        return None
    if shape[-1] != reference_shape[-1]:
        return None
    (h, w), (rh, rw) = shape[-3:-1], reference_shape[-3:-1]
    if rh <= 0 or rw <= 0 or h % rh or w % rw or h // rh != w // rw:
        return None
    return h // rh


def box_downsample(image, factor: int) -> np.ndarray:
    """Mean over factor x factor pixel blocks of an (..., H, W, C) image or stack. For box-filtered pixels this
    is exactly the image the same camera records on a film `factor` times coarser: each coarse pixel's
    radiance is the mean over its area, which the fine pixels tile."""
    a = np.asarray(image)
    if factor == 1:
        return a
    h, w = a.shape[-3:-1]
    if factor < 1 or h % factor or w % factor:
        raise ValueError(f"cannot box-downsample a {h} x {w} image by {factor}: both sides must divide")
    blocks = a.reshape(*a.shape[:-3], h // factor, factor, w // factor, factor, a.shape[-1])
    return blocks.mean(axis=(-4, -2), dtype=np.float64).astype(a.dtype, copy=False)
