"""The refining pass (render/output/LOOK.md, *The refining pass*): a second Open Image Denoise pass whose albedo guide
is the first pass's frame. In snow the first hit's albedo is one colour everywhere, so the guide tells the network
nothing about where a frame's light lies; the first pass's output does."""

from __future__ import annotations

import numpy as np
import pytest

from render.output.denoise import REFINE_GUIDE_PERCENTILE, Guides, _refine_guide, denoise_frame
from render.output.metrics import relmse

pytest.importorskip("pyoidn")

HEIGHT, WIDTH = 192, 256


def lit_faces(seed: int, shape: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """The truth and an unbiased noisy frame of it: a dim gradient with 24 bright elliptic faces of their own
    levels (1-6), the frame's detail lying in its light and not in any albedo; gamma noise of this shape (relative
    noise 1/sqrt(shape)). The faces are the same at every seed, the noise is not."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    truth = 0.2 + 0.3 * x / WIDTH
    rng = np.random.default_rng(100)
    for _ in range(24):
        cx, cy = rng.uniform(0, WIDTH), rng.uniform(0, HEIGHT)
        a, b, angle, level = rng.uniform(8, 30), rng.uniform(3, 10), rng.uniform(0, np.pi), rng.uniform(1, 6)
        u = (x - cx) * np.cos(angle) + (y - cy) * np.sin(angle)
        v = -(x - cx) * np.sin(angle) + (y - cy) * np.cos(angle)
        truth = np.where((u / a) ** 2 + (v / b) ** 2 < 1, level, truth)
    truth = np.repeat(truth[..., None], 3, axis=2).astype(np.float32)
    noise = np.random.default_rng(seed).gamma(shape, 1.0 / shape, size=truth.shape)
    return truth, (truth * noise).astype(np.float32)


def snow_guides() -> Guides:
    """One albedo everywhere, as the first hit on index-matched snow gives, and one normal."""
    return Guides(
        albedo=np.full((HEIGHT, WIDTH, 3), 0.8, np.float32),
        normal=np.broadcast_to(np.array([0.0, 0.0, 1.0], np.float32), (HEIGHT, WIDTH, 3)).copy(),
    )


@pytest.mark.parametrize("seed", [1, 2])
def test_refining_lowers_the_error_where_the_albedo_is_uniform(seed: int):
    truth, raw = lit_faces(seed)
    guides = snow_guides()
    albedo = guides.albedo.copy()
    one = denoise_frame(raw, guides, "high")
    two = denoise_frame(raw, guides, "high", refine=True)
    # Measured 0.938 and 0.934 of the one-pass error (relMSE 0.235 -> 0.221, 0.266 -> 0.248; raw 4.6).
    assert relmse(two, truth) < 0.97 * relmse(one, truth), (relmse(two, truth), relmse(one, truth))
    # Kept at the raw frame's sum per channel, as every denoised frame is.
    np.testing.assert_allclose(two.sum(axis=(0, 1)), raw.sum(axis=(0, 1)), rtol=1e-4)
    # The refining guide is the denoiser's own buffer: the scene's guides are read, never written.
    np.testing.assert_array_equal(guides.albedo, albedo)


def test_a_black_frame_stays_black():
    out = denoise_frame(np.zeros((HEIGHT, WIDTH, 3), np.float32), snow_guides(), "high", refine=True)
    assert not np.any(out)


def test_the_guide_maps_the_percentile_to_one_and_clips():
    rng = np.random.default_rng(3)
    frame = rng.lognormal(0.0, 2.0, size=(64, 48, 3))
    frame[:8] = 0.0  # unlit rows stay out of the percentile
    guide = np.full(frame.shape, -1.0, np.float32)
    _refine_guide(frame, guide)
    luminance = frame.mean(axis=2)
    level = np.percentile(luminance[luminance > 0], REFINE_GUIDE_PERCENTILE)
    np.testing.assert_allclose(guide, np.clip(frame / level, 0.0, 1.0), rtol=1e-6)
    assert guide.min() == 0.0 and guide.max() == 1.0
    # About 0.5 % of the lit pixels' luminance lies above 1 before clipping.
    assert 0.002 < float(np.mean(luminance[8:] / level > 1.0)) < 0.01
    empty = np.full(frame.shape, 0.5, np.float32)
    _refine_guide(np.zeros(frame.shape), empty)
    assert not np.any(empty)
