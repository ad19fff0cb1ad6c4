"""paroct.memory: the peak resident memory of a call, on Linux."""

import mmap

import numpy as np
import pytest

from paroct.memory import peak_resident, start_peak_count


def test_peak_counts_memory_touched_after_the_restart_and_forgets_it_at_the_next():
    start = start_peak_count()
    if start is None:
        pytest.skip("the peak cannot be restarted here (/proc/self/clear_refs)")
    # A fresh anonymous mapping, every page written: the heap may hold freed memory that is
    # still resident (a numpy array of 64 MiB reused it once after the other tests, and the
    # peak did not move).
    block = mmap.mmap(-1, 64 << 20)
    np.frombuffer(block, dtype=np.uint8)[:] = 1
    assert peak_resident() - start >= 60 << 20
    block.close()
    start = start_peak_count()
    assert peak_resident() - start < 16 << 20
