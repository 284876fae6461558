"""The denoised delivery streams its film (render/output/LOOK.md, "Memory"): ``denoise_film`` reads a window of
frames at a time and appends each denoised frame to its file, and gives the file, the frame-sum check and the
flicker of the in-memory computation it replaced, bit for bit; a memory-mapped film four times a limit denoises
within it."""

from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np
import pytest

from common.memory import PeakMemory
from render.output import files
from render.output.denoise import Guides, TemporalRoughness, _at_raw_light, denoise_film

sys.path.insert(0, str(Path(__file__).parent))
from test_composite_memory import sweeping_pulse_film  # noqa: E402

pyoidn = pytest.importorskip("pyoidn")


def in_memory_denoise_frame(frame: np.ndarray, guides: Guides, quality: str) -> np.ndarray:
    """The frame's denoising as it was written before the film streamed: whole-frame float64 temporaries (and the
    local light step the Denoiser takes, render/output/LOOK.md, *Local light*)."""
    if not np.any(frame):
        return np.zeros_like(frame, dtype=np.float32)
    color = np.ascontiguousarray(np.maximum(frame, 0.0), np.float32)
    out = np.maximum(
        np.asarray(
            pyoidn.denoise(color, guides.albedo, guides.normal, hdr=True, clean_aux=True, quality=quality), np.float64
        ),
        0.0,
    )
    _at_raw_light(out, color)
    raw_sum, out_sum = np.asarray(frame, np.float64).sum(axis=(0, 1)), out.sum(axis=(0, 1))
    scale = np.divide(raw_sum, out_sum, out=np.ones(3), where=out_sum > 0)
    return (out * np.maximum(scale, 0.0)).astype(np.float32)


def in_memory_roughness(stack: np.ndarray) -> float:
    """TemporalRoughness as it was: every frame converted to float64, then the expression with its temporaries."""
    rough, total, recent = 0.0, 0.0, []
    for frame in stack:
        frame = np.asarray(frame, np.float64)
        total += float(np.abs(frame).sum())
        if len(recent) == 2:
            rough += float(np.abs(frame - 2.0 * recent[1] + recent[0]).sum())
        recent = [*recent[-1:], frame]
    return rough / total if total > 0 else 0.0


def noisy_film(count: int, height: int, width: int, seed: int = 7) -> np.ndarray:
    """A noisy wavefront crossing the frame, over sparse fireflies, with an all-black frame first."""
    rng = np.random.default_rng(seed)
    frames = np.zeros((count, height, width, 3), np.float32)
    columns = np.arange(width)
    for k in range(1, count):
        band = np.abs(columns - k * width / count) < width / 6
        lit = band[None, :] & (rng.random((height, width)) < 0.7)
        frames[k][lit] = np.exp(rng.normal(-3.0, 1.5, (int(lit.sum()), 3)))
        fire = rng.random((height, width)) < 0.02
        frames[k][fire] += np.exp(rng.normal(-5.0, 2.0, (int(fire.sum()), 3))).astype(np.float32)
    return frames


def flat_guides(height: int, width: int) -> Guides:
    rng = np.random.default_rng(1)
    albedo = (0.6 + 0.2 * rng.random((height, width, 3))).astype(np.float32)
    normal = np.zeros((height, width, 3), np.float32)
    normal[..., 2] = 1.0
    return Guides(albedo, normal)


def memory_mapped(path, frames: np.ndarray) -> np.ndarray:
    np.save(path, frames)
    return np.load(path, mmap_mode="r")


def test_the_streamed_film_is_the_in_memory_one_bit_for_bit(tmp_path, monkeypatch):
    """Read two frames at a time from a memory-mapped film, the denoised file's bytes are np.save's of the
    in-memory stack, and the largest frame-sum change and both flickers are the in-memory values exactly."""
    stack = noisy_film(9, 40, 56)
    guides = flat_guides(40, 56)
    monkeypatch.setattr(files, "WINDOW_BYTES", 2 * stack[0].nbytes)  # windows of 2, 2, 2, 2, 1 frames
    film = denoise_film(memory_mapped(tmp_path / "frames.npy", stack), guides, tmp_path / "den.npy", "fast", False)

    expected = np.stack([in_memory_denoise_frame(frame, guides, "fast") for frame in stack])
    saved = io.BytesIO()
    np.save(saved, expected)
    assert (tmp_path / "den.npy").read_bytes() == saved.getvalue()
    np.testing.assert_array_equal(film.frames, expected)
    assert film.frames.shape == stack.shape and film.frames.dtype == np.float32
    assert not np.any(expected[0]) and np.any(expected[1:])

    raw, den = stack.astype(np.float64).sum(axis=(1, 2, 3)), expected.astype(np.float64).sum(axis=(1, 2, 3))
    changes = [abs(float(np.sum(d, dtype=np.float64)) / r - 1.0) for d, r in zip(expected, raw, strict=True) if r > 0]
    assert film.largest_frame_sum_change == max(changes)
    assert 0 < film.largest_frame_sum_change < 1e-5  # each frame keeps its raw sum, to float32 rounding
    np.testing.assert_allclose(den, raw, rtol=1e-5)

    assert film.temporal_roughness_raw == in_memory_roughness(stack)
    assert film.temporal_roughness_denoised == in_memory_roughness(expected)
    # The definition over the whole stack at once (another summation order): the same to rounding.
    for frames, value in ((stack, film.temporal_roughness_raw), (expected, film.temporal_roughness_denoised)):
        whole = frames.astype(np.float64)
        second = np.abs(np.diff(whole, n=2, axis=0)).sum() / np.abs(whole).sum()
        assert value == pytest.approx(second, rel=1e-12)
    assert film.temporal_roughness_denoised < film.temporal_roughness_raw


def test_temporal_roughness_of_float64_and_float32_frames_agree():
    """Frames handed in float64 (the computation's own precision) give what their float32 values give, when
    they are float32 values: the flicker does not depend on the precision frames arrive in."""
    stack = noisy_film(6, 12, 16, seed=3)
    single, double = TemporalRoughness(), TemporalRoughness()
    for frame in stack:
        single.add(frame)
        double.add(frame.astype(np.float64))
    assert single.value == double.value == in_memory_roughness(stack)
    assert single.value > 0


LIMIT_MIB = 64  # what the film may add to the fixed part of the pass (the denoiser, a few frames)
FILM_MIB = 4 * LIMIT_MIB


@pytest.mark.slow  # about half a minute on 2 cores
def test_a_memory_mapped_film_four_times_the_limit_denoises_within_it(tmp_path, monkeypatch):
    """Reading frames from a memory map and writing the denoised ones into another left both films' pages in
    the resident size: a film twice over. Now a film four times the limit adds less than the limit to what a
    short film of the same frames needs."""
    height, width = 192, 256
    frames = sweeping_pulse_film(tmp_path / "frames.npy", height, width, FILM_MIB)
    assert frames.nbytes >= 4 * LIMIT_MIB * 2**20
    # The stage's window is 64 MiB, sized for a 1080p film; a film of small frames takes one in proportion.
    monkeypatch.setattr(files, "WINDOW_BYTES", 4 * 2**20)
    guides = flat_guides(height, width)

    denoise_film(frames[:4], guides, tmp_path / "warm.npy", "fast", False)  # the denoiser's own set-up
    with PeakMemory() as fixed:
        denoise_film(frames[:16], guides, tmp_path / "short.npy", "fast", False)
    with PeakMemory() as memory:
        result = denoise_film(frames, guides, tmp_path / "out.npy", "fast", False)
    if not memory.exact:
        pytest.skip("this kernel does not let a process reset its peak resident size (/proc/self/clear_refs)")
    print(f"film {frames.nbytes / 2**20:.0f} MiB: added {memory.added_mib:.0f} MiB, 16 frames {fixed.added_mib:.0f}")
    assert memory.added_mib < fixed.added_mib + LIMIT_MIB
    assert result.frames.shape == frames.shape
    np.testing.assert_allclose(
        np.asarray(result.frames[-1], np.float64).sum(axis=(0, 1)),
        np.asarray(frames[-1], np.float64).sum(axis=(0, 1)),
        rtol=1e-5,
    )
