"""Meshing in Morton ranges: the key space cut into ranges of whole max_size octants, each
range's band, octree and tets built from the surface near it and from its neighbours, and
the pieces merged.

Steps toward meshes of 1e9 tets on many workers (docs/design.md, "Toward partitions by
Morton ranges").  A range's band (``band_in_range``: its surface cells, cut cells, classes,
cut points and warps) needs the triangles near it and the x rows through its corners; its
octree (``octree_in_range``) the band and seeds of one ring of max_size octants around it
(the insulation layer of 2:1 balance); its tets (``mesh_range``) its leaves, the leaves
touching them (``touching_leaves``) and the band pieces holding those.  Pieces name points
by lattice coordinates and cut points by their edge (``pack_coords``, ``edge_keys``), so they
join with no shared numbering.  The pinch repair (``range_pinches``) and the finish (quality,
topology, missed parts, compaction: ``range_finish``) run in the ranges, only boundary faces,
counts and used points leaving them; mending by other warps, where a tet leaves the bound,
runs on the merged mesh: the ranges' lattice tets (``range_lattice``) are joined
(``merge_range_lattices``), stuffed and mended as one.
The merged mesh is the one-process pass's, tet for tet and bit for bit
(tests/test_partition.py), because every tie stuffing and mending break is broken by
lattice coordinates, not by vertex ids (sessions 41, 43, 46), and each range's band and
octree are the whole surface's there.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import partial
from typing import Callable, Iterable, Iterator, NamedTuple, Sequence

import numba as nb
import numpy as np

from . import rays
from .band import surface_prune
from .errors import ParoctError
from .frame import CUBE_CORNERS, EDGE_DIRECTIONS, X_AXIS_DIRECTION, FatFrame, row_basis
from .lattice import LeafVertices, graded_tets, number_vertices
from .mesher import (BandStuffing, FinestBand, MeshReport, MeshResult, PassOutcome, TetMesh, _at_boundary_size,
                     _cells_around, _check_memory, _check_winding, _core, _finish, _leaf_levels, _mend, _pass_report,
                     _restrict, _spread_leaf_classes, _Stages, checked_request, cut_edges, halve_whole_band,
                     octree_around_band, outside_bound, pass_frame, pass_losses, report_measures, report_snapshot,
                     restore_report, vertex_classes, warn_bad_tets, warn_unresolved_cuts, with_repairs)
from .octant import (MAX_LEVEL, is_ascending, morton_coords, morton_key, morton_keys, octant_last_key,
                     sorted_lookup)
from .octree import _largest_fitting, octant_lattice_anchors, surface_cells, unique_level_keys
from .sizing import OUTSIDE, UNDECIDED, SizeField, size_field
from .quality import OUTSIDE as OUTSIDE_BOUND
from .owners import owned_ids
from .range_finish import finish_in_ranges
from .range_pinches import BoundaryFaces, OwnerFans, RangeTets, fans_by_owners, owned_boundary, repair_pinches_in_ranges
from .stuffing import CutEdges, cell_cut_edges, collect_cut_edges, mixed_rows, stuff, warp_targets
from .surface import Surface, SurfaceSource

#: No lattice points: (0, 3) int64, what joins of no pieces start from.
_NO_COORDS = np.zeros((0, 3), dtype=np.int64)
#: Bits per axis of a packed lattice coordinate (pack_coords): lattice coordinates of a frame
#: reach 2**MAX_LEVEL.
_COORD_BITS = 21


@nb.njit(cache=True)
def _touching(keys, levels, first, end):
    touches = np.zeros(keys.shape[0], dtype=np.bool_)
    if first == end:
        return touches
    root = np.int64(1) << MAX_LEVEL
    # Keys from the range's first leaf to its last one's last cell are its leaves' or no
    # leaf's (outside the solid): no search there.
    lo, hi = keys[first], octant_last_key(keys[end - 1], levels[end - 1])
    for i in range(first, end):
        side = np.int64(1) << (MAX_LEVEL - levels[i])
        step = max(side >> 1, np.int64(1))  # a touching leaf of a 2:1-balanced tree is no smaller
        reach = side // step  # probe cells -1 .. reach along each axis: a ring around the leaf
        x0, y0, z0 = morton_coords(keys[i])
        # Morton keys grow along each axis: the ring's keys lie between its corners' keys.
        if lo <= morton_key(max(x0 - step, 0), max(y0 - step, 0), max(z0 - step, 0)) and \
                morton_key(min(x0 + side, root - 1), min(y0 + side, root - 1), min(z0 + side, root - 1)) <= hi:
            continue
        for c in range(-1, reach + 1):
            for bb in range(-1, reach + 1):
                for a in range(-1, reach + 1):
                    if 0 <= a < reach and 0 <= bb < reach and 0 <= c < reach:
                        continue  # inside the leaf
                    x, y, z = x0 + a * step, y0 + bb * step, z0 + c * step
                    if x < 0 or y < 0 or z < 0 or x >= root or y >= root or z >= root:
                        continue
                    key = morton_key(x, y, z)
                    if lo <= key <= hi:
                        continue
                    j = np.searchsorted(keys, key, side="right") - 1
                    if j >= 0 and key <= octant_last_key(keys[j], levels[j]) and not first <= j < end:
                        touches[j] = True
    return touches


def touching_leaves(keys: np.ndarray, levels: np.ndarray, first: int, end: int) -> np.ndarray:
    """Indices (ascending) of the leaves outside keys[first:end] whose closed cubes meet the
    closed cube of a leaf in it.

    keys (N,) int64, levels (N,) int8: the leaves of a 2:1-balanced octree (face, edge and
    corner balance; leaves may be missing, as graded_leaves drops those outside the solid),
    sorted by key.  A leaf touching one of side s has side at least s / 2, so it holds one of
    the cells of side s / 2 around it, and it is found by the search for the leaf holding
    that cell's anchor (tests/naive.py: every pair of boxes compared)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    levels = np.ascontiguousarray(levels, dtype=np.int8)
    if not 0 <= first <= end <= keys.shape[0]:
        raise ValueError(f"first = {first}, end = {end}: not a range of the {keys.shape[0]} leaves")
    return np.flatnonzero(_touching(keys, levels, first, end))


def pack_coords(coords: np.ndarray) -> np.ndarray:
    """Lattice coordinates (V, 3) as one int64 each (x | y << 21 | z << 42), equal iff the
    points are."""
    coords = np.asarray(coords, dtype=np.int64)
    return coords[:, 0] | (coords[:, 1] << _COORD_BITS) | (coords[:, 2] << (2 * _COORD_BITS))


def edge_keys(starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The key (E,) int64 of each lattice edge from starts to ends (E, 3): pack_coords of the
    sum of its ends, twice its midpoint, the same whatever numbers the vertices (distinct for
    the edges of a conforming complex, and below 2**21 an axis in a frame of at most
    MAX_LEVEL - 1 levels)."""
    return pack_coords(np.asarray(starts, dtype=np.int64) + np.asarray(ends, dtype=np.int64))


@nb.njit(cache=True)
def _interval_box(first, end, levels):
    """Bounding box (lo (3,), hi (3,) int64, finest-cell coordinates, inclusive) of the finest
    cells of Morton key in [first, end) of a frame of ``levels`` levels, from the coarsest
    octants tiling the interval (hi < lo if it is empty)."""
    lo = np.full(3, np.int64(1) << MAX_LEVEL, dtype=np.int64)
    hi = np.full(3, np.int64(-1), dtype=np.int64)
    shift = MAX_LEVEL - levels
    at = np.int64(first)
    while at < end:
        lev = _largest_fitting(at, end)
        x, y, z = morton_coords(at)
        side = np.int64(1) << (MAX_LEVEL - lev)
        lo[0], lo[1], lo[2] = min(lo[0], x >> shift), min(lo[1], y >> shift), min(lo[2], z >> shift)
        hi[0] = max(hi[0], ((x + side) >> shift) - 1)
        hi[1] = max(hi[1], ((y + side) >> shift) - 1)
        hi[2] = max(hi[2], ((z + side) >> shift) - 1)
        at += np.int64(1) << (3 * (MAX_LEVEL - lev))
    return lo, hi


@nb.njit(cache=True)
def _box_meets_interval(lo, hi, levels, first, end, stack):
    """Whether the box of cells lo..hi (inclusive, (3,) int64 coordinates of the cells of
    ``levels``, within 0 .. 2**levels - 1) holds a cell of Morton key in [first, end)
    (MAX_LEVEL keys): an exact descent from the root through the octants that the box meets
    and the interval holds only in part.  stack: (8 * levels + 8, 4) int64 scratch."""
    shift = MAX_LEVEL - levels
    n = 1
    stack[0, 0], stack[0, 1], stack[0, 2], stack[0, 3] = 0, 0, 0, np.int64(1) << levels
    while n > 0:
        n -= 1
        x, y, z, side = stack[n, 0], stack[n, 1], stack[n, 2], stack[n, 3]
        if x > hi[0] or y > hi[1] or z > hi[2] or x + side <= lo[0] or y + side <= lo[1] or z + side <= lo[2]:
            continue
        key = morton_key(x << shift, y << shift, z << shift)
        last = key + ((side * side * side) << (3 * shift)) - 1
        if last < first or key >= end:
            continue
        if first <= key and last < end:
            return True
        half = side >> 1
        for c in range(8):
            stack[n, 0] = x + half * (c & 1)
            stack[n, 1] = y + half * ((c >> 1) & 1)
            stack[n, 2] = z + half * ((c >> 2) & 1)
            stack[n, 3] = half
            n += 1
    return False


@nb.njit(cache=True, inline="always")
def _boxes_apart(lo, hi, box_lo, box_hi):
    """Whether two boxes lo..hi and box_lo..box_hi (inclusive, (3,)) share no cell."""
    return lo[0] > box_hi[0] or lo[1] > box_hi[1] or lo[2] > box_hi[2] or \
        hi[0] < box_lo[0] or hi[1] < box_lo[1] or hi[2] < box_lo[2]


@nb.njit(cache=True)
def _interval_tests(first, end, levels):
    """What box tests against the interval [first, end) of cells of ``levels`` need: its
    cells' box (_interval_box), _box_meets_interval's stack, and a box lo, hi (3,) to fill."""
    box_lo, box_hi = _interval_box(first, end, levels)
    return box_lo, box_hi, np.empty((8 * levels + 8, 4), dtype=np.int64), np.empty(3, np.int64), np.empty(3, np.int64)


@nb.njit(cache=True)
def _faces_near_interval(snapped, faces, bits, levels, margin, first, end):
    """Mask (F,) of the triangles whose bounding box, grown by ``margin`` finest cells, meets
    a finest cell of Morton key in [first, end) (MAX_LEVEL keys; _box_meets_interval)."""
    out = np.zeros(faces.shape[0], dtype=np.bool_)
    top = (np.int64(1) << levels) - 1
    box_lo, box_hi, stack, lo, hi = _interval_tests(first, end, levels)
    for f in range(faces.shape[0]):
        for k in range(3):
            a = min(snapped[faces[f, 0], k], snapped[faces[f, 1], k], snapped[faces[f, 2], k])
            b = max(snapped[faces[f, 0], k], snapped[faces[f, 1], k], snapped[faces[f, 2], k])
            lo[k] = max((a >> bits) - 1 - margin, 0)  # the closed cells a coordinate touches
            hi[k] = min((b >> bits) + margin, top)
        if lo[0] > hi[0] or lo[1] > hi[1] or lo[2] > hi[2] or _boxes_apart(lo, hi, box_lo, box_hi):
            continue  # off the frame, or far from every cell of the interval: no descent
        out[f] = _box_meets_interval(lo, hi, levels, first, end, stack)
    return out


@nb.njit(cache=True)
def _octants_near_interval(keys, level, cell_level, first, end):
    """Mask (K,) of the octants (keys of ``level``) whose box, grown by one cell of
    cell_level (<= MAX_LEVEL), meets a cell of cell_level of Morton key in [first, end)."""
    out = np.zeros(keys.shape[0], dtype=np.bool_)
    top = (np.int64(1) << cell_level) - 1
    box_lo, box_hi, stack, lo, hi = _interval_tests(first, end, cell_level)
    shift = MAX_LEVEL - cell_level
    side = np.int64(1) << (MAX_LEVEL - level)
    cell_bits = ~((np.int64(1) << (3 * shift)) - 1)
    for i in range(keys.shape[0]):
        if first <= (keys[i] & cell_bits) < end:  # the cell at its anchor is the interval's: most keys a range asks of
            out[i] = True
            continue
        x, y, z = morton_coords(keys[i])
        lo[0], lo[1], lo[2] = max((x >> shift) - 1, 0), max((y >> shift) - 1, 0), max((z >> shift) - 1, 0)
        hi[0] = min(((x + side - 1) >> shift) + 1, top)
        hi[1] = min(((y + side - 1) >> shift) + 1, top)
        hi[2] = min(((z + side - 1) >> shift) + 1, top)
        if not _boxes_apart(lo, hi, box_lo, box_hi):
            out[i] = _box_meets_interval(lo, hi, cell_level, first, end, stack)
    return out


@nb.njit(cache=True, inline="always")
def _neighbour_key(x0, y0, z0, c, side):
    """Key of neighbour c (0..26, itself at 13) of the octant of side ``side`` anchored at
    (x0, y0, z0), or -1 where it lies outside the root."""
    x = x0 + (c % 3 - 1) * side
    y = y0 + ((c // 3) % 3 - 1) * side
    z = z0 + (c // 9 - 1) * side
    root = np.int64(1) << MAX_LEVEL
    if x < 0 or y < 0 or z < 0 or x >= root or y >= root or z >= root:
        return np.int64(-1)
    return morton_key(x, y, z)


@nb.njit(cache=True, inline="always")
def _projected_rows(projected, faces, f, bits, k):
    """The rows (first, last, lattice units; last < first if none) along row coordinate k that
    triangle f's projection's box holds: ceil and floor of its extent over 2**bits."""
    a = min(projected[faces[f, 0], k], projected[faces[f, 1], k], projected[faces[f, 2], k])
    b = max(projected[faces[f, 0], k], projected[faces[f, 1], k], projected[faces[f, 2], k])
    return -((-a) >> bits), b >> bits


@nb.njit(cache=True)
def _faces_over_rows(projected, faces, bits, table, row_lo, n_a, n_b):
    """Mask (F,) of the triangles whose projection's bounding box (projected: the snapped
    vertices' row coordinates (p2, p3), (V, 2)) holds a row marked in the summed-area table
    (n_a + 1, n_b + 1) of the rows from row_lo on."""
    out = np.zeros(faces.shape[0], dtype=np.bool_)
    for f in range(faces.shape[0]):
        a0, a1 = _projected_rows(projected, faces, f, bits, 0)
        b0, b1 = _projected_rows(projected, faces, f, bits, 1)
        i0, i1 = max(a0 - row_lo[0], 0), min(a1 - row_lo[0], n_a - 1)  # from row_lo on
        j0, j1 = max(b0 - row_lo[1], 0), min(b1 - row_lo[1], n_b - 1)
        if i0 > i1 or j0 > j1:
            continue
        out[f] = table[i1 + 1, j1 + 1] - table[i0, j1 + 1] - table[i1 + 1, j0] + table[i0, j0] > 0
    return out


def faces_over_rows(snapped: np.ndarray, faces: np.ndarray, bits: int, direction: int,
                    points: np.ndarray) -> np.ndarray:
    """Ascending ids of the triangles that may cross the lattice rows of ``direction`` through
    points (N, 3) int64 (their row coordinates' boxes hold one of those rows): with them,
    rays.row_crossings gives those rows exactly, so winding numbers and cut points there."""
    basis = row_basis(direction)
    if points.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    rows = rays.in_row_coordinates(np.ascontiguousarray(points, dtype=np.int64), basis)[:, 1:]
    row_lo = rows.min(axis=0)
    n_a, n_b = (rows.max(axis=0) - row_lo + 1).tolist()
    marked = np.zeros((n_a, n_b), dtype=np.int64)
    marked[rows[:, 0] - row_lo[0], rows[:, 1] - row_lo[1]] = 1
    table = np.zeros((n_a + 1, n_b + 1), dtype=np.int64)
    table[1:, 1:] = marked.cumsum(axis=0).cumsum(axis=1)
    projected = np.ascontiguousarray(rays.in_row_coordinates(snapped, basis)[:, 1:])
    return np.flatnonzero(_faces_over_rows(projected, faces, bits, table, row_lo, n_a, n_b))


@dataclass(frozen=True)
class BandPiece:
    """The band's part in a range [first, end) of finest-cell Morton keys (band_in_range),
    everything named by lattice coordinates so that pieces merge without a shared numbering.

    surface_keys, cut_keys, band_keys: sorted keys of the range's cells that meet the surface,
    that are cut cells, that are in the band.  coords (P, 3) int64: the cut cells' corners;
    inside (P,) bool; targets (P,) int64: the edge each warps onto, or -1.  Edges (E,): the
    mixed edges of the tets of the cut cells found around the range whose ends are all
    corners of the range's cut cells, and the edges its corners warp onto: edge_starts,
    edge_ends (E, 3) lattice coordinates (the lexicographically smaller end first, as
    stuffing orients them), directions (E,) int8, fracs (E,), points (E, 3), faces (E,)
    int32 (the surface triangle crossed, -1 at an unresolved midpoint)."""

    surface_keys: np.ndarray
    cut_keys: np.ndarray
    band_keys: np.ndarray
    coords: np.ndarray
    inside: np.ndarray
    targets: np.ndarray
    edge_starts: np.ndarray
    edge_ends: np.ndarray
    directions: np.ndarray
    fracs: np.ndarray
    points: np.ndarray
    faces: np.ndarray


def band_in_range(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, first: int, end: int) -> BandPiece:
    """The band's part in the finest cells of Morton key in [first, end), from the triangles
    near them alone: what finest_band finds there over the whole surface, bit for bit.

    The cells within one cell of the range are enough: a cut cell's corners and edges, and
    all the cut edges around a corner of a range cell (which decide its warp), lie in them.
    Their triangles are those whose box meets the range grown by two cells (the margin of
    surface_cells' test), and the classes of their corners come from the x rows through the
    corners, crossed with the triangles over those rows only (faces_over_rows).  Rows there
    that enter the solid twice in a row are refused as mesh() refuses them (ParoctError): over
    all ranges these rows hold every crossing of the surface."""
    levels = frame.levels
    bits = rays.snap_bits(frame)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    near = _faces_near_interval(snapped, faces, bits, levels, 2, first, end)
    met = surface_cells(frame, snapped, faces[near], bits, levels)
    met = met[_octants_near_interval(met, levels, levels, first, end)]  # within one cell of the range
    own = (met >= first) & (met < end)
    corners = number_vertices(octant_lattice_anchors(met, frame), np.ones(met.shape[0], dtype=np.int64))
    column = np.zeros(faces.shape[0], dtype=bool)
    column[faces_over_rows(snapped, faces, bits, X_AXIS_DIRECTION, corners.coords)] = True
    # The triangles read, as a surface of their own (crossings in time of its size): its
    # triangle i is triangle read[i] of the whole, ascending, so ties break as there.
    read = np.flatnonzero(near | column)
    local_faces = faces[read]
    used = np.zeros(snapped.shape[0], dtype=bool)
    used[local_faces.ravel()] = True
    local_snapped = np.ascontiguousarray(snapped[used])
    local_faces = (np.cumsum(used) - 1)[local_faces]
    crossings = {X_AXIS_DIRECTION: rays.row_crossings(frame, local_snapped, local_faces, X_AXIS_DIRECTION,
                                                      np.flatnonzero(column[read]))}
    for d in range(EDGE_DIRECTIONS.shape[0]):
        if d != X_AXIS_DIRECTION:
            crossings[d] = rays.row_crossings(frame, local_snapped, local_faces, d, np.flatnonzero(near[read]))
    _check_winding(frame, crossings[X_AXIS_DIRECTION], corners.coords)  # as mesh() refuses over every row
    corner_class = rays.winding_numbers(crossings[X_AXIS_DIRECTION], corners.coords) > 0
    is_cut = mixed_rows(corners.corner_ids, corner_class)
    cut_cells, kept = _restrict(corners, is_cut)
    inside = corner_class[kept]
    # The tets' edges, not cell_cut_edges: a cut edge here may be owned by a cell outside these.
    cuts = cut_edges(frame, local_snapped, local_faces, cut_cells.coords,
                     collect_cut_edges(graded_tets(cut_cells), inside, cut_cells.coords), inside, crossings,
                     MeshReport(frame.h, frame.levels))
    targets = warp_targets(cuts, cut_cells.coords, frame.h)  # right at the corners of the range's cells
    around = _cells_around(cut_cells.coords, targets >= 0, MAX_LEVEL - levels)
    cut_keys = met[own & is_cut]
    band_keys = unique_level_keys(np.concatenate([cut_keys, around[(around >= first) & (around < end)]]), levels)
    # The range's cut cells' corners, and the edges they hold or warp onto.
    ours = np.zeros(cut_cells.coords.shape[0], dtype=bool)
    ours[cut_cells.corner_ids[(own & is_cut)[is_cut]].ravel()] = True
    edges = ours[cuts.starts] & ours[cuts.ends]
    warped = ours & (targets >= 0)
    edges[targets[warped]] = True
    edge_ids = np.flatnonzero(edges)
    new_edge = np.full(cuts.starts.shape[0], -1, dtype=np.int64)
    new_edge[edge_ids] = np.arange(edge_ids.shape[0])
    own_targets = np.where(targets[ours] >= 0, new_edge[np.maximum(targets[ours], 0)], -1)
    assert cuts.faces is not None  # cut_edges records each cut point's triangle
    crossed = cuts.faces[edge_ids]
    crossed = np.where(crossed >= 0, read[np.maximum(crossed, 0)] if read.size else -1, -1).astype(np.int32)
    return BandPiece(met[own], cut_keys, band_keys, cut_cells.coords[ours], inside[ours], own_targets,
                     cut_cells.coords[cuts.starts[edge_ids]], cut_cells.coords[cuts.ends[edge_ids]],
                     cuts.directions[edge_ids], cuts.fracs[edge_ids], cuts.points[edge_ids], crossed)


def _first_of_each(keys: np.ndarray, name: str, *agreeing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sorted distinct keys, the index of an occurrence of each) of keys (N,); an
    AssertionError if two occurrences of a key differ in a row of one of the arrays (N, ...)
    (so any occurrence stands for all)."""
    order = np.argsort(keys)  # one sort; np.unique's index and inverse cost more
    ordered = keys[order]
    starts = np.ones(ordered.shape[0], dtype=bool)
    starts[1:] = ordered[1:] != ordered[:-1]
    first = order[starts]
    if not starts.all():
        group_first = first[np.cumsum(starts) - 1]  # each occurrence's first, in sorted order
        for values in agreeing:
            if not np.array_equal(values[group_first], values[order]):
                raise AssertionError(f"pieces disagree on a shared {name}")
    return ordered[starts], first


def merge_band_pieces(frame: FatFrame, pieces: list[BandPiece], report: MeshReport) -> FinestBand:
    """The band of pieces that cover the key space, as finest_band lays it out over the whole
    surface (the same arrays, in the same order): the pieces' cells joined, the corners and
    cut edges numbered as there (the numbering reads only cells and classes), and each vertex's
    class and warp and each edge's cut point taken from the pieces, which must agree where
    they overlap (AssertionError).  Counts the unresolved cut points in the report."""
    surface_keys = np.concatenate([p.surface_keys for p in pieces])
    cut_keys = np.concatenate([p.cut_keys for p in pieces])
    band_keys = np.concatenate([p.band_keys for p in pieces])
    if not (is_ascending(surface_keys) and is_ascending(band_keys)):
        raise ValueError("band pieces must be given in key order, over disjoint ranges")
    corners = number_vertices(octant_lattice_anchors(surface_keys, frame),
                              np.ones(surface_keys.shape[0], dtype=np.int64))
    cut_cells, _ = _restrict(corners, sorted_lookup(cut_keys, surface_keys)[1])
    coords = cut_cells.coords
    index = BandIndex.from_pieces(pieces)  # the pieces' vertices and edges, each once, checked alike
    at, found = sorted_lookup(index.vertex_keys, pack_coords(coords))
    if not found.all() or index.vertex_keys.shape[0] != coords.shape[0]:
        raise AssertionError(f"the pieces hold {index.vertex_keys.shape[0]} band vertices, the cut cells "
                             f"{coords.shape[0]}")
    inside = index.inside[at]
    starts, ends, dirs, *table = cell_cut_edges(cut_cells.corner_ids, inside)  # as finest_band numbers them
    if index.keys.shape[0] != starts.shape[0]:
        raise AssertionError(f"the pieces hold {index.keys.shape[0]} cut edges, the cut cells {starts.shape[0]}")
    keys = edge_keys(coords[starts], coords[ends])
    e = index.edges_at(keys)
    if not np.array_equal(index.directions[e], dirs):
        raise AssertionError("band pieces give a cut edge another direction")
    crossed = index.faces[e]
    cuts = CutEdges(starts, ends, dirs, index.fracs[e], index.points[e], tuple(table), crossed)
    report.unresolved_cuts += int(np.count_nonzero(crossed < 0))
    # Each vertex's warp: its pieces' target edge, found among the merged edges.
    order = np.argsort(keys)
    target_keys = index.target_keys[at]
    targets = np.full(coords.shape[0], -1, dtype=np.int64)
    warped = target_keys >= 0
    targets[warped] = order[np.searchsorted(keys[order], target_keys[warped])]
    return FinestBand(surface_keys, band_keys, BandStuffing(coords, inside, cuts, targets))


def range_bounds(frame: FatFrame, snapped: np.ndarray, n_parts: int, level: int | None = None) -> np.ndarray:
    """Boundaries (n_parts + 1,) int64 of n_parts ranges of Morton keys covering the key
    space, with about as many surface vertices in each, each range made of whole octants of
    ``level`` (default frame.levels, the finest cells; some ranges may be empty): range r is
    keys bounds[r] .. bounds[r + 1] - 1."""
    level = frame.levels if level is None else level
    cells = (snapped >> rays.snap_bits(frame)).clip(0, (1 << frame.levels) - 1) << (MAX_LEVEL - frame.levels)
    keys = np.sort(morton_keys(cells))
    bounds = np.empty(n_parts + 1, dtype=np.int64)
    bounds[0], bounds[-1] = 0, np.int64(1) << (3 * MAX_LEVEL)
    if keys.shape[0]:
        align = 3 * (MAX_LEVEL - level)
        bounds[1:-1] = (keys[(np.arange(1, n_parts) * keys.shape[0]) // n_parts] >> align) << align
    else:
        bounds[1:-1] = 0
    return bounds


def finest_band_in_ranges(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, n_parts: int,
                          report: MeshReport) -> FinestBand:
    """finest_band computed in n_parts ranges of the key space (range_bounds), each from the
    triangles near it (band_in_range), and merged (merge_band_pieces): the same band."""
    bounds = range_bounds(frame, snapped, n_parts)
    pieces = [band_in_range(frame, snapped, faces, int(bounds[r]), int(bounds[r + 1])) for r in range(n_parts)]
    return merge_band_pieces(frame, pieces, report)


@nb.njit(cache=True)
def _faces_over_row_box(projected, faces, bits, lo, hi):
    """Mask (F,) of the triangles whose projection's box (projected: row coordinates (p2, p3)
    of the snapped vertices, (V, 2)) holds a row of lo..hi (inclusive, (2,), lattice units)."""
    out = np.zeros(faces.shape[0], dtype=np.bool_)
    for f in range(faces.shape[0]):
        a0, a1 = _projected_rows(projected, faces, f, bits, 0)
        b0, b1 = _projected_rows(projected, faces, f, bits, 1)
        out[f] = max(a0, lo[0]) <= min(a1, hi[0]) and max(b0, lo[1]) <= min(b1, hi[1])
    return out


def faces_over_box_rows(snapped: np.ndarray, faces: np.ndarray, bits: int, direction: int, box_lo: np.ndarray,
                        box_hi: np.ndarray) -> np.ndarray:
    """Ascending ids of the triangles that may cross a lattice row of ``direction`` through a
    lattice point of the box box_lo..box_hi ((3,) int64, inclusive): their row coordinates'
    boxes meet the rows of the box's corners' span."""
    basis = row_basis(direction)
    corners = np.ascontiguousarray(np.where(CUBE_CORNERS == 1, np.asarray(box_hi), np.asarray(box_lo)),
                                   dtype=np.int64)
    rows = rays.in_row_coordinates(corners, basis)[:, 1:]
    projected = np.ascontiguousarray(rays.in_row_coordinates(snapped, basis)[:, 1:])
    return np.flatnonzero(_faces_over_row_box(projected, faces, bits, rows.min(axis=0), rows.max(axis=0)))


@nb.njit(cache=True)
def _near_ranges(keys, coarse, bounds, out, offsets):
    """keys_near_ranges' kernel: with out empty, counts (K,) of the ranges near each key; else fills
    out from offsets[k] with each key's ranges, ascending."""
    side = np.int64(1) << (MAX_LEVEL - coarse)
    octant_mask = ~((np.int64(1) << (3 * (MAX_LEVEL - coarse))) - 1)
    counts = np.zeros(keys.shape[0], dtype=np.int64)
    found = np.empty(27, dtype=np.int64)
    last = np.int64(-1)  # keys sorted: a coarse octant's cells come together, and share their ranges
    n = 0
    for i in range(keys.shape[0]):
        octant = keys[i] & octant_mask
        if octant == last:
            counts[i] = n
            if out.shape[0]:
                for q in range(n):
                    out[offsets[i] + q] = found[q]
            continue
        last = octant
        x0, y0, z0 = morton_coords(keys[i])
        x0, y0, z0 = x0 & ~(side - 1), y0 & ~(side - 1), z0 & ~(side - 1)
        n = 0
        for c in range(27):
            key = _neighbour_key(x0, y0, z0, c, side)
            if key < 0:
                continue
            r = np.searchsorted(bounds, key, side="right") - 1
            listed = False
            for q in range(n):
                listed = listed or found[q] == r
            if not listed:
                found[n] = r
                n += 1
        found[:n].sort()
        counts[i] = n
        if out.shape[0]:
            for q in range(n):
                out[offsets[i] + q] = found[q]
    return counts


def keys_near_ranges(keys: np.ndarray, coarse: int, bounds: np.ndarray) -> list[np.ndarray]:
    """For each range of ``bounds`` (range_bounds at level ``coarse``), the keys (ascending,
    from keys (K,) sorted, of cells of any level not coarser than ``coarse``) of the cells
    within one octant of level ``coarse`` of it: what octree_in_range reads of them, routed
    once (27 neighbours a cell) rather than tested by every range."""
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    bounds = np.ascontiguousarray(bounds, dtype=np.int64)
    counts = _near_ranges(keys, coarse, bounds, np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    ranges = np.empty(int(offsets[-1]), dtype=np.int64)
    _near_ranges(keys, coarse, bounds, ranges, offsets)
    owner = np.repeat(np.arange(keys.shape[0]), counts)
    order = np.argsort(ranges, kind="stable")  # by range, then key order
    split = np.searchsorted(ranges[order], np.arange(bounds.shape[0]))
    return [keys[owner[order[split[r]:split[r + 1]]]] for r in range(bounds.shape[0] - 1)]


def octree_in_range(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, surface: Surface, field: SizeField,
                    surface_keys: np.ndarray, band_keys: np.ndarray, first: int,
                    end: int) -> tuple[np.ndarray, np.ndarray]:
    """The leaves of octree_around_band's octree (keys (N,) int64, levels (N,) int8, sorted)
    with keys in [first, end), from the band's cells and the surface's cells within one
    max_size octant of the range and the triangles over the x rows there.

    [first, end) is made of whole octants of max_size (the coarsest seeds' level, ``coarse``):
    no seed or leaf the octree keeps straddles it.  A leaf's place in a 2:1-balanced octree
    depends only on the octants given in the insulation layer of the max_size octant holding
    it, its 26 neighbours of that size (Sundar, Sampath & Biros 2008, Sec. 4), so balancing the
    seeds and band cells of the range and that ring gives its leaves.  The seeds are
    size_seeds' over the ring and range: octants beyond are dropped as if outside, and those
    partly in it or coarser than max_size and not wholly in the range are left undecided (the
    surface cells that would decide them may lie beyond)."""
    finest = frame.levels
    coarse = max(0, finest - field.coarse_depth)
    step = np.int64(1) << (3 * (MAX_LEVEL - coarse))
    if first % step or (end % step and end != np.int64(1) << (3 * MAX_LEVEL)):
        raise ValueError(f"first = {first}, end = {end}: not whole octants of level {coarse}")
    if first >= end:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int8)
    surface_keys = surface_keys[_octants_near_interval(surface_keys, finest, coarse, first, end)]
    band_keys = band_keys[_octants_near_interval(band_keys, finest, coarse, first, end)]
    box_lo, box_hi = _interval_box(first, end, coarse)
    grow = finest - coarse
    column = faces_over_box_rows(snapped, faces, rays.snap_bits(frame), X_AXIS_DIRECTION, (box_lo - 1) << grow,
                                 (box_hi + 2) << grow)
    x_rows = rays.row_crossings(frame, snapped, faces, X_AXIS_DIRECTION, column)
    classify = surface_prune(frame, surface_keys, x_rows)

    def prune(octants: np.ndarray, level: int) -> np.ndarray:
        found = np.full(octants.shape[0], OUTSIDE, dtype=np.int8)
        near = _octants_near_interval(octants, level, coarse, first, end)
        last = octants + (np.int64(1) << (3 * (MAX_LEVEL - level))) - 1
        whole = near & ((level >= coarse) | ((octants >= first) & (last < end)))
        found[near] = UNDECIDED
        found[whole] = classify(octants[whole], level)
        return found

    return octree_around_band(frame, x_rows, surface, field, surface_keys, band_keys, prune=prune, within=(first, end))


@dataclass(frozen=True)
class BandIndex:
    """Band pieces (band_in_range) as one table by lattice coordinates, so that a range finds
    its band vertices and cut edges by binary searches, with no numbering shared with other
    ranges.  coords (P, 3): the band vertices, by ascending vertex_keys (P,) (pack_coords);
    inside (P,); target_keys (P,): edge_keys of the edge each warps onto, or -1.  Cut edges
    by ascending keys (E,) (edge_keys): starts, ends (E, 3), directions, fracs, points (E, 3),
    faces.  Pieces that disagree on a vertex or an edge they share are an AssertionError."""

    vertex_keys: np.ndarray
    coords: np.ndarray
    inside: np.ndarray
    target_keys: np.ndarray
    keys: np.ndarray
    starts: np.ndarray
    ends: np.ndarray
    directions: np.ndarray
    fracs: np.ndarray
    points: np.ndarray
    faces: np.ndarray

    @classmethod
    def from_pieces(cls, pieces: Sequence[BandPiece]) -> BandIndex:
        def joined(name: str, empty: np.ndarray) -> np.ndarray:
            return np.concatenate([empty] + [getattr(p, name) for p in pieces])

        starts, ends = joined("edge_starts", _NO_COORDS), joined("edge_ends", _NO_COORDS)
        keys = edge_keys(starts, ends)
        directions, fracs = joined("directions", np.zeros(0, np.int8)), joined("fracs", np.zeros(0))
        points, faces = joined("points", np.zeros((0, 3))), joined("faces", np.zeros(0, np.int32))
        keys_sorted, e = _first_of_each(keys, "cut edge", directions, fracs.view(np.int64), points.view(np.int64),
                                        faces)
        offsets = np.cumsum([0] + [p.edge_starts.shape[0] for p in pieces])
        targets = joined("targets", np.zeros(0, np.int64))
        targets += np.repeat(offsets[:-1], [p.targets.shape[0] for p in pieces]) * (targets >= 0)
        target_keys = np.full(targets.shape[0], -1, dtype=np.int64)
        target_keys[targets >= 0] = keys[targets[targets >= 0]]
        coords, inside = joined("coords", _NO_COORDS), joined("inside", np.zeros(0, bool))
        vertex_sorted, v = _first_of_each(pack_coords(coords), "vertex", inside, target_keys)
        return cls(vertex_sorted, coords[v], inside[v], target_keys[v], keys_sorted, starts[e], ends[e], directions[e],
                   fracs[e], points[e], faces[e])

    def vertices_on(self, leaves: FinestLeaves) -> np.ndarray:
        """Indices (ascending) of the band vertices that are a corner of one of a range's
        finest leaves: every band vertex its leaves have as a corner, since a band vertex is a
        corner of a finest band cell, which touches every leaf with the vertex as a corner."""
        return np.flatnonzero(leaves.corners_among(self.coords))

    def near(self, v: np.ndarray) -> BandIndex:
        """The part of the index a range whose band vertices are v (ascending indices:
        vertices_on its leaves) reads: those vertices, the cut edges with both ends among them
        (every mixed edge of its tets) and the edges they warp onto."""
        vertex_keys = self.vertex_keys[v]
        held = sorted_lookup(vertex_keys, pack_coords(self.starts))[1] & sorted_lookup(vertex_keys,
                                                                                        pack_coords(self.ends))[1]
        targets = self.target_keys[v]
        held[self.edges_at(targets[targets >= 0])] = True
        e = np.flatnonzero(held)
        return BandIndex(vertex_keys, self.coords[v], self.inside[v], self.target_keys[v], self.keys[e],
                         self.starts[e], self.ends[e], self.directions[e], self.fracs[e], self.points[e],
                         self.faces[e])

    def edges_at(self, keys: np.ndarray) -> np.ndarray:
        """The index of the cut edge of each key (K,); AssertionError if one is none."""
        at, found = sorted_lookup(self.keys, keys)
        if not found.all():
            raise AssertionError(f"{int((~found).sum())} mixed edges of a range are not cut edges of its band pieces")
        return at


@dataclass(frozen=True)
class RangeMesh:
    """One range's stuffed tets, its own leaves' only, and the points they use.  points
    (V + E, 3) float64: lattice vertices where the warps put them, then cut points; tets
    (M, 4) int32 into points; vertex_keys (V,) int64: pack_coords of each lattice vertex;
    inside (V,) bool; target_keys (V,) int64: edge_keys of the cut edge each vertex warps
    onto, or -1, and target_faces (V,) int32 the surface triangle there (-1 if none);
    cut_keys (E,) int64: edge_keys of the edge of each cut point, and cut_faces (E,) int32
    its triangle."""

    points: np.ndarray
    tets: np.ndarray
    vertex_keys: np.ndarray
    inside: np.ndarray
    target_keys: np.ndarray
    target_faces: np.ndarray
    cut_keys: np.ndarray
    cut_faces: np.ndarray


def band_pieces_for(keys: np.ndarray, levels: np.ndarray, rows: np.ndarray, finest: int,
                    bounds: np.ndarray) -> np.ndarray:
    """Indices (ascending) of the band pieces of key ranges ``bounds`` (range_bounds) that a
    range whose own and touching leaves are keys[rows] reads: those holding one of its finest
    leaves.  Every cut cell with a corner on one of its own leaves is such a leaf (it touches
    the leaf), so these pieces hold every band vertex its tets use, its class, its warp and
    the edge it warps onto."""
    fine = keys[rows][levels[rows] == finest]
    return np.unique(np.searchsorted(bounds, fine, side="right") - 1)


def mesh_range(frame: FatFrame, keys: np.ndarray, levels: np.ndarray, band: BandIndex, first: int,
               end: int, around: np.ndarray | None = None) -> RangeMesh:
    """Number, classify, emit and stuff the leaves keys[first:end] of graded_leaves' octree
    (keys, levels) from them, the leaves touching them and the band pieces they read (band:
    indexed, BandIndex.from_pieces of band_pieces_for's pieces).

    Vertices are numbered over the range and its touching leaves, the band's vertices among
    their corners first (number_vertices' prefix), so that split points, classes and the quad
    rule's corner-before-centre order come out as over the whole octree; only the range's own
    tets are emitted and stuffed.  Its cut edges are those its tets hold, plus those its
    vertices warp onto in touching cells.  around: touching_leaves(keys, levels, first, end),
    if the caller has it."""
    vertices, inside, tets, in_range = _range_lattice_tets(frame, keys, levels, band, first, end, around)
    cuts, cut_at, targets = _range_cuts(band, in_range, vertices.coords, tets, inside)
    points, out_tets, _ = stuff(frame.to_space(vertices.coords), vertices.coords, tets, inside, cuts, targets,
                                first_centre=vertices.first_centre, with_offsets=False)
    # Only the points the range's tets use: vertices of touching leaves alone may lack the
    # edge they warp onto here, and their own range places them.
    n = vertices.coords.shape[0]
    used = np.zeros(points.shape[0], dtype=bool)
    used[out_tets.ravel()] = True
    new_id = np.cumsum(used) - 1
    lattice = np.flatnonzero(used[:n])
    warped = targets[lattice] >= 0
    target_edges = cut_at[targets[lattice][warped]]
    target_keys = np.full(lattice.shape[0], -1, dtype=np.int64)
    target_keys[warped] = band.keys[target_edges]
    target_faces = np.full(lattice.shape[0], -1, dtype=np.int32)
    target_faces[warped] = band.faces[target_edges]
    cut_edges_used = cut_at[used[n:]]
    return RangeMesh(points[used], new_id[out_tets].astype(np.int32), pack_coords(vertices.coords[lattice]),
                     inside[lattice], target_keys, target_faces, band.keys[cut_edges_used], band.faces[cut_edges_used])


class FinestLeaves(NamedTuple):
    """A range's leaves of the frame's finest level: keys (L,) sorted, in octree coordinates
    (lattice << shift), and the box lo..hi ((3,) int64, lattice units) of their anchors."""

    keys: np.ndarray
    shift: int
    lo: np.ndarray
    hi: np.ndarray

    def corners_among(self, coords: np.ndarray) -> np.ndarray:
        """Mask (P,) of the lattice points coords (P, 3) that are a corner of one of the leaves."""
        return _on_finest_leaves(np.ascontiguousarray(coords, dtype=np.int64), self.keys, self.shift, self.lo, self.hi)


def finest_leaves(keys: np.ndarray, levels: np.ndarray, frame: FatFrame) -> FinestLeaves:
    """FinestLeaves of the leaves (keys, levels: sorted) at the frame's finest level."""
    fine = np.compress(levels == frame.levels, keys)
    lo, hi = _leaf_box(fine, MAX_LEVEL - frame.levels)
    return FinestLeaves(fine, MAX_LEVEL - frame.levels, lo, hi)


@nb.njit(cache=True)
def _leaf_box(keys, shift):
    """The box (lo (3,), hi (3,)) in lattice units of the anchors of octants keys (empty:
    lo above hi)."""
    lo = np.full(3, np.int64(1) << 62)
    hi = np.full(3, np.int64(-1))
    for k in range(keys.shape[0]):
        x, y, z = morton_coords(keys[k])
        lo[0], lo[1], lo[2] = min(lo[0], x >> shift), min(lo[1], y >> shift), min(lo[2], z >> shift)
        hi[0], hi[1], hi[2] = max(hi[0], x >> shift), max(hi[1], y >> shift), max(hi[2], z >> shift)
    return lo, hi


@nb.njit(cache=True, parallel=True)
def _on_finest_leaves(coords, fine_keys, shift, lo, hi):
    """FinestLeaves.corners_among: whether one of the 8 cells with the point as a corner (those
    of non-negative anchor) is among fine_keys (anchors in lo..hi).  The box rejects most
    points of the pieces a range reads (their neighbours'); the others cost up to eight
    binary searches.  (Listing the leaves' corners and sorting them out took a quarter of a
    range's time, tray_bottom at diag/320 in 1 range.)"""
    out = np.zeros(coords.shape[0], dtype=np.bool_)
    n = fine_keys.shape[0]
    for i in nb.prange(coords.shape[0]):
        x, y, z = coords[i, 0], coords[i, 1], coords[i, 2]
        if x < lo[0] or x > hi[0] + 1 or y < lo[1] or y > hi[1] + 1 or z < lo[2] or z > hi[2] + 1:
            continue
        for c in range(8):
            ax, ay, az = x - (c & 1), y - ((c >> 1) & 1), z - ((c >> 2) & 1)
            if ax < 0 or ay < 0 or az < 0:
                continue
            key = morton_key(ax << shift, ay << shift, az << shift)
            j = np.searchsorted(fine_keys, key)
            if j < n and fine_keys[j] == key:
                out[i] = True
                break
    return out


def _range_lattice_tets(frame: FatFrame, keys: np.ndarray, levels: np.ndarray, band: BandIndex, first: int, end: int,
                        around: np.ndarray | None) -> tuple[LeafVertices, np.ndarray, np.ndarray, np.ndarray]:
    """mesh_range's lattice: (the vertices of the range's own and touching leaves, their
    classes (V,), the own leaves' lattice tets with an inside vertex (T, 4) int32, in_range:
    local vertex i < len(in_range) is band vertex in_range[i])."""
    if around is None:
        around = touching_leaves(keys, levels, first, end)
    before = int(np.searchsorted(around, first))
    rows = np.concatenate([around[:before], np.arange(first, end, dtype=np.int64), around[before:]])
    own = np.arange(before, before + end - first)
    anchors = octant_lattice_anchors(keys[rows], frame)
    sides = np.int64(1) << (frame.levels - levels[rows].astype(np.int64))
    in_range = band.vertices_on(finest_leaves(keys[rows], levels[rows], frame))
    vertices = number_vertices(anchors, sides, prefix=band.coords[in_range], eager=False)
    inside = vertex_classes(vertices, band.inside[in_range])
    # A touching leaf may have band corners in pieces the range does not read, and spread a
    # wrong class to the corners it shares; the range's own leaves, whose band corners are
    # all read, spread theirs last (a leaf with no cut edge gives every sharer one class).
    _spread_leaf_classes(vertices.corner_ids[own], vertices.split_row[own], vertices.split_ids, inside,
                         in_range.shape[0])
    own_vertices = LeafVertices(vertices.corner_ids[own], vertices.split_row[own], vertices.split_ids,
                                vertices.coords, vertices.first_centre)
    return vertices, inside, graded_tets(own_vertices, inside), in_range


@dataclass(frozen=True)
class RangeLattice:
    """One range's own lattice tets, for stuffing and mending them with every other range's
    as one mesh (merge_range_lattices).  coords (W, 3) int64: the lattice coordinates of their
    vertices; inside (W,) bool; centre (W,) bool: a face centre that is no leaf's corner
    (number_vertices numbers those last, and the quad rule puts them last on template
    faces); tets (T, 4) int32 into coords, as graded_tets gives them."""

    coords: np.ndarray
    inside: np.ndarray
    centre: np.ndarray
    tets: np.ndarray


def range_lattice(frame: FatFrame, keys: np.ndarray, levels: np.ndarray, band: BandIndex, first: int, end: int,
                  around: np.ndarray | None = None) -> RangeLattice:
    """The lattice tets of leaves keys[first:end] (with an inside vertex), numbered and
    classified as mesh_range numbers and classifies them, not stuffed.  Arguments as for
    mesh_range."""
    vertices, inside, tets, _ = _range_lattice_tets(frame, keys, levels, band, first, end, around)
    used = np.zeros(vertices.coords.shape[0], dtype=bool)
    used[tets.ravel()] = True
    ids = np.flatnonzero(used)
    return RangeLattice(vertices.coords[ids], inside[ids], ids >= vertices.first_centre,
                        np.searchsorted(ids, tets).astype(np.int32))


def merge_range_lattices(pieces: Sequence[RangeLattice],
                         band: BandIndex) -> tuple[np.ndarray, np.ndarray, np.ndarray, CutEdges, np.ndarray, int]:
    """The ranges' lattice tets as one lattice to stuff: (coords (V, 3), tets (T, 4) int32,
    inside (V,), cuts, targets (V,) into cuts, first_centre), the arguments stuff takes.
    Each vertex once, the leaf corners first and the face centres that are no leaf's corner
    after them (first_centre: the first of those), each part by coordinates; the cut edges
    those of the joined tets (collect_cut_edges), their cut points and triangles and the
    warps from band (BandIndex.from_pieces of every range's band piece).  Pieces that
    disagree on a shared vertex are an AssertionError."""
    coords_all = np.concatenate([np.zeros((0, 3), np.int64)] + [p.coords for p in pieces])
    centre_all = np.concatenate([np.zeros(0, bool)] + [p.centre for p in pieces])
    inside_all = np.concatenate([np.zeros(0, bool)] + [p.inside for p in pieces])
    vertex_keys, first = _first_of_each(pack_coords(coords_all), "lattice vertex", centre_all, inside_all)
    order = np.argsort(centre_all[first], kind="stable")  # corners first, each part by key
    new_id = np.empty(order.shape[0], dtype=np.int64)
    new_id[order] = np.arange(order.shape[0])
    coords, inside = coords_all[first[order]], inside_all[first[order]]
    tets = np.concatenate([np.zeros((0, 4), np.int32)] + [
        new_id[np.searchsorted(vertex_keys, pack_coords(p.coords))][p.tets].astype(np.int32) for p in pieces])
    starts, ends, directions, *table = collect_cut_edges(tets, inside, coords)
    cut_keys = edge_keys(coords[starts], coords[ends])
    at = band.edges_at(cut_keys)
    cuts = CutEdges(starts, ends, directions, band.fracs[at], band.points[at], tuple(table), band.faces[at])
    in_band, found = sorted_lookup(band.vertex_keys, pack_coords(coords))
    target_keys = np.where(found, band.target_keys[np.where(found, in_band, 0)], -1)
    by_key = np.argsort(cut_keys)
    edge_at, held = sorted_lookup(cut_keys[by_key], target_keys)
    warped = target_keys >= 0
    if not held[warped].all():
        raise AssertionError(f"{int((~held[warped]).sum())} vertices warp onto edges of no range's tets")
    targets = np.where(warped, by_key[np.where(held, edge_at, 0)], -1).astype(np.int64)
    return coords, tets, inside, cuts, targets, int(np.count_nonzero(~centre_all[first]))


def _range_cuts(band: BandIndex, in_range: np.ndarray, coords: np.ndarray, tets: np.ndarray,
                inside: np.ndarray) -> tuple[CutEdges, np.ndarray, np.ndarray]:
    """The range's CutEdges (its tets' mixed edges, then the band edges its band vertices warp
    onto that its tets lack, where both ends are its vertices), the band edge (E,) of each (an
    index into band's edges), and the targets (V,) into them.  Local vertex i <
    len(in_range) is band vertex in_range[i]."""
    starts, ends, directions, head, upper, chain = collect_cut_edges(tets, inside, coords)
    cut_at = band.edges_at(edge_keys(coords[starts], coords[ends]))
    wanted = np.full(in_range.shape[0], -1, dtype=np.int64)
    warps = band.target_keys[in_range] >= 0
    wanted[warps] = band.edges_at(band.target_keys[in_range][warps])
    sorted_ids = np.argsort(cut_at)
    at, held = sorted_lookup(cut_at[sorted_ids], wanted)
    extra = np.unique(wanted[(wanted >= 0) & ~held])
    band_vertices = pack_coords(band.coords[in_range])  # ascending: in_range is
    start_at, start_found = sorted_lookup(band_vertices, pack_coords(band.starts[extra]))
    end_at, end_found = sorted_lookup(band_vertices, pack_coords(band.ends[extra]))
    both = start_found & end_found
    extra, extra_starts, extra_ends = extra[both], start_at[both].astype(starts.dtype), end_at[both].astype(ends.dtype)
    # Extra edges are in no tet: the lookup table (head, upper, chain) never reaches them.
    table = (head, np.concatenate([upper, np.maximum(extra_starts, extra_ends).astype(upper.dtype)]),
             np.concatenate([chain, np.full(extra.shape[0], -1, dtype=chain.dtype)]))
    all_at = np.concatenate([cut_at, extra])
    cuts = CutEdges(np.concatenate([starts, extra_starts]), np.concatenate([ends, extra_ends]),
                    np.concatenate([directions, band.directions[extra].astype(directions.dtype)]),
                    band.fracs[all_at], band.points[all_at], table, band.faces[all_at])
    extra_at, extra_held = sorted_lookup(extra, wanted)
    targets = np.full(coords.shape[0], -1, dtype=np.int64)
    held_ids = sorted_ids[at] if sorted_ids.size else at
    targets[: in_range.shape[0]] = np.where(held, held_ids, np.where(extra_held, cut_at.shape[0] + extra_at, -1))
    return cuts, all_at, targets


def unpack_coords(keys: np.ndarray) -> np.ndarray:
    """Lattice coordinates (N, 3) int64 of pack_coords' keys (N,) (its inverse)."""
    keys = np.asarray(keys, dtype=np.int64)
    mask = (np.int64(1) << _COORD_BITS) - 1
    return np.stack([keys & mask, (keys >> _COORD_BITS) & mask, keys >> (2 * _COORD_BITS)], axis=1)


def point_owners(frame: FatFrame, coords: np.ndarray, key_bounds: np.ndarray) -> np.ndarray:
    """The range (N,) int64 owning each lattice point (coords (N, 3)) among the key ranges
    key_bounds (range_bounds): the one whose keys hold the finest cell anchored at the point
    (moved into the frame where the point is on its far faces).  A cut point's owner is that
    of the lattice point at half its edge key's coordinates (edge_keys: twice the midpoint)."""
    top = (np.int64(1) << frame.levels) - 1
    cells = np.clip(np.asarray(coords, dtype=np.int64), 0, top) << (MAX_LEVEL - frame.levels)
    return np.searchsorted(key_bounds, morton_keys(np.ascontiguousarray(cells)), side="right") - 1


@dataclass(frozen=True)
class RangeNumbering:
    """The mesh's ids of the ranges' points (number_ranges): vertex_ids[r] (V_r,) of piece r's
    lattice vertices, 0..n_vertices-1; edge_ids[r] of its edges (its cut points', then those
    its vertices warp onto), 0..n_edges-1, the cut points being points n_vertices + those;
    vertex_owners[r], edge_owners[r]: the range owning each (point_owners)."""

    vertex_ids: list[np.ndarray]
    edge_ids: list[np.ndarray]
    n_vertices: int
    n_edges: int
    vertex_owners: list[np.ndarray]
    edge_owners: list[np.ndarray]


def number_ranges(pieces: Sequence[RangeMesh], frame: FatFrame, key_bounds: np.ndarray) -> RangeNumbering:
    """Each lattice vertex and each cut point numbered once, by the ranges that own them
    (point_owners, owned_ids): in range order, and by key within a range."""
    n_ranges = key_bounds.shape[0] - 1
    vertex_owners = [point_owners(frame, unpack_coords(p.vertex_keys), key_bounds) for p in pieces]
    vertex_ids, n_vertices = owned_ids([p.vertex_keys for p in pieces], vertex_owners, n_ranges)
    # A piece's edges: those of its cut points, then those its vertices warp onto.
    edges = [np.concatenate([p.cut_keys, p.target_keys[p.target_keys >= 0]]) for p in pieces]
    edge_owners = [point_owners(frame, unpack_coords(e) >> 1, key_bounds) for e in edges]
    edge_ids, n_edges = owned_ids(edges, edge_owners, n_ranges)
    return RangeNumbering(vertex_ids, edge_ids, n_vertices, n_edges, vertex_owners, edge_owners)


def range_tets(piece: RangeMesh, numbering: RangeNumbering, r: int) -> RangeTets:
    """Range r's tets (piece) in the mesh's point ids (numbering), for the pinch repair in
    ranges (range_pinches)."""
    n_cut = piece.cut_keys.shape[0]
    core = _core(piece.inside, piece.target_keys, piece.points.shape[0])  # target_keys -1: no warp, as targets
    ids = np.concatenate([numbering.vertex_ids[r], numbering.n_vertices + numbering.edge_ids[r][:n_cut]])
    owners = np.concatenate([numbering.vertex_owners[r], numbering.edge_owners[r][:n_cut]])
    return RangeTets(ids, piece.tets, core, piece.points, owners)


def merge_ranges(pieces: list[RangeMesh], frame: FatFrame, key_bounds: np.ndarray,
                 numbering: RangeNumbering | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """The pieces (the ranges of key_bounds, in order) as one stuffed mesh: each lattice vertex
    once, then each cut point once (by its edge), the cut points of the edges the vertices
    warp onto included (NaN where no tet uses one): (points (L + C, 3), tets (M, 4) int32,
    inside (L,), targets (L,) into the C cut points, cut_faces (C,) int32 the triangle of
    each).  Points are numbered by number_ranges (numbering: its result, if the caller has
    it).  A vertex or cut point the pieces place, classify or warp differently is an
    AssertionError: stuffing in ranges must agree where they meet."""
    numbering = number_ranges(pieces, frame, key_bounds) if numbering is None else numbering
    vertex_ids, edge_ids = numbering.vertex_ids, numbering.edge_ids
    n_vertices, n_edges = numbering.n_vertices, numbering.n_edges
    inside = np.zeros(n_vertices, dtype=bool)
    targets = np.full(n_vertices, -1, dtype=np.int64)
    points = np.full((n_vertices + n_edges, 3), np.nan)
    cut_faces = np.full(n_edges, -1, dtype=np.int32)
    piece_targets = []
    for p, v, e in zip(pieces, vertex_ids, edge_ids):
        n, n_cut = p.vertex_keys.shape[0], p.cut_keys.shape[0]
        warped = p.target_keys >= 0
        t = np.full(n, -1, dtype=np.int64)
        t[warped] = e[n_cut:]
        piece_targets.append(t)
        inside[v], targets[v], points[v] = p.inside, t, p.points[:n]
        points[n_vertices + e[:n_cut]] = p.points[n:]
        cut_faces[e[:n_cut]], cut_faces[e[n_cut:]] = p.cut_faces, p.target_faces[warped]
    tets = []
    for p, v, e, t in zip(pieces, vertex_ids, edge_ids, piece_targets):
        n, n_cut = p.vertex_keys.shape[0], p.cut_keys.shape[0]
        if not np.array_equal(inside[v], p.inside):
            raise AssertionError("ranges classify a shared lattice vertex differently")
        if not np.array_equal(targets[v], t):
            raise AssertionError("ranges warp a shared lattice vertex differently")
        if not np.array_equal(points[v], p.points[:n]):
            raise AssertionError("ranges place a shared lattice vertex differently")
        if not np.array_equal(points[n_vertices + e[:n_cut]], p.points[n:]):
            raise AssertionError("ranges place a shared cut point differently")
        tets.append(np.concatenate([v, n_vertices + e[:n_cut]])[p.tets].astype(np.int32))
    return (points, np.concatenate(tets) if tets else np.zeros((0, 4), dtype=np.int32), inside, targets,
            cut_faces)


def mesh_in_ranges(source: SurfaceSource | Surface, size: float | None = None, *, n_parts: int,
                   divisions: float | None = None, max_size: float | None = None, thin_features: bool = True,
                   min_size: float | None = None, max_memory: float | None = None,
                   mapper: Callable[..., Iterable] | None = None) -> MeshResult:
    """mesh() in n_parts ranges of Morton keys (range_bounds, whole max_size octants; ranges
    left empty, as when they are more than the octants the surface meets, are dropped).  A
    pass (_pass_in_ranges) builds in each range the band from the triangles near it
    (band_in_range), the octree from the band within one max_size octant of it
    (octree_in_range), and the tets of its leaves from them, the leaves touching them and the
    band pieces it reads (mesh_range); their pinches are repaired in the ranges (range_pinches:
    only the boundary faces and the tets near pinches leave them) and the mesh finished in
    the ranges (range_finish: quality, topology, missed parts and compaction, as
    mesher._finish on the merged mesh), the result being the owners' points and the ranges'
    tets one after another.  No band or octree of the whole surface is built, and no mesh is
    merged but the result (merge_ranges only where the pinch repair must run on the whole).

    thin_features, min_size, max_memory: as mesh(), but where a pass loses part of the solid
    the whole band is refined by halves (mesher.halve_whole_band, mesh()'s own halving);
    mesh() first refines only near the thin walls, which the ranges do not do yet.  So
    the result is mesh()'s where that pass keeps the solid or mesh() too refines the whole
    band, and a finer mesh where mesh() keeps it by refining near thin walls.  Curvature,
    layers and the other asks are not done in ranges either.

    mapper(function, *iterables): runs each of the three stages over the ranges and returns
    their results in order, as the built-in map does (the default: one range after another);
    an executor's map (concurrent.futures.ProcessPoolExecutor().map, a Dask client's map and
    gather) runs them side by side: the functions and their arguments pickle.

    A pass's tets and points are those of mesh()'s pass at its size (``mesh(source, size,
    max_size=max_size, thin_features=False)`` for the first), in another vertex order.  Where
    a tet leaves [10.7, 164.8] degrees, mesh() stuffs again and mends by other warps (bunny
    at diag/30, uniform); so do the ranges, their lattice tets (range_lattice) joined into one
    lattice (merge_range_lattices): the mending is not per range yet."""
    if isinstance(n_parts, (bool, np.bool_)) or not isinstance(n_parts, (int, np.integer)) or n_parts < 1:
        raise ParoctError(f"n_parts = {n_parts!r}: must be a whole number of ranges, at least 1")
    if mapper is not None and not callable(mapper):
        raise ParoctError(f"mapper = {mapper!r}: must be a function like map(function, *iterables), or None")
    run = map if mapper is None else mapper
    n_parts = int(n_parts)
    surface, h, floor, whole_floor, budget = checked_request(source, size, divisions, thin_features, min_size,
                                                             max_memory)
    field = size_field(h, max_size)
    _check_memory(surface, field, budget)
    stage_seconds: dict = {}  # stage times add up over the passes
    return with_repairs(surface, halve_whole_band(surface, field, floor, whole_floor, budget, bool(thin_features),
                                                  partial(_pass_in_ranges, surface, field, n_parts=n_parts, run=run,
                                                          stage_seconds=stage_seconds), []))


def _pass_in_ranges(surface: Surface, field: SizeField, band: float, *, n_parts: int, run: Callable[..., Iterable],
                    stage_seconds: dict) -> PassOutcome:
    """mesh_in_ranges' pass with the whole band at size band (field: the request), as
    mesher._mesh_at's: the result, what it lost, and where it lost, the advice and the walls
    and gaps (mesher._walls_of_loss, over the whole surface)."""
    attempt = _at_boundary_size(field, band)
    report = _pass_report(surface, field, band, stage_seconds)
    stages = _Stages(report, None)
    frame = pass_frame(attempt.size, surface, report)
    stages.done("frame")
    snapped = rays.snap_surface(frame, surface.vertices)
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    coarse = max(0, frame.levels - attempt.coarse_depth)  # the seeds' coarsest level: ranges are its octants
    # Ranges of whole coarse octants: past one per octant the surface meets, the rest are
    # empty, and are dropped (10**6 ranges of a 30 k-tet sphere took minutes, 0.6 ms each).
    # Past one range a surface vertex the bounds repeat (range_bounds splits by them): the same
    # ranges, with no array of n_parts bounds (10**30 ranges).
    key_bounds = np.unique(range_bounds(frame, snapped, min(n_parts, snapped.shape[0] + 1), coarse))
    firsts, ends = key_bounds[:-1].tolist(), key_bounds[1:].tolist()
    band_pieces = _mapped(run, partial(band_in_range, frame, snapped, faces), firsts, ends, kind=BandPiece)
    _in_order([p.surface_keys for p in band_pieces], firsts, ends)
    report.unresolved_cuts = unresolved_cuts(band_pieces)
    # Each range's octree reads the band and surface cells within one max_size octant of it.
    near_surface = keys_near_ranges(np.concatenate([p.surface_keys for p in band_pieces]), coarse, key_bounds)
    near_band = keys_near_ranges(np.concatenate([p.band_keys for p in band_pieces]), coarse, key_bounds)
    octrees = _mapped(run, partial(octree_in_range, frame, snapped, faces, surface, attempt), near_surface, near_band,
                      firsts, ends, kind=tuple)
    _in_order([leaves for leaves, _ in octrees], firsts, ends)
    keys = np.concatenate([leaves for leaves, _ in octrees])
    levels = np.concatenate([leaf_levels for _, leaf_levels in octrees])
    report.n_leaves, report.leaf_levels = int(keys.shape[0]), _leaf_levels(frame, levels)
    stages.done("octree")
    if keys.shape[0] == 0:  # no leaf inside: the solid is thinner than the lattice everywhere
        result = MeshResult(TetMesh(np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int32)), report, surface,
                            np.zeros((0, 3), dtype=np.int32), np.zeros(0, dtype=np.int32))
    else:
        result = _stuffed_in_ranges(surface, frame, band, keys, levels, key_bounds, band_pieces,
                                    np.cumsum([0] + [leaves.shape[0] for leaves, _ in octrees]), run, report, stages)
    return PassOutcome(result, *pass_losses(surface, report, frame, faces, snapped, stages=stages), report, "")


def _stuffed_in_ranges(surface: Surface, frame: FatFrame, size: float, keys: np.ndarray, levels: np.ndarray,
                       key_bounds: np.ndarray, band: Sequence[BandPiece], bounds: np.ndarray,
                       run: Callable[..., Iterable], report: MeshReport, stages: _Stages) -> MeshResult:
    """The ranges' tets of the leaves (keys, levels: sorted, bounds: the first leaf of each
    range and the end) stuffed, repaired and finished in the ranges, or mended as one where
    a tet leaves the bound (mesh_in_ranges); size: the band's longest edge."""
    firsts = key_bounds[:-1].tolist()
    pieces = _mapped(run, partial(_range_task, mesh_range, frame),
                     range_shares(frame, keys, levels, key_bounds, band, bounds), kind=RangeMesh, count=len(firsts))
    stages.done("stuff")
    numbering = number_ranges(pieces, frame, key_bounds)
    parts = [range_tets(p, numbering, r) for r, p in enumerate(pieces)]
    owned = owned_boundary(parts, len(parts))  # the boundary, held by its owners
    fans = fans_by_owners(owned, len(parts))
    kept = repair_pinches_in_ranges(parts, len(parts), fans)
    fresh = report_snapshot(report)
    if kept is not None:
        result = _finish_ranges(parts, kept, owned, fans, pieces, numbering.n_vertices, report, stages, surface, size)
    else:  # the repair must run on the whole mesh (never seen on a mesher's mesh)
        points, tets, inside, targets, cut_faces = merge_ranges(pieces, frame, key_bounds, numbering)
        result = _finish(points, tets, inside, targets, cut_faces, report, stages, surface, size)
    del parts
    if outside_bound(report):
        # As mesh(): stuffed again with every tet measured and other warps tried near the bad
        # ones, here over the ranges' lattice tets joined into one lattice.
        restore_report(report, fresh)
        lattices = _mapped(run, partial(_range_task, range_lattice, frame),
                           range_shares(frame, keys, levels, key_bounds, band, bounds), kind=RangeLattice,
                           count=len(firsts))
        coords, lattice_tets, inside, cuts, targets, first_centre = merge_range_lattices(lattices,
                                                                                         BandIndex.from_pieces(band))
        lattice_points = frame.to_space(coords)
        points, tets, offsets = stuff(lattice_points, coords, lattice_tets, inside, cuts, targets, flat_ok=True,
                                      first_centre=first_centre)
        stages.done("stuff")
        points, tets, targets, offsets, flags = _mend(lattice_points, coords, first_centre, lattice_tets, inside,
                                                      cuts, targets, points, tets, offsets)
        report.bad_tets = int(np.count_nonzero((flags & OUTSIDE_BOUND) != 0))
        stages.done("warps")
        assert cuts.faces is not None  # taken from the band
        result = _finish(points, tets, inside, targets, cuts.faces, report, stages, surface, size)
        warn_bad_tets(report)
    return result


def _finish_ranges(parts: Sequence[RangeTets], kept: Sequence[np.ndarray], owned: Sequence[BoundaryFaces],
                   fans: Sequence[OwnerFans] | None, pieces: Sequence[RangeMesh], n_vertices: int, report: MeshReport,
                   stages: _Stages, surface: Surface, size: float) -> MeshResult:
    """mesher._finish of the ranges' tets (parts: the pieces' in mesh ids, owned and fans:
    their boundary held by its owners and its fans, kept: what the pinch repair in ranges
    keeps of them), each range finishing its own (range_finish): the mesh and the report of
    the ranges' tets joined in range order."""
    removed = [np.flatnonzero(~alive) for alive in kept]
    report.repaired_tets = sum(r.shape[0] for r in removed)
    if report.repaired_tets:
        # The vertices of removed tets (few: near pinches) go to every range: their exposed
        # faces can now lie on the boundary, found again.
        bared = np.unique(np.concatenate([p.ids[p.tets[r]].ravel() for p, r in zip(parts, removed)]))
        parts = [dataclasses.replace(p, tets=p.tets[alive], core=p.core & ~np.isin(p.ids, bared))
                 for p, alive in zip(parts, kept)]
        owned, fans = owned_boundary(parts, len(parts)), None
    stages.done("repair")
    point_faces = [np.concatenate([piece.target_faces, piece.cut_faces]).astype(np.int32) for piece in pieces]
    done = finish_in_ranges(parts, owned, point_faces, n_vertices, surface, size, fans)
    report_measures(done.summary, int(done.tets.shape[0]), done.topology, report)
    report.missed_vertices, report.missed_faces = done.missed_vertices, done.missed_faces
    report.n_vertices = int(done.points.shape[0])
    stages.done("quality")
    warn_unresolved_cuts(report)
    return MeshResult(TetMesh(done.points, done.tets), report, surface, done.boundary, done.point_faces)


def _mapped(run: Callable[..., Iterable], function: Callable, *iterables, kind: type, count: int | None = None) -> list:
    """run(function, *iterables) as a list, or ParoctError unless it is what map gives: one
    result a range (count, or the length of the first iterable), each a ``kind`` (a mapper
    handing back futures, say, instead of gathering them)."""
    try:
        results = list(run(function, *iterables))
    except TypeError as err:
        raise ParoctError(f"mapper(function, *iterables) failed: {err}; it must work as map does") from None
    expected = len(iterables[0]) if count is None else count
    if len(results) != expected:
        raise ParoctError(f"mapper returned {len(results)} results for {expected} ranges: it must return one result a "
                          "range, in order, as map does")
    wrong = next((r for r in results if not isinstance(r, kind)), None)
    if wrong is not None:
        raise ParoctError(f"mapper returned {type(wrong).__name__!r} results where {kind.__name__} was due: it must "
                          "return the results themselves, in order, as map does")
    return results


def _in_order(keys: Sequence[np.ndarray], firsts: list[int], ends: list[int]) -> None:
    """ParoctError unless each range's result holds keys of its own range [firsts[r], ends[r])
    only (a mapper that returns results out of order)."""
    for r, held in enumerate(keys):
        if held.shape[0] and not (firsts[r] <= held[0] and held[-1] < ends[r]):
            raise ParoctError(f"mapper returned range {r}'s result out of place: it must return the results in "
                              "order, as map does")


@dataclass(frozen=True)
class RangeShare:
    """What one range's tets task reads (range_shares), and no more: keys, levels (N,) its own
    leaves, keys[first:end], and those touching them (touching_leaves: around, indices into
    these), sorted; band: the part of the band their corners read (BandIndex.near)."""

    keys: np.ndarray
    levels: np.ndarray
    first: int
    end: int
    around: np.ndarray
    band: BandIndex


def range_shares(frame: FatFrame, keys: np.ndarray, levels: np.ndarray, key_bounds: np.ndarray,
                 band: Sequence[BandPiece], leaf_bounds: np.ndarray) -> Iterator[RangeShare]:
    """The share of each range of leaves leaf_bounds[r]..leaf_bounds[r + 1] - 1 of the octree
    (keys, levels), one after another: a task sent its share (to another process, a Dask
    worker) is not sent the whole octree and band.  band: the band pieces of the key ranges
    key_bounds; a range's part is taken from the pieces holding its finest leaves
    (band_pieces_for), so no index of the whole band is built."""
    for first, end in zip(leaf_bounds[:-1].tolist(), leaf_bounds[1:].tolist()):
        around = touching_leaves(keys, levels, first, end)
        rows = np.sort(np.concatenate([np.arange(first, end), around]))
        read = band_pieces_for(keys, levels, rows, frame.levels, key_bounds)
        before = int(np.searchsorted(around, first))
        leaves = finest_leaves(keys[rows], levels[rows], frame)
        local_around = np.concatenate([np.arange(before), np.arange(before + end - first, rows.shape[0])])
        index = BandIndex.from_pieces([_piece_near(band[i], leaves) for i in read])
        yield RangeShare(keys[rows], levels[rows], before, before + end - first, local_around,
                         index.near(index.vertices_on(leaves)))


def _piece_near(piece: BandPiece, leaves: FinestLeaves) -> BandPiece:
    """The part of a band piece that BandIndex.near can keep for a range whose finest leaves
    these are: its vertices on those leaves (BandIndex.vertices_on), its edges with both ends
    on them, and the edges those vertices warp onto.  Joining these parts instead of the
    whole pieces sorts only what a range reads."""
    kept = leaves.corners_among(piece.coords)
    edge_kept = leaves.corners_among(piece.edge_starts) & leaves.corners_among(piece.edge_ends)
    targets = piece.targets[kept]
    edge_kept[targets[targets >= 0]] = True
    new_edge = np.cumsum(edge_kept) - 1
    return dataclasses.replace(piece, coords=piece.coords[kept], inside=piece.inside[kept],
                               targets=np.where(targets >= 0, new_edge[targets], -1),
                               edge_starts=piece.edge_starts[edge_kept], edge_ends=piece.edge_ends[edge_kept],
                               directions=piece.directions[edge_kept], fracs=piece.fracs[edge_kept],
                               points=piece.points[edge_kept], faces=piece.faces[edge_kept])


def _range_task(task: Callable, frame: FatFrame, share: RangeShare):
    """task (mesh_range or range_lattice) of one range's share: one range's task in
    mesh_in_ranges."""
    return task(frame, share.keys, share.levels, share.band, share.first, share.end, share.around)


def unresolved_cuts(pieces: Sequence[BandPiece]) -> int:
    """How many distinct cut edges of the pieces have no crossing (a midpoint, face -1)."""
    keys = [edge_keys(p.edge_starts[p.faces < 0], p.edge_ends[p.faces < 0]) for p in pieces]
    return int(np.unique(np.concatenate(keys)).shape[0]) if keys else 0


__all__ = ["BandIndex", "BandPiece", "RangeLattice", "RangeMesh", "band_in_range", "band_pieces_for", "edge_keys",
           "faces_over_box_rows", "faces_over_rows", "finest_band_in_ranges", "keys_near_ranges",
           "merge_band_pieces", "merge_range_lattices", "merge_ranges", "mesh_in_ranges", "mesh_range", "number_ranges",
           "octree_in_range", "pack_coords", "point_owners", "range_bounds", "range_lattice",
           "range_shares", "range_tets", "RangeNumbering", "RangeShare", "touching_leaves", "unpack_coords", "unresolved_cuts"]
