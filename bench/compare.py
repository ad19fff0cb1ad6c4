"""paroct against TetGen, fTetWild, Gmsh and Netgen on a folder of closed surfaces.

    python bench/compare.py [FOLDER] [--divisions 40 80] [--meshers paroct tetgen ...]
                            [--models bunny fandisk] [--time-limit 300] [--memory-limit 8]
                            [--repeat 1] [--json results.json] [--markdown tables.md]
    python bench/compare.py --from-json results40.json results80.json [--markdown tables.md]

Peers come from the optional extra: pip install -e ".[bench]".  Each run is a subprocess
of this script (``--child``) with a wall-time limit and an address-space limit; it meshes
once (``--repeat N``: N children, the fastest counts, the same rule for every mesher; the
mesher call alone is timed, reading the surface included; a paroct child first meshes
small parts on every path, so its cached numba kernels are loaded, as in a long-lived
process) and saves the mesh; peak memory is the child's peak RSS during the call above its
RSS before it, the heap returned to the system and the peak reset first.  The parent
measures every mesh with the same function, paroct.check.mesh_metrics, against the input
surface.  Failures (exceptions, time or memory limit, no tets) are rows with their reason,
never dropped.
Peers are set up as a careful user would, for a target long edge ``size`` = diagonal / N:
- paroct: ``paroct.mesh(size=size)`` (graded, thin features refined).
- TetGen: quality switch (radius-edge 1.2, min dihedral 10) and a fixed volume bound (``-a``)
  of a regular tet of edge ``size``.
- fTetWild (pytetwild): ideal edge length ``size``, default envelope (1e-3 of the diagonal).
- Gmsh: the STL merged, surfaces classified (40 degrees), a volume from the surface loop,
  MeshSizeMax = ``size``; Delaunay (Algorithm3D 1) and HXT (10).
- Netgen: STL geometry, maxh = ``size``.
- CGAL (pygalmesh, Mesh_3 on the polyhedral domain with features): cell circumradius and
  surface Delaunay ball radius of a regular tet and triangle of edge ``size`` (sqrt(6)/4 and
  1/sqrt(3) of it), facet distance size / 10, facet angle >= 25, radius-edge ratio <= 2,
  feature edges <= ``size``; default perturb and exude.  pygalmesh has no wheel: it builds
  against the system's CGAL and Eigen (apt-get install libcgal-dev libeigen3-dev, then
  pip install pygalmesh).
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MESHERS = ("paroct", "paroct-sharp", "tetgen", "ftetwild", "gmsh-delaunay", "gmsh-hxt", "netgen", "cgal")


def _regular_tet_volume(edge: float) -> float:
    return edge**3 / (6 * np.sqrt(2))


def run_mesher(name: str, path: Path, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the surface file with one mesher; returns (points (N, 3), tets (M, 4))."""
    if name in ("paroct", "paroct-sharp"):  # paroct-sharp: the boundary moved onto sharp edges after
        import paroct

        result = paroct.mesh(path, size=size)
        if name == "paroct-sharp":
            result = result.with_sharp_edges()
        return result.mesh.points, result.mesh.tets
    from paroct.surface import load_surface

    surface = load_surface(path)
    vertices, faces = surface.vertices, surface.faces.astype(np.int32)
    if name == "tetgen":
        import tetgen

        nodes, elems, *_ = tetgen.TetGen(vertices, faces).tetrahedralize(
            quality=True, minratio=1.2, mindihedral=10.0, fixedvolume=True, maxvolume=_regular_tet_volume(size))
        return nodes, elems
    if name == "ftetwild":
        import pytetwild

        return pytetwild.tetrahedralize(vertices, faces, edge_length_abs=size)
    if name.startswith("gmsh"):
        import gmsh

        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.merge(str(path))
            gmsh.model.mesh.classifySurfaces(40 * np.pi / 180, True, True, np.pi)
            gmsh.model.mesh.createGeometry()
            loop = gmsh.model.geo.addSurfaceLoop([s for _, s in gmsh.model.getEntities(2)])
            gmsh.model.geo.addVolume([loop])
            gmsh.model.geo.synchronize()
            gmsh.option.setNumber("Mesh.MeshSizeMax", size)
            gmsh.option.setNumber("Mesh.Algorithm3D", 1 if name == "gmsh-delaunay" else 10)
            gmsh.model.mesh.generate(3)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            points = coords.reshape(-1, 3)
            index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
            index[tags.astype(np.int64)] = np.arange(len(tags))
            _, node_tags = gmsh.model.mesh.getElementsByType(4)
            return points, index[node_tags.astype(np.int64)].reshape(-1, 4)
        finally:
            gmsh.finalize()
    if name == "netgen":
        from netgen.stl import STLGeometry

        m = STLGeometry(str(path)).GenerateMesh(maxh=size)
        points = np.array([p.p for p in m.Points()])
        tets = np.array([[v.nr - 1 for v in e.vertices] for e in m.Elements3D()], dtype=np.int64)
        return points, tets
    if name == "cgal":
        import pygalmesh

        mesh = pygalmesh.generate_volume_mesh_from_surface_mesh(
            str(path), min_facet_angle=25.0, max_radius_surface_delaunay_ball=size / np.sqrt(3),
            max_facet_distance=size / 10, max_circumradius_edge_ratio=2.0, max_cell_circumradius=size * np.sqrt(6) / 4,
            max_edge_size_at_feature_edges=size, verbose=False, seed=0)
        return mesh.points, mesh.get_cells_type("tetra")
    raise ValueError(f"unknown mesher {name}")


def warm_up_paroct() -> None:
    """Mesh small parts on every path of paroct once: graded, uniform, pinch repair (angle_block
    at diag/35, then moved onto its sharp edges), a thin plate that takes the thin-feature path,
    a block with a thin fin whose rounds near it change the band's level and mend warps (the
    halving tried first keeps bunny and the plate off that path), a slanted rod, whose box
    is so empty that its vertices are numbered through a brick directory (without it,
    fea_part's first call loaded those kernels inside the timed call), and two small cubes at
    opposite corners of their box, whose crossings lie thinly in the box of their rows (the
    row sort's comparison path: without them tray_bottom's timed call loaded its kernel from
    the cache, 6 ms).  Run in a process of its own before all children, it fills the numba
    cache (a fresh checkout has none, and a compile inside a child would count against its
    time limit); run in each paroct child before the timed call, it loads every kernel, as a
    long-lived process has them.  tests/test_kernels.py meshes the same parts to check that
    no kernel compiles twice."""
    import manifold3d

    import paroct

    paroct.mesh(ROOT / "data" / "bunny.stl", divisions=10)
    paroct.mesh(ROOT / "data" / "angle_block.stl", divisions=35).with_sharp_edges()
    paroct.mesh(ROOT / "data" / "bunny.stl", size=0.025, max_size=0.025)
    paroct.mesh(manifold3d.Manifold.cube([1, 1, 0.04]), size=0.2)
    fin = manifold3d.Manifold.cube([0.8, 0.02, 0.3]).translate([0.1, 0.49, 0.5])
    paroct.mesh(manifold3d.Manifold.cube([1.0, 1.0, 0.5]) + fin, size=0.1)
    paroct.mesh(manifold3d.Manifold.cylinder(1.0, 0.05, 0.05, 16).rotate([0, 54.7356, 45]), size=0.02,
                thin_features=False)
    corner = manifold3d.Manifold.cube([0.1, 0.1, 0.1])
    paroct.mesh(corner + corner.translate([0.9, 0.9, 0.9]), size=0.014)


def _memory_baseline() -> tuple[int, bool]:
    """Return the heap to the system and restart the peak-RSS count, so that the peak after
    the call minus this baseline is the memory the call itself needed (imports and warm-up
    excluded, freed heap not reused for free).  Returns (baseline bytes, whether the peak
    was restarted); where it cannot be (not Linux), the baseline is the high-water mark so
    far, and small calls read 0."""
    import ctypes
    import gc

    from paroct.memory import start_peak_count

    gc.collect()
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass
    now = start_peak_count()
    if now is None:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, False
    return now, True


def _child(args) -> int:
    from paroct.memory import peak_resident

    limit = int(args.memory_limit * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    if args.mesher.startswith("paroct"):
        warm_up_paroct()
    baseline, reset = _memory_baseline()
    t = time.perf_counter()
    points, tets = run_mesher(args.mesher, Path(args.model), args.size)
    seconds = time.perf_counter() - t
    peak = (peak_resident() if reset else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024) - baseline
    np.savez(args.out, points=np.asarray(points, dtype=np.float64), tets=np.asarray(tets, dtype=np.int64),
             seconds=seconds, peak=peak)
    return 0


def _warm_paroct() -> None:
    """Fill paroct's numba cache in a process of its own, before every timed child."""
    subprocess.run([sys.executable, __file__, "--warm-up"], check=True, capture_output=True)


def measure(mesher: str, model: Path, size: float, time_limit: float, memory_limit: float, repeat: int = 1) -> dict:
    """``repeat`` runs, each in a child process; the fastest one's time and peak memory, the
    mesh measured; a dict with 'status' 'ok' or the first failure."""
    from paroct.check import mesh_metrics
    from paroct.surface import load_surface

    row = {"mesher": mesher, "model": model.stem, "size": size}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "mesh.npz"
        cmd = [sys.executable, __file__, "--child", "--mesher", mesher, "--model", str(model), "--size", repr(size),
               "--out", str(out), "--memory-limit", str(memory_limit)]
        for _ in range(repeat):
            out.unlink(missing_ok=True)
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, timeout=time_limit)
            except subprocess.TimeoutExpired:
                return {**row, "status": f"timeout after {time_limit:.0f} s"}
            if proc.returncode != 0 or not out.exists():
                lines = [s for s in (proc.stderr or "").strip().splitlines() if s.strip()]
                reason = lines[-1][:120] if lines else f"exit code {proc.returncode}"
                if "MemoryError" in (proc.stderr or "") or "bad_alloc" in (proc.stderr or ""):
                    reason = f"memory limit {memory_limit:g} GiB: {reason}"
                return {**row, "status": f"failed: {reason}"}
            data = np.load(out)
            points, tets = data["points"], data["tets"]
            if tets.shape[0] == 0:
                return {**row, "status": "failed: no tets"}
            if float(data["seconds"]) < row.get("seconds", np.inf):
                row.update(seconds=float(data["seconds"]), peak_bytes=int(data["peak"]))
    row.update(mesh_metrics(points, tets, load_surface(model)))
    row["tets_per_s"] = row["tets"] / row["seconds"]
    row["bytes_per_tet"] = row["peak_bytes"] / row["tets"]
    row["status"] = "ok"
    return row


COLUMNS = [("tets", "{:>9d}"), ("seconds", "{:8.2f}"), ("tets_per_s", "{:10.0f}"), ("bytes_per_tet", "{:7.0f}"),
           ("min_dihedral", "{:6.2f}"), ("p1_dihedral", "{:6.2f}"), ("max_dihedral", "{:6.2f}"),
           ("min_radius_ratio", "{:6.3f}"), ("mean_radius_ratio", "{:6.3f}"), ("frac_radius_ratio_below_0.3", "{:7.4f}"),
           ("inverted", "{:5d}"), ("volume_error", "{:+8.4f}"), ("hausdorff", "{:8.5f}"), ("closed", "{!s:>6}"),
           ("topology_kept", "{!s:>6}")]


def format_row(row: dict) -> str:
    head = f"{row['model']:12s} {row['mesher']:14s}"
    if row["status"] != "ok":
        return f"{head} {row['status']}"
    return head + " " + " ".join(fmt.format(row[key]) for key, fmt in COLUMNS)


def summary(rows: list[dict]) -> list[str]:
    """Per mesher: successes, medians and worst cases."""
    out = [f"{'mesher':14s} {'ok':>5s} {'med tets/s':>11s} {'med B/tet':>9s} {'worst min dih':>13s} {'med p1 dih':>10s} "
           f"{'worst max dih':>13s} {'worst 3r/R':>10s} {'med |vol err|':>13s} {'worst haus':>10s} {'closed':>6s}"]
    for mesher in dict.fromkeys(r["mesher"] for r in rows):
        mine = [r for r in rows if r["mesher"] == mesher]
        ok = [r for r in mine if r["status"] == "ok"]
        if not ok:
            out.append(f"{mesher:14s} {0:>2d}/{len(mine):<2d}")
            continue
        med = lambda k: statistics.median(r[k] for r in ok)  # noqa: E731
        out.append(f"{mesher:14s} {len(ok):>2d}/{len(mine):<2d} {med('tets_per_s'):11.0f} {med('bytes_per_tet'):9.0f} "
                   f"{min(r['min_dihedral'] for r in ok):13.2f} {med('p1_dihedral'):10.2f} "
                   f"{max(r['max_dihedral'] for r in ok):13.2f} {min(r['min_radius_ratio'] for r in ok):10.3f} "
                   f"{statistics.median(abs(r['volume_error']) for r in ok):13.4f} {max(r['hausdorff'] for r in ok):10.5f} "
                   f"{sum(r['closed'] for r in ok):>3d}/{len(ok)}")
    return out


def markdown(rows: list[dict]) -> str:
    """Per-level markdown tables: per mesher medians and worst cases, then the failures."""
    out = []
    for div in dict.fromkeys(r["divisions"] for r in rows):
        level = [r for r in rows if r["divisions"] == div]
        out += [f"### size = diagonal / {div:g}", "",
                "| mesher | ok | median tets/s | median time s | worst min dihedral | median 1st-pct dihedral "
                "| worst max dihedral | worst min 3r/R | median mean 3r/R | median \|volume error\| % "
                "| worst Hausdorff / diag | closed, topology kept |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for mesher in dict.fromkeys(r["mesher"] for r in level):
            mine = [r for r in level if r["mesher"] == mesher]
            ok = [r for r in mine if r["status"] == "ok"]
            if not ok:
                out.append(f"| {mesher} | 0/{len(mine)} |" + " |" * 10)
                continue
            med = lambda k: statistics.median(r[k] for r in ok)  # noqa: E731
            out.append(
                f"| {mesher} | {len(ok)}/{len(mine)} | {med('tets_per_s'):,.0f} | {med('seconds'):.2f} "
                f"| {min(r['min_dihedral'] for r in ok):.2f} | {med('p1_dihedral'):.2f} "
                f"| {max(r['max_dihedral'] for r in ok):.2f} | {min(r['min_radius_ratio'] for r in ok):.3f} "
                f"| {med('mean_radius_ratio'):.3f} | {100 * statistics.median(abs(r['volume_error']) for r in ok):.2f} "
                f"| {max(r['hausdorff'] for r in ok):.4f} | {sum(r['closed'] for r in ok)}, "
                f"{sum(r['topology_kept'] for r in ok)} of {len(ok)} |")
        failed = [r for r in level if r["status"] != "ok"]
        if failed:
            out += ["", "Failures: " + "; ".join(f"{r['mesher']} on {r['model']}: {r['status']}" for r in failed)]
        out += ["", *per_model_ratios(level), ""]
    return "\n".join(out)


def per_model_ratios(level: list[dict], reference: str = "paroct") -> list[str]:
    """Markdown table over the models of one size: the reference mesher's tets, time and
    peak bytes per tet, and against each other mesher that meshed the model, tets/s ratio
    (reference over peer: > 1 means the reference is faster) and bytes-per-tet ratio (peer
    over reference: > 1 means the reference needs less memory per tet); medians last."""
    ok = {(r["mesher"], r["model"]): r for r in level if r["status"] == "ok"}
    peers = [m for m in dict.fromkeys(r["mesher"] for r in level) if m != reference]
    models = [m for m in dict.fromkeys(r["model"] for r in level) if (reference, m) in ok]
    if not peers or not models:
        return []
    head = f"| model | {reference} tets | {reference} s | {reference} B/tet |"
    head += "".join(f" tets/s over {p} | {p} B/tet over {reference} |" for p in peers)
    out = [head, "|---" * (4 + 2 * len(peers)) + "|"]
    speed = {p: [] for p in peers}
    memory = {p: [] for p in peers}
    for model in models:
        ref = ok[(reference, model)]
        line = f"| {model} | {ref['tets']:,} | {ref['seconds']:.3f} | {ref['bytes_per_tet']:.0f} |"
        for p in peers:
            peer = ok.get((p, model))
            if peer is None:
                line += " failed | |"
                continue
            speed[p].append(ref["tets_per_s"] / peer["tets_per_s"])
            line += f" {speed[p][-1]:.1f} |"
            if ref["bytes_per_tet"] > 0 and peer["bytes_per_tet"] > 0:  # 0: not measured (older results)
                memory[p].append(peer["bytes_per_tet"] / ref["bytes_per_tet"])
                line += f" {memory[p][-1]:.1f} |"
            else:
                line += " n/a |"
        out.append(line)
    line = "| median | | | |"
    for p in peers:
        line += f" **{statistics.median(speed[p]):.1f}** |" if speed[p] else " |"
        line += f" **{statistics.median(memory[p]):.1f}** |" if memory[p] else " |"
    return out + [line]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", nargs="?", default=str(ROOT.parent / "shared" / "data" / "corpus"))
    ap.add_argument("--divisions", type=float, nargs="+", default=[40, 80])
    ap.add_argument("--meshers", nargs="+", default=list(MESHERS), choices=MESHERS)
    ap.add_argument("--models", nargs="+", help="model names (file stems) to run; default all")
    ap.add_argument("--time-limit", type=float, default=300.0, help="seconds per run")
    ap.add_argument("--memory-limit", type=float, default=8.0, help="GiB of address space per run")
    ap.add_argument("--repeat", type=int, default=1, help="runs per mesher, model and size; the fastest counts")
    ap.add_argument("--json", help="write all rows to this file")
    ap.add_argument("--markdown", help="write per-level summary tables (markdown) to this file")
    ap.add_argument("--from-json", nargs="+", help="only tabulate rows saved by earlier --json runs")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--warm-up", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--mesher", help=argparse.SUPPRESS)
    ap.add_argument("--model", help=argparse.SUPPRESS)
    ap.add_argument("--size", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        return _child(args)
    if args.warm_up:
        warm_up_paroct()
        return 0
    if args.from_json:
        # A later file's row replaces an earlier one for the same mesher, model and size.
        merged = {(r["mesher"], r["model"], r["divisions"]): r for f in args.from_json for r in json.loads(Path(f).read_text())}
        rows = list(merged.values())
        text = markdown(rows)
        Path(args.markdown).write_text(text) if args.markdown else print(text)
        return 0
    from paroct.surface import load_surface

    files = sorted(Path(args.folder).glob("*.stl"))
    if args.models:
        files = [f for f in files if f.stem in args.models]
    if not files:
        print(f"no surfaces in {args.folder}", file=sys.stderr)
        return 2
    _warm_paroct()
    rows = []
    for div in args.divisions:
        print(f"\n== size = diagonal / {div:g}")
        print(f"{'model':12s} {'mesher':14s} " + " ".join(k[:9] for k, _ in COLUMNS))
        for f in files:
            size = load_surface(f).diagonal / div
            for mesher in args.meshers:
                row = measure(mesher, f, size, args.time_limit, args.memory_limit, args.repeat)
                row["divisions"] = div
                rows.append(row)
                print(format_row(row), flush=True)
                if args.json:  # after every row: a run stopped midway keeps what it measured
                    Path(args.json).write_text(json.dumps(rows, indent=1))
        print()
        print("\n".join(summary([r for r in rows if r["divisions"] == div])))
    if args.markdown:
        Path(args.markdown).write_text(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
