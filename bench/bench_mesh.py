"""Per-model benchmark of paroct.mesh: tets, time per stage, throughput, quality, accuracy.

    python bench/bench_mesh.py [FOLDER] [--divisions 40 80 160] [--no-hausdorff] [--uniform] [--repeat N]

FOLDER defaults to ../shared/data/corpus.  Numba compilation is excluded: a small warm-up
mesh compiles (or loads from cache) every kernel first.  Prints one row per model and
size, then the throughput at the finest size (whole mesh() call, surface already loaded).
--repeat N times every mesh() call N times and reports the fastest (and its stage times): on a
shared machine single runs vary by 10-20 %.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

import paroct
from paroct.errors import ParoctError
from paroct.surface import load_surface

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default=str(ROOT.parent / "shared" / "data" / "corpus"))
    ap.add_argument("--divisions", type=float, nargs="+", default=[40, 80, 160])
    ap.add_argument("--no-hausdorff", action="store_true", help="skip the (slower) two-sided Hausdorff distance")
    ap.add_argument("--uniform", action="store_true", help="one size everywhere (max_size = size), no thin-feature refinement")
    ap.add_argument("--repeat", type=int, default=1, help="time each mesh() call this many times, report the fastest")
    args = ap.parse_args(argv)
    files = sorted(Path(args.folder).glob("*.stl")) + sorted(Path(args.folder).glob("*.obj")) + sorted(Path(args.folder).glob("*.off"))
    if not files:
        print(f"no surfaces in {args.folder}", file=sys.stderr)
        return 2
    _warm_up()
    check_mesh = None
    if not args.no_hausdorff:
        try:
            from paroct.check import check_mesh
        except ImportError:
            pass

    stages = ["octree", "classify", "emit", "stuff", "warps", "repair", "quality"]
    head = (f"{'model':12s} {'div':>4s} {'tets':>9s} {'verts':>8s} {'sec':>6s} {'Mtet/s':>6s} "
            + " ".join(f"{s[:6]:>6s}" for s in stages)
            + f" {'mindih':>6s} {'maxdih':>6s} {'min3rR':>6s} {'int.dih':>13s} {'lv':>2s} {'fat%':>4s} {'size/req':>8s}"
            + f" {'volerr%':>7s} {'topo':>4s} {'haus/d':>8s} {'check':>5s}  note")
    print(head)
    finest = max(args.divisions)
    rates = []
    for f in files:
        surface = load_surface(f)
        for div in args.divisions:
            try:
                sec, result = min((_timed_mesh(surface, div, args.uniform) for _ in range(max(1, args.repeat))),
                                  key=lambda run: run[0])
            except ParoctError as exc:
                print(f"{f.stem:12s} {div:4.0f} error: {exc}")
                continue
            rep = result.report
            rate = rep.n_tets / sec / 1e6
            if div == finest:
                rates.append(rate)
            haus, valid = float("nan"), "-"
            if check_mesh is not None:
                checked = check_mesh(result.mesh.points, result.mesh.tets, surface)
                haus, valid = checked.hausdorff, "ok" if checked.ok else "BAD"
            note = "warn: " + rep.warnings[0][:60] if rep.warnings else ""
            topo = "same" if (rep.boundary_components, rep.boundary_genus) == (rep.input_components, rep.input_genus) else "DIFF"
            print(f"{f.stem:12s} {div:4.0f} {rep.n_tets:9d} {rep.n_vertices:8d} {sec:6.2f} {rate:6.2f} "
                  + " ".join(f"{rep.stage_seconds.get(s, 0.0):6.3f}" for s in stages)
                  + f" {rep.min_dihedral:6.2f} {rep.max_dihedral:6.2f} {rep.min_radius_ratio:6.3f}"
                  f" {rep.interior_min_dihedral:6.2f}-{rep.interior_max_dihedral:6.2f} {len(rep.leaf_levels):2d}"
                  f" {100 * rep.fat_fraction:4.0f} {rep.size / rep.requested_size:8.4f}"
                  f" {100 * rep.volume_error:7.2f} {topo:>4s} {haus:8.2e} {valid:>5s}  {note}")
            sys.stdout.flush()
    if rates:
        print(f"\nthroughput at diag/{finest:.0f}: median {np.median(rates):.2f} M tets/s, min {min(rates):.2f}, max {max(rates):.2f}"
              f" (whole mesh() call, fastest of {max(1, args.repeat)}, 1 process, numba threads = {paroct_threads()})")
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB")
    return 0


def _timed_mesh(surface, div: float, uniform: bool):
    """(seconds, result) of one mesh() call at size = diagonal / div."""
    t = time.perf_counter()
    if uniform:
        size = surface.diagonal / div
        result = paroct.mesh(surface, size=size, max_size=size, thin_features=False)
    else:
        result = paroct.mesh(surface, divisions=div)
    return time.perf_counter() - t, result


def _warm_up() -> None:
    """Compile (or load from the numba cache) every kernel, including pinch repair and the thin-feature
    diagnosis, which only run on parts that need them: a block with a fin thinner than the size."""
    import manifold3d

    paroct.mesh(ROOT / "data" / "xyz_cube.stl", divisions=10)
    fin = manifold3d.Manifold.cube([1.0, 1.0, 0.5]) + manifold3d.Manifold.cube([1.0, 0.03, 0.5]).translate([0, 0, 0.5])
    paroct.mesh(fin, size=0.1)


def paroct_threads() -> int:
    import numba

    return numba.get_num_threads()


if __name__ == "__main__":
    sys.exit(main())
