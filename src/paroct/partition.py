"""Meshing in Morton ranges: the leaves split into contiguous ranges of their sorted keys, each
range numbered, classified, emitted and stuffed on its own, and the pieces merged.

The first working step toward meshes of 1e9 tets on many workers (docs/design.md, "Toward
partitions by Morton ranges").  What a range needs beyond its own leaves is one ring of
leaves touching them (``touching_leaves``): the split points of its transition leaves and
the classes of its vertices depend on no other leaf.  Band data (the cut cells' classes,
cut points and warps, O(surface)) comes from one process, as do the octree and the finish
(pinch repair, quality, compaction); mending by other warps, which needs the whole mesh, is
not done per range (a range pass whose tets leave the bound says so).  The merged mesh is
the one-process pass's, tet for tet and bit for bit (tests/test_partition.py), because every
tie stuffing breaks is broken by lattice coordinates, not by vertex ids (sessions 41, 43).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .errors import ParoctError
from .frame import CUBE_CORNERS, FatFrame
from .lattice import LeafVertices, graded_tets, number_vertices
from .mesher import (BandStuffing, MeshResult, _at_boundary_size, _available_memory, _check_memory, _finish, _losses,
                     _pass_report, _refuse_losing_too_much, _Stages, pass_leaves, resolve_size, vertex_classes)
from .octant import MAX_LEVEL, morton_coords, morton_key, octant_last_key, sorted_lookup
from .octree import octant_lattice_anchors
from .sizing import size_field
from .stuffing import DIHEDRAL_BOUND, CutEdges, collect_cut_edges, stuff
from .surface import Surface, SurfaceSource, load_surface

#: Bits per axis of a packed lattice coordinate (pack_coords): lattice coordinates of a frame
#: reach 2**MAX_LEVEL.
_COORD_BITS = 21


def leaf_ranges(n_leaves: int, n_parts: int) -> np.ndarray:
    """Boundaries (n_parts + 1,) int64 of n_parts contiguous ranges of about equal numbers of
    leaves: range r is leaves[bounds[r]:bounds[r + 1]] (some empty if n_parts > n_leaves)."""
    if n_parts < 1:
        raise ValueError(f"n_parts = {n_parts}: must be at least 1")
    return (np.arange(n_parts + 1, dtype=np.int64) * n_leaves) // n_parts


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


@dataclass(frozen=True)
class BandIndex:
    """The band (graded_leaves' BandStuffing) with its vertices and cut edges sorted once, so
    that a range finds its part by binary searches, in time of its own size.  vertex_keys:
    pack_coords of the band vertices, ascending, vertex_ids: the band id of each; edge_keys:
    start * P + end of the cut edges (band ids), ascending, edge_ids: the edge of each."""

    band: BandStuffing
    vertex_keys: np.ndarray
    vertex_ids: np.ndarray
    edge_keys: np.ndarray
    edge_ids: np.ndarray

    @classmethod
    def build(cls, band: BandStuffing) -> BandIndex:
        packed = pack_coords(band.coords)
        vertex_ids = np.argsort(packed)
        edges = band.cuts.starts.astype(np.int64) * band.coords.shape[0] + band.cuts.ends
        edge_ids = np.argsort(edges)
        return cls(band, packed[vertex_ids], vertex_ids, edges[edge_ids], edge_ids)

    def vertices_at(self, coords: np.ndarray) -> np.ndarray:
        """Band ids (ascending, distinct) of the band vertices among coords (K, 3)."""
        at, found = sorted_lookup(self.vertex_keys, pack_coords(coords))
        return np.unique(self.vertex_ids[at[found]])

    def edges(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """The cut edge of each (start, end) pair of band ids; AssertionError if one is none."""
        at, found = sorted_lookup(self.edge_keys, starts.astype(np.int64) * self.band.coords.shape[0] + ends)
        if not found.all():
            raise AssertionError(f"{int((~found).sum())} mixed edges of a range are not cut edges of the band")
        return self.edge_ids[at]


@dataclass(frozen=True)
class RangeMesh:
    """One range's stuffed tets, its own leaves' only, and the points they use.  points
    (V + E, 3) float64: lattice vertices where the warps put them, then cut points; tets
    (M, 4) int32 into points; vertex_keys (V,) int64: pack_coords of each lattice vertex;
    inside (V,) bool; targets (V,) int64: the band cut edge (an index into the band's
    CutEdges) each vertex warps onto, or -1; cut_ids (E,) int64: the band cut edge of each
    cut point."""

    points: np.ndarray
    tets: np.ndarray
    vertex_keys: np.ndarray
    inside: np.ndarray
    targets: np.ndarray
    cut_ids: np.ndarray


def mesh_range(frame: FatFrame, keys: np.ndarray, levels: np.ndarray, band: BandIndex, first: int,
               end: int) -> RangeMesh:
    """Number, classify, emit and stuff the leaves keys[first:end] of graded_leaves' octree
    (keys, levels; band: its band, indexed), from them, the leaves touching them and the band.

    Vertices are numbered over the range and its touching leaves, the band's vertices among
    their corners first (number_vertices' prefix, in band order), so that split points,
    classes and the quad rule's corner-before-centre order come out as over the whole octree;
    only the range's own tets are emitted and stuffed.  Its cut edges are the band's that its
    tets hold, plus those its vertices warp onto in touching cells."""
    around = touching_leaves(keys, levels, first, end)
    before = int(np.searchsorted(around, first))
    rows = np.concatenate([around[:before], np.arange(first, end, dtype=np.int64), around[before:]])
    own = np.arange(before, before + end - first)
    anchors = octant_lattice_anchors(keys[rows], frame)
    sides = np.int64(1) << (frame.levels - levels[rows].astype(np.int64))
    corners = (anchors[:, None, :] + sides[:, None, None] * CUBE_CORNERS[None, :, :]).reshape(-1, 3)
    in_range = band.vertices_at(corners)  # local vertex i < len(in_range) is band vertex in_range[i]
    vertices = number_vertices(anchors, sides, prefix=band.band.coords[in_range], eager=False)
    inside = vertex_classes(vertices, band.band.inside[in_range])
    own_vertices = LeafVertices(vertices.corner_ids[own], vertices.split_row[own], vertices.split_ids,
                                vertices.coords, vertices.first_centre)
    tets = graded_tets(own_vertices, inside)
    cuts, cut_ids, targets = _range_cuts(band, in_range, vertices.coords, tets, inside)
    points, out_tets, _ = stuff(frame.to_space(vertices.coords), vertices.coords, tets, inside, cuts, targets,
                                first_centre=vertices.first_centre)
    # Only the points the range's tets use: vertices of touching leaves alone may lack the
    # edge they warp onto here, and their own range places them.
    n = vertices.coords.shape[0]
    used = np.zeros(points.shape[0], dtype=bool)
    used[out_tets.ravel()] = True
    new_id = np.cumsum(used) - 1
    lattice = np.flatnonzero(used[:n])
    global_targets = np.full(n, -1, dtype=np.int64)
    warped = targets >= 0
    global_targets[warped] = cut_ids[targets[warped]]
    return RangeMesh(points[used], new_id[out_tets].astype(np.int32), pack_coords(vertices.coords[lattice]),
                     inside[lattice], global_targets[lattice], cut_ids[used[n:]])


def _range_cuts(band: BandIndex, in_range: np.ndarray, coords: np.ndarray, tets: np.ndarray,
                inside: np.ndarray) -> tuple[CutEdges, np.ndarray, np.ndarray]:
    """The range's CutEdges (its tets' mixed edges, then the band edges its band vertices warp
    onto that its tets lack, where both ends are its vertices), the band edge (E,) of each,
    and the targets (V,) into them.  Local vertex i < len(in_range) is band vertex
    in_range[i] (ascending)."""
    band_cuts = band.band.cuts
    starts, ends, directions, head, upper, chain = collect_cut_edges(tets, inside, coords)
    cut_ids = band.edges(in_range[starts], in_range[ends])  # mixed edges join band vertices
    wanted = band.band.targets[in_range]
    sorted_ids = np.argsort(cut_ids)
    at, held = sorted_lookup(cut_ids[sorted_ids], wanted)
    extra = np.unique(wanted[(wanted >= 0) & ~held])
    start_at, start_found = sorted_lookup(in_range, band_cuts.starts[extra])
    end_at, end_found = sorted_lookup(in_range, band_cuts.ends[extra])
    both = start_found & end_found
    extra, extra_starts, extra_ends = extra[both], start_at[both].astype(starts.dtype), end_at[both].astype(ends.dtype)
    # Extra edges are in no tet: the lookup table (head, upper, chain) never reaches them.
    table = (head, np.concatenate([upper, np.maximum(extra_starts, extra_ends).astype(upper.dtype)]),
             np.concatenate([chain, np.full(extra.shape[0], -1, dtype=chain.dtype)]))
    all_ids = np.concatenate([cut_ids, extra])
    faces = None if band_cuts.faces is None else band_cuts.faces[all_ids]
    cuts = CutEdges(np.concatenate([starts, extra_starts]), np.concatenate([ends, extra_ends]),
                    np.concatenate([directions, band_cuts.directions[extra].astype(directions.dtype)]),
                    band_cuts.fracs[all_ids], band_cuts.points[all_ids], table, faces)
    extra_at, extra_held = sorted_lookup(extra, wanted)
    targets = np.full(coords.shape[0], -1, dtype=np.int64)
    held_ids = sorted_ids[at] if sorted_ids.size else at
    targets[: in_range.shape[0]] = np.where(held, held_ids, np.where(extra_held, cut_ids.shape[0] + extra_at, -1))
    return cuts, all_ids, targets


def merge_ranges(pieces: list[RangeMesh], n_cuts: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pieces as one stuffed mesh, each lattice vertex once (by its coordinates), then the
    band's n_cuts cut points in band order, as one pass over the whole octree lays them out:
    (points (L + n_cuts, 3), tets (M, 4) int32, inside (L,), targets (L,) into the band's cut
    edges).  A vertex or cut point the pieces place differently is an
    AssertionError: stuffing in ranges must agree where they meet."""
    all_keys = np.concatenate([p.vertex_keys for p in pieces])
    _, first, vertex_of = np.unique(all_keys, return_index=True, return_inverse=True)
    n_vertices = first.shape[0]
    points = np.empty((n_vertices + n_cuts, 3))
    placed = np.zeros(n_cuts, dtype=bool)
    inside = np.concatenate([p.inside for p in pieces])[first]
    targets = np.concatenate([p.targets for p in pieces])[first]
    lattice = np.concatenate([p.points[: p.vertex_keys.shape[0]] for p in pieces])
    points[:n_vertices] = lattice[first]
    if not np.array_equal(lattice, points[vertex_of]):
        raise AssertionError("ranges place a shared lattice vertex differently")
    tets, start = [], 0
    for p in pieces:
        n = p.vertex_keys.shape[0]
        new_id = np.concatenate([vertex_of[start:start + n], n_vertices + p.cut_ids])
        cut_points = p.points[n:]
        seen = placed[p.cut_ids]
        if not np.array_equal(points[n_vertices + p.cut_ids[seen]], cut_points[seen]):
            raise AssertionError("ranges place a shared cut point differently")
        points[n_vertices + p.cut_ids] = cut_points
        placed[p.cut_ids] = True
        tets.append(new_id[p.tets].astype(np.int32))
        start += n
    points[n_vertices:][~placed] = np.nan  # cut points no range uses: no tet refers to them
    return points, np.concatenate(tets) if tets else np.zeros((0, 4), dtype=np.int32), inside, targets


def mesh_in_ranges(source: SurfaceSource | Surface, size: float | None = None, *, n_parts: int,
                   divisions: float | None = None, max_size: float | None = None) -> MeshResult:
    """One meshing pass at ``size`` (graded up to max_size, as mesh()), its leaves meshed in
    n_parts Morton ranges (mesh_range) and merged (merge_ranges), then finished as one mesh
    (pinch repair, quality, compaction).

    The same tets and points as ``mesh(source, size, max_size=max_size, thin_features=False)``
    where that pass needs no mending (its tets inside [10.7, 164.8] degrees at once, as on
    every corpus part at diag/40 and /80), in another vertex order.  Refinement near thin
    walls, curvature and the other asks are not done per range yet; a pass whose tets leave
    the bound warns (mending needs the whole mesh)."""
    if isinstance(n_parts, (bool, np.bool_)) or not isinstance(n_parts, (int, np.integer)) or n_parts < 1:
        raise ParoctError(f"n_parts = {n_parts!r}: must be a whole number of ranges, at least 1")
    surface = source if isinstance(source, Surface) and source.validated else load_surface(source)
    h = resolve_size(surface, size, divisions)
    field = _at_boundary_size(size_field(h, max_size), h)
    _check_memory(surface, field, _available_memory())
    report = _pass_report(surface, field, h, {})
    stages = _Stages(report, None)
    frame, _, _, _, keys, levels, band = pass_leaves(surface, field, report, stages)
    if keys.shape[0] == 0:
        _refuse_losing_too_much(report, h, "thin walls are not refined in ranges: use mesh()")
    bounds, index = leaf_ranges(keys.shape[0], n_parts), BandIndex.build(band)
    pieces = [mesh_range(frame, keys, levels, index, int(bounds[r]), int(bounds[r + 1])) for r in range(int(n_parts))]
    stages.done("stuff")
    points, tets, inside, targets = merge_ranges(pieces, band.cuts.starts.shape[0])
    cut_faces = band.cuts.faces
    assert cut_faces is not None  # cut_edges records each cut point's triangle
    result = _finish(points, tets, inside, targets, cut_faces, report, stages, surface, h)
    if report.n_tets and not DIHEDRAL_BOUND[0] <= report.min_dihedral <= report.max_dihedral <= DIHEDRAL_BOUND[1]:
        report.warnings.append(f"dihedral angles {report.min_dihedral:.4g} .. {report.max_dihedral:.4g} leave "
                               f"[{DIHEDRAL_BOUND[0]}, {DIHEDRAL_BOUND[1]}]: mending by other warps needs the whole "
                               "mesh and is not done in ranges")
    lost = _losses(report, surface)
    if lost:
        _refuse_losing_too_much(report, h, "thin walls are not refined in ranges: use mesh()")
        report.warnings.append(f"{lost} (thin walls are not refined in ranges)")
    return result


__all__ = ["BandIndex", "RangeMesh", "leaf_ranges", "merge_ranges", "mesh_in_ranges", "mesh_range", "pack_coords",
           "touching_leaves"]
