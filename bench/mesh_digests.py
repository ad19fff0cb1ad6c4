"""Digests of paroct's meshes, to check that a change meant to keep them keeps them byte for byte.

    python bench/mesh_digests.py [--folder DIR] [--divisions 40 80 160] [--json OUT] [--against OLD.json]

Meshes every model of the folder (default: the shared corpus) and three generated parts at
each size diagonal / divisions, and prints per mesh the md5 of its points' and tets' bytes
and its tet count.  The generated parts have thin places, so they take the passes after a
losing one at the sizes where the corpus may not: a block with a fin 0.02 thick, a plate
0.04 thick and two slabs 0.03 apart joined by a wall.  --json writes the digests; --against
compares with such a file and exits 1 if a mesh differs from it or is not in it.  A failed
mesh is recorded by its error, so a change in what fails shows too.  Digests compare only
on one machine and environment: numba's code and the last bits of float arithmetic may
differ elsewhere.  Sessions 51-55 checked each speed change this way, with a script in /tmp
that this one replaces (the 45 meshes at diag/40, /80 and /160 take 15 s here).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

from timing import CORPUS, surface_files


def generated_parts() -> dict:
    """{name: manifold3d.Manifold} of the generated parts (see the module docstring)."""
    import manifold3d

    cube = manifold3d.Manifold.cube
    return {
        "fin": cube([1.0, 1.0, 0.5]) + cube([0.8, 0.02, 0.3]).translate([0.1, 0.49, 0.5]),
        "plate": cube([1.0, 1.0, 0.04]),
        "slabs": cube([1.0, 1.0, 0.1]) + cube([1.0, 1.0, 0.1]).translate([0.0, 0.0, 0.13]) + cube([0.1, 1.0, 0.3]),
    }


def digest(source, divisions: float) -> str:
    """'md5 n_tets' of mesh(source, divisions=divisions), or 'error: ...' if it raises."""
    import paroct

    try:
        mesh = paroct.mesh(source, divisions=divisions).mesh
    except Exception as err:  # any error: a change in what fails is a change too
        return f"error: {type(err).__name__}: {err}"[:200]
    return f"{hashlib.md5(mesh.points.tobytes() + mesh.tets.tobytes()).hexdigest()} {mesh.tets.shape[0]}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folder", default=str(CORPUS), help="folder of surface files (default: the shared corpus)")
    ap.add_argument("--divisions", type=float, nargs="+", default=[40.0, 80.0, 160.0])
    ap.add_argument("--json", help="write the digests to this file")
    ap.add_argument("--against", help="a --json file to compare with; exit 1 on a difference")
    args = ap.parse_args(argv)
    old = None
    if args.against:
        try:
            old = json.loads(Path(args.against).read_text())
        except (OSError, ValueError) as err:
            print(f"{args.against}: {err}", file=sys.stderr)
            return 2
    sources = {p.stem: p for p in surface_files(args.folder)} | generated_parts()
    digests, differ = {}, []
    for divisions in args.divisions:
        for name, source in sources.items():
            key = f"{name}/{divisions:g}"
            digests[key] = digest(source, divisions)
            verdict = ""
            if old is not None:
                verdict = "same" if old.get(key) == digests[key] else f"DIFFERS (was {old.get(key, 'missing')})"
                if verdict != "same":
                    differ.append(key)
            print(f"{key:24s} {digests[key]} {verdict}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(digests, indent=0) + "\n")
    if old is not None:
        missing = sorted(set(old) - set(digests))
        print(f"{len(digests) - len(differ)} of {len(digests)} meshes as in {args.against}"
              + (f"; differ: {', '.join(differ)}" if differ else "")
              + (f"; not meshed now: {', '.join(missing)}" if missing else ""))
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
