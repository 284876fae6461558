"""Peak resident memory of one piece of work in this process, so that each renderer's figure is its own.

Linux keeps a process's peak resident size (VmHWM) and lets the process reset it to the current
size by writing 5 to /proc/self/clear_refs. ``PeakMemory`` resets it on entry and reads it on exit:
``peak_mib`` is the process's peak while the work ran (what it needed, libraries and the Python
interpreter included) and ``added_mib`` the part above the size at entry. Where the reset is not
allowed, ``peak_mib`` falls back to the process's lifetime peak and ``exact`` is False.
"""

from __future__ import annotations

import resource
from pathlib import Path
from types import TracebackType

_STATUS = Path("/proc/self/status")
_CLEAR_REFS = Path("/proc/self/clear_refs")


def _status_mib(field: str) -> float | None:
    try:
        for line in _STATUS.read_text().splitlines():
            if line.startswith(field + ":"):
                return float(line.split()[1]) / 1024.0  # kB
    except OSError:
        return None
    return None


class PeakMemory:
    """``with PeakMemory() as memory: work()``, then ``memory.peak_mib`` and ``memory.added_mib``."""

    def __init__(self) -> None:
        self.exact = False
        self.start_mib = 0.0
        self.peak_mib = 0.0

    def __enter__(self) -> PeakMemory:
        try:
            _CLEAR_REFS.write_text("5")
            self.exact = True
        except OSError:
            self.exact = False
        self.start_mib = _status_mib("VmRSS") or 0.0
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        peak = _status_mib("VmHWM") if self.exact else None
        self.peak_mib = peak if peak is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    @property
    def added_mib(self) -> float:
        return max(0.0, self.peak_mib - self.start_mib)

    def record(self) -> dict[str, float | bool]:
        """The figures for a stats or timing file."""
        return {
            "peak_memory_mib": round(self.peak_mib, 1),
            "peak_memory_added_mib": round(self.added_mib, 1),
            "peak_memory_exact": self.exact,
        }
