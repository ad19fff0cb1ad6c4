"""paroct on generated solids: random CSG parts and random ribbed plates (session 33).

    python bench/bench_generated.py [--kind csg plates] [--seeds 0 80] [--divisions 40 80] [--curvature N] [--layers K]

Parts the corpus does not have, built by manifold3d from a seed: ``csg``, unions and
differences of 3-9 rotated boxes, spheres and cylinders (slivers down to 1e-6 of the part);
``plates``, rotated plates with ribs 0.01-0.2 thick, through holes, pockets and bosses.  One
line per part and size: tets, seconds, tets/s, dihedral range (OUTSIDE if it leaves
[10.7, 164.8]), volume error, boundary components and genus against the input's, and the
number of warnings; then per kind and size the count of warnings, meshes outside the bound
and failures, and the total time.  Every part should mesh; a warning is paroct saying it
could not keep the solid down to min_size.  --curvature and --layers are passed to mesh()
(session 40: sizing from the surface on parts it was not tuned on).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from manifold3d import Manifold

import paroct
from paroct.errors import ParoctError
from paroct.stuffing import DIHEDRAL_BOUND


def _primitive(rng: np.random.Generator) -> Manifold:
    kind = rng.integers(3)
    s = rng.uniform(0.1, 1.0, 3)
    if kind == 0:
        p = Manifold.cube(s.tolist(), True)
    elif kind == 1:
        p = Manifold.sphere(float(s[0]) / 2, int(rng.integers(8, 48)))
    else:
        p = Manifold.cylinder(float(s[2]), float(s[0]) / 2, float(s[1]) / 2 * rng.integers(0, 2),
                              int(rng.integers(6, 40)), True)
    return p.rotate(rng.uniform(0, 360, 3).tolist()).translate(rng.uniform(-0.6, 0.6, 3).tolist())


def csg_part(seed: int) -> Manifold:
    """Unions and differences of 3-9 random primitives."""
    rng = np.random.default_rng(seed)
    s = _primitive(rng)
    for _ in range(int(rng.integers(2, 9))):
        q = _primitive(rng)
        s = s - q if rng.random() < 0.45 else s + q
    return s


def plate_part(seed: int) -> Manifold:
    """A plate with random ribs, through holes, pockets and bosses, rotated."""
    rng = np.random.default_rng(1000 + seed)
    length, width, thick = rng.uniform(1, 4), rng.uniform(0.5, 3), rng.uniform(0.05, 0.6)
    s = Manifold.cube([length, width, thick])
    for _ in range(int(rng.integers(0, 6))):
        t, h = rng.uniform(0.01, 0.2), rng.uniform(0.05, 1.0)
        if rng.random() < 0.5:
            s += Manifold.cube([length, t, h]).translate([0, rng.uniform(0, width - t), thick])
        else:
            s += Manifold.cube([t, width, h]).translate([rng.uniform(0, length - t), 0, thick])
    for _ in range(int(rng.integers(0, 10))):
        r = rng.uniform(0.01, 0.3)
        s -= Manifold.cylinder(thick * 3 + 2, r, r, int(rng.integers(8, 48))).translate(
            [rng.uniform(0, length), rng.uniform(0, width), -1])
    for _ in range(int(rng.integers(0, 4))):
        a, b = rng.uniform(0.1, length / 2), rng.uniform(0.1, width / 2)
        s -= Manifold.cube([a, b, thick]).translate([rng.uniform(0, length - a), rng.uniform(0, width - b),
                                                      rng.uniform(0.01, 0.9) * thick])
    for _ in range(int(rng.integers(0, 3))):
        r = rng.uniform(0.05, 0.4)
        s += Manifold.cylinder(rng.uniform(0.1, 1.0), r, r, int(rng.integers(12, 64))).translate(
            [rng.uniform(0, length), rng.uniform(0, width), thick])
    return s.rotate(rng.uniform(0, 360, 3).tolist())


KINDS = {"csg": csg_part, "plates": plate_part}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", nargs="+", choices=sorted(KINDS), default=sorted(KINDS))
    ap.add_argument("--seeds", type=int, nargs=2, default=[0, 40], metavar=("FIRST", "END"))
    ap.add_argument("--divisions", type=float, nargs="+", default=[40, 80])
    ap.add_argument("--curvature", type=float, default=None)
    ap.add_argument("--layers", type=float, default=None)
    args = ap.parse_args(argv)
    sizing = {"curvature": args.curvature, "layers": args.layers}
    paroct.mesh(csg_part(1), divisions=10)  # compile or load the kernels
    for kind in args.kind:
        totals = {d: [0, 0, 0, 0.0] for d in args.divisions}  # warned, outside, failed, seconds
        for seed in range(*args.seeds):
            part = KINDS[kind](seed)
            if part.is_empty() or part.volume() < 1e-3:
                continue
            for d in args.divisions:
                t = time.perf_counter()
                try:
                    rep = paroct.mesh(part, divisions=d, **sizing).report
                except ParoctError as exc:
                    totals[d][2] += 1
                    print(f"{kind} {seed:3d} /{d:g}: failed: {exc}", flush=True)
                    continue
                dt = time.perf_counter() - t
                outside = not DIHEDRAL_BOUND[0] <= rep.min_dihedral <= rep.max_dihedral <= DIHEDRAL_BOUND[1]
                totals[d][0] += bool(rep.warnings)
                totals[d][1] += outside
                totals[d][3] += dt
                print(f"{kind} {seed:3d} /{d:g}: {rep.n_tets:9d} tets {dt:7.2f} s {rep.n_tets / dt / 1e6:5.2f} M/s "
                      f"dihedral {rep.min_dihedral:6.2f}-{rep.max_dihedral:6.2f}{' OUTSIDE' if outside else ''} "
                      f"volume {100 * rep.volume_error:+6.2f}% components {rep.boundary_components}/{rep.input_components} "
                      f"genus {rep.boundary_genus}/{rep.input_genus} warnings {len(rep.warnings)}", flush=True)
        for d, (warned, outside, failed, seconds) in totals.items():
            print(f"{kind} /{d:g}: {warned} warned, {outside} outside the bound, {failed} failed, {seconds:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
