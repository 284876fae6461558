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
