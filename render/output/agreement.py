"""Does our render agree with the reference? The ratio of their per-channel means, with its noise.

Both images are Monte Carlo estimates, so their ratio R = Σ ours / Σ reference is noisy. Its standard
error comes from a delete-one-tile jackknife: the image (every frame, for a stack) is cut into tiles,
and R is recomputed with each tile left out. The image's structure cancels in the ratio (ours and the
reference see the same scene); what the leave-one-out values spread over is the noise of both
renders. A channel disagrees when |R − 1| exceeds both 3σ and 3 %: beyond the noise, and by an amount
that matters. That is the guard the compare stage applies to every run and the sweep summary repeats.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SIGMAS = 3.0
TOLERANCE = 0.03
TILES = 8  # tiles along each image axis


@dataclass(frozen=True)
class Agreement:
    """Per channel (R, G, B): ratio of means ours / reference, its standard error, and the verdict."""

    ratio: tuple[float, float, float]
    sigma: tuple[float, float, float]

    @property
    def reference_black(self) -> bool:
        """Ours has light in a channel where the reference has none (ratio +inf): a delta light behind a
        dielectric in Mitsuba, say (render/core/DESIGN.md §11). Both black (nan) is no disagreement."""
        return any(np.isposinf(r) for r in self.ratio)

    @property
    def disagrees(self) -> bool:
        return self.reference_black or any(
            abs(r - 1.0) > SIGMAS * s and abs(r - 1.0) > TOLERANCE
            for r, s in zip(self.ratio, self.sigma)
            if np.isfinite(r)
        )

    def text(self) -> str:
        if self.reference_black:
            return "DISAGREES: the reference is black where ours is not (ours / reference = ∞ in some channel)"
        parts = " / ".join(f"{r:.3f} ± {s:.3f}" for r, s in zip(self.ratio, self.sigma))
        verdict = "DISAGREES" if self.disagrees else "agrees"
        return f"{verdict}: ours / reference {parts} (R / G / B; flagged beyond {SIGMAS:g}σ and {TOLERANCE:.0%})"


def _tile_sums(image: np.ndarray, tiles: int) -> np.ndarray:
    """Sums over (tiles × tiles) spatial tiles of an (..., H, W, 3) array: shape (tiles², 3)."""
    data = np.asarray(image, np.float64)
    data = data.reshape(-1, *data.shape[-3:]).sum(axis=0)  # frames add up: (H, W, 3)
    height, width = data.shape[:2]
    rows = np.array_split(np.arange(height), min(tiles, height))
    cols = np.array_split(np.arange(width), min(tiles, width))
    return np.array([data[np.ix_(r, c)].reshape(-1, 3).sum(axis=0) for r in rows for c in cols])


def agreement(ours: np.ndarray, reference: np.ndarray, tiles: int = TILES) -> Agreement:
    """Compare two images or frame stacks of the same shape (..., H, W, 3)."""
    if np.shape(ours) != np.shape(reference):
        raise ValueError(f"cannot compare shapes {np.shape(ours)} and {np.shape(reference)}")
    a, b = _tile_sums(ours, tiles), _tile_sums(reference, tiles)
    n = len(a)
    total_a, total_b = a.sum(axis=0), b.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):  # a black reference gives inf, both black nan
        ratio = total_a / total_b
        leave_one_out = (total_a - a) / (total_b - b)  # (n, 3)
        spread = leave_one_out - leave_one_out.mean(axis=0)
        sigma = np.sqrt((n - 1) / n * (spread**2).sum(axis=0))
    return Agreement(
        tuple(float(x) for x in ratio),  # type: ignore[arg-type]
        tuple(float(x) for x in sigma),  # type: ignore[arg-type]
    )
