"""Time paroct's mesh writers against meshio's on one mesh: seconds and megabytes per format.

    python bench/bench_write.py [SURFACE] [--divisions 80] [--repeat 3] [--no-meshio]

SURFACE defaults to the corpus's round_rod (4 M tets at diag/80).  Every format is written
to a temporary folder and read back by meshio, which must give the same points and tets.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import meshio
import numpy as np

import paroct
from paroct.io import output_format, write_mesh
from timing import fastest

ROOT = Path(__file__).resolve().parent.parent
SUFFIXES = [".vtu", ".inp", ".mesh", ".msh", ".vtk"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("surface", nargs="?", default=str(ROOT.parent / "shared" / "data" / "corpus" / "round_rod.stl"))
    ap.add_argument("--divisions", type=float, default=80)
    ap.add_argument("--repeat", type=int, default=3, help="write each format this many times, report the fastest")
    ap.add_argument("--no-meshio", action="store_true", help="skip meshio's own writers (slow: up to 30 s each)")
    args = ap.parse_args(argv)
    if not Path(args.surface).is_file():
        print(f"no such surface: {args.surface}", file=sys.stderr)
        return 2
    result = paroct.mesh(args.surface, divisions=args.divisions)
    points, tets = result.mesh.points, result.mesh.tets
    print(f"{Path(args.surface).name} diag/{args.divisions:g}: {len(tets)} tets, {len(points)} vertices")
    print(f"{'format':8s} {'paroct s':>9s} {'MB':>6s} {'meshio s':>9s} {'MB':>6s}")
    with tempfile.TemporaryDirectory() as folder:
        write_mesh(Path(folder) / "warm.inp", points[:4], tets[:1] * 0)  # compile or load the row kernel
        for suffix in SUFFIXES:
            ours = Path(folder) / f"ours{suffix}"
            t_ours = fastest(lambda: write_mesh(ours, points, tets), args.repeat)
            back = meshio.read(ours, file_format=output_format(ours)[0])
            if not (np.array_equal(back.points, points) and np.array_equal(back.cells[0].data, tets)):
                print(f"{suffix}: read back differs", file=sys.stderr)
                return 1
            row = f"{suffix:8s} {t_ours:9.3f} {ours.stat().st_size / 1e6:6.1f}"
            if not args.no_meshio:
                theirs = Path(folder) / f"theirs{suffix}"
                fmt, options = output_format(theirs)
                mesh = meshio.Mesh(points, [("tetra", tets.astype(np.int64))])
                t_theirs = fastest(lambda: meshio.write(theirs, mesh, file_format=fmt, **options), 1)
                row += f" {t_theirs:9.3f} {theirs.stat().st_size / 1e6:6.1f}"
            print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
