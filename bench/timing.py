"""Timing and model lists shared by the bench scripts (run as scripts, they find it beside them)."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable

#: The corpus of real parts beside the project.
CORPUS = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "corpus"


def surface_files(folder: str | Path) -> list[Path]:
    """The surface files of folder (by extension), sorted; exits with a message if none."""
    from paroct.readers import SURFACE_EXTENSIONS

    if not Path(folder).is_dir():
        sys.exit(f"{folder} is not a folder")
    models = sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in SURFACE_EXTENSIONS)
    if not models:
        sys.exit(f"no surfaces in {folder}")
    return models


def fastest(call: Callable[[], object], repeat: int) -> float:
    """Seconds of the fastest of ``repeat`` calls (on a shared machine single runs vary by 10-20 %)."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        call()
        best = min(best, time.perf_counter() - t)
    return best
