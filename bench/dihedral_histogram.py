"""Histogram of all dihedral angles of each mesher's mesh of one part.

    python bench/dihedral_histogram.py [SURFACE] [--divisions 40] [--out docs/benchmarks/dihedral_hist.png]

Needs the ``bench`` extra (peers and matplotlib).  Meshers that fail are left out of the
figure and named on stdout.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from compare import MESHERS, ROOT, run_mesher

from paroct.quality import tet_dihedral_angles
from paroct.surface import load_surface


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("surface", nargs="?", default=str(ROOT.parent / "shared" / "data" / "corpus" / "fandisk.stl"))
    ap.add_argument("--divisions", type=float, default=40)
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks" / "dihedral_hist.png"))
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(args.surface)
    size = load_surface(path).diagonal / args.divisions
    angles = {}
    for name in MESHERS:
        try:
            points, tets = run_mesher(name, path, size)
        except Exception as exc:  # a peer's failure is reported, not fatal
            print(f"{name}: failed: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}")
            continue
        tets = np.asarray(tets, dtype=np.int64)
        a = tet_dihedral_angles(np.asarray(points, dtype=np.float64), tets).ravel()
        if np.median(a) > 90:  # negatively oriented convention: angles come out as 180 - angle
            a = tet_dihedral_angles(np.asarray(points, dtype=np.float64), tets[:, [1, 0, 2, 3]]).ravel()
        angles[name] = a
        print(f"{name}: {len(tets)} tets, dihedral {a.min():.2f} .. {a.max():.2f}")
    fig, axes = plt.subplots(len(angles), 1, figsize=(7, 1.5 * len(angles)), sharex=True)
    for ax, (name, a) in zip(np.atleast_1d(axes), angles.items()):
        ax.hist(a, bins=np.arange(0, 181, 2), color="tab:blue" if name == "paroct" else "tab:gray")
        ax.set_yscale("log")
        ax.set_ylabel(name, rotation=0, ha="right", fontsize=9)
        ax.axvline(a.min(), color="red", lw=0.8)
        ax.axvline(a.max(), color="red", lw=0.8)
        ax.text(0.99, 0.8, f"{a.min():.1f} .. {a.max():.1f} deg", transform=ax.transAxes, ha="right", fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("dihedral angle (degrees); red: extremes")
    fig.suptitle(f"{path.stem} at size = diagonal / {args.divisions:g}", fontsize=10)
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=80)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
