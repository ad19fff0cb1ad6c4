"""The meshing pipeline: surface -> frame -> octree -> classify and cut -> stuff -> report.

Each stage is a pure function over arrays; this module only sequences them, times them
and turns their findings into the report.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, NamedTuple, Sequence

import numba as nb
import numpy as np

from . import rays
from .boundary import DEFAULT_FEATURE_ANGLE, BoundaryPatches, _tagged_boundary, surface_labels, tag_boundary
from .check import chord_volumes, far_from_points, long_triangle_centres
from .errors import ParoctError
from .intersections import crossing_triangles
from .features import ThinFeatures
from .lfs import (FeatureAsks, curvature_asks, function_asks, merged_asks, no_asks, patch_asks, region_asks,
                  surface_pieces, wall_asks)
from .features import thin_features as find_thin_features
from .frame import CUBE_CORNERS, EDGE_DIRECTIONS, LATTICE_TO_SPACE, X_AXIS_DIRECTION, FatFrame, fat_frame, space_point
from .band import (BandLevels, FineSurfaceCells, band_cells, band_levels, kept_leaves, local_leaves, merge_band_levels,
                   no_band_levels, surface_prune)
from .lattice import LeafVertices, graded_tets, number_vertices, vertex_spacing
from .octant import MAX_LEVEL, ancestor_keys, morton_key, morton_keys, octants_in_cells, sorted_lookup, sorted_unique
from .octree import (FaceBuckets, balance, face_buckets, faces_meeting_cells, octant_lattice_anchors, surface_cells,
                     unique_level_keys)
from .quality import OUTSIDE, TetSummary, outlier_flags, summarize
from .repair import remove_pinches
from .sharp import snap_to_features
from .sizing import Region, SizeField, SizeFunction, positive_number, size_field, size_seeds
from .stuffing import (DIHEDRAL_BOUND, CutEdges, cell_cut_edges, collect_cut_edges, mixed_rows, restuff,
                       retarget_warps, stuff, warp_targets)
from .surface import Surface, SurfaceSource, load_surface
from .topology import SurfaceTopology, used_vertices

#: 3r/R of Todd's fat tet, 3 / sqrt(10).
FAT_RADIUS_RATIO = 3 / np.sqrt(10)
#: Default element size as a fraction of the bounding-box diagonal.
DEFAULT_DIVISIONS = 40
#: Peak bytes of a pass per tet that estimate_tets (or, near thin places, _local_tets) counts
#: for it: the memory guard.  Session 43 measured 54-87 on the corpus' one-level passes of
#: 0.4-4 M estimated tets, graded (diag/160) and uniform (diag/120), and 54 on fea_part at
#: diag/1000 (97 M estimated, 61 M made, writing the .msh included), where sessions 2-3 had
#: measured 196-205 and set 250; smaller meshes read more (to 130) but their totals are small.
BYTES_PER_TET = 150
#: Bytes a crossing of a lattice row with the surface takes while FramedSurface.build crosses
#: the x rows of a refined frame (key, fraction, sign and triangle, 21 bytes, in the fill's
#: slots and again sorted, and the row index) ...
CROSSING_BYTES = 64
#: ... of which there are at most the surface's area times this over h**2: lattice rows of one
#: direction per unit area across them (det A = 1/2 a cell, a row step |A e_x| = sqrt(3)/2;
#: the corpus' x rows cross 0.37-0.61 of that at diag/40 and /160).
ROWS_PER_AREA = 3.0**0.5
#: Thickness of the finest band in units of size, for the memory estimate (cells met by the
#: surface plus a ring on each side, times the Freudenthal cell's extent).
BAND_CELLS = 4
#: Graded interiors hold transition leaves: their tets per max_size^3, against the fat lattice's.
TRANSITION_FACTOR = 4
#: Deepest frame allowed: row and cell indices must fit the 21-bit fields of the crossing keys.
MAX_FRAME_LEVELS = MAX_LEVEL - 1


@dataclass(frozen=True)
class TetMesh:
    """A tetrahedral mesh: points (N, 3) float64, tets (M, 4) int32 of positive volume."""

    points: np.ndarray
    tets: np.ndarray

    def __post_init__(self):
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise ValueError(f"points.shape = {self.points.shape}, expected (N, 3)")
        if self.tets.ndim != 2 or self.tets.shape[1] != 4:
            raise ValueError(f"tets.shape = {self.tets.shape}, expected (M, 4)")
        if self.tets.size and (self.tets.min() < 0 or self.tets.max() >= self.points.shape[0]):
            raise ValueError(f"tets index {self.tets.min()}..{self.tets.max()} but len(points) = {self.points.shape[0]}")


@dataclass
class MeshReport:
    """What the mesher did and measured.  Lengths in model units, angles in degrees."""

    size: float
    levels: int
    requested_size: float = float("nan")
    max_size: float = float("nan")
    n_leaves: int = 0
    leaf_levels: tuple = ()
    fat_fraction: float = float("nan")
    interior_min_dihedral: float = float("nan")
    interior_max_dihedral: float = float("nan")
    n_tets: int = 0
    n_vertices: int = 0
    min_dihedral: float = float("nan")
    max_dihedral: float = float("nan")
    min_radius_ratio: float = float("nan")
    mesh_volume: float = 0.0
    solid_volume: float = 0.0
    input_genus: int = 0
    input_components: int = 0
    boundary_genus: int = 0
    boundary_components: int = 0
    boundary_manifold: bool = True
    unresolved_cuts: int = 0
    repaired_tets: int = 0
    bad_tets: int = 0
    missed_vertices: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    missed_faces: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    stage_seconds: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    @property
    def volume_error(self) -> float:
        """(mesh volume - solid volume) / solid volume."""
        return (self.mesh_volume - self.solid_volume) / self.solid_volume if self.solid_volume else float("nan")


@dataclass(frozen=True)
class MeshResult:
    """What mesh() returns: the mesh, the report, and the surface it fills (None when built
    by hand), which boundary_patches tags the mesh's boundary by."""

    mesh: TetMesh
    report: MeshReport
    surface: Surface | None = field(default=None, repr=False, compare=False)
    #: The mesh's boundary triangles (B, 3) int32, outward, as the pinch repair found them, or
    #: None (a result built by hand): boundary_patches starts from them.
    boundary_faces: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: The surface triangle (N,) int32 each mesh point lies on (an index into surface.faces):
    #: the one crossed at its cut point, for the boundary vertices stuffing placed; -1 for
    #: the others (inside, or moved since).  None for a result built by hand.
    #: boundary_patches tags a boundary triangle whose three vertices lie on one patch so.
    point_faces: np.ndarray | None = field(default=None, repr=False, compare=False)

    def boundary_patches(self, feature_angle: float | None = None) -> BoundaryPatches:
        """The mesh's boundary triangles, each tagged with the patch of the surface it lies
        on: the input's named groups if it has them and feature_angle is None, else the
        surface split at edges sharper than ``feature_angle`` degrees (default
        DEFAULT_FEATURE_ANGLE; boundary.boundary_patches)."""
        return _tagged_boundary(self.mesh.points, self.mesh.tets, self._surface(), feature_angle, self.boundary_faces,
                                self.point_faces)

    def _surface(self) -> Surface:
        if self.surface is None:
            raise ParoctError("this result has no surface to take the patches from; call "
                              "paroct.boundary_patches(points, tets, surface) instead")
        return self.surface

    def with_sharp_edges(self, feature_angle: float | None = None) -> MeshResult:
        """A new result whose boundary vertices beside the surface's sharp edges and corners
        are moved onto them, each only as far as the tets around it keep their quality
        (sharp.snap_to_features; reach: one size).  The edges are the borders of the patches
        boundary_patches(feature_angle) tags: the input's named groups, or the surface split
        at feature_angle degrees (default 40).  The report's angles, 3r/R and volume are
        measured again, and a note says how many vertices moved."""
        surface = self._surface()
        labelled = surface_labels(surface, feature_angle)
        tets = np.ascontiguousarray(self.mesh.tets, dtype=np.int64)  # once, for the tagging and the stars
        patches = tag_boundary(self.mesh.points, tets, surface, *labelled, self.boundary_faces, self.point_faces)
        snapped = snap_to_features(self.mesh.points, tets, patches, surface, labelled[0], self.report.size)
        del tets
        report = dataclasses.replace(self.report, warnings=list(self.report.warnings), notes=list(self.report.notes),
                                     stage_seconds=dict(self.report.stage_seconds))
        if self.mesh.tets.shape[0]:
            summary = summarize(snapped.points, self.mesh.tets, np.zeros(snapped.points.shape[0], dtype=np.bool_),
                                FAT_RADIUS_RATIO)
            report.min_dihedral, report.max_dihedral = summary.min_dihedral, summary.max_dihedral
            report.min_radius_ratio, report.mesh_volume = summary.min_radius_ratio, summary.volume
            report.fat_fraction = summary.n_fat / self.mesh.tets.shape[0]
        report.notes.append(f"sharp edges: {snapped.moved.size} of {snapped.tried} boundary vertices within one size of "
                            "an edge or corner between patches moved onto it (or part of the way)")
        point_faces = None
        if self.point_faces is not None:  # a moved vertex lies on a curve, maybe off its triangle
            point_faces = self.point_faces.copy()
            point_faces[snapped.moved] = -1
        return MeshResult(TetMesh(snapped.points, self.mesh.tets), report, self.surface, self.boundary_faces,
                          point_faces)


def estimate_tets(surface: Surface, field: SizeField) -> int:
    """Rough upper estimate of the lattice tets: 12 per h^3 (Freudenthal cells have volume h^3 / 2)
    in a band of BAND_CELLS * size around the surface, and 12 per max_size^3 times
    TRANSITION_FACTOR in the rest of the box, never more than the uniform lattice of the box
    nor than solid_tets at size."""
    h = field.size
    cells = float(np.prod((surface.bbox_max - surface.bbox_min + 2 * h) / h))  # ratios: h^3 can underflow
    uniform = min(12 * cells, solid_tets(surface, h))
    graded = 12 * surface.area / h * BAND_CELLS / h + TRANSITION_FACTOR * 12 * cells / (field.max_size / h)**3
    estimate = min(uniform, graded) if not field.regions and field.function is None else uniform
    return int(min(estimate, 2**62))


def solid_tets(surface: Surface, size: float) -> float:
    """Upper estimate of the tets of a mesh whose finest long edge is size, at least as fine
    everywhere: 12 per size^3 of the solid's volume and 12 per size^2 of its area (the cut
    and stuffed tets of a band about one size thick).  On the corpus at diag/40 and /80 (uniform
    lattice) it is 1.09-2.07 x the tets made; it bounds thin shells, where a band BAND_CELLS
    thick on both sides of every wall counts far more than the solid holds (session 14's
    fuzzed hollow cube: 127 M estimated, 36 M made)."""
    return 12 * surface.volume / size / size / size + 12 * surface.area / size / size


def _available_memory() -> int:
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 8 << 30


class _Stages:
    def __init__(self, report: MeshReport, progress: Callable[[str], None] | None):
        self.report = report
        self.progress = progress
        self._t = time.perf_counter()

    def done(self, name: str) -> None:
        now = time.perf_counter()
        self.report.stage_seconds[name] = self.report.stage_seconds.get(name, 0.0) + now - self._t
        self._t = now
        if self.progress:
            self.progress(name)


def resolve_size(surface: Surface, size: float | None, divisions: float | None) -> float:
    """The finest long edge: ``size`` if given, else the diagonal over ``divisions`` (default 40).
    ParoctError for anything but a positive number, for a size above the part's bounding-box
    diagonal (a mesh of nothing: most likely other units), and for one the octree cannot
    reach (more than 2^MAX_FRAME_LEVELS sizes across the part)."""
    if size is not None:
        h = positive_number("size", size)
    else:
        h = surface.diagonal / positive_number("divisions", DEFAULT_DIVISIONS if divisions is None else divisions)
    if h > surface.diagonal:
        raise ParoctError(f"size = {h:.6g} is larger than the whole part (its bounding-box diagonal is "
                          f"{surface.diagonal:.6g}): check the units, or give --divisions (default {DEFAULT_DIVISIONS})")
    if not h * 2.0**MAX_FRAME_LEVELS >= surface.diagonal:
        raise ParoctError(f"size = {h:.6g} is too small for the part: its bounding-box diagonal {surface.diagonal:.6g} "
                          f"is more than 2^{MAX_FRAME_LEVELS} sizes")
    largest = _largest_coordinate(surface)
    if h < MIN_SIZE_STEPS * np.spacing(largest):
        raise ParoctError(f"size = {h:.6g} is less than {MIN_SIZE_STEPS} steps of float64 ({np.spacing(largest):.3g} each) "
                          f"at the part's coordinates (up to {largest:.6g}): the mesh's points could not be placed; "
                          "move the part near the origin (subtract its centre)")
    return h


#: Smallest element size, in steps of float64 at the part's largest coordinate: points then
#: sit to 1/256 of a size, angles to a fraction of a degree.  A cube of 1e-6 at 1e9 (its
#: size 0.7 steps) made flat tets.
MIN_SIZE_STEPS = 256


def _largest_coordinate(surface: Surface) -> float:
    """The surface's largest coordinate magnitude, where float64's steps are widest."""
    return float(np.abs(np.concatenate([surface.bbox_min, surface.bbox_max])).max())


def mesh(
    source: SurfaceSource | Surface,
    size: float | None = None,
    *,
    divisions: float | None = None,
    max_size: float | None = None,
    regions: Sequence[Region] = (),
    size_function: SizeFunction | None = None,
    curvature: float | None = None,
    layers: float | None = None,
    patch_sizes: Mapping[str, float] | None = None,
    thin_features: bool = True,
    min_size: float | None = None,
    max_memory: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> MeshResult:
    """Fill a closed solid with graded fat-lattice tets, the boundary stuffed onto its surface.

    source: surface file path (STL, OBJ, OFF, PLY, MSH), manifold3d.Manifold, (vertices, faces)
    or a loaded Surface.  size: finest long edge in model units, used all along the boundary
    (default: bounding-box diagonal / divisions, divisions default 40).  max_size: largest
    long edge inside (default 8 * size, rounded down to a power-of-two multiple of size;
    max_size = size gives a uniform lattice).  regions: paroct.Box / paroct.Sphere asking for
    a smaller size inside them; size_function: h(x) for points (N, 3) returning sizes (N,),
    evaluated at octant corners and centres.  Both are clamped to at least size inside; on
    the boundary, a size below size refines it there, as patch_sizes do.
    curvature: N elements per full turn of the surface: the boundary refined to long edges of
    at most 2 pi r / N where it bends with radius r (as Gmsh's Mesh.MeshSizeFromCurvature;
    lfs.curvature_asks: measured at the scale of each level, so noise finer than the elements
    and creases of the triangulation ask nothing).  layers: K elements across every wall
    thinner than K * size, the boundary there refined to long edges of at most its thickness
    / K (lfs.wall_asks).  Both refine by halves of size, down to min_size (default size /
    16); the band then changes level, and every tet is measured and mended or refined
    further as near thin walls, so the dihedral bound holds.  patch_sizes: {name: size}, a
    long edge for the boundary on named patches (the input's named groups, else patch_1,
    patch_2, ... of the surface split at 40 degrees, as boundary_patches() names them),
    refined the same way (lfs.patch_asks).
    thin_features: when the mesh loses topology (boundary components, genus), loses or gains
    more than 1 % of the volume, or misses surface vertices by more than 2 * size (parts
    thinner than the lattice dropped), the solid is meshed again: if the whole boundary at
    size / 2 is estimated at fewer tets than refining near the thin places, at size / 2 (about
    one element across walls as thin as it; layers asks for more); else, or if that still
    loses, with the boundary refined only near the walls and gaps thinner than 2 * size
    and the missed parts, to two element layers across each (first at most size / 8, then
    deeper while it still loses, down to min_size, default size / 16, until rounds there
    lose the same: SAME_LOSS_ROUNDS), every tet measured,
    other warps tried near any outside [10.7, 164.8] degrees (and near needles, 3r/R below
    NEEDLE_RATIO) and the band refined where they do not mend an angle; before a deeper round,
    the whole boundary at the coarsest of size / 2, size / 4, ... not yet tried, where
    estimated at fewer tets than that round; if that does not keep the solid, the whole
    boundary size shrinks by halves instead (skipping the sizes tried), as far as max_memory
    allows (not below size / 8 unless min_size is given).  Where the boundary's chords away
    from the thin places are estimated to lose more than 1 % of the volume by themselves
    (check.chord_volumes), which no refinement near them mends, no round is made: the whole
    boundary shrinks by halves at once, and the rounds start from the first halved size
    whose chords do not rule them out.  Where every pass loses, the coarsest that no finer
    one keeps more of the solid than (keeps_more) is returned with a warning: the size
    asked, where refining kept nothing more.  The report's notes say what
    was done.
    False keeps size and only warns.  A mesh that keeps less than half the solid's volume
    raises ParoctError, as one with no tets does.  max_memory: bytes the run may use
    (default: the machine's available memory); a size that would need more is refused before
    any work.  progress: called with each stage's name when it ends; an exception it raises
    stops the meshing there and reaches the caller unchanged (the way to cancel a run).
    """
    t0 = time.perf_counter()
    surface, h, floor, whole_floor, budget = checked_request(source, size, divisions, thin_features, min_size,
                                                             max_memory)
    field = size_field(h, max_size, regions, size_function, curvature, layers, patch_sizes)
    if progress is not None and not callable(progress):
        raise ParoctError(f"progress = {progress!r}: must be a function taking a stage's name, or None")
    _check_memory(surface, field, budget)
    loaded = time.perf_counter() - t0
    if progress:
        progress("load")

    notes: list[str] = []
    stage_seconds = {"load": loaded}  # stage times add up over the attempts
    t_asks = time.perf_counter()
    asks, ask_notes = _feature_asks(surface, field, floor)
    notes.extend(ask_notes)
    if field.asks_boundary:
        stage_seconds["sizing"] = time.perf_counter() - t_asks
        if progress:
            progress("sizing")

    def whole_pass(band: float) -> PassOutcome:
        report = _pass_report(surface, field, band, stage_seconds)
        return PassOutcome(*_whole_pass(surface, field, band, asks, budget, report, progress, stage_seconds))

    def refine_locally(at_band: MeshResult, band: float, lost: str, walls: ThinFeatures) -> LocalOutcome:
        # Rounds from the whole band at band: h, or a half of it where the chords at the sizes
        # above lost the volume away from the thin places; the size field's own asks go with
        # it, their depths counted from band.
        banded = field if band == h else _at_boundary_size(field, band)
        base = asks if band == h else asks.deeper_than(int(round(np.log2(h / band))))
        first = _first_local_ask(surface, banded, walls, floor, base)
        why = _chords_lose_elsewhere(surface, banded, first, at_band)
        if why:
            note = f"refining the band only near thin places: {why}; refining the whole band instead"
            return LocalOutcome(None, [], [note], False, chords_lose=True)
        # The whole band at band / 2, band / 4, ... as memory allows, for _thin_locally to try
        # where one is estimated at fewer tets than its next round (band / 2 before the first).
        # Not at whole_floor: should everything lose, the pass there is the one returned, as
        # before session 34.
        wholes, whole = [], band / 2
        while whole > whole_floor * (1 + 1e-9) and _fits(surface, field, whole, budget):
            wholes.append(whole)
            whole /= 2
        local, why, tried, tried_notes = _thin_locally(surface, banded, walls, floor, budget, lost, wholes, progress,
                                                       stage_seconds, base, first)
        if local is not None:
            local.report.requested_size = h  # made for banded; the tried passes' reports are not returned
            local.report.notes = [*notes, *local.report.notes]
            return LocalOutcome(local, tried, [], False)
        if why:
            tried_notes = [*tried_notes, f"refining the band only near thin places: {why}; refining the whole band instead"]
        return LocalOutcome(None, tried, tried_notes, why == LOCAL_MEMORY)

    return with_repairs(surface, halve_whole_band(surface, field, floor, whole_floor, budget, thin_features, whole_pass,
                                                  notes, refine_locally))


def with_repairs(surface: Surface, result: MeshResult) -> MeshResult:
    """result, its report's warnings led by what loading mended in the surface (Surface.repairs)."""
    result.report.warnings[:0] = surface.repairs
    return result


class Request(NamedTuple):
    """checked_request's result: the surface, the size h, the floors (size_floors) and the
    memory budget in bytes."""

    surface: Surface
    h: float
    floor: float
    whole_floor: float
    budget: float


def checked_request(source: SurfaceSource | Surface, size: float | None, divisions: float | None,
                    thin_features: bool, min_size: float | None, max_memory: float | None) -> Request:
    """The options mesh() and partition.mesh_in_ranges share, checked (ParoctError naming a
    wrong one), with the surface loaded unless a validated one is given."""
    if size is not None and divisions is not None:
        raise ParoctError(f"size = {size!r} and divisions = {divisions!r}: give one (size = diagonal / divisions)")
    if not isinstance(thin_features, (bool, np.bool_)):
        raise ParoctError(f"thin_features = {thin_features!r}: must be True or False")
    surface = source if isinstance(source, Surface) and source.validated else load_surface(source)
    h = resolve_size(surface, size, divisions)
    floor, whole_floor = size_floors(surface, h, min_size)
    budget = _available_memory() if max_memory is None else positive_number("max_memory", max_memory, infinite=True)
    return Request(surface, h, floor, whole_floor, budget)


class PassOutcome(NamedTuple):
    """One pass of halve_whole_band: the result, what it lost ('' if nothing: _losses), the
    advice on what would keep it, the walls and gaps measured where it lost (else None), its
    report, and a note ('' if none)."""

    result: MeshResult
    lost: str
    advice: str
    walls: ThinFeatures | None
    report: MeshReport
    note: str


class LocalOutcome(NamedTuple):
    """What refining near thin places gave halve_whole_band: the result if it kept the solid
    (else None), the whole-band passes it tried that lost, notes on them, whether memory
    stopped it, and whether no round was made because the chords away from the thin places
    lose the volume at that size (_chords_lose_elsewhere)."""

    result: MeshResult | None
    tried: list[LosingPass]
    notes: list[str]
    memory_bound: bool
    chords_lose: bool = False


def size_floors(surface: Surface, h: float, min_size: float | None) -> tuple[float, float]:
    """(floor, whole_floor): the finest boundary size refinement near thin places may reach
    (min_size, by default h / DEFAULT_MIN_SIZE_DIVISOR, never below MIN_SIZE_STEPS float
    steps of the largest coordinate) and the finest the whole band is halved to (floor if
    min_size is given, else not below h / 2**WHOLE_BAND_DEPTH).  ParoctError if min_size
    exceeds h."""
    floor = h / DEFAULT_MIN_SIZE_DIVISOR if min_size is None else positive_number("min_size", min_size)
    if floor > h * (1 + 1e-9):  # min_size = size, computed apart from it, may round above it
        raise ParoctError(f"min_size = {floor:.6g} must be at most size = {h:.6g}: it is the finest boundary size "
                          "refinement near thin places may reach")
    floor = min(h, max(floor, MIN_SIZE_STEPS * np.spacing(_largest_coordinate(surface))))  # thin walls refine no further
    return floor, floor if min_size is not None else max(floor, h / 2**WHOLE_BAND_DEPTH)


def halve_whole_band(surface: Surface, field: SizeField, floor: float, whole_floor: float, budget: float,
                     thin_features: bool, one_pass: Callable[[float], PassOutcome], notes: list[str],
                     refine_locally: Callable[[MeshResult, float, str, ThinFeatures], LocalOutcome] | None = None
                     ) -> MeshResult:
    """mesh()'s passes: one_pass(band) at band = field.size; while it loses (_losses) and
    thin_features, refine_locally (if given; with the pass's result, its size, what it lost
    and its walls) near the walls after the first (after the first at half the size where
    the chords at size lost the volume away from them: LocalOutcome.chords_lose, and so on
    down), then the whole band at halves of the size (skipping those refine_locally
    tried), down to whole_floor as the budget allows, until a pass keeps the solid or a
    finer pass loses more with nothing to explain it (touching parts).  Returns the last
    pass's result, or if it lost, the best one kept or else the coarsest that no finer pass
    keeps more than (coarsest_keeping_as_much), its report noting the steps (notes first)
    and warning of what it lost.  ParoctError if it keeps less than half the solid or has no tets."""
    h = field.size
    band, memory_bound, tried = h, False, list[float]()  # tried: whole-band sizes below h that a pass lost at
    local_band, refined_locally = h, False  # the whole band's size the rounds near thin places start from
    best: tuple | None = None  # the whole-band pass whose boundary is nearest the input's so far
    losing: list[LosingPass] = []  # every whole-band pass that lost
    kept_text = ""
    while True:
        result, lost, advice, walls, report, note = one_pass(band)
        if note:
            notes.append(note)
        if lost:
            losing.append(losing_pass(band, result, lost, advice, report, keep=band == h))
        if refine_locally is not None and thin_features and lost and band == local_band and walls is not None:
            local = refine_locally(result, band, lost, walls)
            if local.result is not None:
                return local.result
            tried += [p.band for p in local.tried]
            losing.extend(local.tried)
            notes.extend(local.notes)
            memory_bound = memory_bound or local.memory_bound
            refined_locally = refined_locally or not local.chords_lose
            if local.chords_lose:
                local_band = band / 2
        # Parts touching along an edge or at a point have no wall or gap between them that a
        # size could resolve: they come out joined at every size, and the finer the band the
        # more lattice edges join them (two cubes sharing an edge, turned 30 and 40 degrees,
        # at diag/30: genus 0, 2, 3 at size / 2, / 4, / 8, and 1.36 M tets at the end for
        # 0.17 M).  A finer pass further from the input's components and genus than the best
        # before (nearest the input's, then least volume error), with no squarely facing wall
        # or gap thinner than 2 x size nor missed part to explain it, ends the halving, and
        # the best pass is returned.
        distance = _topology_distance(report)
        if thin_features and best is not None and distance > best[0] and _unexplained(report, walls, band):
            kept_text = (f"the pass at boundary size {best[4]:.4g} is kept: at {band:.4g} {lost}, further from the "
                         "input, with no wall or gap thinner than 2 x size to explain it (parts touching along an edge "
                         "or at a point stay joined at any size); ")
            _, result, lost, report, band = best
            advice = ""
            break
        if lost and (best is None or (distance, abs(report.volume_error)) < (best[0], abs(best[3].volume_error))):
            best = (distance, result, lost, report, band)
        # By halves, the coarsest first (skipping the sizes refine_locally tried): what
        # the rounds near thin places could not keep comes out joined or split at any size,
        # and a coarser band may keep what a finer one loses.  Going straight to two layers
        # across the thinnest wall, as before, took random unions and differences of boxes,
        # spheres and cylinders at diag/40 (session 33) to size / 8 with a changed genus
        # and 2.6 M tets, where size / 4 keeps the solid with 0.55 M.
        finer = band / 2
        while finer in tried:  # h / 2, h / 4, ...: halving a float is exact
            finer /= 2
        finer = max(finer, whole_floor)  # not in tried: those are above whole_floor
        while finer < band * (1 - 1e-9) and not _fits(surface, field, finer, budget):
            finer, memory_bound = finer * 2, True
        if not (thin_features and lost and finer < band * (1 - 1e-9)):
            break
        notes.append(f"boundary size {band:.4g} -> {finer:.4g}: at {band:.4g} {lost}; {advice}")
        band = finer
    report.notes = notes
    if lost:
        floor_text = kept_text or _why_no_finer(band, floor, whole_floor, thin_features, memory_bound,
                                                None if refine_locally is None else refined_locally)
        coarser = None if kept_text else coarsest_keeping_as_much(surface, losing)
        # A pass to refuse is refused at the finest size tried, which says the most.
        if coarser is not None and coarser.band > band and not _losing_too_much(coarser.report):
            floor_text += (f"the pass at boundary size {coarser.band:.4g} is kept, as the finer ones kept no more of "
                           "the solid; ")
            band, lost, advice, report = coarser.band, coarser.lost, coarser.advice, coarser.report
            if coarser.result is None:  # only the pass at size is held; another is made again, the same
                again = one_pass(band)
                result, report = again.result, again.report
            else:
                result = coarser.result
            report.notes = notes
        _refuse_losing_too_much(report, band, f"{floor_text}{advice}")  # why it went no finer, then what would keep it
        report.warnings.append(f"{floor_text}{lost}" + (f"; {advice}" if advice else ""))
    return result


def _why_no_finer(band: float, floor: float, whole_floor: float, thin_features: bool, memory_bound: bool,
                  refined_locally: bool | None) -> str:
    """Why halve_whole_band's last pass, at boundary size band, lost and none finer was made
    ('' if thin_features is off), as a clause ending in '; '.  refined_locally: whether
    refinement near thin places was tried (False: the chords away from them lost the volume
    at every size it could start from), None where it is not made (meshing in ranges)."""
    if thin_features and band <= floor * (1 + 1e-9):
        return f"min_size = {floor:.4g} reached; "
    if thin_features and memory_bound:
        return f"a boundary size below {band:.4g} would not fit in memory (max_memory); "
    if thin_features and band <= whole_floor * (1 + 1e-9) and refined_locally:
        return f"min_size = {floor:.4g} reached near thin places and the whole boundary refined to {band:.4g}; "
    if thin_features and band <= whole_floor * (1 + 1e-9) and refined_locally is None:
        return (f"the whole boundary refined to {band:.4g}, as far as it goes without min_size (finer only near thin "
                "places, which mesh() refines and meshing in ranges does not yet); ")
    if thin_features and band <= whole_floor * (1 + 1e-9):
        return (f"the whole boundary refined to {band:.4g}, as far as it goes without min_size (no refinement near "
                "thin places: the chords away from them lost the volume at each size it could start from); ")
    return ""


class LosingPass(NamedTuple):
    """A whole-band pass that lost part of the solid (losing_pass): its boundary size, what it
    lost, the advice, its report, its boundary's points (B, 3) (None if the result had no
    boundary faces) and the result, if held."""

    band: float
    lost: str
    advice: str
    report: MeshReport
    boundary_points: np.ndarray | None
    result: MeshResult | None


def losing_pass(band: float, result: MeshResult, lost: str, advice: str, report: MeshReport, keep: bool) -> LosingPass:
    """The LosingPass of a pass at boundary size band, holding its result if keep (a mesh
    held through the finer passes adds to their peak)."""
    faces = result.boundary_faces
    points = None if faces is None else boundary_points(result.mesh.points, faces)
    return LosingPass(band, lost, advice, report, points, result if keep else None)


def coarsest_keeping_as_much(surface: Surface, losing: Sequence[LosingPass]) -> LosingPass:
    """The coarsest of the passes (at least one) that no finer one keeps more than
    (keeps_more): where refining only spent tets, the mesh at the size asked.  A cube with
    fins 1e-7 of it thick (a slicer's test part) lost them at size / 8 as at the size asked,
    in 3.8 M tets for 36 k."""
    ordered = sorted(losing, key=lambda p: -p.band)
    for i, candidate in enumerate(ordered):
        if not any(keeps_more(surface, finer, candidate) for finer in ordered[i + 1:]):
            return candidate
    raise ValueError("no losing passes")  # the finest has none finer


def keeps_more(surface: Surface, finer: LosingPass, coarser: LosingPass) -> bool:
    """Whether the finer pass keeps more of the solid than the coarser by any measure: a
    boundary nearer the input's components and genus, a volume error smaller by over
    VOLUME_LOSS_WARNING, or fewer surface vertices or triangle centres missed by the coarser
    pass's reach (boundary_misses at its size: the finer pass's own reach is shorter).  Any
    one will do: a pass nearer in topology but further in volume is no cheaper way to the
    same loss (a plate lost whole against one full of holes).  A pass without its boundary's
    points is taken to keep more."""
    if _topology_distance(finer.report) < _topology_distance(coarser.report):
        return True
    if abs(finer.report.volume_error) < abs(coarser.report.volume_error) - VOLUME_LOSS_WARNING:
        return True
    if finer.boundary_points is None:
        return True
    vertices, centres = boundary_misses(surface, finer.boundary_points, coarser.band)
    return vertices.size < coarser.report.missed_vertices.size or centres.size < coarser.report.missed_faces.size


def _topology_distance(report: MeshReport) -> int:
    """How far the pass's boundary is from the input's: the differences in components and
    genus, summed."""
    return abs(report.boundary_components - report.input_components) + abs(report.boundary_genus - report.input_genus)


def _unexplained(report: MeshReport, walls: ThinFeatures | None, band: float) -> bool:
    """Whether nothing a finer band could resolve explains what the pass at boundary size band
    lost: no missed part of the surface, and no squarely facing wall or gap (walls: the pass's,
    _walls_of_loss) thinner than 2 x band."""
    return not _missed(report) and (walls is None or not walls.thinnest_below(2 * band)[0])


def _feature_asks(surface: Surface, field: SizeField, floor: float) -> tuple[FeatureAsks, list[str]]:
    """Where the size field's curvature, layers, patch sizes, and regions and size function
    below field.size (lfs.py) ask for a boundary finer than field.size, down to floor (none
    unless they are given), and notes on patch sizes, regions and the function."""
    if not field.asks_boundary:
        return no_asks(), []
    max_depth = _local_depth(field.size, floor)
    coarse = fat_frame(surface.bbox_min, surface.bbox_max, field.size)
    # One cut of the surface serves every ask that reads it (layers read the lattice rows).
    only_layers = field.curvature is None and not field.patch_sizes and field.function is None \
        and all(region.size >= field.size for region in field.regions)
    cut = None if only_layers else surface_pieces(surface, coarse)
    asks, notes = no_asks(), list[str]()
    for found, found_notes in (region_asks(surface, coarse, field.regions, max_depth, cut),
                               function_asks(surface, coarse, field.function, max_depth, cut),
                               patch_asks(surface, coarse, field.patch_sizes, max_depth, cut)):
        asks, notes = merged_asks(asks, found), notes + found_notes
    if max_depth < 1:
        return no_asks(), notes
    if field.curvature is not None:
        asks = merged_asks(asks, curvature_asks(surface, coarse, field.curvature, max_depth, DEFAULT_FEATURE_ANGLE,
                                                cut))
    if field.layers is not None:
        walls = surface_thin_features(surface, coarse).facing_below(THIN_FACING)
        found, found_notes = wall_asks(walls, field.size, field.layers, max_depth)
        asks, notes = merged_asks(asks, found), notes + found_notes
    return asks, notes


def _whole_pass(surface: Surface, field: SizeField, band: float, asks: FeatureAsks, budget: float,
                report: MeshReport, progress: Callable[[str], None] | None,
                stage_seconds: dict) -> tuple[MeshResult, str, str, ThinFeatures | None, MeshReport, str]:
    """One pass with the whole band at size band (field.size / 2**k), refined further where
    asks (depths below field.size) ask for finer than band: _mesh_at, or with asks
    _mesh_with_asks.  Returns _mesh_at's (result, lost, advice, walls), the pass's report
    (``report`` unless asks made their own) and a note ('' if none).  Should the band not be
    refined as asked (memory, a frame too deep, tets outside the bound after the rounds), the
    pass is made without the asks and its report warns."""
    finer = asks.deeper_than(int(round(np.log2(field.size / band))))
    attempt = _at_boundary_size(field, band)
    if not finer.empty:
        sized = _mesh_with_asks(surface, attempt, finer, budget, progress, stage_seconds)
        if isinstance(sized, tuple):
            return sized
        report.warnings.append(f"curvature, layers or patch sizes not honoured at boundary size {band:.4g}: the "
                               f"boundary was not refined where {finer.why}: {sized}")
    return *_mesh_at(surface, attempt, report, progress), report, ""


def _mesh_with_asks(surface: Surface, field: SizeField, asks: FeatureAsks, budget: float,
                    progress: Callable[[str], None] | None,
                    stage_seconds: dict) -> tuple[MeshResult, str, str, ThinFeatures | None, MeshReport, str] | str:
    """The pass with the band refined where asks say (measure-and-refine rounds:
    _refine_rounds): _whole_pass's tuple, or why the band could not be refined so."""
    coarse = fat_frame(surface.bbox_min, surface.bbox_max, field.size)
    deepest = int(asks.depth.max())
    frame = _refined_frame(coarse, deepest)
    if frame.levels > MAX_FRAME_LEVELS:
        return f"a frame of {frame.levels} levels is too deep"
    wanted = _asked_levels(coarse, deepest, asks)
    if not _local_fits(surface, field, wanted, frame, budget):
        return LOCAL_MEMORY
    framed = FramedSurface.build(surface, frame, coarse.levels)
    result, report, rounds, why = _refine_rounds(surface, field, framed, wanted, budget, progress, stage_seconds)
    if result is None:
        return why
    assert report is not None  # a result comes with its report
    note = f"boundary refined to {frame.h:.4g} where {asks.why}, in {rounds} measure-and-refine round{'s' * (rounds > 1)}"
    lost, advice, walls = pass_losses(surface, report, coarse, framed.faces)
    return result, lost, advice, walls, report, note


def _losing_too_much(report: MeshReport) -> bool:
    """Whether _refuse_losing_too_much refuses the pass."""
    return report.n_tets == 0 or report.volume_error < -LOST_TOO_MUCH


def _refuse_losing_too_much(report: MeshReport, band: float, advice: str) -> None:
    """ParoctError if the mesh at boundary size band has no tets, or keeps less than half the
    solid (LOST_TOO_MUCH): what is left is not the part."""
    if report.n_tets == 0:
        raise ParoctError(f"no tets: the solid is thinner than size = {band:.4g} everywhere; {advice}")
    if report.volume_error < -LOST_TOO_MUCH:
        raise ParoctError(f"the mesh at boundary size {band:.4g} keeps only {100 * (1 + report.volume_error):.2g}% "
                          f"of the solid's volume; {advice}")


def _pass_report(surface: Surface, field: SizeField, band: float, stage_seconds: dict) -> MeshReport:
    """An empty report of one pass at boundary size band for the request field (its size is
    the one asked); stage_seconds is shared, so stage times add up over the passes."""
    return MeshReport(size=band, requested_size=field.size, levels=0, max_size=field.max_size,
                      solid_volume=surface.volume, input_genus=surface.genus, input_components=surface.components,
                      stage_seconds=stage_seconds)


def _local_depth(size: float, floor: float) -> int:
    """Levels below size that local refinement may go: down to floor."""
    return int(np.floor(np.log2(size / floor) + 1e-9))


def _first_local_ask(surface: Surface, field: SizeField, walls: ThinFeatures, floor: float,
                     base: FeatureAsks) -> LocalAsk | None:
    """_local_ask of the first round near thin places (levels capped at WHOLE_BAND_DEPTH, no
    extra), which _chords_lose_elsewhere and _thin_locally both read (made once: 1.9 ms of
    plate_holes at diag/40); None where floor leaves no level below field.size."""
    max_depth = _local_depth(field.size, floor)
    if max_depth < 1:
        return None
    coarse = fat_frame(surface.bbox_min, surface.bbox_max, field.size)
    return _local_ask(coarse, walls, min(max_depth, WHOLE_BAND_DEPTH), 0, base)


def _chords_lose_elsewhere(surface: Surface, field: SizeField, first: LocalAsk | None, at_size: MeshResult) -> str:
    """Why no round near the thin places (_thin_locally) can keep the solid, or '' if one may.

    A round refines the band in the coarse cells near the walls and gaps (and where base
    asks), and the 2:1 balance splits the cells around those asked two levels or more finer
    (one cell further: a split neighbour's leaves coarsen to size / 2 across it); elsewhere
    its boundary is the pass at size's (at_size), and so is the volume error of that
    boundary's chords, stuffing's own, second order in size.  Where that error, as
    check.chord_volumes estimates it over at_size's boundary triangles whose centroid lies in
    a cell left at size, is beyond VOLUME_LOSS_WARNING, every round loses (the estimate is
    below the true error on most parts, so this holds the more): fertility at diag/40 lost
    1.8 % at size (estimated 1.5, 1.1 of it away from its thin walls), its round near them
    1.2 % in 33 ms, before the whole band at size / 2 kept it.  first: the first round's ask
    (_first_local_ask; None or no band: no round, and '')."""
    if at_size.boundary_faces is None or at_size.point_faces is None or not at_size.boundary_faces.size:
        return ""
    if first is None or first.wanted is None:
        return ""
    coarse = fat_frame(surface.bbox_min, surface.bbox_max, field.size)
    wanted = first.wanted
    deep = wanted.levels >= coarse.levels + 2
    if deep.any():  # in the coarse frame, a cell's anchor in lattice units is its coordinates
        centres = octant_lattice_anchors(wanted.keys[deep], coarse) + 0.5
        wanted = merge_band_levels(wanted, band_levels(coarse, coarse.levels, centres,
                                                       np.full(centres.shape[0], coarse.levels + 1)))
    points, faces = at_size.mesh.points, at_size.boundary_faces
    errors = chord_volumes(points, faces, at_size.point_faces, surface.vertices, surface.faces)
    centroids = (points[faces[:, 0]] + points[faces[:, 1]] + points[faces[:, 2]]) / 3.0
    cells = np.clip(np.floor(coarse.to_lattice(centroids)), 0, (1 << coarse.levels) - 1).astype(np.int64)
    keys = morton_keys(cells) << (3 * (MAX_LEVEL - coarse.levels))
    elsewhere = float(errors[wanted.level_of(keys) == coarse.levels].sum()) / surface.volume
    if abs(elsewhere) <= VOLUME_LOSS_WARNING:
        return ""
    return (f"away from them the boundary at size {field.size:.4g} is estimated to {'lose' if elsewhere < 0 else 'gain'} "
            f"{100 * abs(elsewhere):.1f}% of the volume (its chords), which no round near them changes")


def _thin_locally(surface: Surface, field: SizeField, walls: ThinFeatures, floor: float, budget: float, lost: str,
                  wholes: Sequence[float], progress: Callable[[str], None] | None,
                  stage_seconds: dict, base: FeatureAsks,
                  first: LocalAsk | None = None) -> tuple[MeshResult | None, str, list[LosingPass], list[str]]:
    """Refine the band only near the thin walls and gaps (two element layers across each,
    down to ``floor``), measure, mend and refine until every tet is within DIHEDRAL_BOUND, and
    one level more while the mesh still loses topology or volume.

    base: asks of the size field's own (curvature, layers, patch sizes: lfs.py; depths below
    field.size) that every round and whole-band pass keeps.
    wholes: whole-band sizes below field.size, coarsest first, that may be tried instead.
    first: the first step's ask, _first_local_ask's for these surface, field, walls, floor and
    base (made here if None).
    Before a round, the coarsest not yet tried is meshed over the whole band when
    estimate_tets puts it below the round's _local_tets (before the first round size / 2,
    then size / 4 below QUARTER_BAND_SHARE of it), once each; the rounds go on where it
    loses.  The rounds' local volume error is what the thin places lose, and stuffing's error
    elsewhere (second order in size, a chord's) none of them mends: a sphere of 0.5 M triangles united with a cube lost
    1.5-1.7 % at diag/20 in four rounds to size / 16, 1.0 s, and the whole band at size / 2
    keeps it.

    Returns (result, '', tried, []) with the notes in the result's report; or (None, why,
    tried, notes) when that did not succeed (no thin place found: why = ''; the floor or the
    memory budget reached; the rounds stopped finding fewer tets outside the bound), and the
    caller refines the whole band.  tried: the whole-band passes that lost (LosingPass,
    results not held); notes: theirs."""
    coarse = fat_frame(surface.bbox_min, surface.bbox_max, field.size)
    max_depth = _local_depth(field.size, floor)
    wholes, tried, tried_notes = list(wholes), list[LosingPass](), list[str]()
    if max_depth < 1:  # min_size leaves no finer level to refine to
        return None, "", tried, tried_notes
    notes = [f"at boundary size {field.size:.4g} {lost}"]
    framed, tried_band, lost_at_floor, same_at_floor = None, None, None, 0
    cap, extra = min(max_depth, WHOLE_BAND_DEPTH), 0
    needs = _thin_asks(coarse, walls, max_depth, 0)[1]  # the levels each sample's two layers need
    thinnest = float(np.min(walls.thickness, initial=np.inf, where=walls.thickness > 0))  # 0: not measured
    for step in range(2 * max_depth + 1):  # each step deepens the cap, the asks or both
        frame, depth, wanted = first if step == 0 and first is not None else _local_ask(coarse, walls, cap, extra, base)
        if depth.size == 0:
            return None, "", tried, tried_notes
        if frame.levels > MAX_FRAME_LEVELS:
            return None, f"a frame of {frame.levels} levels is too deep", tried, tried_notes
        assert wanted is not None  # _local_ask asks a band unless one of the two above
        local = _local_tets(surface, field, wanted)
        # Before any round near thin places, the whole band is halved (size / 2) when that is
        # estimated at fewer tets than the first round, whatever the pass at size lost. Both
        # estimates are upper bounds, _local_tets 3.4-7.2 x the tets of a first round on the corpus'
        # thin parts at diag/40, estimate_tets 1.5-1.9 x the whole band's, so halving is chosen
        # while it makes up to about twice a round's tets: it needs no second round and keeps the
        # band on one level. Where the pass lost stuffing's own chord error on a bumpy surface,
        # which no round mends, halving keeps it (armadillo at diag/40: three rounds made 0.49 M
        # tets in 0.81 s; the whole band at size / 2 0.10 M in 0.19 s). Where it lost walls about as
        # thick as the lattice, or dropped a part thinner, halving often keeps them too, with far
        # fewer tets than two layers across every wall: tray_bottom at diag/80 0.18 M against 1.24 M
        # tets, a 1 mm stepped shim at diag/40 73 k against 0.99 M (session 49; until then halving
        # was skipped where the pass missed surface vertices or lost 4 % of the volume or more). If
        # the halved band still loses, the rounds start from size, as without it (from size / 2 they
        # would go a level deeper: fea_part at diag/60, 6.1 M tets against 2.5 M), having spent one
        # pass cheaper than the round.
        # Before the first round, size / 4 too where size / 2 lost, when estimated at under a
        # third of the round (QUARTER_BAND_SHARE); before later rounds, the coarsest left.
        while wholes and (step > 0 or wholes[0] in (field.size / 2, field.size / 4)):
            first_quarter = step == 0 and wholes[0] == field.size / 4
            whole = estimate_tets(surface, _at_boundary_size(field, wholes[0]))
            if whole >= (local * QUARTER_BAND_SHARE if first_quarter else local) or (
                    first_quarter and thinnest < field.size / 8):
                break
            size = wholes.pop(0)
            why = (f"the whole band at size / {field.size / size:g} is estimated at {whole} tets, "
                   f"{'under a third of' if first_quarter else 'fewer than'} the {local} of a round near them")
            whole_report = _pass_report(surface, field, size, stage_seconds)
            kept, still, advice, _, whole_report, note = _whole_pass(surface, field, size, base, budget,
                                                                     whole_report, progress, stage_seconds)
            if not still:
                whole_report.notes = [*notes, f"boundary refined to {size:.4g} everywhere: {why}",
                                      *([note] if note else [])]
                return kept, "", tried, []
            tried.append(losing_pass(size, kept, still, advice, whole_report, keep=False))
            del kept
            note = (f"boundary refined to {size:.4g} everywhere ({why}): at {size:.4g} {still}; "
                    f"refining near thin places from {field.size:.4g} instead")
            notes.append(note)
            tried_notes.append(note)
            if step > 0:
                break
        if not _local_fits(surface, field, wanted, frame, budget):
            return None, LOCAL_MEMORY, tried, tried_notes
        if framed is None or framed.frame.levels != frame.levels:  # same origin: same levels, same frame
            framed, tried_band = FramedSurface.build(surface, frame, coarse.levels), None
        if tried_band is not None and _same_band(framed, tried_band, wanted):
            deeper = _next_ask(needs, depth, cap, extra, max_depth)
            if deeper is None:
                break
            cap, extra = deeper
            continue
        tried_band = wanted
        result, report, rounds, why = _refine_rounds(surface, field, framed, wanted, budget, progress, stage_seconds)
        if result is None:
            return None, why, tried, tried_notes
        assert report is not None  # a result comes with its report
        known = walls.thickness[walls.thickness < 2 * coarse.h] > 0  # as _thin_asks picks its samples
        beyond = int(np.max(depth - needs, initial=0, where=known))
        layers = f", {beyond} level{'s' * (beyond > 1)} finer than two layers need" if beyond > 0 else ""
        measured = np.flatnonzero(walls.thickness > 0)  # the others are surface the boundary missed
        thinnest = measured[np.argmin(walls.thickness[measured])] if measured.size else -1
        what = (f"thinnest {'wall' if walls.is_wall[thinnest] else 'gap'} {walls.thickness[thinnest]:.4g}"
                if measured.size else "parts the lattice missed")
        notes.append(f"boundary refined to {frame.h:.4g} only near the {depth.size} samples of walls and gaps thinner "
                     f"than 2 x size ({what}{layers}), in {rounds} measure-and-refine round{'s' * (rounds > 1)}")
        still = _losses(report, surface)
        if not still:
            report.notes = notes
            return result, "", tried, []
        notes.append(f"at boundary size {frame.h:.4g} near thin walls {still}")
        deeper = _next_ask(needs, depth, cap, extra, max_depth)
        if deeper is None:
            break
        same_at_floor = same_at_floor + 1 if cap == max_depth and lost_at_floor == still else 0
        if same_at_floor == SAME_LOSS_ROUNDS:
            return None, (f"min_size = {floor:.4g} reached near the thin places, and {SAME_LOSS_ROUNDS} rounds one level "
                          "deeper each for the samples above it lost the same"), tried, tried_notes
        lost_at_floor = still if cap == max_depth else None
        cap, extra = deeper
    return None, f"min_size = {floor:.4g} reached near the thin places and the mesh still lost", tried, tried_notes


def _refine_rounds(surface: Surface, field: SizeField, framed: FramedSurface, wanted: BandLevels, budget: float,
                   progress: Callable[[str], None] | None,
                   stage_seconds: dict) -> tuple[MeshResult | None, MeshReport | None, int, str]:
    """Mesh with the band refined where ``wanted`` asks (framed: the surface in the finest
    frame) and refine it further around every tet outside DIHEDRAL_BOUND that other warps do
    not mend, up to MAX_REFINE_ROUNDS rounds, or until STALLED_ROUNDS rounds in a row find
    no fewer such tets.  Returns (result, its report, rounds, '') or (None, the last report or
    None, rounds, why not)."""
    frame, coarse_level = framed.frame, framed.coarse_level
    local = _local_tets(surface, field, wanted)
    fewest, stalled, result, report = np.iinfo(np.int64).max, 0, None, None
    window: tuple[np.ndarray, np.ndarray] | None = None
    for rounds in range(1, MAX_REFINE_ROUNDS + 1):
        if local * BYTES_PER_TET > budget:
            return None, report, rounds, LOCAL_MEMORY
        report = _pass_report(surface, field, frame.h, stage_seconds)
        result, asks = _mesh_locally(surface, field, framed, wanted, report, progress, window)
        if result is not None:
            return result, report, rounds, ""
        if window is None:
            fewest, stalled = (report.bad_tets, 0) if report.bad_tets < fewest else (fewest, stalled + 1)
        elif asks.keys.size == 0:  # the refined cells are clean: check everything
            window = None
            continue
        merged = merge_band_levels(wanted, asks)
        if stalled == STALLED_ROUNDS or (np.array_equal(merged.keys, wanted.keys) and np.array_equal(merged.levels, wanted.levels)):
            break
        # Only the cells near the new asks change: check those alone until they are clean.
        changed = merged.keys[wanted.level_of(merged.keys) != merged.levels]
        anchors = octant_lattice_anchors(changed, frame)
        at_coarse = np.full(changed.shape[0], coarse_level)
        outer, inner = (band_levels(frame, coarse_level, anchors, at_coarse, ring).keys
                        for ring in (WINDOW_RING, WINDOW_RING - 2))
        window = (outer, inner)
        wanted = merged
        local = _local_tets(surface, field, wanted)
    assert report is not None  # set by every round that does not return
    return None, report, rounds, (f"{report.bad_tets} tets were still outside [{DIHEDRAL_BOUND[0]}, {DIHEDRAL_BOUND[1]}] "
                                  f"degrees after {rounds} measure-and-refine rounds")


def _same_band(framed: FramedSurface, a: BandLevels, b: BandLevels) -> bool:
    """Whether two asks give the same band cells in framed's frame, and so the same mesh (a
    deeper ask in cells the surface does not meet changes nothing).  Only later rounds ask:
    the first round's cells cost fea_part /40 94 ms, a repeat from framed.fine_cells 16."""
    bits = rays.snap_bits(framed.frame)
    cells = [band_cells(framed.frame, framed.snapped, framed.faces, bits, framed.buckets, w, framed.fine_cells)
             for w in (a, b)]
    return all(np.array_equal(x, y) for x, y in zip(*cells))


def _next_ask(needs: np.ndarray, depth: np.ndarray, cap: int, extra: int, max_depth: int) -> tuple[int, int] | None:
    """(cap, extra) of _thin_locally's next round after one that still lost (needs: the
    samples' depths for two layers, _thin_asks with extra 0 and max_depth; depth: the round's,
    _thin_asks with max_depth = cap).  While the cap withholds from some sample the levels its
    two layers need, the cap deepens by one and nothing else does.
    (Before, those samples waited at the cap while the others went one level deeper a round:
    nine 0.01 slots in a 4 x 4 x 0.5 plate at diag/40 ask 5 levels, and three passes at
    size / 8 each lost the same 1.3 %, 18.5 s in all, where size / 16 keeps the slots, 9.9.)
    Otherwise one level more for every sample (extra), the cap following once all have
    reached it; None once every sample is at max_depth (no round left)."""
    if np.any(needs > cap):
        return cap + 1, extra
    if depth.min() < cap:
        return cap, extra + 1
    return (cap + 1, extra + 1) if cap < max_depth else None


#: Before the first round near thin places, where the whole band at size / 2 lost, the whole
#: band at size / 4 is tried when estimated at under this share of the round's tets and no
#: wall or gap measured is thinner than size / 8.  _local_tets overestimates a round's tets
#: 3.4-7.2 x and estimate_tets a whole band's 1.5-1.9 x, so a third means the band is expected
#: to make no more tets than the round.  A part about as thin as size / 4 all over is then
#: meshed whole instead of near all of it (tray_bottom at diag/40: 177 k tets against 1.24 M;
#: round_rod at diag/80: 0.63 M against 4.05 M; a bent 1.2 mm sheet bracket at diag/40: 88 k
#: against 0.61 M).  Estimated at 0.37-0.85 of the round, it made up to twice the round's tets
#: (fea_part at diag/80: 5.28 M against 2.66 M); with a wall or gap under size / 8 it lost in 9
#: of the 11 passes of the corpus and unseen files (session 49), each a pass spent for nothing.
QUARTER_BAND_SHARE = 1 / 3
#: Rounds near thin places stop when the samples at min_size can go no deeper and this many
#: rounds in a row, each one level deeper for the samples above it, lost the same as the one
#: before (the same components, genus and volume lost): a random plate at diag/80 lost the
#: same genus in four such rounds, 3.1 -> 21.8 M tets, 17 s; another kept its genus in the
#: round after two such (1 here kept it from the solid, 8.4 M tets, session 34).
SAME_LOSS_ROUNDS = 2
#: Why _thin_locally stopped when the next round would not fit in memory.
LOCAL_MEMORY = "it would not fit in memory (max_memory)"
#: Default min_size: size divided by this.  Only the band near thin places goes that deep by
#: default (walls of 1-2 x size / 8 need it: at size / 8 they come apart, session 13's fuzzing).
DEFAULT_MIN_SIZE_DIVISOR = 16
#: Levels below size that the first local rounds (and, unless min_size is given, the whole
#: band) refine to at most: size / 8.  Local rounds that still lose go one level deeper each,
#: down to min_size; parts kept at size / 8 get the same mesh as before the floor deepened.
WHOLE_BAND_DEPTH = 3
#: Refine for walls and gaps whose two sides face each other this squarely (unit normals' dot
#: product below it, about 25 degrees): knife edges and wedge tips are not walls.
THIN_FACING = -0.9


def _local_tets(surface: Surface, field: SizeField, wanted: BandLevels) -> int:
    """estimate_tets plus, for each coarse cell asked d levels finer, a band of BAND_CELLS
    fine cells (six tets each) across the 4**d fine cells its surface meets; never more than
    solid_tets at the finest size asked."""
    depth = wanted.levels.astype(np.int64) - wanted.coarse_level
    local = estimate_tets(surface, field) + int(6 * BAND_CELLS * np.sum(4.0**depth))
    return int(min(local, solid_tets(surface, field.size / 2.0 ** int(depth.max(initial=0)))))


def _local_fits(surface: Surface, field: SizeField, wanted: BandLevels, frame: FatFrame, budget: float) -> bool:
    """Whether a pass with the band refined where wanted asks, in frame (the finest), is
    estimated within budget bytes: its tets (_local_tets) and, before any tet, the crossings of
    the frame's x rows with the whole surface (FramedSurface.build; a patch asked at 1e-5 of
    bunny at diag/10 made it allocate 10 GiB for them)."""
    rows = surface.area * ROWS_PER_AREA / frame.h**2 * CROSSING_BYTES
    return _local_tets(surface, field, wanted) * BYTES_PER_TET + rows <= budget


def _check_memory(surface: Surface, field: SizeField, budget: float) -> None:
    tets = estimate_tets(surface, field)
    if tets * BYTES_PER_TET > budget:
        raise ParoctError(
            f"size = {field.size:.6g} needs about {tets:.3g} lattice tets and {_bytes_text(tets * BYTES_PER_TET)}, "
            f"more than the {_bytes_text(budget)} allowed; use a larger size or raise max_memory (--max-memory)"
        )


def _bytes_text(n: float) -> str:
    """A byte count as people read it: 812 bytes, 3.4 MiB, 2.1 GiB."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n:.0f} bytes"


def _at_boundary_size(field: SizeField, band: float) -> SizeField:
    """The requested size field with a (smaller) boundary size; a uniform request stays uniform."""
    return size_field(band, band if field.max_size == field.size else field.max_size, field.regions, field.function,
                      field.curvature, field.layers, field.patch_sizes)


def _fits(surface: Surface, field: SizeField, band: float, budget: float) -> bool:
    return estimate_tets(surface, _at_boundary_size(field, band)) * BYTES_PER_TET <= budget


def _mesh_at(surface: Surface, field: SizeField, report: MeshReport,
             progress: Callable[[str], None] | None, *, mend: bool = False) -> tuple[MeshResult, str, str, ThinFeatures | None]:
    """One meshing pass at the field's boundary size: (result, what the mesh lost or '', advice,
    the walls and gaps whose sides face each other squarely (THIN_FACING), found only if the
    mesh lost something).

    The band is one level, the setting of Labelle and Shewchuk's bound (DIHEDRAL_BOUND); the
    report's extremes, measured anyway, check it.  Should a tet fall outside (a random union
    and difference of boxes, spheres and cylinders gave 10.50 degrees: three vertices of a
    +000 lattice tet warped 0.39-0.41 of a short edge, two of them off the tet; see
    docs/design.md), the pass runs again with ``mend``: every stuffed tet measured and other
    warps tried near the bad ones (_mend), as where the band changes level."""
    if not mend:
        fresh = report_snapshot(report)
    stages = _Stages(report, progress)
    h = field.size
    frame, snapped, faces, crossings, keys, levels, band = pass_leaves(surface, field, report, stages)

    # The band's vertices come first, so its classes, cut edges and warps keep their ids.
    # Stuffing cuts no template here (every tet it touches is a fat tet of the band), so the
    # minimal face-centre rule's fewer tets can be had.
    vertices = number_vertices(octant_lattice_anchors(keys, frame), np.int64(1) << (frame.levels - levels.astype(np.int64)),
                               prefix=band.coords, eager=False)
    coords, first_centre = vertices.coords, vertices.first_centre
    n_band = band.coords.shape[0]
    inside = vertex_classes(vertices, band.inside)
    stages.done("classify")

    tets = graded_tets(vertices, inside)  # tets with no inside vertex stay outside
    stages.done("emit")

    targets = np.full(coords.shape[0], -1, dtype=np.int64)
    targets[:n_band] = band.targets
    cuts = band.cuts
    # Stuffing needs only the coordinates, tets, classes and cut edges: the leaves' corner and
    # split ids, the leaves and the band's cells are freed before it allocates its output.
    del vertices, band, keys, levels
    lattice_points = frame.to_space(coords)
    points, out_tets, offsets = stuff(lattice_points, coords, tets, inside, cuts, targets, flat_ok=mend,
                                      first_centre=first_centre, with_offsets=mend)
    stages.done("stuff")
    if mend:
        points, out_tets, targets, offsets, flags = _mend(lattice_points, coords, first_centre, tets, inside, cuts,
                                                          targets, points, out_tets, offsets)
        report.bad_tets = int(np.count_nonzero((flags & OUTSIDE) != 0))
        stages.done("warps")
    # The lattice's tets and coordinates and the cut-edge tables are done with: freed before
    # _finish's face matching allocates its own, they are not in the peak.
    cut_faces = cuts.faces
    assert cut_faces is not None  # cut_edges records each cut point's triangle
    del coords, tets, cuts, lattice_points, offsets
    result = _finish(points, out_tets, inside, targets, cut_faces, report, stages, surface, h)
    if not mend and outside_bound(report):
        restore_report(report, fresh)  # the caller's report, as it came in
        return _mesh_at(surface, field, report, progress, mend=True)
    warn_bad_tets(report)
    return (result, *pass_losses(surface, report, frame, faces, snapped, crossings, stages))


def outside_bound(report: MeshReport) -> bool:
    """Whether a pass's measured dihedral angles leave DIHEDRAL_BOUND (it has tets)."""
    return bool(report.n_tets) and not DIHEDRAL_BOUND[0] <= report.min_dihedral <= report.max_dihedral <= DIHEDRAL_BOUND[1]


def report_snapshot(report: MeshReport) -> MeshReport:
    """A copy of report to restore_report from: its lists copied, stage_seconds shared (stage
    times add up over the passes)."""
    return dataclasses.replace(report, stage_seconds=report.stage_seconds, warnings=list(report.warnings),
                               notes=list(report.notes))


def restore_report(report: MeshReport, snapshot: MeshReport) -> None:
    """Put every field of report back as report_snapshot took it, in place."""
    for name in MeshReport.__dataclass_fields__:
        setattr(report, name, getattr(snapshot, name))


def warn_bad_tets(report: MeshReport) -> None:
    """The warning for tets that mending (_mend) left outside DIHEDRAL_BOUND, if any."""
    if report.bad_tets:
        report.warnings.append(f"{report.bad_tets} tets stayed outside [{DIHEDRAL_BOUND[0]}, {DIHEDRAL_BOUND[1]}] "
                               "degrees after other warps were tried near them")


def pass_frame(h: float, surface: Surface, report: MeshReport) -> FatFrame:
    """The frame of a pass at size h around the surface (ParoctError if deeper than
    MAX_FRAME_LEVELS); sets report.levels."""
    frame = fat_frame(surface.bbox_min, surface.bbox_max, h)
    if frame.levels > MAX_FRAME_LEVELS:
        raise ParoctError(f"size = {h:.6g} is too small for the solid (needs {frame.levels} octree levels, "
                          f"at most {MAX_FRAME_LEVELS})")
    report.levels = frame.levels
    return frame


class PassLeaves(NamedTuple):
    """The octree of a pass with its band on one level (pass_leaves): the frame, the surface in
    it (snapped vertices, faces, {X_AXIS_DIRECTION: x-row crossings}) and graded_leaves' sorted
    leaves (keys, levels) and band."""

    frame: FatFrame
    snapped: np.ndarray
    faces: np.ndarray
    crossings: dict
    keys: np.ndarray
    levels: np.ndarray
    band: BandStuffing


def pass_leaves(surface: Surface, field: SizeField, report: MeshReport, stages: _Stages) -> PassLeaves:
    """The frame at field.size (pass_frame), the surface's x rows and the leaves of a pass whose
    band is one level (graded_leaves); fills the report's levels, leaves and leaf levels."""
    frame = pass_frame(field.size, surface, report)
    stages.done("frame")
    snapped, faces, crossings = checked_x_rows(surface, frame)
    keys, levels, band = graded_leaves(frame, snapped, faces, crossings, surface, field, report)
    report.n_leaves = int(keys.shape[0])
    report.leaf_levels = _leaf_levels(frame, levels)
    stages.done("octree")
    return PassLeaves(frame, snapped, faces, crossings, keys, levels, band)


def pass_losses(surface: Surface, report: MeshReport, frame: FatFrame, faces: np.ndarray,
                snapped: np.ndarray | None = None, crossings: dict | None = None,
                stages: _Stages | None = None) -> tuple[str, str, ThinFeatures | None]:
    """What a pass (report) lost (_losses, '' if nothing) and, if it lost something, the advice
    and the walls and gaps to refine near (_walls_of_loss, measured in frame: faces (F, 3)
    int64, snapped and the row crossings by direction if the caller has them), marking the
    stage "features"; else ('', '', None)."""
    lost = _losses(report, surface)
    if not lost:
        return "", "", None
    snapped = rays.snap_surface(frame, surface.vertices) if snapped is None else snapped
    advice, walls = _walls_of_loss(surface, frame, snapped, faces, {} if crossings is None else crossings, report)
    if stages is not None:
        stages.done("features")
    return lost, advice, walls


def _walls_of_loss(surface: Surface, frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, crossings: dict,
                   report: MeshReport) -> tuple[str, ThinFeatures]:
    """After a pass that lost something (report): the advice naming the thinnest wall and gap,
    and the walls and gaps to refine near, measured in frame (snapped, faces: the surface in
    it; crossings: the row crossings by direction computed so far, completed here), with the
    parts the boundary missed.  ParoctError if the triangles near those cross others."""
    features = surface_thin_features(surface, frame, snapped, faces, crossings)
    advice = _thin_feature_advice(features, frame.h, surface)
    walls = features.facing_below(THIN_FACING)
    if _missed(report):
        near = np.zeros(faces.shape[0], dtype=bool)
        near[report.missed_faces] = True
        if report.missed_vertices.size:
            at_missed = np.zeros(snapped.shape[0], dtype=bool)
            at_missed[report.missed_vertices] = True
            near |= at_missed[faces].any(axis=1)
        _refuse_crossings(surface, np.flatnonzero(near))
        walls = _with_missed_parts(walls, frame, snapped, faces[near])
    return advice, walls


def surface_thin_features(surface: Surface, frame: FatFrame, snapped: np.ndarray | None = None,
                          faces: np.ndarray | None = None, crossings: dict | None = None) -> ThinFeatures:
    """The walls and gaps the lattice rows of every direction measure (features.thin_features)
    on the surface in frame; snapped, faces (int64) and crossings (the row crossings by
    direction computed so far, completed in place) if the caller has them."""
    snapped = rays.snap_surface(frame, surface.vertices) if snapped is None else snapped
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64) if faces is None else faces
    crossings = {} if crossings is None else crossings
    for d in range(EDGE_DIRECTIONS.shape[0]):
        if d not in crossings:
            crossings[d] = rays.row_crossings(frame, snapped, faces, d)
    return find_thin_features(frame, crossings, surface.vertices, faces)


def checked_x_rows(surface: Surface, frame: FatFrame) -> tuple[np.ndarray, np.ndarray, dict]:
    """The surface in frame: its vertices snapped (rays.snap_surface), its faces (F, 3) int64
    and {X_AXIS_DIRECTION: its crossings with the rows along x}; ParoctError if a row enters
    or leaves the solid twice in a row (_check_winding), as a pass and paroct info refuse."""
    snapped = rays.snap_surface(frame, surface.vertices)
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    crossings = {X_AXIS_DIRECTION: rays.row_crossings(frame, snapped, faces, X_AXIS_DIRECTION)}
    _check_winding(frame, crossings[X_AXIS_DIRECTION])
    return snapped, faces, crossings


def _check_winding(frame: FatFrame, crossings: rays.RowCrossings, points: np.ndarray | None = None) -> None:
    """Refuse a surface that a lattice row enters twice without leaving (or leaves twice):
    parts that overlap or fold through one another.  Its solid, the points of positive
    winding number, is not what its volume and topology say, so every check of the mesh
    against them would mislead (a self-overlapping bent bar went to min_size and warned of
    dropped thin parts).  points: only the rows through them (rays.first_winding_outside)."""
    bad = rays.first_winding_outside(crossings, points)
    if bad >= 0:
        x, y, z = rays.crossing_points(frame, crossings, np.array([bad]))[0]
        grid = frame.h / 2.0**rays.snap_bits(frame)
        raise ParoctError(f"the surface intersects itself: a line through ({x:.6g}, {y:.6g}, {z:.6g}) enters or leaves "
                          "the solid twice in a row (overlapping or folded parts, or parts less than about "
                          f"{grid:.2g} apart, which the exact arithmetic's grid joins); join the overlapping parts into "
                          "one closed surface first (e.g. a union in manifold3d or a CAD tool)")


def _missed(report: MeshReport) -> bool:
    """Whether the boundary missed a surface vertex or triangle centre (boundary_misses)."""
    return bool(report.missed_vertices.size or report.missed_faces.size)


def _refuse_crossings(surface: Surface, near: np.ndarray) -> None:
    """Refuse a surface whose triangles ``near`` (ids) cross other triangles: a mesh that misses
    part of the surface may do so because the surface passes through the solid's inside (a
    spike pushed through the far side), which the lattice rows need not see.  A part thinner
    than the lattice crosses nothing, and is refined instead."""
    other = crossing_triangles(surface.vertices, surface.faces, near)
    hit = np.flatnonzero(other >= 0)
    if hit.size:
        f, g = int(near[hit[0]]), int(other[hit[0]])
        x, y, z = surface.vertices[surface.faces[f]].mean(axis=0)
        raise ParoctError(f"the surface intersects itself: its triangle {f} (centre ({x:.6g}, {y:.6g}, {z:.6g})) crosses "
                          f"triangle {g}, and {hit.size - 1} more of the triangles near the parts the mesh misses cross "
                          "others; repair the surface (e.g. remove the self-intersections in a mesh tool) first")


def _with_missed_parts(walls: ThinFeatures, frame: FatFrame, snapped: np.ndarray, around: np.ndarray) -> ThinFeatures:
    """walls plus samples of thickness 0 (unknown, see _thin_asks) at the centres of the
    finest cells that the triangles ``around`` (B, 3) the missed surface points meet.  The rows
    measure a part thinner than their spacing only where one happens to cross it (a thin rod
    is crossed in a few places along its length), and its vertices may all lie at its ends."""
    cells = surface_cells(frame, snapped, around, rays.snap_bits(frame), frame.levels)
    points = frame.to_space(octant_lattice_anchors(cells, frame) + 0.5)
    return ThinFeatures(np.concatenate([walls.thickness, np.zeros(points.shape[0])]),
                        np.concatenate([walls.points, points]),
                        np.concatenate([walls.is_wall, np.ones(points.shape[0], dtype=bool)]),
                        np.concatenate([walls.facing, np.full(points.shape[0], -1.0)]))


def _finish(points: np.ndarray, out_tets: np.ndarray, inside: np.ndarray, targets: np.ndarray, cut_faces: np.ndarray,
            report: MeshReport, stages: _Stages, surface: Surface, size: float, *, removed: int = 0,
            lost: np.ndarray | None = None) -> MeshResult:
    """Repair pinches, fill the report's quality, volume and topology, and drop unused points:
    the result of a pass.  points, out_tets: stuff's output; inside, targets (V,): over the
    lattice vertices, points 0..V-1 of the stuffed mesh; cut_faces (E,): the surface triangle
    of each cut point, points V..V+E-1 (CutEdges.faces); size: the band's longest edge.
    removed, lost: where the pinches were repaired already (in ranges), the number of tets
    removed and the mask (len(points),) of their vertices, whose exposed faces can now lie
    on the boundary."""
    core = _core(inside, targets, points.shape[0])
    if lost is not None:
        core &= ~lost
    out_tets, again, faces_out, boundary = remove_pinches(out_tets, core, points)
    report.repaired_tets = removed + again
    stages.done("repair")

    _measure(points, out_tets, core, boundary, report)
    report.missed_vertices, report.missed_faces = boundary_misses(surface, boundary_points(points, faces_out), size)
    points, out_tets, new_id = _compact(points, out_tets)
    point_faces = _point_faces(targets, cut_faces, new_id, points.shape[0])
    mesh = TetMesh(points, out_tets)
    faces_out = np.take(new_id, faces_out)  # every boundary vertex is a tet's: none is -1
    report.n_vertices = int(mesh.points.shape[0])
    stages.done("quality")
    warn_unresolved_cuts(report)
    return MeshResult(mesh, report, surface, faces_out, point_faces)


def warn_unresolved_cuts(report: MeshReport) -> None:
    """The report's warning of cut points placed at edge midpoints, if any were."""
    if report.unresolved_cuts:
        report.warnings.append(
            f"{report.unresolved_cuts} cut points were placed at edge midpoints: no row crossing matched "
            "(lattice vertices lie exactly on the surface there); the boundary is up to size/2 off at those edges"
        )


@nb.njit(cache=True, parallel=True)
def _point_faces(targets, cut_faces, new_id, n_points):
    """The surface triangle (n_points,) int32 each point of the compacted mesh lies on: stuffed
    point p (lattice vertices, targets (V,), then cut points, cut_faces (E,)) is point
    new_id[p] (-1: dropped); a lattice vertex lies on its warp target's, -1 if it does not
    warp; a cut point on its own."""
    faces = np.empty(n_points, dtype=np.int32)
    n = targets.shape[0]
    for p in nb.prange(new_id.shape[0]):
        q = new_id[p]
        if q >= 0:
            faces[q] = cut_faces[p - n] if p >= n else (cut_faces[targets[p]] if targets[p] >= 0 else -1)
    return faces


#: A surface vertex with no mesh boundary vertex within this many times the band's longest
#: edge is missed: the boundary passes more than (MISS_REACH - 1) x size from it, since every
#: point of a boundary triangle lies within one edge of its vertices.  Stuffing cuts sharp
#: edges by well under one size, so only dropped parts (rods, fins, shells thinner than the
#: lattice) and filled gaps reach this.
MISS_REACH = 3.0


def boundary_points(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The points (B, 3) of the vertices that the boundary faces (F, 3) use, in id order.  A
    kernel marks them: numpy's scatter of True at faces.ravel() took 4 ms of tray_bottom's
    boundary at diag/40; compress is 3x points[mask]."""
    return np.compress(used_vertices(faces, points.shape[0]), points, axis=0)


def boundary_misses(surface: Surface, boundary_points: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """The surface vertices and triangles (by their centres; indices, ascending) the mesh
    boundary (its vertices' points (B, 3)) misses: no boundary vertex within MISS_REACH x
    size.  A long triangle's centre tells of a rod dropped between its ends, or of a spike
    through the solid; only triangles with an edge over size are asked (armadillo's 86 k
    centres cost 2 ms a pass)."""
    n = surface.vertices.shape[0]
    long, centres = long_triangle_centres(surface.vertices, surface.faces, size)
    far = far_from_points(np.concatenate([surface.vertices, centres]), boundary_points, MISS_REACH * size)
    return np.flatnonzero(far[:n]), long[far[n:]]


#: Volume loss (relative) above which mesh() raises instead of returning the mesh with a
#: warning: what is left is not the part.
LOST_TOO_MUCH = 0.5
#: Volume loss (relative) above which the mesh is said to have lost part of the solid.
VOLUME_LOSS_WARNING = 0.01


def _losses(report: MeshReport, surface: Surface) -> str:
    """What the mesh lost against the input, as one clause, or '' if nothing."""
    lost = []
    if report.volume_error < -VOLUME_LOSS_WARNING:
        lost.append(f"the mesh lost {-100 * report.volume_error:.1f}% of the volume")
    elif report.volume_error > VOLUME_LOSS_WARNING:
        lost.append(f"the mesh gained {100 * report.volume_error:.1f}% of volume (a gap was filled)")
    if report.boundary_components != report.input_components or report.boundary_genus != report.input_genus:
        lost.append(
            f"the boundary has {report.boundary_components} components and genus {report.boundary_genus} "
            f"(input {report.input_components} and {report.input_genus})"
        )
    if _missed(report):
        x, y, z = (surface.vertices[report.missed_vertices[0]] if report.missed_vertices.size
                   else surface.vertices[surface.faces[report.missed_faces[0]]].mean(axis=0))
        lost.append(f"the boundary misses {report.missed_vertices.size} surface vertices and {report.missed_faces.size} "
                    f"triangle centres by more than "
                    f"{MISS_REACH - 1:g} x size, e.g. ({x:.6g}, {y:.6g}, {z:.6g}) (a part thinner than the lattice was dropped)")
    return " and ".join(lost)


def _thin_feature_advice(features: ThinFeatures, h: float, surface: Surface) -> str:
    """Names the thinnest wall and gap and a size that puts two element layers across them;
    where the rows found none (a part thinner than their spacing is crossed by few or none),
    the solid's mean thickness, twice its volume over its area (a slab's thickness; a rod's
    or ball's is a half and a third of its width), and the size that is half of it."""
    found, smallest = features.thinnest_below(2 * h)
    if not found:
        mean = 2 * surface.volume / surface.area
        if mean / 2 >= h:
            return f"no wall or gap thinner than 2 x size = {2 * h:.4g} was found; try a smaller size"
        return (f"no wall or gap thinner than 2 x size = {2 * h:.4g} was found along the lattice rows, but the solid is "
                f"{mean:.4g} thick on average (twice its volume over its area): size = {mean / 2:.4g} or less would "
                "put two elements across it")
    return f"thinnest {', thinnest '.join(found)}; size = {smallest / 2:.4g} would keep it (now {h:.4g})"


#: Rounds of measure-and-refine a locally refined band gets before paroct refines the whole
#: band instead (each round refines the band around every tet outside DIHEDRAL_BOUND) ...
MAX_REFINE_ROUNDS = 10
#: ... or as soon as this many rounds in a row found no fewer bad tets than the best before.
STALLED_ROUNDS = 3
#: Rounds after the first stuff the coarse cells within this ring of the cells just refined
#: (2:1 balance and templates change the leaves up to about two cells away) and measure the
#: tets two cells less far; the whole band is measured again once those are clean.
WINDOW_RING = 4
#: Rounds of retarget_warps (each followed by stuffing and measuring again what it changed)
#: before the band is refined.
RETARGET_PASSES = 3
#: Mending also tries other warps at needles, tets with 3r/R below this: the bound on the
#: dihedral angles does not limit them (a needle can have good angles), and where the band
#: does not change level stuffing gives none below about 0.1 (corpus, diag/40 to /160).
#: Only tried: a needle left never makes the band finer.
NEEDLE_RATIO = 0.15


def _refined_frame(frame: FatFrame, depth: int) -> FatFrame:
    """The frame ``depth`` levels finer: same origin, so its lattice holds this one's."""
    return FatFrame(origin=frame.origin, h=frame.h / 2**depth, levels=frame.levels + depth)


class LocalAsk(NamedTuple):
    """A round's ask near thin places (_local_ask): the finest frame, the depths (K,) of
    _thin_asks and the band asked in that frame (None if none)."""

    frame: FatFrame
    depth: np.ndarray
    wanted: BandLevels | None


def _local_ask(coarse: FatFrame, walls: ThinFeatures, max_depth: int, extra: int, base: FeatureAsks) -> LocalAsk:
    """LocalAsk: the finest frame, the depths (K,) of _thin_asks and the band asked for in that
    frame, with base's asks too (None if no wall or gap asks: K = 0, or a frame deeper than
    MAX_FRAME_LEVELS)."""
    points, depth = _thin_asks(coarse, walls, max_depth, extra)
    deepest = max(int(depth.max(initial=0)), int(base.depth.max(initial=0)))
    frame = _refined_frame(coarse, deepest)
    if depth.size == 0 or frame.levels > MAX_FRAME_LEVELS:
        return LocalAsk(frame, depth, None)
    walls_asked = band_levels(frame, coarse.levels, points * 2.0**deepest, coarse.levels + depth)
    if base.empty:
        return LocalAsk(frame, depth, walls_asked)
    return LocalAsk(frame, depth, merge_band_levels(walls_asked, _asked_levels(coarse, deepest, base)))


def _asked_levels(coarse: FatFrame, deepest: int, asks: FeatureAsks) -> BandLevels:
    """The band levels asks ask for, in the frame ``deepest`` levels below coarse, each point
    with its ring."""
    frame = _refined_frame(coarse, deepest)
    asked = no_band_levels(coarse.levels)
    coords = coarse.to_lattice(asks.points) * 2.0**deepest
    for ring in np.unique(asks.ring).tolist():
        mine = asks.ring == ring
        asked = merge_band_levels(asked, band_levels(frame, coarse.levels, coords[mine], coarse.levels + asks.depth[mine],
                                                     ring=ring))
    return asked


def _thin_asks(coarse: FatFrame, walls: ThinFeatures, max_depth: int, extra: int) -> tuple[np.ndarray, np.ndarray]:
    """Lattice points (K, 3) of ``coarse`` and depths (K,) in levels below it: two element
    layers across every wall or gap thinner than 2 h (one more level per ``extra``), at most
    max_depth."""
    thin = walls.thickness < 2 * coarse.h
    thickness = walls.thickness[thin]
    # Thickness 0 is unknown (parts the boundary missed, _with_missed_parts): one level to start.
    depth = np.ceil(np.log2(2 * coarse.h / np.where(thickness > 0, thickness, coarse.h)) - 1e-9).astype(np.int64)
    depth = np.clip(depth + extra, 1, max_depth)
    return coarse.to_lattice(walls.points[thin]), depth


@dataclass(frozen=True)
class FramedSurface:
    """The surface in one frame, for the passes that share it: snapped vertices and faces
    (rays.snap_surface), the row crossings computed so far by direction (filled as stuffing
    needs them), the triangles of each surface cell of coarse_level (face_buckets) and the
    finer surface cells found so far (filled as band_cells needs them)."""

    frame: FatFrame
    coarse_level: int
    snapped: np.ndarray
    faces: np.ndarray
    crossings: dict
    buckets: FaceBuckets
    fine_cells: FineSurfaceCells

    @classmethod
    def build(cls, surface: Surface, frame: FatFrame, coarse_level: int) -> FramedSurface:
        snapped = rays.snap_surface(frame, surface.vertices)
        faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
        crossings = {X_AXIS_DIRECTION: rays.row_crossings(frame, snapped, faces, X_AXIS_DIRECTION)}
        return cls(frame, coarse_level, snapped, faces, crossings,
                   face_buckets(frame, snapped, faces, rays.snap_bits(frame), coarse_level), FineSurfaceCells())


def _mesh_locally(surface: Surface, field: SizeField, framed: FramedSurface, wanted: BandLevels,
                  report: MeshReport, progress: Callable[[str], None] | None,
                  window: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[MeshResult | None, BandLevels]:
    """One pass with a band refined where ``wanted`` asks (framed.frame: the finest frame,
    whose level framed.coarse_level has long edge field.size).  Tets outside
    stuffing.DIHEDRAL_BOUND are mended by other warps (retarget_warps) where they can be.
    Returns the result, or None if a tet stays outside, and then where the band must be finer.

    window: (outer, inner) sorted keys of coarse cells.  Then the pass only checks: it stuffs
    the leaves in the outer cells and measures the tets whose lattice vertices all lie in the
    inner ones, and always returns None (no asks: none of those is bad)."""
    stages = _Stages(report, progress)
    frame, coarse_level, snapped, faces = framed.frame, framed.coarse_level, framed.snapped, framed.faces
    crossings, buckets = framed.crossings, framed.buckets
    report.levels = frame.levels
    bits = rays.snap_bits(frame)
    band_keys, band_cell_levels = band_cells(frame, snapped, faces, bits, buckets, wanted, framed.fine_cells)
    keys, levels, in_band = local_leaves(frame, band_keys, band_cell_levels, buckets.keys, coarse_level,
                                         crossings[X_AXIS_DIRECTION], surface.bbox_min - field.size,
                                         surface.bbox_max + field.size, field)
    report.n_leaves = int(keys.shape[0])
    report.leaf_levels = _leaf_levels(frame, levels)
    if window is not None:
        keep = octants_in_cells(keys, window[0], coarse_level)
        keys, levels, in_band = keys[keep], levels[keep], in_band[keep]
    stages.done("octree")

    sides = np.int64(1) << (frame.levels - levels.astype(np.int64))
    # Stuffing cuts the templates of band leaves here: the eager rule's, on which its quad rule
    # never cycles; the other leaves keep the minimal rule's fewer tets.
    vertices = number_vertices(octant_lattice_anchors(keys, frame), sides, eager=in_band)
    coords, first_centre = vertices.coords, vertices.first_centre
    inside = np.ones(coords.shape[0], dtype=bool)
    ids = _band_vertex_ids(vertices, in_band)
    inside[ids] = rays.winding_numbers(crossings[X_AXIS_DIRECTION], np.take(coords, ids, axis=0)) > 0
    del ids
    stages.done("classify")

    tets = graded_tets(vertices, inside)
    spacing = vertex_spacing(vertices, sides)
    # The leaves and their corner and split ids are done with: freed before the cut edges and
    # stuffing allocate (fea_part at diag/80: 35 MB).
    del vertices, keys, levels, in_band, sides
    stages.done("emit")

    cuts = cut_edges(frame, snapped, faces, coords, collect_cut_edges(np.ascontiguousarray(tets), inside, coords), inside,
                     crossings, report, buckets)
    targets = warp_targets(cuts, coords, frame.h, spacing)
    lattice_points = frame.to_space(coords)
    points, out_tets, offsets = stuff(lattice_points, coords, tets, inside, cuts, targets, flat_ok=True,
                                      first_centre=first_centre)
    stages.done("stuff")

    # Measured before the pinch repair, which needs a mesh that does not fold: a band that
    # changes level may give tets outside the bound.  Other warps near them mend most; where
    # they do not, this pass only says where the band must be finer.
    points, out_tets, targets, offsets, flags = _mend(lattice_points, coords, first_centre, tets, inside, cuts,
                                                      targets, points, out_tets, offsets)
    # != 0: np.flatnonzero of a bool mask is 20x faster than of uint8 (0.4 vs 8 ms on
    # fea_part's 2.7 M tets at diag/80).
    bad = np.flatnonzero((flags & OUTSIDE) != 0)
    stages.done("warps")
    lattice = out_tets[bad].astype(np.int64)
    is_lattice = lattice < coords.shape[0]  # the bad tets' lattice vertices (every tet has one)
    if window is not None and bad.size:
        some = lattice[np.arange(bad.size), np.argmax(is_lattice, axis=1)][:, None]
        cells = morton_keys((coords[np.where(is_lattice, lattice, some)].reshape(-1, 3)
                             >> (frame.levels - coarse_level)) << (MAX_LEVEL - coarse_level))
        measured = octants_in_cells(cells, window[1], coarse_level).reshape(-1, 4).all(axis=1)
        bad, lattice, is_lattice = bad[measured], lattice[measured], is_lattice[measured]
    report.bad_tets = int(bad.size)
    asks = no_band_levels(coarse_level)
    if bad.size:
        # Refine the band around each bad tet to the finest level among its lattice vertices'
        # leaves (one level more if they are all alike).
        sides = spacing[np.where(is_lattice, lattice, 0)]
        finest_side = np.where(is_lattice, sides, np.iinfo(np.int64).max).min(axis=1)
        level = frame.levels - np.log2(finest_side).astype(np.int64)
        level = np.where(finest_side == np.where(is_lattice, sides, 0).max(axis=1), level + 1, level)
        level = np.minimum(level, frame.levels)
        rows, cols = np.nonzero(is_lattice)
        asks = band_levels(frame, coarse_level, coords[lattice[rows, cols]], level[rows])
        stages.done("quality")
        return None, asks
    if window is not None:
        stages.done("quality")
        return None, asks
    # As in _mesh_at: what stuffing needed is freed before _finish allocates.
    cut_faces = cuts.faces
    assert cut_faces is not None  # cut_edges records each cut point's triangle
    del coords, tets, cuts, spacing, lattice_points, flags, offsets
    return _finish(points, out_tets, inside, targets, cut_faces, report, stages, surface, field.size), asks


def _mend(lattice_points, coords, first_centre: int, tets, inside, cuts: CutEdges, targets, points, out_tets,
          offsets) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Measure the stuffed tets (stuff's points, out_tets, offsets for these lattice tets and
    warp targets) and try other warps near those outside DIHEDRAL_BOUND or needles
    (retarget_warps), restuffing and measuring again, RETARGET_PASSES times at most, or until
    a search moves nothing; one known to (the last settled and covered every vertex it would
    search) is skipped: on fea_part at diag/80 the third search, 18 ms, found nothing to move.
    Returns (points, out_tets, targets, offsets, flags (M,) uint8: outlier_flags' verdicts)."""
    flags = _outside_bound(points, out_tets, _core(inside, targets, points.shape[0]))
    last = None
    for _ in range(RETARGET_PASSES):
        if not flags.any():
            break
        # points follow the new warps in place: restuff takes them as they are.
        last = retarget_warps(lattice_points, coords, tets, inside, cuts, targets, np.flatnonzero(flags != 0),
                              NEEDLE_RATIO, offsets=offsets, points=points,
                              settled=last.searched if last is not None and last.settled else None,
                              first_centre=first_centre)
        if not last.changed:
            break
        # Only the lattice tets around the vertices that warp elsewhere change: stuff and
        # measure those again; the others' tets and flags move in place.
        points, out_tets, again, offsets, flags = restuff(lattice_points, coords, tets, inside, cuts, targets, out_tets,
                                                          last.targets, offsets=offsets, flat_ok=True, points=points,
                                                          flags=flags, rows=last.rows, first_centre=first_centre)
        targets = last.targets
        flags[again] = _outside_bound(points, np.take(out_tets, again, axis=0), _core(inside, targets, points.shape[0]))
    return points, out_tets, targets, offsets, flags


def _core(inside: np.ndarray, targets: np.ndarray, n_points: int) -> np.ndarray:
    """Mask (n_points,) of the stuffed mesh's core vertices: the unwarped inside lattice
    vertices (points 0..V-1; inside, targets (V,)), not the cut points after them."""
    core = np.zeros(n_points, dtype=bool)
    core[: inside.shape[0]] = inside & (targets < 0)
    return core


def _outside_bound(points: np.ndarray, tets: np.ndarray, core: np.ndarray) -> np.ndarray:
    """Flags (M,) uint8 of the tets: OUTSIDE with a dihedral angle outside DIHEDRAL_BOUND
    (folded and flat ones included: 0 and 180 degrees), NEEDLE for the others with 3r/R below
    NEEDLE_RATIO, else 0 (quality.outlier_flags).  core: _core's mask.  Tets of four core
    vertices are lattice tets stuffing copied, fat tets and transition templates (dihedral
    angles in [30, 135] degrees, 3r/R >= 0.4: docs/transitions.md), so only the band's are
    measured (half of round_rod's 4.05 M tets at diag/80, the band of a thin rod)."""
    return outlier_flags(points, tets, core, DIHEDRAL_BOUND[0], DIHEDRAL_BOUND[1], NEEDLE_RATIO)


def _leaf_levels(frame: FatFrame, levels: np.ndarray) -> tuple:
    """The distinct leaf levels counted from the finest (0 = finest), ascending."""
    return tuple(int(v) for v in np.flatnonzero(np.bincount(frame.levels - levels.astype(np.int64))))


def _band_vertex_ids(vertices: LeafVertices, in_band: np.ndarray) -> np.ndarray:
    """Ids of the vertices of the band leaves (in_band (L,)): corners and split points."""
    marked = np.zeros(vertices.coords.shape[0], dtype=bool)
    _mark_leaf_vertices(vertices.corner_ids, vertices.split_row, vertices.split_ids,
                        np.ascontiguousarray(in_band, dtype=np.bool_), marked)
    return np.flatnonzero(marked)


@nb.njit(cache=True)
def _mark_leaf_vertices(corner_ids, split_row, split_ids, in_band, marked):
    """marked[v] = True for the corners and split points v of the leaves in_band (numpy's
    boolean gathers of the (L, 8) and (C, 18) tables took 13 ms on tray_bottom)."""
    for i in range(corner_ids.shape[0]):
        if not in_band[i]:
            continue
        for c in range(8):
            marked[corner_ids[i, c]] = True
        r = split_row[i]
        if r >= 0:
            for k in range(split_ids.shape[1]):
                if split_ids[r, k] >= 0:
                    marked[split_ids[r, k]] = True


@dataclass(frozen=True)
class BandStuffing:
    """The finest band's vertices and what stuffing needs of them, computed while building the
    octree: coords (P, 3) int64 lattice coordinates (the corners of the cut cells), inside (P,)
    classes, cuts of their cut edges and warp targets (P,) (stuffing.warp_targets)."""

    coords: np.ndarray
    inside: np.ndarray
    cuts: CutEdges
    targets: np.ndarray


class FinestBand(NamedTuple):
    """The band of a pass whose band is one level (finest_band): surface_keys (S,) sorted keys
    of the finest cells that meet the surface (octree.surface_cells), keys (B,) sorted keys of
    the band's cells, and stuffing, the band's BandStuffing."""

    surface_keys: np.ndarray
    keys: np.ndarray
    stuffing: BandStuffing


def finest_band(frame: FatFrame, snapped, faces, crossings: dict, report: MeshReport) -> FinestBand:
    """The band at the frame's finest level: every cell with corners of both classes (cut
    cells: all tets that stuffing cuts) and every cell with a corner that stuffing warps,
    with the cut cells' corners, classes, cut edges and warps (graded_leaves builds the
    octree around it).  crossings: {X_AXIS_DIRECTION: x-row crossings, ...}; the other
    directions' rows are crossed here and added to it."""
    finest = frame.levels
    met = surface_cells(frame, snapped, faces, rays.snap_bits(frame), finest)
    corners = number_vertices(octant_lattice_anchors(met, frame), np.ones(met.shape[0], dtype=np.int64))
    corner_class = rays.winding_numbers(crossings[X_AXIS_DIRECTION], corners.coords) > 0
    is_cut = mixed_rows(corners.corner_ids, corner_class)
    cut_keys = np.compress(is_cut, met)
    cut_cells, kept = _restrict(corners, is_cut)
    inside = corner_class[kept]
    cuts = cut_edges(frame, snapped, faces, cut_cells.coords, cell_cut_edges(cut_cells.corner_ids, inside), inside,
                     crossings, report)
    targets = warp_targets(cuts, cut_cells.coords, frame.h)
    around = _cells_around(cut_cells.coords, targets >= 0, MAX_LEVEL - finest)
    band = unique_level_keys(np.concatenate([cut_keys, around]), finest)
    return FinestBand(met, band, BandStuffing(cut_cells.coords, inside, cuts, targets))


def graded_leaves(frame: FatFrame, snapped, faces, crossings: dict, surface: Surface, field: SizeField,
                  report: MeshReport, band: FinestBand | None = None) -> tuple[np.ndarray, np.ndarray, BandStuffing]:
    """Sorted leaves (keys (N,) int64, levels (N,) int8) of the 2:1-balanced octree that may hold
    inside tets, and the stuffing data of the band.

    The finest level holds the *band* (finest_band, unless given): every cell with corners of
    both classes (cut cells: all tets that stuffing cuts) and every cell with a corner that
    stuffing warps.  So stuffing only touches fat tets of one size (the Labelle-Shewchuk
    setting), and the boundary is exactly the uniform lattice's.  Every other leaf has all
    finest-level lattice points in its closure of one class (else a fine edge in it would be
    cut and its cell in the band), and none warped: its anchor's winding number classifies
    it, outside leaves are dropped, and inside leaves emit fat tets or transition templates.
    The size field decides the rest, up to max_size.
    """
    if band is None:
        band = finest_band(frame, snapped, faces, crossings, report)
    keys, levels = octree_around_band(frame, crossings[X_AXIS_DIRECTION], surface, field, band.surface_keys, band.keys)
    return keys, levels, band.stuffing


def octree_around_band(frame: FatFrame, x_crossings: rays.RowCrossings, surface: Surface, field: SizeField,
                       surface_keys: np.ndarray, band_keys: np.ndarray, *,
                       prune: Callable[[np.ndarray, int], np.ndarray] | None = None,
                       within: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """graded_leaves' octree around a band: the band's cells (band_keys, sorted, finest level)
    and the size field's seeds (pruned where no cell meeting the surface, surface_keys, lies),
    balanced, with the leaves outside the solid dropped: sorted (keys (N,) int64, levels (N,)
    int8).  prune: size_seeds' prune instead of that one; within (first, end): only the leaves
    of keys first..end-1 (partition.octree_in_range passes both)."""
    finest = frame.levels
    seeds = size_seeds(frame, surface.bbox_min - frame.h, surface.bbox_max + frame.h, field,
                       prune=surface_prune(frame, surface_keys, x_crossings) if prune is None else prune)
    seed_keys, seed_levels, _ = seeds
    if np.all(seed_levels == finest):  # a uniform lattice: already balanced, nothing to complete
        keys = sorted_unique(np.concatenate([band_keys, seed_keys]))
        levels = np.full(keys.shape[0], finest, dtype=np.int8)
    else:
        keys, levels = balance(np.concatenate([band_keys, seed_keys]),
                               np.concatenate([np.full(band_keys.shape[0], finest, dtype=np.int8), seed_levels]))
    if within is not None:
        mine = (keys >= within[0]) & (keys < within[1])
        keys, levels = keys[mine], levels[mine]
    in_band = np.zeros(keys.shape[0], dtype=bool)
    fine = np.nonzero(levels == finest)[0]
    in_band[fine] = sorted_lookup(band_keys, keys[fine])[1]
    keep = kept_leaves(frame, keys, levels, in_band, seeds, x_crossings)
    return np.compress(keep, keys), np.compress(keep, levels)


@nb.njit(cache=True, parallel=True)
def _cells_around(coords, marked, shift):
    """Octree keys (K,) of the unit cells around the marked lattice points (coords (V, 3)):
    the 8 cells with the point as a corner, those of non-negative anchor, with repeats, in
    point order; anchors shifted left by ``shift`` (to octree coordinates) before keying.
    Count, prefix sum and fill over chunks of the points.  (numpy's broadcast, filter and
    keying took 3 ms on plate_holes diag/80.)"""
    n_points = coords.shape[0]
    n_chunks = min(n_points, POINT_CHUNKS)
    starts = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in nb.prange(n_chunks):
        starts[c + 1] = _cells_around_chunk(coords, marked, shift, c * n_points // n_chunks,
                                            (c + 1) * n_points // n_chunks, starts[:0], 0)
    for c in range(n_chunks):
        starts[c + 1] += starts[c]
    out = np.empty(starts[n_chunks], dtype=np.int64)
    for c in nb.prange(n_chunks):
        _cells_around_chunk(coords, marked, shift, c * n_points // n_chunks, (c + 1) * n_points // n_chunks, out,
                            starts[c])
    return out


@nb.njit(cache=True, inline="always")
def _cells_around_chunk(coords, marked, shift, first, end, out, k):
    """_cells_around for points first..end-1: writes their keys to out from k on unless out is
    empty (counting only); returns how many."""
    start = k
    for v in range(first, end):
        if not marked[v]:
            continue
        for c in range(8):
            x = coords[v, 0] - CUBE_CORNERS[c, 0]
            y = coords[v, 1] - CUBE_CORNERS[c, 1]
            z = coords[v, 2] - CUBE_CORNERS[c, 2]
            if x >= 0 and y >= 0 and z >= 0:
                if out.shape[0]:
                    out[k] = morton_key(x << shift, y << shift, z << shift)
                k += 1
    return k - start


def vertex_classes(vertices: LeafVertices, band_inside: np.ndarray) -> np.ndarray:
    """Class (V,) bool of every vertex of graded_leaves' leaves, numbered with the band's
    vertices (band_inside (P,)) first: no winding numbers needed.

    Every other vertex belongs to a leaf that is not a cut cell, so all finest lattice points
    in the leaf's closure share one class (graded_leaves): the class of a band vertex among its
    corners (a band cell around a warped vertex has that vertex), else inside (a leaf with no
    band corner is kept only when its anchor is inside).
    """
    inside = np.empty(vertices.coords.shape[0], dtype=bool)
    inside[: band_inside.shape[0]] = band_inside
    _spread_leaf_classes(vertices.corner_ids, vertices.split_row, vertices.split_ids, inside, band_inside.shape[0])
    return inside


@nb.njit(cache=True)
def _spread_leaf_classes(corner_ids, split_row, split_ids, inside, n_band):
    for i in range(corner_ids.shape[0]):
        leaf_inside = True
        for c in range(8):
            if corner_ids[i, c] < n_band:
                leaf_inside = inside[corner_ids[i, c]]
                break
        for c in range(8):
            if corner_ids[i, c] >= n_band:
                inside[corner_ids[i, c]] = leaf_inside
        r = split_row[i]
        if r >= 0:
            for p in range(split_ids.shape[1]):
                if split_ids[r, p] >= n_band:
                    inside[split_ids[r, p]] = leaf_inside


def _restrict(vertices: LeafVertices, leaves: np.ndarray) -> tuple[LeafVertices, np.ndarray]:
    """The vertices of the selected leaves (mask (L,)) of a one-level octree, renumbered in
    order, and the mask (V,) of the old vertices kept."""
    corner_ids, coords, kept = _restricted(vertices.corner_ids, leaves, vertices.coords)
    return LeafVertices(corner_ids, np.full(corner_ids.shape[0], -1, dtype=np.int64),
                        np.zeros((0, 18), dtype=np.int32), coords, coords.shape[0]), kept


@nb.njit(cache=True)
def _restricted(corner_ids, leaves, coords):
    """_restrict's corner ids (K, 8) int32 renumbered, coordinates (W, 3) and kept mask (V,),
    in one pass each (numpy's boolean row gathers and remaps took 1.6 ms on plate_holes)."""
    kept = np.zeros(coords.shape[0], dtype=np.bool_)
    n = 0
    for i in range(leaves.shape[0]):
        if leaves[i]:
            n += 1
            for c in range(8):
                kept[corner_ids[i, c]] = True
    new_id = np.empty(coords.shape[0], dtype=np.int32)
    m = 0
    for v in range(coords.shape[0]):
        new_id[v] = m
        m += kept[v]
    out_coords = np.empty((m, 3), dtype=coords.dtype)
    for v in range(coords.shape[0]):
        if kept[v]:
            for k in range(3):
                out_coords[new_id[v], k] = coords[v, k]
    out_ids = np.empty((n, 8), dtype=np.int32)
    n = 0
    for i in range(leaves.shape[0]):
        if leaves[i]:
            for c in range(8):
                out_ids[n, c] = new_id[corner_ids[i, c]]
            n += 1
    return out_ids, out_coords, kept


def cut_edges(frame: FatFrame, snapped, faces, coords, edges: tuple, inside, crossings: dict, report: MeshReport,
              buckets: FaceBuckets | None = None) -> CutEdges:
    """Cut points of the edges whose ends differ in class, ``edges`` as collect_cut_edges
    gives them for tets (or cell_cut_edges for the cells of a one-level band): unit lattice
    edges along their rows, others (coarse lattice edges, template edges) against the
    triangles of ``buckets`` (needed only if there are such edges)."""
    starts, ends, dirs, *table = edges
    fracs = np.empty(starts.shape[0])
    crossed = np.empty(starts.shape[0], dtype=np.int32)
    other = np.nonzero(dirs < 0)[0]
    if other.size:
        if buckets is None:
            raise ValueError(f"{other.size} cut edges are not unit lattice edges: cut_edges needs face buckets")
        f, unresolved, hit = rays.segment_cut_fractions(buckets, frame, snapped, faces, coords, starts[other],
                                                        ends[other], inside[starts[other]])
        fracs[other], crossed[other] = f, hit
        report.unresolved_cuts += int(unresolved.sum())
    near = None
    status = np.zeros(starts.shape[0], dtype=np.int8)
    rows_of = {}  # the crossings read here: every row, or near the unit edges only (not kept)
    per_direction = _direction_counts(dirs, EDGE_DIRECTIONS.shape[0])
    for d in range(EDGE_DIRECTIONS.shape[0]):
        if per_direction[d] == 0:
            continue
        if d in crossings:
            rows_of[d] = crossings[d]
        elif other.size == 0:
            rows_of[d] = crossings[d] = rays.row_crossings(frame, snapped, faces, d)
        else:
            # A band that changes level: its unit edges lie in its finest leaves, often a small
            # part of the surface, so only the triangles of the coarse cells holding them are
            # crossed.  (A band of one level cuts unit edges only, and needs every row.)
            if near is None:
                assert buckets is not None  # checked above, as other.size > 0
                near = np.flatnonzero(_faces_near_unit_edges(frame, buckets, coords, starts, ends, dirs, faces.shape[0]))
            rows_of[d] = rays.row_crossings(frame, snapped, faces, d, near)
    rays.add_edge_cut_fractions(rows_of, coords, starts, inside, dirs, fracs, status, crossed)
    report.unresolved_cuts += int(status.sum())
    points = _cut_points(coords, starts, ends, fracs, np.ascontiguousarray(frame.origin, dtype=np.float64),
                         float(frame.h), LATTICE_TO_SPACE)
    return CutEdges(starts, ends, dirs, fracs, points, tuple(table), crossed)


@nb.njit(cache=True)
def _direction_counts(dirs, n_directions):
    """Count (n_directions,) of the edges of each direction (dirs -1, other edges, not
    counted): numpy's bincount of dirs + 1 wrote an (E,) temporary first (2.3 ms of
    tray_bottom's 1.2 M cut edges at diag/40)."""
    counts = np.zeros(n_directions, dtype=np.int64)
    for e in range(dirs.shape[0]):
        if dirs[e] >= 0:
            counts[dirs[e]] += 1
    return counts


def _faces_near_unit_edges(frame: FatFrame, buckets: FaceBuckets, coords: np.ndarray, starts: np.ndarray,
                           ends: np.ndarray, dirs: np.ndarray, n_faces: int) -> np.ndarray:
    """Mask (n_faces,) of the triangles in the buckets of the cells holding an end of a unit
    lattice edge (dirs >= 0): a closed unit edge lies in the closed cell of either end, so
    these triangles give all its crossings."""
    unit = dirs >= 0
    ends_used = np.zeros(coords.shape[0], dtype=bool)
    ends_used[starts[unit]] = True
    ends_used[ends[unit]] = True
    at = np.compress(ends_used, coords, axis=0)  # a boolean index of (V, 3) took 3x longer
    at <<= MAX_LEVEL - frame.levels
    return faces_meeting_cells(buckets, ancestor_keys(morton_keys(at), buckets.level), n_faces)


@nb.njit(cache=True, parallel=True)
def _cut_points(coords, starts, ends, fracs, origin, h, matrix):
    """Space points (E, 3) float64 at fraction fracs[e] from coords[starts[e]] to
    coords[ends[e]]: frame.to_space(coords[starts] + fracs[:, None] * (coords[ends] -
    coords[starts])), same rounding, without the lattice points' array in between."""
    out = np.empty((starts.shape[0], 3))
    for e in nb.prange(starts.shape[0]):
        p, q = starts[e], ends[e]
        f = fracs[e]
        space_point(origin, h, matrix, float(coords[p, 0]) + f * float(coords[q, 0] - coords[p, 0]),
                    float(coords[p, 1]) + f * float(coords[q, 1] - coords[p, 1]),
                    float(coords[p, 2]) + f * float(coords[q, 2] - coords[p, 2]), out, e)
    return out


def _compact(points, tets):
    """Drop unreferenced points (unused cut points, vertices of dropped tets); keep the order.
    tets (M, 4) int32 are renumbered in place (a new (M, 4) array cost a fresh page every
    256 tets) and returned, with the new id of each old point (-1: dropped)."""
    new_id = _used_ids(tets, points.shape[0])
    _renumber(tets, new_id)
    return np.compress(new_id >= 0, points, axis=0), tets, new_id  # compress: 3x a boolean index


@nb.njit(cache=True, parallel=True)
def _used_ids(tets, n_points):
    """New id (n_points,) int32 of each point that a tet uses, numbered in point order; -1 for
    the others.  Marks in parallel (every thread writes True), then counts, prefix-sums and
    fills over chunks of the points (serial, 0.28 ms of bunny's 160 k tets at diag/80; 0.12)."""
    used = np.zeros(n_points, dtype=np.bool_)
    for t in nb.prange(tets.shape[0]):
        for k in range(tets.shape[1]):
            used[tets[t, k]] = True
    n_chunks = min(n_points, POINT_CHUNKS)
    starts = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in nb.prange(n_chunks):
        count = 0
        for v in range(c * n_points // n_chunks, (c + 1) * n_points // n_chunks):
            count += used[v]
        starts[c + 1] = count
    for c in range(n_chunks):
        starts[c + 1] += starts[c]
    new_id = np.empty(n_points, dtype=np.int32)
    for c in nb.prange(n_chunks):
        n = starts[c]
        for v in range(c * n_points // n_chunks, (c + 1) * n_points // n_chunks):
            new_id[v] = n if used[v] else -1
            n += used[v]
    return new_id


#: Chunks of the points that _used_ids counts and fills in parallel.
POINT_CHUNKS = 64


@nb.njit(cache=True, parallel=True)
def _renumber(tets, new_id):
    """tets[t, i] = new_id[tets[t, i]], in place."""
    for t in nb.prange(tets.shape[0]):
        for i in range(4):
            tets[t, i] = new_id[tets[t, i]]


def _measure(points, tets, core, topo: SurfaceTopology, report: MeshReport) -> None:
    """Quality, volume and boundary topology (topo: the boundary's).  Tets with all four vertices
    core (unwarped inside lattice vertices) are lattice tets the boundary does not touch: their
    extreme dihedral angles are reported apart (they must stay in [30, 135] degrees)."""
    report_measures(summarize(points, tets, core, FAT_RADIUS_RATIO), int(tets.shape[0]), topo, report)


def report_measures(summary: TetSummary, n_tets: int, topo: SurfaceTopology, report: MeshReport) -> None:
    """_measure's report of n_tets tets' summary and their boundary's topology."""
    report.n_tets = n_tets
    if n_tets:
        report.min_dihedral = summary.min_dihedral
        report.max_dihedral = summary.max_dihedral
        report.min_radius_ratio = summary.min_radius_ratio
        report.fat_fraction = summary.n_fat / n_tets
        report.interior_min_dihedral = summary.interior_min_dihedral
        report.interior_max_dihedral = summary.interior_max_dihedral
    report.mesh_volume = summary.volume
    report.boundary_genus = topo.genus
    report.boundary_components = topo.components
    report.boundary_manifold = topo.manifold
