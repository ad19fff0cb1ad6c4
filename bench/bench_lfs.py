"""What sizing from the surface (mesh(curvature=N), mesh(layers=K)) buys and costs, per model.

    python bench/bench_lfs.py [FOLDER] [--divisions 40] [--curvature 12] [--layers 2] [--repeat 3]

For every surface of FOLDER (default: the corpus) and size, meshes it plainly, with
curvature=N, and with layers=K, and prints for each: tets, the time of mesh() (fastest of
repeat, kernels warm) and of its sizing stage (finding where the surface asks), the band's
deepest level below size (thin walls' refinement included), the tets that level would cost over the whole boundary
(mesher.estimate_tets, an upper bound: 1.5-1.9 x the tets made, session 20), and the
benchmark's measures (paroct.check.mesh_metrics): volume error, Hausdorff distance /
diagonal, smallest and largest dihedral angle.  Last, per option, the medians over the models
of the tets and Hausdorff distance against the plain mesh's.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

import paroct
from paroct.check import mesh_metrics
from paroct.mesher import estimate_tets
from paroct.sizing import size_field
from timing import CORPUS, fastest, surface_files

ROOT = Path(__file__).resolve().parent.parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default=str(CORPUS))
    ap.add_argument("--divisions", type=float, nargs="+", default=[40])
    ap.add_argument("--curvature", type=float, default=12.0)
    ap.add_argument("--layers", type=float, default=2.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    models = surface_files(args.folder)
    options = {"plain": {}, f"curvature {args.curvature:g}": {"curvature": args.curvature},
               f"layers {args.layers:g}": {"layers": args.layers}}
    paroct.mesh(ROOT / "data" / "angle_block.stl", divisions=10, curvature=12, layers=2)  # compile or load the kernels
    print(f"{'model':12s} {'div':>4s} {'option':>13s} {'tets':>9s} {'mesh ms':>8s} {'sizing ms':>9s} {'deepest':>7s} "
          f"{'whole band':>10s} {'vol err %':>9s} {'hausdorff':>9s} {'dihedral':>13s}")
    for divisions in args.divisions:
        tets_ratio, hausdorff_ratio = {name: [] for name in options}, {name: [] for name in options}
        for path in models:
            plain = None
            for name, kw in options.items():
                result = paroct.mesh(path, divisions=divisions, **kw)
                seconds = fastest(lambda: paroct.mesh(path, divisions=divisions, **kw), args.repeat)
                metrics = mesh_metrics(result.mesh.points, result.mesh.tets, result.surface)
                size = result.report.requested_size
                deepest = round(math.log2(size / result.report.size))  # the band's finest level, below size
                whole = estimate_tets(result.surface, size_field(size / 2**deepest)) if deepest > 0 else result.report.n_tets
                sizing = result.report.stage_seconds.get("sizing", 0.0)
                print(f"{path.stem:12s} {divisions:4g} {name:>13s} {result.report.n_tets:9d} {1e3 * seconds:8.1f} "
                      f"{1e3 * sizing:9.1f} {deepest:7d} {whole:10d} {100 * metrics['volume_error']:+9.3f} "
                      f"{metrics['hausdorff']:9.4f} {metrics['min_dihedral']:6.2f}{metrics['max_dihedral']:7.1f}")
                if plain is None:
                    plain = (result.report.n_tets, metrics["hausdorff"])
                tets_ratio[name].append(result.report.n_tets / plain[0])
                if plain[1]:
                    hausdorff_ratio[name].append(metrics["hausdorff"] / plain[1])
        for name in options:
            if name != "plain":
                print(f"diag/{divisions:g} {name}: median tets / plain {statistics.median(tets_ratio[name]):.2f}, "
                      f"Hausdorff / plain {statistics.median(hausdorff_ratio[name]):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
