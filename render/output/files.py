"""The files a render stage leaves behind, read back in one place.

Both renderers' stages write ``steady.npy`` (H, W, 3) and, when transient, ``frames.npy``
(T, H, W, 3) float32. Ours describes its film in ``stats.json`` (``frame_mode``, ``start_opl_m``,
``bin_width_opl_m``, ``temporal_bins``); the reference in ``timing.json`` (``film``: ``start_opl``,
``bin_width_opl``, ``temporal_bins``, ``frame_mode`` "bins"). ``RenderOutputs.read`` gives either as
one typed object, and ``FrameAxis.as_bins`` is the only conversion of gate frames (densities per
metre of OPL at bin centres) to bins (integrals over each bin) in the project.

Beside every ``frames.npy``, both stages write ``frames.json`` (``write_frames``), the one documented
description of the stack: its layout, frame mode, unit, the time axis (frame centres in metres of OPL
and in nanoseconds since first light, i.e. since the window opens) and how to convert it to bins.
"""

from __future__ import annotations

import json
import mmap
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from common.atomic import save_npy_atomic, write_json_atomic
from common.units import NS_PER_M_OPL

OURS_STATS = "stats.json"
REFERENCE_TIMING = "timing.json"
STEADY = "steady.npy"
FRAMES = "frames.npy"
FRAMES_DESCRIPTION = "frames.json"
FRAME_UNITS = {
    "bins": "W m^-2 sr^-1 per bin (the radiance integrated over each bin's OPL)",
    "gate": "W m^-2 sr^-1 per metre of OPL (the radiance density at each bin's centre)",
}


@dataclass(frozen=True)
class FrameAxis:
    """The time axis of a frame stack (mitransient's names), in metres of optical path length."""

    start_opl: float
    bin_width_opl: float
    frame_mode: str = "bins"  # "bins": integrals over each bin; "gate": densities at bin centres; "steady"
    temporal_bins: int = 0

    def centre(self, k: int) -> float:
        """OPL at the centre of frame ``k`` [m]."""
        return self.start_opl + (k + 0.5) * self.bin_width_opl

    def as_bins(self, frames: np.ndarray) -> np.ndarray:
        """Frames as bin integrals: gate densities times the bin width, bins as they are."""
        return frames * self.bin_width_opl if self.frame_mode == "gate" else frames

    def in_bins(self) -> FrameAxis:
        """This axis for frames converted by ``as_bins``."""
        return FrameAxis(self.start_opl, self.bin_width_opl, "bins", self.temporal_bins)

    def describe(self, frame_count: int) -> dict[str, Any]:
        """The time axis of ``frame_count`` frames, for frames.json and EXR metadata."""
        centres = [self.centre(k) for k in range(frame_count)]
        return {
            "frame_mode": self.frame_mode,
            "unit": FRAME_UNITS.get(self.frame_mode, ""),
            "start_opl_m": self.start_opl,
            "bin_width_opl_m": self.bin_width_opl,
            "temporal_bins": frame_count,
            "frame_centres_opl_m": centres,
            "frame_centres_ns_since_first_light": [(c - self.start_opl) * NS_PER_M_OPL for c in centres],
            "to_bins": "multiply by bin_width_opl_m" if self.frame_mode == "gate" else "already bins",
        }


WINDOW_BYTES = 64 * 2**20  # what a pass over a film holds of it at a time


def frame_windows(frames: np.ndarray, window_bytes: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """``(first frame, frames)`` windows of a (T, ...) stack, each a copy of at most ``window_bytes``
    (``WINDOW_BYTES`` by default; at least one frame), so that a pass over a film larger than memory holds a window at a time.

    A memory-mapped stack (``RenderOutputs.frames(memory_mapped=True)``) has its pages dropped from the
    process after each window: mapped pages count in the resident size until unmapped, and a pass over
    the 6 GiB of a full video's film would otherwise show as 6 GiB resident (they stay in the page cache,
    so a second pass reads them back from memory)."""
    frame_bytes = max(1, int(np.prod(frames.shape[1:])) * frames.dtype.itemsize)
    step = max(1, (WINDOW_BYTES if window_bytes is None else window_bytes) // frame_bytes)
    mapping = getattr(frames, "_mmap", None)  # numpy.memmap keeps its mmap.mmap there
    for first in range(0, len(frames), step):
        yield first, np.array(frames[first : first + step])
        if isinstance(mapping, mmap.mmap) and hasattr(mmap, "MADV_DONTNEED"):
            mapping.madvise(mmap.MADV_DONTNEED)


def write_frames(folder: Path, frames: np.ndarray, axis: FrameAxis, **about: Any) -> None:
    """Write ``frames.npy`` (T, H, W, 3) float32 and its description ``frames.json`` (``about`` adds
    entries, e.g. the renderer and whether the camera leg is in the OPL)."""
    save_npy_atomic(folder / FRAMES, frames)
    describe_frames(folder, frames.shape, axis, **about)


def describe_frames(folder: Path, shape: tuple[int, ...], axis: FrameAxis, **about: Any) -> None:
    """Write ``frames.json`` for a ``frames.npy`` already in ``folder`` (a windowed or merged render
    writes its frames to disk as it goes)."""
    description = {
        "file": FRAMES,
        "layout": "(T, H, W, 3) float32, linear RGB, frame k at OPL start_opl_m + (k + 1/2) bin_width_opl_m",
        "shape": list(shape),
        **axis.describe(int(shape[0])),
        **about,
    }
    write_json_atomic(folder / FRAMES_DESCRIPTION, description)


@dataclass
class RenderOutputs:
    """One render stage's folder: ``renderer`` is "ours" (stats.json) or "reference" (timing.json)."""

    folder: Path
    renderer: str
    axis: FrameAxis | None
    stats: dict[str, Any] = field(repr=False)

    @classmethod
    def read(cls, folder: str | Path) -> RenderOutputs:
        """Read the description of ``folder``; arrays load on demand (``steady()``, ``frames()``)."""
        folder = Path(folder)
        axis: FrameAxis | None
        if (folder / OURS_STATS).is_file():
            stats = json.loads((folder / OURS_STATS).read_text(encoding="utf-8"))
            axis = FrameAxis(
                float(stats.get("start_opl_m", 0.0)),
                float(stats.get("bin_width_opl_m", 0.0)),
                str(stats.get("frame_mode", "steady")),
                int(stats.get("temporal_bins", 0)),
            )
            return cls(folder, "ours", axis, stats)
        if (folder / REFERENCE_TIMING).is_file():
            timing = json.loads((folder / REFERENCE_TIMING).read_text(encoding="utf-8"))
            film = timing.get("film") or {}
            axis = None
            if timing.get("transient"):
                axis = FrameAxis(
                    float(film.get("start_opl", 0.0)),
                    float(film.get("bin_width_opl", 0.0)),
                    "bins",
                    int(film.get("temporal_bins", 0)),
                )
            return cls(folder, "reference", axis, timing)
        raise FileNotFoundError(
            f"{folder}: neither {OURS_STATS} (our render) nor {REFERENCE_TIMING} (the reference) is there; "
            "run the render or reference stage first"
        )

    def _array(self, name: str, memory_mapped: bool = False) -> np.ndarray | None:
        path = self.folder / name
        if not path.is_file():
            return None
        return np.load(path, allow_pickle=False, mmap_mode="r" if memory_mapped else None)

    def steady(self) -> np.ndarray | None:
        """The steady image (H, W, 3), or None when the stage wrote none."""
        return self._array(STEADY)

    def frames(self, memory_mapped: bool = False) -> np.ndarray | None:
        """The frames (T, H, W, 3) float32 as written (gate or bins), or None; ``memory_mapped`` reads them
        from disk as they are used (a poster or video film larger than memory)."""
        return self._array(FRAMES, memory_mapped)

    def frames_as_bins(self) -> np.ndarray | None:
        """The frames as bin integrals, comparable between renderers."""
        frames = self.frames()
        if frames is None or self.axis is None:
            return frames
        return self.axis.as_bins(frames)


__all__ = [
    "FRAMES",
    "WINDOW_BYTES",
    "FRAMES_DESCRIPTION",
    "FRAME_UNITS",
    "OURS_STATS",
    "REFERENCE_TIMING",
    "STEADY",
    "FrameAxis",
    "RenderOutputs",
    "describe_frames",
    "frame_windows",
    "write_frames",
]
