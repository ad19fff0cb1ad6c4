"""Graded against uniform meshes on every model (issue 3's acceptance figures).

    python bench/bench_grading.py [FOLDER] [--divisions 80 160] [--max-factor 8]

For each model and size: graded tets (default max_size), uniform tets (max_size = size,
the same finest band and boundary), their ratio, the graded growth from the coarser to the
finer size, the leaf levels, the fraction of exactly-fat tets, the octree time per million
leaves and the dihedral range of the tets the boundary does not touch.  Medians at the end.
Thin-feature refinement is off here, so both meshes have the boundary of the requested size
(bench_mesh.py shows the default, refined meshes).
"""

from __future__ import annotations

import argparse
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
    ap.add_argument("--divisions", type=float, nargs=2, default=[80, 160])
    ap.add_argument("--max-factor", type=int, default=8, help="max_size / size")
    args = ap.parse_args(argv)
    files = sorted(Path(args.folder).glob("*.stl"))
    if not files:
        print(f"no surfaces in {args.folder}", file=sys.stderr)
        return 2
    paroct.mesh(ROOT / "data" / "xyz_cube.stl", divisions=10)  # compile or load the kernels
    print(f"{'model':12s} {'div':>4s} {'graded':>9s} {'uniform':>9s} {'ratio':>5s} {'growth':>6s} {'levels':>7s} "
          f"{'fat%':>5s} {'oct s/Mleaf':>11s} {'int.dih':>13s} {'dihedral':>13s} {'volerr%':>7s} {'sec':>6s}")
    ratios, growths = [], []
    for f in files:
        surface = load_surface(f)
        previous = None
        for div in args.divisions:
            size = surface.diagonal / div
            try:
                t = time.perf_counter()
                graded = paroct.mesh(surface, size=size, max_size=args.max_factor * size, thin_features=False).report
                sec = time.perf_counter() - t
                uniform = paroct.mesh(surface, size=size, max_size=size, thin_features=False).report
            except ParoctError as exc:  # e.g. no tets: a solid thinner than the size everywhere
                print(f"{f.stem:12s} {div:4.0f} error: {exc}")
                previous = None
                continue
            ratio = graded.n_tets / uniform.n_tets
            growth = graded.n_tets / previous if previous else float("nan")
            previous = graded.n_tets
            if div == max(args.divisions):
                ratios.append(ratio)
                growths.append(growth)
            per_leaf = graded.stage_seconds["octree"] / max(graded.n_leaves, 1) * 1e6
            print(f"{f.stem:12s} {div:4.0f} {graded.n_tets:9d} {uniform.n_tets:9d} {ratio:5.2f} {growth:6.2f} "
                  f"{','.join(map(str, graded.leaf_levels)):>7s} {100 * graded.fat_fraction:5.1f} {per_leaf:11.2f} "
                  f"{graded.interior_min_dihedral:6.2f}-{graded.interior_max_dihedral:6.2f} "
                  f"{graded.min_dihedral:6.2f}-{graded.max_dihedral:6.2f} {100 * graded.volume_error:7.2f} {sec:6.2f}")
            sys.stdout.flush()
    if ratios:
        print(f"\nat diag/{max(args.divisions):.0f}: median graded/uniform {np.nanmedian(ratios):.3f} (target <= 0.65), "
              f"median growth from diag/{min(args.divisions):.0f} {np.nanmedian(growths):.2f} (target <= 5, uniform 8)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
