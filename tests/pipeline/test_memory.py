"""PeakMemory measures one piece of work's peak, not the process's lifetime peak, so the memory column
of the comparison differs between renderers run one after the other in one process."""

from __future__ import annotations

import numpy as np

from pipeline.memory import PeakMemory


def test_each_block_gets_its_own_peak():
    with PeakMemory() as big:
        block = np.ones(200 * 2**20 // 8)  # 200 MiB, touched
        del block
    with PeakMemory() as small:
        block = np.ones(20 * 2**20 // 8)  # 20 MiB
        del block
    assert big.added_mib >= 190
    if small.exact:  # the peak was reset: the earlier 200 MiB does not show
        assert 15 <= small.added_mib <= 60
        assert small.peak_mib < big.peak_mib - 120
    record = small.record()
    assert set(record) == {"peak_memory_mib", "peak_memory_added_mib", "peak_memory_exact"}
