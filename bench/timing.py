"""Timing shared by the bench scripts (run as scripts, they find it beside them)."""

from __future__ import annotations

import time
from typing import Callable


def fastest(call: Callable[[], object], repeat: int) -> float:
    """Seconds of the fastest of ``repeat`` calls (on a shared machine single runs vary by 10-20 %)."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - t)
    return best
