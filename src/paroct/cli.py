"""The ``paroct`` command: mesh a closed surface, check a tet mesh, print the paper's table.

Exit codes: 0 success; 1 ``check`` found problems; 2 a user error (bad input or options),
printed as one line ``paroct: error: ...``; 130 interrupted.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import sys
import time
import warnings
from pathlib import Path
from typing import Sequence

import numpy as np

from . import __version__
from .boundary import DEFAULT_FEATURE_ANGLE, checked_feature_angle
from .errors import ParoctError

#: --patches given without an angle: the input's named groups where it has them (not a
#: string: argparse would convert it with the option's type).
_INPUT_GROUPS = object()
#: Named patches listed one a line in the summary, at most.
_LISTED_PATCHES = 20

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class _UsageError(Exception):
    """An argparse complaint, turned into the one-line error."""


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        # Values such as -1e-3 and -inf are numbers, not options (argparse's own pattern takes
        # only -12 and -1.5), so that a negative size is refused as a size, not as a syntax error.
        self._negative_number_matcher = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$",
                                                   re.IGNORECASE)

    def error(self, message: str):  # argparse would print the usage and exit; we print one line
        raise _UsageError(message)


def _err(message: str) -> None:
    if _status is not None:
        _status.clear()
    print(f"paroct: {message}", file=sys.stderr, flush=True)


class StatusLine:
    """What a long run is doing, on one terminal line that is rewritten in place: nothing for
    the first SHOW_AFTER seconds (short runs print nothing), then the last stage that ended
    and the time so far.  Called with a stage's name as mesh()'s progress; clear() erases the
    line before other output."""

    SHOW_AFTER = 1.0

    def __init__(self, stream, clock=time.perf_counter):
        self.stream, self.clock, self.start, self.shown = stream, clock, clock(), False

    def __call__(self, stage: str) -> None:
        self.show(f"{stage} done")

    def show(self, what: str) -> None:
        elapsed = self.clock() - self.start
        if elapsed >= self.SHOW_AFTER:
            self.stream.write(f"\r\x1b[Kparoct: {what} ({elapsed:.1f} s)")
            self.stream.flush()
            self.shown = True

    def clear(self) -> None:
        if self.shown:
            self.stream.write("\r\x1b[K")
            self.stream.flush()
            self.shown = False


#: The status line of the run in progress, if stderr is a terminal (_err clears it first).
_status: StatusLine | None = None


@contextlib.contextmanager
def _terminal_status(enabled: bool):
    """A StatusLine on stderr while the block runs, if enabled and stderr is a terminal
    (else None); erased when the block ends, also by an error."""
    global _status
    status = None
    if enabled and sys.stderr.isatty() and os.environ.get("TERM") != "dumb":
        status = StatusLine(sys.stderr)
    _status = status
    try:
        yield status
    finally:
        if status is not None:
            status.clear()
        _status = None


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    _err(f"warning: {_one_line(message)}")


def _one_line(text: object) -> str:
    return "; ".join(part.strip() for part in str(text).splitlines() if part.strip()) or "unknown error"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``paroct`` command (subcommands mesh, check, info, paper-table)."""
    parser = _Parser(prog="paroct", description="Tetrahedral meshes of closed solids from Todd's fat (BCC) triangulation.")
    parser.add_argument("--version", action="version", version=f"paroct {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    m = sub.add_parser("mesh", help="fill a closed surface with tets", description="Fill the solid bounded by SURFACE "
                       "(STL, OBJ, OFF, PLY, Gmsh MSH) with fat-lattice tets and write them to OUT.")
    m.add_argument("surface", metavar="SURFACE", help="closed surface file: .stl, .obj, .off, .ply or .msh (a Gmsh surface mesh)")
    m.add_argument("-o", "--output", metavar="OUT",
                   help="output mesh; format by extension (.vtu, .msh, .mesh, .inp, .vtk, ...); "
                        "default: SURFACE's name with .vtu in the current folder")
    size = m.add_mutually_exclusive_group()
    size.add_argument("--size", type=float, metavar="H", help="finest long edge (used along the boundary), model units")
    size.add_argument("--divisions", type=float, metavar="N", help="size = bounding-box diagonal / N (default 40)")
    grading = m.add_mutually_exclusive_group()
    grading.add_argument("--max-size", type=float, metavar="H",
                         help="largest long edge inside, rounded down to size * 2^k (default 8 x size)")
    grading.add_argument("--uniform", action="store_true", help="one size everywhere (max size = size)")
    m.add_argument("--min-size", type=float, metavar="H",
                   help="smallest boundary size that thin walls and gaps, --curvature and --layers may ask for "
                        "(default size / 16)")
    m.add_argument("--curvature", type=float, metavar="N",
                   help="N elements per full turn of the surface: the boundary refined by halves of size to long "
                        "edges of at most 2 pi r / N where it bends with radius r (creases of the triangulation and "
                        "noise finer than the elements ask nothing)")
    m.add_argument("--layers", type=float, metavar="K",
                   help="K elements across every wall thinner than K x size: the boundary refined by halves of size "
                        "to long edges of at most the wall's thickness / K")
    m.add_argument("--keep-size", action="store_true",
                   help="do not refine for thin walls and gaps (only warn when the mesh loses them)")
    m.add_argument("--refine-box", type=float, nargs=7, action="append", default=[],
                   metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1", "H"),
                   help="long edge at most H in the box [X0,X1]x[Y0,Y1]x[Z0,Z1] (repeatable)")
    m.add_argument("--refine-sphere", type=float, nargs=5, action="append", default=[],
                   metavar=("X", "Y", "Z", "R", "H"), help="long edge at most H within R of (X, Y, Z) (repeatable)")
    m.add_argument("--refine-patch", nargs=2, action="append", default=[], metavar=("NAME", "H"),
                   help="long edge at most H on the boundary patch NAME: one of the input's named groups, or "
                        f"patch_1, patch_2, ... of the surface split at {DEFAULT_FEATURE_ANGLE:g} degrees (as --patches "
                        "writes them; paroct info lists them) (repeatable)")
    m.add_argument("--patches", type=float, nargs="?", const=_INPUT_GROUPS, metavar="ANGLE",
                   help="also write the boundary triangles, tagged by surface patch: the input's named groups (the "
                        "solids of an ASCII STL, an OBJ's g groups, a Gmsh file's physical surfaces) if it has them, "
                        "else the surface split at edges "
                        f"sharper than {DEFAULT_FEATURE_ANGLE:g} degrees; with ANGLE, split at ANGLE degrees whatever "
                        "the groups.  Gmsh physical groups in .msh, surfaces and node sets in .inp, references in "
                        ".mesh, cell data boundary_patch elsewhere")
    m.add_argument("--sharp-edges", type=float, nargs="?", const=_INPUT_GROUPS, metavar="ANGLE",
                   help="move the boundary vertices beside sharp edges and corners onto them, as far as the tets "
                        "around each keep dihedral angles in [15, 150] degrees; the edges are the borders of the "
                        "patches --patches would write (the input's named groups, else the surface split at "
                        f"{DEFAULT_FEATURE_ANGLE:g} degrees; with ANGLE, split at ANGLE degrees)")
    m.add_argument("--max-memory", type=float, metavar="GIB",
                   help="refuse sizes needing more than this many GiB (default: the available memory)")
    m.add_argument("--threads", type=int, metavar="N",
                   help="threads to mesh with (default: every CPU); the mesh is the same with any number")
    talk = m.add_mutually_exclusive_group()
    talk.add_argument("-v", "--verbose", action="store_true", help="report each stage as it ends, stage times and peak memory")
    talk.add_argument("-q", "--quiet", action="store_true", help="no summary (warnings and errors still go to stderr)")
    m.set_defaults(run=_run_mesh)

    c = sub.add_parser("check", help="check a tet mesh", description="Check a tet mesh: inverted tets, conformity, "
                       "boundary topology, quality; with --against, volume and Hausdorff distance to the surface. "
                       "Exit code 1 if the mesh has problems.")
    c.add_argument("mesh", metavar="MESH", help="tet mesh file (.vtu, .msh, .mesh, .inp, .vtk, ...)")
    c.add_argument("--against", metavar="SURFACE", help="the closed surface the mesh should fill")
    c.set_defaults(run=_run_check)

    i = sub.add_parser("info", help="describe a surface before meshing it",
                       description="Describe the solid bounded by SURFACE: its shells, genus, volume and box, the "
                       "named groups it holds (the patches --patches writes), its patches and corners at a feature "
                       "angle, the tets and memory one pass at the size would take (an upper estimate), the "
                       "walls and gaps thinner than twice the size, and where --curvature and --layers would refine.")
    i.add_argument("surface", metavar="SURFACE", help="closed surface file: .stl, .obj, .off, .ply or .msh (a Gmsh surface mesh)")
    sized = i.add_mutually_exclusive_group()
    sized.add_argument("--size", type=float, metavar="H", help="finest long edge, as for mesh")
    sized.add_argument("--divisions", type=float, metavar="N", help="size = bounding-box diagonal / N (default 40)")
    i.add_argument("--feature-angle", type=float, default=DEFAULT_FEATURE_ANGLE, metavar="ANGLE",
                   help=f"split the surface into patches at edges sharper than ANGLE degrees (default {DEFAULT_FEATURE_ANGLE:g})")
    i.add_argument("--curvature", type=float, metavar="N", help="also say where mesh --curvature N would refine, and "
                   "the tets it would take at most")
    i.add_argument("--layers", type=float, metavar="K", help="also say where mesh --layers K would refine, and the "
                   "tets it would take at most")
    i.add_argument("--refine-patch", nargs=2, action="append", default=[], metavar=("NAME", "H"),
                   help="also say what mesh --refine-patch NAME H would refine (repeatable)")
    i.add_argument("--min-size", type=float, metavar="H", help="as for mesh (default size / 16)")
    i.set_defaults(run=_run_info)

    p = sub.add_parser("paper-table", help="recompute the seed paper's Table 1, with errata",
                       description="Recompute the seed paper's Table 1 and list its errata.")
    p.set_defaults(run=_run_paper_table)
    return parser


def console_main() -> int:
    """The ``paroct`` program (and ``python -m paroct``): main() in a process of its own, whose
    OpenMP threads sleep when idle unless the environment says otherwise (OMP_WAIT_POLICY).
    Spinning, as they do by default, two runs side by side on 2 cores took 720 ms a call
    each on bunny at diag/80 (24 alone): each run's waiting threads held the cores the other's
    needed.  Asleep, 37-39 ms each; alone, 7 % slower than spinning, a fraction of the
    program's start.  Set here, before numba first starts its threads; the library leaves
    its host process's settings alone (README: several runs at once)."""
    let_idle_threads_sleep()
    return main()


def let_idle_threads_sleep() -> None:
    """Ask OpenMP to let idle threads sleep (OMP_WAIT_POLICY=PASSIVE) unless the environment
    already sets the policy or GOMP_SPINCOUNT; effective only before numba first starts its
    threads.  For processes sharing the cores: the program, and the tests' xdist workers."""
    if "GOMP_SPINCOUNT" not in os.environ:
        os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``paroct`` command with ``argv`` (default: sys.argv[1:]); returns the exit code."""
    parser = build_parser()
    try:
        with warnings.catch_warnings():
            # meshio's readers trip numpy overflow/division warnings on valid files (e.g. ASCII STL);
            # any other Python warning is shown as one line.
            warnings.filterwarnings("ignore", category=RuntimeWarning, module=r"meshio(\.|$)")
            warnings.showwarning = _show_warning
            args = parser.parse_args(None if argv is None else [os.fspath(a) if isinstance(a, os.PathLike) else a
                                                                 for a in argv])
            if args.command is None:
                raise _UsageError("choose a command: mesh, check, info or paper-table (see paroct --help)")
            return args.run(args)
    except (_UsageError, ParoctError) as exc:
        _err(f"error: {_one_line(exc)}")
        return EXIT_USAGE
    except KeyboardInterrupt:
        _err("interrupted")
        return EXIT_INTERRUPTED
    except SystemExit as exc:  # --help and --version
        return exc.code if isinstance(exc.code, int) else (EXIT_OK if exc.code is None else EXIT_USAGE)


def _run_mesh(args: argparse.Namespace) -> int:
    from .io import checked_output

    source = Path(args.surface)
    if args.output == "":
        raise ParoctError("-o '': give a file name (or leave -o out for the surface's name with .vtu)")
    out = Path(args.output) if args.output else Path.cwd() / (source.stem + ".vtu")
    # Refuse a bad output or feature angle before spending the meshing time.
    checked_output(out, boundary=args.patches is not None)
    for angle in (args.patches, args.sharp_edges):
        if angle is not None and angle is not _INPUT_GROUPS:
            checked_feature_angle(angle)
    patch_sizes = _sizing_options(args)
    max_memory = None
    if args.max_memory is not None:
        if not (math.isfinite(args.max_memory * 2**30) and args.max_memory > 0):  # 1e300 GiB: inf bytes
            raise ParoctError(f"--max-memory {args.max_memory}: must be a positive number of GiB")
        max_memory = int(args.max_memory * 2**30)

    with _threads(args.threads):
        return _mesh_and_write(args, source, out, patch_sizes, max_memory)


@contextlib.contextmanager
def _threads(n: int | None):
    """Run the block with numba's thread count at n (None: as it is), restored after: main()
    may be called in a process that goes on (the tests)."""
    import numba

    if n is None:
        yield
        return
    most = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
    if not 1 <= n <= most:
        raise ParoctError(f"--threads {n}: must be from 1 to {most}, the CPUs numba starts threads for "
                          "(the environment variable NUMBA_NUM_THREADS sets that)")
    before = numba.get_num_threads()
    numba.set_num_threads(n)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def _mesh_and_write(args: argparse.Namespace, source: Path, out: Path, patch_sizes, max_memory) -> int:
    from .io import write_mesh
    from .memory import peak_resident, start_peak_count
    from .mesher import mesh, resolve_size
    from .sizing import Box, Sphere
    from .surface import load_surface

    def progress(stage: str) -> None:
        _err(f"{stage} done")

    if not args.quiet and not _kernels_cached():
        _err("compiling the numba kernels on this first run (2 to 3 minutes on 2 cores; cached afterwards)")
    memory_start = start_peak_count() if args.verbose else None
    t0 = time.perf_counter()
    regions: list[Box | Sphere] = [Box(lo=tuple(b[:3]), hi=tuple(b[3:6]), size=b[6]) for b in args.refine_box]
    regions += [Sphere(center=tuple(b[:3]), radius=b[3], size=b[4]) for b in args.refine_sphere]
    with _terminal_status(not (args.quiet or args.verbose)) as status:
        surface = load_surface(source)
        t_loaded = time.perf_counter()
        max_size = resolve_size(surface, args.size, args.divisions) if args.uniform else args.max_size
        result = mesh(surface, args.size, divisions=args.divisions, max_size=max_size, regions=regions,
                      curvature=args.curvature, layers=args.layers, patch_sizes=patch_sizes,
                      thin_features=not args.keep_size, min_size=args.min_size,
                      max_memory=max_memory, progress=progress if args.verbose else status)
        if args.sharp_edges is not None:
            if status is not None:
                status.show("moving the boundary onto sharp edges")
            result = result.with_sharp_edges(None if args.sharp_edges is _INPUT_GROUPS else args.sharp_edges)
        if args.patches is not None and status is not None:
            status.show("splitting the boundary into patches")
        boundary = None if args.patches is None else result.boundary_patches(
            None if args.patches is _INPUT_GROUPS else args.patches)
        t1 = time.perf_counter()
        if status is not None:
            status.show(f"writing {out}")
        write_mesh(out, result.mesh.points, result.mesh.tets, boundary=boundary)
        t2 = time.perf_counter()
    peak = peak_resident() if memory_start is not None else None
    used = None if peak is None or memory_start is None else max(peak - memory_start, 0)
    report = result.report
    for warning in report.warnings:
        _err(f"warning: {_one_line(warning)}")
    if not args.quiet:
        print(format_mesh_summary(report, out, mesh_seconds=t1 - t0, write_seconds=t2 - t1, verbose=args.verbose,
                                  load_seconds=t_loaded - t0,
                                  peak_bytes=used, boundary=boundary))
    return EXIT_OK


def format_mesh_summary(report, out: Path | str, mesh_seconds: float, write_seconds: float, verbose: bool = False,
                        load_seconds: float | None = None, peak_bytes: int | None = None, boundary=None) -> str:
    """Printable summary of a mesher.MeshReport: counts, quality, volume, topology, times (seconds).

    load_seconds: time spent loading the surface before mesh() was called, added to the
    report's "load" stage (which only times what mesh() itself did).  peak_bytes: peak
    resident memory of loading, meshing and writing above the process's before (verbose
    only; None: not measured).  boundary: the BoundaryPatches written, if any (their
    time counts as meshing)."""
    err = report.volume_error
    err_text = "n/a" if math.isnan(err) else f"{100 * err:+.2f}%"
    lines = [
        f"wrote {out}: {report.n_tets} tets, {report.n_vertices} vertices",
        f"size {report.size:.4g} .. {report.size * 2 ** max(report.leaf_levels, default=0):.4g} "
        f"({len(report.leaf_levels)} leaf levels), {100 * report.fat_fraction:.1f}% exactly fat tets",
        f"dihedral angles {report.min_dihedral:.2f} .. {report.max_dihedral:.2f} deg, min 3r/R {report.min_radius_ratio:.4f}",
        f"volume {report.mesh_volume:.6g}, solid {report.solid_volume:.6g} ({err_text})",
        f"boundary {report.boundary_components} components, genus {report.boundary_genus}"
        f"{'' if report.boundary_manifold else ', NOT manifold'}; "
        f"input {report.input_components} components, genus {report.input_genus}",
    ]
    if boundary is not None:
        empty = boundary.n_patches - np.unique(boundary.patches).size
        how = ("the input's named groups" if boundary.feature_angle is None
               else f"feature angle {boundary.feature_angle:g} deg")
        lines.append(f"boundary {len(boundary.faces)} triangles in {boundary.n_patches} patches ({how})"
                     f"{f', {empty} of them too small for the size' if empty else ''}")
        if boundary.feature_angle is None:
            counts = np.bincount(boundary.patches, minlength=boundary.n_patches + 1)[1:]
            lines += [f"  patch {p} {name!r}: {n} triangles"
                      for p, (name, n) in enumerate(zip(boundary.names[:_LISTED_PATCHES], counts), start=1)]
            if boundary.n_patches > _LISTED_PATCHES:
                lines.append(f"  ... and {boundary.n_patches - _LISTED_PATCHES} more")
    lines += [f"note: {note}" for note in report.notes]
    if verbose:
        lines.append(f"unresolved cuts {report.unresolved_cuts}, repaired tets {report.repaired_tets}, "
                     f"{report.n_leaves} leaves, frame depth {report.levels}")
        lines.append(f"tets the boundary does not touch: dihedral {report.interior_min_dihedral:.2f} .. "
                     f"{report.interior_max_dihedral:.2f} deg")
        stages = dict(report.stage_seconds)
        stages["load"] = stages.get("load", 0.0) + (load_seconds or 0.0)
        lines += [f"  {stage:<10} {seconds:8.3f} s" for stage, seconds in stages.items()]
        lines.append(f"  {'write':<10} {write_seconds:8.3f} s")
        if peak_bytes is not None:
            # The kernels a process loads on first use count too: about 60 MiB, which small meshes show.
            lines.append(f"peak memory {peak_bytes / 2**20:.1f} MiB above the start, "
                         f"{peak_bytes / max(report.n_tets, 1):.0f} bytes per tet (kernels loaded included)")
    lines.append(f"time {mesh_seconds + write_seconds:.3f} s")
    return "\n".join(lines)


def _kernels_cached() -> bool:
    """Whether numba's on-disk cache holds the stuffing kernels (the last stage to compile)."""
    import os

    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    folder = Path(cache_dir) if cache_dir else Path(__file__).resolve().parent / "__pycache__"
    return folder.is_dir() and any(folder.rglob("stuffing*.nbi"))


def _sizing_options(args: argparse.Namespace) -> list[tuple[str, float]]:
    """Check --curvature and --layers (mesh and info share them) before any work, and return
    the (name, size) pairs of the --refine-patch NAME H options; ParoctError for a value that
    is not a positive number."""
    from .sizing import positive_number

    for name, value in (("--curvature", args.curvature), ("--layers", args.layers)):
        if value is not None:
            positive_number(name, value)
    pairs = []
    for name, text in args.refine_patch:
        try:
            pairs.append((name, positive_number(f"--refine-patch {name}", float(text))))
        except ValueError:
            raise ParoctError(f"--refine-patch {name} {text}: the size must be a number") from None
    return pairs


def _run_info(args: argparse.Namespace) -> int:
    from .boundary import surface_patches
    from .mesher import BYTES_PER_TET, estimate_tets, resolve_size
    from .sharp import feature_curves
    from .sizing import positive_number, size_field
    from .surface import load_surface

    patch_sizes = _sizing_options(args)
    if args.min_size is not None:
        positive_number("--min-size", args.min_size)
    surface = load_surface(args.surface)
    size = resolve_size(surface, args.size, args.divisions)
    lo, hi = surface.bbox_min, surface.bbox_max
    shells = "1 shell" if surface.components == 1 else f"{surface.components} shells"
    lines = [f"{args.surface}: {len(surface.faces)} triangles, {len(surface.vertices)} vertices, {shells}, "
             f"genus {surface.genus}",
             f"volume {surface.volume:.6g}, area {surface.area:.6g}",
             f"box ({lo[0]:.6g}, {lo[1]:.6g}, {lo[2]:.6g}) .. ({hi[0]:.6g}, {hi[1]:.6g}, {hi[2]:.6g}), "
             f"diagonal {surface.diagonal:.6g}"]
    if surface.face_groups is None:
        lines.append("named groups: none (paroct mesh --patches splits at the feature angle)")
    else:
        counts = np.bincount(surface.face_groups, minlength=len(surface.group_names))
        lines.append(f"named groups: {len(surface.group_names)} (paroct mesh --patches writes them as the patches)")
        lines += [f"  {g} {name!r}: {n} triangles" for g, (name, n) in
                  enumerate(zip(surface.group_names[:_LISTED_PATCHES], counts), start=1)]
        if len(surface.group_names) > _LISTED_PATCHES:
            lines.append(f"  ... and {len(surface.group_names) - _LISTED_PATCHES} more")
    labels = surface_patches(surface, args.feature_angle)
    curves = feature_curves(surface, labels)
    lines.append(f"at {args.feature_angle:g} degrees: {int(labels.max(initial=0))} patches, {len(curves.segments)} "
                 f"edges between them, {len(curves.corners)} corners")
    if surface.face_groups is None:
        lines += _patch_lines(surface, labels)
    tets = estimate_tets(surface, size_field(size))
    lines.append(f"size {size:.6g} (diagonal / {surface.diagonal / size:.4g}): one pass at this size makes at most "
                 f"about {tets:.3g} tets in {tets * BYTES_PER_TET / 2**30:.3g} GiB (graded, max_size 8 x size)")
    lines.append(_thin_places(surface, size))
    if args.curvature is not None or args.layers is not None or patch_sizes:
        lines.append(_feature_sizing(surface, size, args, patch_sizes))
    print("\n".join(lines))
    return EXIT_OK


def _feature_sizing(surface, size: float, args: argparse.Namespace, patch_sizes: list) -> str:
    """Where mesh's --curvature, --layers and --refine-patch (args, patch_sizes) would refine
    the boundary, and the tets a pass with them would make at most (mesher._local_tets: about
    3-7 x a first pass near thin walls)."""
    from .frame import fat_frame
    from .mesher import BYTES_PER_TET, DEFAULT_MIN_SIZE_DIVISOR, _asked_levels, _feature_asks, _local_tets
    from .sizing import size_field

    field = size_field(size, curvature=args.curvature, layers=args.layers, patch_sizes=patch_sizes)
    floor = size / DEFAULT_MIN_SIZE_DIVISOR if args.min_size is None else min(args.min_size, size)
    asks, notes = _feature_asks(surface, field, floor)
    options = " ".join([f"--{name} {value:g}" for name, value in (("curvature", args.curvature),
                                                                   ("layers", args.layers)) if value is not None]
                       + [f"--refine-patch {name} {value:g}" for name, value in patch_sizes])
    said = "".join(f"\n  {note}" for note in notes)
    if asks.empty:
        return f"{options}: nothing finer than size asked{said}"
    deepest = int(asks.depth.max())
    wanted = _asked_levels(fat_frame(surface.bbox_min, surface.bbox_max, size), deepest, asks)
    tets = _local_tets(surface, field, wanted)
    return (f"{options}: the boundary refined to {size / 2**deepest:.4g} at most where {asks.why}, in "
            f"{wanted.keys.size} cells of size; one pass makes at most about {tets:.3g} tets in "
            f"{tets * BYTES_PER_TET / 2**30:.3g} GiB{said}")


def _patch_lines(surface, labels: np.ndarray) -> list[str]:
    """One line per patch (up to _LISTED_PATCHES, largest first): its name as --patches and
    --refine-patch know it, triangles, area and area-weighted centre."""
    tris = surface.vertices[surface.faces]
    area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    n = int(labels.max(initial=0))
    counts = np.bincount(labels, minlength=n + 1)[1:]
    areas = np.bincount(labels, area, minlength=n + 1)[1:]
    centres = np.stack([np.bincount(labels, area * tris[:, :, k].mean(axis=1), minlength=n + 1)[1:] for k in range(3)],
                       axis=1) / np.maximum(areas, np.finfo(float).tiny)[:, None]
    order = np.argsort(-areas, kind="stable")[:_LISTED_PATCHES]
    lines = [f"  patch_{k + 1}: {counts[k]} triangles, area {areas[k]:.4g}, centre ({centres[k, 0]:.4g}, "
             f"{centres[k, 1]:.4g}, {centres[k, 2]:.4g})" for k in order]
    if n > _LISTED_PATCHES:
        lines.append(f"  ... and {n - _LISTED_PATCHES} more (the largest are listed)")
    return lines


def _thin_places(surface, size: float) -> str:
    """The thinnest walls and gaps under 2 x size that the lattice rows at size find with their
    two sides facing squarely (those mesh() refines near, when the mesh at size loses them)."""
    from .frame import fat_frame
    from .mesher import THIN_FACING, checked_x_rows, surface_thin_features

    frame = fat_frame(surface.bbox_min, surface.bbox_max, size)
    features = surface_thin_features(surface, frame, *checked_x_rows(surface, frame))  # refused as mesh refuses
    found, _ = features.facing_below(THIN_FACING).thinnest_below(2 * size)
    if not found:
        return f"no wall or gap thinner than 2 x size = {2 * size:.4g} found along the lattice rows"
    return (f"thinner than 2 x size = {2 * size:.4g}: thinnest {', thinnest '.join(found)}; if a pass at this size "
            "loses them, paroct mesh refines near them, at more tets than the estimate above")


def _run_check(args: argparse.Namespace) -> int:
    from .check import check_mesh
    from .io import read_mesh
    from .surface import load_surface

    with _terminal_status(True) as status:
        points, tets = read_mesh(args.mesh)
        surface = load_surface(args.against) if args.against else None
        if status is not None:
            status.show(f"checking {len(tets)} tets")
        report = check_mesh(points, tets, surface)
    print(report.format())
    return EXIT_OK if report.ok else EXIT_CHECK_FAILED


def _run_paper_table(args: argparse.Namespace) -> int:
    from .paper import format_paper_table

    print(format_paper_table())
    return EXIT_OK
