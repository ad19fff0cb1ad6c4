"""What moving the boundary onto sharp edges (MeshResult.with_sharp_edges) buys and costs, per model.

    python bench/bench_sharp.py [FOLDER] [--divisions 40 80] [--feature-angle 40] [--repeat 3]

For every surface of FOLDER (default: the corpus) and size, meshes it, then prints the
vertices tried and moved, the time of with_sharp_edges and of boundary_patches (the tagging
it starts with, and what --patches writes; fastest of repeat, kernels warm) against mesh()'s,
and the benchmark's measures (paroct.check.mesh_metrics) before and after:
volume error, Hausdorff distance / diagonal, smallest and largest dihedral angle.  Last, per
size, the medians of the volume error's and the Hausdorff distance's ratio after / before.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import paroct
from paroct.check import mesh_metrics
from timing import CORPUS, fastest, surface_files

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default=str(CORPUS))
    ap.add_argument("--divisions", type=float, nargs="+", default=[40, 80])
    ap.add_argument("--feature-angle", type=float, default=None,
                    help="split the surface at this angle (default: named groups, else 40 degrees)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    models = surface_files(args.folder)
    warm = paroct.mesh(ROOT / "data" / "angle_block.stl", divisions=10)  # compile or load the kernels
    warm.with_sharp_edges(), warm.boundary_patches()
    print(f"{'model':12s} {'div':>4s} {'tets':>9s} {'moved':>11s} {'mesh ms':>8s} {'sharp ms':>8s} {'tag ms':>7s} "
          f"{'vol err %':>17s} {'hausdorff/diag':>17s} {'min dihedral':>13s} {'max dihedral':>13s}")
    for divisions in args.divisions:
        volume_ratios, hausdorff_ratios = [], []
        for path in models:
            result = paroct.mesh(path, divisions=divisions)
            mesh_seconds = fastest(lambda: paroct.mesh(path, divisions=divisions), args.repeat)
            sharp = result.with_sharp_edges(args.feature_angle)
            seconds = fastest(lambda: result.with_sharp_edges(args.feature_angle), args.repeat)
            tagging = fastest(lambda: result.boundary_patches(args.feature_angle), args.repeat)
            before = mesh_metrics(result.mesh.points, result.mesh.tets, result.surface)
            after = mesh_metrics(sharp.mesh.points, sharp.mesh.tets, result.surface)
            moved = sharp.report.notes[-1].split(" boundary vertices")[0].removeprefix("sharp edges: ")
            print(f"{path.stem:12s} {divisions:4g} {len(result.mesh.tets):9d} {moved:>11s} {1e3 * mesh_seconds:8.1f} "
                  f"{1e3 * seconds:8.1f} {1e3 * tagging:7.1f} {100 * before['volume_error']:+8.3f}{100 * after['volume_error']:+9.3f} "
                  f"{before['hausdorff']:8.4f}{after['hausdorff']:9.4f} {before['min_dihedral']:6.2f}{after['min_dihedral']:7.2f} "
                  f"{before['max_dihedral']:6.1f}{after['max_dihedral']:7.1f}")
            if before["volume_error"]:
                volume_ratios.append(abs(after["volume_error"]) / abs(before["volume_error"]))
            if before["hausdorff"]:
                hausdorff_ratios.append(after["hausdorff"] / before["hausdorff"])
        print(f"diag/{divisions:g}: median |volume error| after / before {statistics.median(volume_ratios):.3f}, "
              f"Hausdorff {statistics.median(hausdorff_ratios):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
