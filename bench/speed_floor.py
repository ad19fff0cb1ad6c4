"""How far paroct is from a tets/s target against a peer, model by model, and what no pass avoids.

    python bench/speed_floor.py RESULTS.json [...] [--peer tetgen] [--factor 100] [--repeat 7]

RESULTS: bench/compare.py --json output holding paroct's and the peer's rows.  For every
model and size both meshed, prints:
- budget: the time paroct may take for ``factor`` x the peer's tets/s with the tets it made,
  paroct tets / (factor x peer tets/s);
- needs: paroct's time over the budget, the speed-up the target asks on that model;
- floor: what every meshing pass pays per surface, whatever the mesh: reading and welding the
  file (load_surface), the crossings of the seven lattice row directions with the surface
  and the lattice cells the surface meets, both at the requested size (fastest of
  ``repeat``, kernels warm).  A model whose floor exceeds its budget cannot reach the target
  without new algorithms for those passes;
- fresh and kept: the mesh call after the heap is returned to the system, as compare.py's
  children return it before their timed call (so that their peak memory is the call's), and
  with the heap kept from the call before, as in a process that meshes again; faults: the
  call's minor page faults after the return (first touches of fresh memory).  Their
  difference is what fresh pages cost the call;
- kernels: the time inside paroct's numba kernels (dispatch included) of the fastest kept
  call, every kernel called from Python timed; the rest of the call is the Python and numpy
  between them.  A model whose kernels exceed its budget cannot reach the target however
  little runs between them.
Last, per size, the median of needs, what the models that need least ask when more than
half of them reach the target (which takes the median over the models there), and the
median over all models of the kernels' time against the budget.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from timing import fastest

ROOT = Path(__file__).resolve().parent.parent


def surface_floor(path: Path, size: float, repeat: int) -> tuple[float, float, float]:
    """Seconds of (load, seven row directions, surface cells) at size, fastest of repeat."""
    from paroct import rays
    from paroct.frame import EDGE_DIRECTIONS, fat_frame
    from paroct.octree import surface_cells
    from paroct.surface import load_surface

    load = fastest(lambda: load_surface(path), repeat)
    surface = load_surface(path)
    frame = fat_frame(surface.bbox_min, surface.bbox_max, size)
    snapped = rays.snap_surface(frame, surface.vertices)
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    rows = fastest(lambda: [rays.row_crossings(frame, snapped, faces, d) for d in range(EDGE_DIRECTIONS.shape[0])],
                    repeat)
    cells = fastest(lambda: surface_cells(frame, snapped, faces, rays.snap_bits(frame), frame.levels), repeat)
    return load, rows, cells


def heap_cost(path: Path, size: float, repeat: int) -> tuple[float, float, int]:
    """Seconds of the mesh call at size after the heap is returned (compare._memory_baseline)
    and with it kept, fastest of repeat each, and the fewest minor page faults of the first."""
    import resource

    import paroct
    from compare import _memory_baseline

    def call(fresh: bool) -> tuple[float, int]:
        if fresh:
            _memory_baseline()
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        t = time.perf_counter()
        paroct.mesh(path, size=size)
        return time.perf_counter() - t, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults

    call(False)
    fresh = [call(True) for _ in range(repeat)]
    kept = [call(False)[0] for _ in range(repeat)]
    return min(s for s, _ in fresh), min(kept), min(f for _, f in fresh)


def kernel_seconds(path: Path, size: float, repeat: int) -> tuple[float, float]:
    """(seconds, seconds inside numba kernels) of the fastest of repeat mesh calls at size,
    heap kept: every numba dispatcher that paroct's modules hold is timed while they run (a
    kernel called from another kernel is inside its caller's time), then put back.  One call
    runs first, unwrapped, so that no kernel compiles while its callees' names are wrappers."""
    import importlib
    import pkgutil

    import numba

    import paroct

    paroct.mesh(path, size=size)
    spent = [0.0]

    def timed(kernel):
        def call(*args, **kwargs):
            t = time.perf_counter()
            try:
                return kernel(*args, **kwargs)
            finally:
                spent[0] += time.perf_counter() - t
        return call

    wrapped, held = {}, []
    for info in pkgutil.iter_modules(paroct.__path__):
        if info.name == "__main__":
            continue
        module = importlib.import_module(f"paroct.{info.name}")
        for name, obj in list(vars(module).items()):
            if isinstance(obj, numba.core.registry.CPUDispatcher):
                held.append((module, name, obj))
                setattr(module, name, wrapped.setdefault(id(obj), timed(obj)))
    try:
        best = None
        for _ in range(repeat):
            spent[0] = 0.0
            t = time.perf_counter()
            paroct.mesh(path, size=size)
            call = (time.perf_counter() - t, spent[0])
            best = call if best is None or call < best else best
        return best
    finally:
        for module, name, obj in held:
            setattr(module, name, obj)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="+", help="bench/compare.py --json files")
    ap.add_argument("--folder", default=str(ROOT.parent / "shared" / "data" / "corpus"))
    ap.add_argument("--peer", default="tetgen")
    ap.add_argument("--factor", type=float, default=100.0)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    rows = []
    for name in args.results:
        try:
            rows += json.loads(Path(name).read_text())
        except (OSError, ValueError) as err:
            print(f"{name}: {err}", file=sys.stderr)
            return 2
    ok = {(r["mesher"], r["model"], r["divisions"]): r for r in rows if r["status"] == "ok"}
    cases = [(m, d) for (mesher, m, d) in ok if mesher == "paroct" and (args.peer, m, d) in ok]
    if not cases:
        print(f"no model that paroct and {args.peer} both meshed in {', '.join(args.results)}", file=sys.stderr)
        return 2
    missing = sorted({m for m, _ in cases if next(Path(args.folder).glob(f"{m}.*"), None) is None})
    if missing:
        print(f"not in {args.folder}: {', '.join(missing)} (--folder: where the models are)", file=sys.stderr)
        return 2
    sys.path.insert(0, str(ROOT / "bench"))
    from compare import warm_up_paroct

    warm_up_paroct()
    print(f"{'size':>5s} {'model':12s} {'paroct ms':>9s} {'budget ms':>9s} {'needs':>6s} {'floor ms':>8s} "
          f"{'load':>6s} {'7 rows':>6s} {'cells':>6s} {'floor/budget':>12s} {'fresh ms':>8s} {'kept ms':>7s} "
          f"{'faults':>7s} {'kernels ms':>10s} {'kernels/budget':>14s}")
    needs, kernel_needs = {}, {}
    for model, div in sorted(cases, key=lambda c: (c[1], c[0])):
        ours, peer = ok[("paroct", model, div)], ok[(args.peer, model, div)]
        budget = ours["tets"] / (args.factor * peer["tets_per_s"])
        path = next(Path(args.folder).glob(f"{model}.*"))
        load, rays_s, cells = surface_floor(path, ours["size"], args.repeat)
        floor = load + rays_s + cells
        fresh, kept, faults = heap_cost(path, ours["size"], args.repeat)
        _, kernels = kernel_seconds(path, ours["size"], args.repeat)
        needs.setdefault(div, []).append(ours["seconds"] / budget)
        kernel_needs.setdefault(div, []).append(kernels / budget)
        print(f"/{div:<4g} {model:12s} {1e3 * ours['seconds']:9.1f} {1e3 * budget:9.1f} {needs[div][-1]:6.2f} "
              f"{1e3 * floor:8.1f} {1e3 * load:6.1f} {1e3 * rays_s:6.1f} {1e3 * cells:6.1f} {floor / budget:12.2f} "
              f"{1e3 * fresh:8.1f} {1e3 * kept:7.1f} {faults:7d} {1e3 * kernels:10.1f} {kernels / budget:14.2f}",
              flush=True)
    for div, values in needs.items():
        half = len(values) // 2 + 1  # more than half of the models
        print(f"/{div:g}: median needs {statistics.median(values):.2f} x; the {half} cheapest of {len(values)} "
              f"need up to {sorted(values)[half - 1]:.2f} x; the kernels alone, a median over all "
              f"{len(values)} of {statistics.median(kernel_needs[div]):.2f} x of the budget")
    return 0


if __name__ == "__main__":
    sys.exit(main())
