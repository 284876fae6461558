"""Compositing holds a window of the film, not the film (issue 32): a memory-mapped film four times larger
than the limit set here composites within it, measured as the stage measures itself (common/memory.py).

The limit is on what the film adds beyond the stage's fixed part: the four H.264 encoders' look-ahead and
the libraries, which depend on the frame size and not on the film's length, and which a short film of the
same frames measures."""

from __future__ import annotations

import numpy as np
import pytest

from common.memory import PeakMemory
from pipeline.schema.composite import CompositeConfig
from render.output import files
from render.output.composite import composite_film
from render.output.files import FrameAxis
from render.output.video import probe_mp4

LIMIT_MIB = 64  # what the film may add to the stage's fixed part
FILM_MIB = 4 * LIMIT_MIB


def sweeping_pulse_film(path, height: int, width: int, mib: float) -> np.ndarray:
    """A film of at least ``mib`` MiB written to ``path`` (.npy) and opened memory-mapped: a pulse sweeping over
    a faint noisy floor, frame by frame."""
    count = int(np.ceil(mib * 2**20 / (height * width * 3 * 4)))
    film = np.lib.format.open_memmap(path, mode="w+", dtype=np.float32, shape=(count, height, width, 3))
    rng = np.random.default_rng(0)
    for k in range(count):
        film[k] = 0.01 * rng.random((height, width, 3), dtype=np.float32)
        film[k, 40:56, k * width // count : k * width // count + 4] += 1.0
    film.flush()
    del film
    return np.load(path, mmap_mode="r")


@pytest.mark.slow  # about a minute on 2 cores
def test_a_memory_mapped_film_four_times_the_limit_composites_within_it(tmp_path, monkeypatch):
    height, width = 192, 256
    frames = sweeping_pulse_film(tmp_path / "frames.npy", height, width, FILM_MIB)
    count = frames.shape[0]
    assert frames.nbytes >= 4 * LIMIT_MIB * 2**20
    # The stage's window is 64 MiB, sized for a 1080p film; a film of small frames takes one in proportion.
    monkeypatch.setattr(files, "WINDOW_BYTES", 4 * 2**20)
    cfg = CompositeConfig(video_min_height=64, fps=24, archival_cut=True, light_in_flight=True)
    steady = np.ones((height, width, 3), np.float32)

    def run(film, out):
        axis = FrameAxis(1.0, 0.003, "bins", len(film))
        return composite_film(film, axis, cfg, out, streaks=True, steady=steady, exr_attributes={})[0]

    run(frames[:4], tmp_path / "warm")  # what loads once (encoder, EXR and font libraries) is not the film's
    with PeakMemory() as fixed:
        run(frames[:16], tmp_path / "short")
    with PeakMemory() as memory:
        written = run(frames, tmp_path / "out")
    if not memory.exact:
        pytest.skip("this kernel does not let a process reset its peak resident size (/proc/self/clear_refs)")
    print(f"film {frames.nbytes / 2**20:.0f} MiB: added {memory.added_mib:.0f} MiB, 16 frames {fixed.added_mib:.0f}")
    assert memory.added_mib < fixed.added_mib + LIMIT_MIB
    assert probe_mp4(written["cumulative_video"])["frames"] == count
    assert len(list(written["exr_frames"].glob("*.exr"))) == count
