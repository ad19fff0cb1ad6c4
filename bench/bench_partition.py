"""Meshing in Morton ranges against the one-process pass (paroct.partition, session 44).

    python bench/bench_partition.py [FOLDER] [--divisions 40 80] [--parts 1 4 16] [--repeat 3]

For each model and size, the one pass at the size (``mesh(..., thin_features=False)``) and
``mesh_in_ranges`` with each number of ranges: tets, seconds (fastest of --repeat), and
whether the meshes are the same (points and tets up to numbering: SAME, else DIFF; a pass
that mends by other warps or refines nothing differs where mending moved warps, MENDS).
Then the band alone: ``finest_band`` over the whole surface against
``finest_band_in_ranges`` in each number of key ranges (seconds, fastest of --repeat; SAME
when every array is equal, bit for bit, else DIFF).
The ranges run one after another here: the figure is the cost of splitting (halo, band
lookups, merge) against one process, not a parallel speed-up.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import CORPUS, fastest, surface_files  # noqa: E402

import paroct  # noqa: E402
from paroct.check import canonical_form  # noqa: E402
from paroct.errors import ParoctError  # noqa: E402
from paroct.frame import fat_frame  # noqa: E402
from paroct.mesher import MeshReport, checked_x_rows, finest_band  # noqa: E402
from paroct.partition import finest_band_in_ranges, mesh_in_ranges  # noqa: E402


def canonical(result) -> tuple[np.ndarray, np.ndarray]:
    return canonical_form(result.mesh.points, result.mesh.tets)


def same_band(a, b) -> bool:
    """Whether two finest_band results hold equal arrays (cut fractions bit for bit)."""
    x, y = a.stuffing, b.stuffing
    arrays = [(a.surface_keys, b.surface_keys), (a.keys, b.keys), (x.coords, y.coords), (x.inside, y.inside),
              (x.targets, y.targets), (x.cuts.starts, y.cuts.starts), (x.cuts.ends, y.cuts.ends),
              (x.cuts.directions, y.cuts.directions), (x.cuts.fracs.view(np.int64), y.cuts.fracs.view(np.int64)),
              (x.cuts.points.view(np.int64), y.cuts.points.view(np.int64)), (x.cuts.faces, y.cuts.faces),
              *zip(x.cuts.table, y.cuts.table)]
    return all(p.shape == q.shape and np.array_equal(p, q) for p, q in arrays)


def band_row(surface, size: float, parts: list[int], repeat: int) -> str:
    """Seconds of the band over the whole surface and in each number of ranges, and SAME/DIFF."""
    frame = fat_frame(surface.bbox_min, surface.bbox_max, size)
    snapped, faces, crossings = checked_x_rows(surface, frame)

    def whole():
        return finest_band(frame, snapped, faces, dict(crossings), MeshReport(size, frame.levels))

    def ranged(k):
        return finest_band_in_ranges(frame, snapped, faces, k, MeshReport(size, frame.levels))

    want = whole()
    verdicts = ["SAME" if same_band(ranged(k), want) else "DIFF" for k in parts]
    seconds = [fastest(whole, repeat)] + [fastest(lambda: ranged(k), repeat) for k in parts]
    return " ".join(f"{s:11.4f}" for s in seconds) + "  " + ",".join(verdicts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default=str(CORPUS))
    ap.add_argument("--divisions", type=float, nargs="+", default=[40, 80])
    ap.add_argument("--parts", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    models = surface_files(args.folder)
    data = Path(__file__).resolve().parent.parent / "data"
    mesh_in_ranges(data / "bunny.stl", divisions=10, n_parts=2)  # compile or load the kernels
    print(f"{'model':12s} {'div':>4s} {'tets':>9s} {'one pass s':>10s} "
          + " ".join(f"{f'{k} ranges s':>11s}" for k in args.parts) + "  same  "
          + f"{'band s':>11s} " + " ".join(f"{f'band/{k} s':>11s}" for k in args.parts) + "  same")
    for path in models:
        surface = paroct.load_surface(path)
        diagonal = float(np.linalg.norm(surface.bbox_max - surface.bbox_min))
        for divisions in args.divisions:
            size = diagonal / divisions
            try:
                whole = paroct.mesh(surface, size, thin_features=False)
            except ParoctError as exc:
                print(f"{path.stem:12s} {divisions:4g} refused: {str(exc)[:70]}")
                continue
            one = fastest(lambda: paroct.mesh(surface, size, thin_features=False), args.repeat)
            want = canonical(whole)
            seconds, verdicts = [], []
            for k in args.parts:
                ranged = mesh_in_ranges(surface, size, n_parts=k, thin_features=False)
                seconds.append(fastest(lambda: mesh_in_ranges(surface, size, n_parts=k, thin_features=False), args.repeat))
                got = canonical(ranged)
                same = got[0].shape == want[0].shape and np.array_equal(got[0], want[0]) and \
                    got[1].shape == want[1].shape and np.array_equal(got[1], want[1])
                verdicts.append("SAME" if same else ("MENDS" if "warps" in whole.report.stage_seconds else "DIFF"))
            print(f"{path.stem:12s} {divisions:4g} {len(whole.mesh.tets):9d} {one:10.3f} "
                  + " ".join(f"{s:11.3f}" for s in seconds) + "  " + ",".join(verdicts) + "  "
                  + band_row(surface, size, args.parts, args.repeat), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
