"""paroct.memory: the peak resident memory of a call, on Linux."""

import numpy as np
import pytest

from paroct.memory import peak_resident, start_peak_count


def test_peak_counts_memory_touched_after_the_restart_and_forgets_it_at_the_next():
    start = start_peak_count()
    if start is None:
        pytest.skip("the peak cannot be restarted here (/proc/self/clear_refs)")
    block = np.ones((64 << 20) // 8)  # 64 MiB, every page written
    assert peak_resident() - start >= 60 << 20
    del block
    start = start_peak_count()
    assert peak_resident() - start < 16 << 20
