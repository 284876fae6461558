"""PeakMemory measures one piece of work's peak, not the process's lifetime peak, so the memory column
of the comparison differs between renderers run one after the other in one process."""

from __future__ import annotations

import mmap

from common.memory import PeakMemory


def touch(mib: int) -> None:
    """Make ``mib`` MiB resident and free them again (fresh pages, whatever the allocator holds)."""
    block = mmap.mmap(-1, mib * 2**20)
    for offset in range(0, mib * 2**20, 4096):
        block[offset] = 1
    block.close()


def test_each_block_gets_its_own_peak():
    with PeakMemory() as big:
        touch(200)
    with PeakMemory() as small:
        touch(20)
    assert big.added_mib >= 190
    if small.exact:  # the peak was reset: the earlier 200 MiB does not show
        assert 15 <= small.added_mib <= 60
        assert small.peak_mib < big.peak_mib - 120
    record = small.record()
    assert set(record) == {"peak_memory_mib", "peak_memory_added_mib", "peak_memory_exact"}
