"""Local feature size: where the boundary must be finer than size, read off the surface.

Three asks, each only when the user makes it (SizeField.curvature, .layers, .patch_sizes):

- **curvature** N: boundary elements of long edge at most 2 pi r / N where the surface bends
  with radius r (N elements per full turn, as Gmsh's Mesh.MeshSizeFromCurvature).  The
  curvature is measured at the scale of the elements each level would make (curvature_asks,
  bent_cells): the largest principal curvature of a least-squares normal field over the
  lattice cells around, per patch, so that scan noise finer than a cell averages out; a
  level is asked only where the bend shrinks at the next scale, which a crease of the
  triangulation never does.  Edges sharper than the feature angle, or than one element's
  turn, are edges of the part (boundary.surface_patches), not curvature.
- **layers** K: at least K element layers across every wall (material, not gap) thinner than
  K x size: long edge at most t / K for a wall of thickness t, from the thickness samples that
  the lattice rows measure (features.thin_features; wall_asks).
- **patch sizes**: a long edge asked on a named patch of the boundary (the input's named
  groups, else patch_1, patch_2, ... of the surface split at the feature angle, as
  MeshResult.boundary_patches names them): the patch's triangles ask the levels below size
  that reach it (patch_asks).
- **regions** (sizing.Box, sizing.Sphere) and a **size function** asking for less than
  size: the boundary there asks the levels that reach it (region_asks, function_asks); the
  interior stays at least size, the finest of the interior lattice.

Each gives asks (FeatureAsks): points (S, 3) in model units, depths (S,) int64, the levels
below size each point needs (1 or more, at most max_depth), and the ring of coarse cells
each point's ask covers.  The mesher turns them into band levels
(band.band_levels) and refines the band there, measuring and mending the tets where it
changes level (mesher._refine_rounds).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .boundary import surface_labels, surface_patches
from .errors import ParoctError
from .features import ThinFeatures, face_normals
from .frame import SPACE_TO_LATTICE, FatFrame
from .sizing import evaluated_size_function
from .surface import Surface


@dataclass(frozen=True)
class FeatureAsks:
    """Where the boundary must be finer than size: points (S, 3) float64 in model units,
    depth (S,) int64 levels below size (>= 1) at each, ring (S,) int64 the coarse cells
    around each point's that share its ask (band.band_levels), and a line saying why for
    the notes."""

    points: np.ndarray
    depth: np.ndarray
    ring: np.ndarray
    why: str

    @property
    def empty(self) -> bool:
        return self.depth.size == 0

    def deeper_than(self, levels: int) -> FeatureAsks:
        """The asks for more than ``levels`` levels below size, as levels below size / 2**levels."""
        if levels <= 0:
            return self
        keep = self.depth > levels
        return FeatureAsks(self.points[keep], self.depth[keep] - levels, self.ring[keep], self.why)


def no_asks() -> FeatureAsks:
    return FeatureAsks(np.zeros((0, 3)), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), "")


def merged_asks(a: FeatureAsks, b: FeatureAsks) -> FeatureAsks:
    """Both sets of asks (a's first); why joins the non-empty texts."""
    why = " and ".join(w for w in (a.why, b.why) if w)
    return FeatureAsks(np.concatenate([a.points, b.points]), np.concatenate([a.depth, b.depth]),
                       np.concatenate([a.ring, b.ring]), why)


def pieces_asks(frame: FatFrame, asked: list[tuple[np.ndarray, int]], why: str) -> FeatureAsks:
    """Asks for ``level`` levels in the cells of frame's lattice that each set of triangle
    pieces (P, 3, 3) meets (cells_met; ring 0), for the (pieces, level) pairs of asked."""
    if not asked:
        return no_asks()
    cells = [cells_met(frame, pieces) for pieces, _ in asked]
    depth = np.concatenate([np.full(c.shape[0], level, dtype=np.int64) for c, (_, level) in zip(cells, asked)])
    return FeatureAsks(frame.to_space(np.concatenate(cells) + 0.5), depth, np.zeros(depth.size, dtype=np.int64), why)


@dataclass(frozen=True)
class SurfacePieces:
    """The surface's triangles cut to a frame's size (triangle_pieces), shared by the asks:
    corners (P, 3, 3), the triangle (P,) of each piece, and probes (P * 4, 3), each piece's
    corners and centroid, where regions and size functions are read."""

    corners: np.ndarray
    owner: np.ndarray
    probes: np.ndarray


def surface_pieces(surface: Surface, frame: FatFrame) -> SurfacePieces:
    """The surface's triangles cut to pieces no longer than frame.h."""
    corners, owner = triangle_pieces(np.asarray(surface.vertices, dtype=np.float64)[surface.faces], frame.h)
    return SurfacePieces(corners, owner, np.concatenate([corners, corners.mean(axis=1, keepdims=True)], axis=1).reshape(-1, 3))


#: Degrees below which curvature_asks splits no patch, however many elements a turn asks:
#: smooth surfaces are tessellated with facets turning a few degrees each, and splitting
#: there (360 / N for N = 1000 is 0.36) cut them into patches of one facet, flat, so a larger
#: N refined less, and a large enough one nothing (bunny at diag/10: N = 32, 128, 1000, 1e5
#: gave 478 k, 304 k, 139 k, 30 k tets, the last as without curvature).  10 degrees is
#: 360 / 36: N up to 36 split as before.
MIN_CURVATURE_SPLIT = 10.0


def curvature_split_angle(feature_angle: float, per_turn: float) -> float:
    """Degrees at which curvature_asks splits the surface into patches measured apart: the
    feature angle, or the turn of one element, 360 / per_turn, if smaller (an edge turning
    more than an element may is an edge of the part, not curvature), but not below
    MIN_CURVATURE_SPLIT (so more elements a turn never ask fewer)."""
    return min(feature_angle, max(360 / per_turn, MIN_CURVATURE_SPLIT))


#: A bend measured at one scale is resolved by finer elements only if it shrinks when measured
#: at half the scale (a fillet's bend per cell halves; a crease's, one edge of the
#: triangulation, stays): the finer cells' bend must be below this fraction of the coarser's.
SHRINKS = 0.75


def curvature_asks(surface: Surface, frame: FatFrame, per_turn: float, max_depth: int, feature_angle: float,
                   cut: SurfacePieces | None = None) -> FeatureAsks:
    """Asks for long edges of at most 2 pi r / per_turn where the surface bends with radius
    r, measured at the scale of the elements each level would make (bent_cells), coarse to
    fine.  The triangles are split into pieces of edge at most frame.h and binned by
    centroid into the cells of frame's lattice (edge frame.h, the size): a cell's bend is its
    curvature times the cell's edge, the turn of the surface from cell to cell, and a cell
    bends too much for elements of its size when that exceeds 2 pi / per_turn.  The pieces in
    and around those cells are cut to half the edge and binned into cells of half the edge: a
    cell that bent too much asks one level finer if every finer cell of its pieces bends less
    than SHRINKS times it, and the finer cells of those that still bend too much are measured
    again, down to max_depth.  A bend that does not shrink is a crease of the triangulation,
    which no element size resolves.  Each patch of the surface split at
    curvature_split_angle (boundary.surface_patches) is measured apart: an edge turning more
    than one element may is an edge of the part, not curvature.  cut: the surface
    cut to frame.h (surface_pieces), if it already is."""
    if max_depth < 1:
        return no_asks()
    vertices = np.ascontiguousarray(surface.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    normals = face_normals(vertices, faces)
    patches = surface_patches(surface, curvature_split_angle(feature_angle, per_turn))
    limit = 2 * np.pi / per_turn
    cut = surface_pieces(surface, frame) if cut is None else cut
    pieces, owner = cut.corners, cut.owner
    centres, bend, group = _bends(frame, 0, *_piece_measures(frame, 0, pieces), patches[owner], normals[owner])
    too_bent = bend > limit
    asked_pieces, smallest = [], np.inf
    for d in range(max_depth):
        if not too_bent.any():
            break
        # The pieces in and around the cells that bend too much, cut to the finer cells; of
        # those, the ones in the finer cells inside them (core) and the ring around, for the fits.
        bent = np.floor(frame.to_lattice(centres[too_bent]) * 2**d).astype(np.int64)
        near = _near_cells(np.floor(frame.to_lattice(centres) * 2**d).astype(np.int64)[group], bent)
        level_pieces = pieces
        pieces, child_of = triangle_pieces(pieces[near], frame.h / 2 ** (d + 1))
        centroids, area, finer_cells = _piece_measures(frame, d + 1, pieces)
        core = _near_cells(finer_cells // 2, bent, ring=False)
        if not core.any():  # no piece lies in a cell that bent (its group's centre rounded across a face)
            break
        keep = _near_cells(finer_cells, finer_cells[core])
        pieces, child_of, core = pieces[keep], child_of[keep], core[keep]
        parent, owner = group[near][child_of], owner[near][child_of]
        finer_centres, finer_bend, finer_group = _bends(frame, d + 1, centroids[keep], area[keep], finer_cells[keep],
                                                        patches[owner], normals[owner], core)
        # A cell is asked finer if the worst of its pieces' finer cells bends less than it:
        # a fillet's bend halves; a crease's stays, and noise rarely halves everywhere.
        worst_child = np.zeros(bend.shape[0])
        np.maximum.at(worst_child, parent, finer_bend[finer_group])
        asked = too_bent & (worst_child < SHRINKS * bend)
        if asked.any():
            finite = asked & np.isfinite(bend)
            if finite.any():
                smallest = min(smallest, frame.h / 2**d / bend[finite].max())
            asked_pieces.append((level_pieces[asked[group]], d + 1))
        from_asked = np.zeros(finer_bend.shape[0], dtype=bool)
        from_asked[finer_group[asked[parent]]] = True
        centres, bend, group, too_bent = finer_centres, finer_bend, finer_group, (finer_bend > limit) & from_asked
    deepest = max((level for _, level in asked_pieces), default=0)
    return pieces_asks(frame, asked_pieces, f"the surface curves more than {per_turn:g} elements per turn allow ("
                       + (f"smallest radius about {smallest:.4g}, " if np.isfinite(smallest) else "")
                       + f"up to {deepest} level{'s' * int(deepest > 1)} finer)")


def _piece_measures(frame: FatFrame, depth: int, pieces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroids (P, 3), areas (P,) and the cells (P, 3) int64 of frame's lattice ``depth``
    levels finer that hold the centroids, of the triangles pieces (P, 3, 3)."""
    return _measures(np.ascontiguousarray(pieces), np.ascontiguousarray(frame.origin, dtype=np.float64),
                     2.0**depth / frame.h, SPACE_TO_LATTICE.astype(np.float64))


@nb.njit(cache=True)
def _measures(pieces, origin, scale, matrix):
    n = pieces.shape[0]
    centroids, area, cells = np.empty((n, 3)), np.empty(n), np.empty((n, 3), dtype=np.int64)
    for t in range(n):
        for k in range(3):
            centroids[t, k] = (pieces[t, 0, k] + pieces[t, 1, k] + pieces[t, 2, k]) / 3
        ux, uy, uz = pieces[t, 1, 0] - pieces[t, 0, 0], pieces[t, 1, 1] - pieces[t, 0, 1], pieces[t, 1, 2] - pieces[t, 0, 2]
        vx, vy, vz = pieces[t, 2, 0] - pieces[t, 0, 0], pieces[t, 2, 1] - pieces[t, 0, 1], pieces[t, 2, 2] - pieces[t, 0, 2]
        area[t] = 0.5 * np.sqrt((uy * vz - uz * vy) ** 2 + (uz * vx - ux * vz) ** 2 + (ux * vy - uy * vx) ** 2)
        for i in range(3):
            u = 0.0
            for k in range(3):
                u += matrix[i, k] * (centroids[t, k] - origin[k])
            cells[t, i] = np.int64(np.floor(u * scale))
    return centroids, area, cells


def _bends(frame: FatFrame, depth: int, centroids: np.ndarray, area: np.ndarray, cells: np.ndarray,
           patch: np.ndarray, normals: np.ndarray, measure: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """bent_cells of pieces (their centroids, areas, cells of frame's lattice ``depth`` levels
    finer: _piece_measures; their patches and unit normals), the curvature times the cells'
    edge: (centres, bend, group of each piece); measure (P,): as in bent_cells."""
    centres, curvature, group = bent_cells(cells, patch, centroids, normals, area, measure)
    return centres, curvature * (frame.h / 2**depth), group


def cells_met(frame: FatFrame, pieces: np.ndarray) -> np.ndarray:
    """The distinct cells (C, 3) int64 of frame's lattice that the bounding boxes (in lattice
    coordinates) of the triangles pieces (P, 3, 3) meet: every cell a piece meets, and a few
    beside it; in order of their coordinates (x slowest)."""
    if pieces.shape[0] == 0:
        return np.zeros((0, 3), dtype=np.int64)
    return _box_cells(np.ascontiguousarray(pieces, dtype=np.float64), np.ascontiguousarray(frame.origin, dtype=np.float64),
                      1.0 / frame.h, SPACE_TO_LATTICE.astype(np.float64))


@nb.njit(cache=True)
def _box_cells(pieces, origin, scale, matrix):
    n = pieces.shape[0]
    lo = np.empty((n, 3), dtype=np.int64)
    hi = np.empty((n, 3), dtype=np.int64)
    count = 0
    for t in range(n):
        for i in range(3):
            low, high = np.inf, -np.inf
            for c in range(3):
                u = 0.0
                for k in range(3):
                    u += matrix[i, k] * (pieces[t, c, k] - origin[k])
                low, high = min(low, u * scale), max(high, u * scale)
            lo[t, i], hi[t, i] = np.int64(np.floor(low)), np.int64(np.floor(high))
        count += (hi[t, 0] - lo[t, 0] + 1) * (hi[t, 1] - lo[t, 1] + 1) * (hi[t, 2] - lo[t, 2] + 1)
    first = np.empty(3, dtype=np.int64)
    span = np.empty(3, dtype=np.int64)
    for i in range(3):
        first[i] = lo[:, i].min()
        span[i] = hi[:, i].max() - first[i] + 1
    keys = np.empty(count, dtype=np.int64)
    m = 0
    for t in range(n):
        for x in range(lo[t, 0], hi[t, 0] + 1):
            for y in range(lo[t, 1], hi[t, 1] + 1):
                for z in range(lo[t, 2], hi[t, 2] + 1):
                    keys[m] = ((x - first[0]) * span[1] + (y - first[1])) * span[2] + (z - first[2])
                    m += 1
    keys.sort()
    out = np.empty((count, 3), dtype=np.int64)
    u = 0
    for j in range(count):
        if j > 0 and keys[j] == keys[j - 1]:
            continue
        out[u, 0] = keys[j] // (span[1] * span[2]) + first[0]
        out[u, 1] = keys[j] // span[2] % span[1] + first[1]
        out[u, 2] = keys[j] % span[2] + first[2]
        u += 1
    return out[:u]


def _near_cells(cells: np.ndarray, marked: np.ndarray, ring: bool = True) -> np.ndarray:
    """Mask (S,) of the cells (S, 3) among the marked cells (B, 3, repeats allowed), or next
    to one (26 around) with ring."""
    if len(cells) == 0 or len(marked) == 0:  # near nothing (the kernel's box needs both)
        return np.zeros(len(cells), dtype=bool)
    return _near(np.ascontiguousarray(cells, dtype=np.int64), np.ascontiguousarray(marked, dtype=np.int64), ring)


@nb.njit(cache=True)
def _near(cells, marked, ring):
    lo = np.empty(3, dtype=np.int64)
    span = np.empty(3, dtype=np.int64)
    for k in range(3):
        lo[k] = min(cells[:, k].min(), marked[:, k].min()) - 1
        span[k] = max(cells[:, k].max(), marked[:, k].max()) - lo[k] + 2
    reach = 1 if ring else 0
    keys = np.empty(marked.shape[0], dtype=np.int64)
    for b in range(marked.shape[0]):
        keys[b] = ((marked[b, 0] - lo[0]) * span[1] + (marked[b, 1] - lo[1])) * span[2] + (marked[b, 2] - lo[2])
    keys.sort()
    unique = 0
    for b in range(keys.shape[0]):
        if b == 0 or keys[b] != keys[b - 1]:
            keys[unique] = keys[b]
            unique += 1
    # The marked cells moved by the 9 (dx, dy) steps; the 3 dz steps of one are consecutive
    # keys, so a cell is near when the first table key from its own minus reach is within
    # 2 reach of it.
    table = np.empty(unique * (2 * reach + 1) ** 2, dtype=np.int64)
    n = 0
    for b in range(unique):
        for dx in range(-reach, reach + 1):
            for dy in range(-reach, reach + 1):
                table[n] = keys[b] + (dx * span[1] + dy) * span[2]
                n += 1
    table.sort()
    out = np.empty(cells.shape[0], dtype=np.bool_)
    for s in range(cells.shape[0]):
        key = ((cells[s, 0] - lo[0]) * span[1] + (cells[s, 1] - lo[1])) * span[2] + (cells[s, 2] - lo[2])
        at = np.searchsorted(table, key - reach)
        out[s] = at < n and table[at] <= key + reach
    return out


def triangle_pieces(corners: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (S, 3, 3) cut into pieces with no edge longer than spacing: the pieces'
    corners (P, 3, 3) float64 and the triangle (P,) each came from, in order of triangle.
    A triangle with a longer edge is cut into k = ceil(longest / spacing) >= 2 strips by the lines
    parallel to its shortest edge through the points that split the other two edges in k
    equal parts, each strip a triangle and the rest two (2 k - 1 pieces), and the pieces cut
    the same way until none is too long.  A sliver of length L gives about 2 L / spacing
    pieces (a split into similar triangles gives (L / spacing)**2, longest-edge bisection
    about (L / spacing)**1.6)."""
    pieces = np.ascontiguousarray(corners, dtype=np.float64).reshape(-1, 3, 3)
    parent = np.arange(pieces.shape[0])
    done_pieces, done_parent = [], []
    while pieces.shape[0]:
        small = _short_enough(pieces, float(spacing))
        done_pieces.append(pieces[small])
        done_parent.append(parent[small])
        pieces, parent = pieces[~small], parent[~small]
        if pieces.shape[0]:
            counts = _strip_counts(pieces, float(spacing))
            child_of = np.repeat(np.arange(pieces.shape[0]), counts)
            pieces, parent = _strips(pieces, float(spacing), counts), parent[child_of]
    pieces, parent = np.concatenate(done_pieces), np.concatenate(done_parent)
    order = np.argsort(parent, kind="stable")
    return pieces[order], parent[order]


@nb.njit(cache=True)
def _short_enough(pieces, spacing):
    """Mask (P,) of the pieces with no edge longer than spacing."""
    out = np.empty(pieces.shape[0], dtype=np.bool_)
    for t in range(pieces.shape[0]):
        longest = 0.0
        for j in range(3):
            d = 0.0
            for m in range(3):
                d += (pieces[t, (j + 1) % 3, m] - pieces[t, j, m]) ** 2
            longest = max(longest, d)
        out[t] = longest <= spacing * spacing
    return out


@nb.njit(cache=True)
def _strip_plan(tri, spacing):
    """(a, k): the corner opposite tri's shortest edge and the number of strips."""
    shortest, a, longest = np.inf, 0, 0.0
    for j in range(3):
        d = 0.0
        for m in range(3):
            d += (tri[(j + 2) % 3, m] - tri[(j + 1) % 3, m]) ** 2  # the edge opposite corner j
        if d < shortest:
            shortest, a = d, j
        longest = max(longest, d)
    # At least 2: only pieces _short_enough rejects are cut, and an edge whose square rounds
    # above spacing**2 may have a root that rounds to spacing (k = 1 would cut it into itself).
    return a, max(2, int(np.ceil(np.sqrt(longest) / spacing)))


@nb.njit(cache=True)
def _strip_counts(pieces, spacing):
    counts = np.empty(pieces.shape[0], dtype=np.int64)
    for t in range(pieces.shape[0]):
        counts[t] = 2 * _strip_plan(pieces[t], spacing)[1] - 1
    return counts


@nb.njit(cache=True)
def _strips(pieces, spacing, counts):
    out = np.empty((counts.sum(), 3, 3))
    n = 0
    for t in range(pieces.shape[0]):
        a, k = _strip_plan(pieces[t], spacing)
        pa, pb, pc = pieces[t, a], pieces[t, (a + 1) % 3], pieces[t, (a + 2) % 3]
        for i in range(k):
            f0, f1 = i / k, (i + 1) / k
            # p_i on a-b, q_i on a-c: the triangle (p_i, p_i+1, q_i+1), then (p_i, q_i+1, q_i) but at the tip
            for m in range(3):
                out[n, 0, m] = pa[m] + f0 * (pb[m] - pa[m])
                out[n, 1, m] = pa[m] + f1 * (pb[m] - pa[m])
                out[n, 2, m] = pa[m] + f1 * (pc[m] - pa[m])
            n += 1
            if i > 0:
                for m in range(3):
                    out[n, 0, m] = pa[m] + f0 * (pb[m] - pa[m])
                    out[n, 1, m] = pa[m] + f1 * (pc[m] - pa[m])
                    out[n, 2, m] = pa[m] + f0 * (pc[m] - pa[m])
                n += 1
    return out


def bent_cells(cells: np.ndarray, patch: np.ndarray, points: np.ndarray, normals: np.ndarray,
               weight: np.ndarray, measure: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The surface's curvature at the scale of a lattice cell.  Samples (S,) of the surface:
    their cells (S, 3) int64 lattice cells (one scale), patch ids (S,), points (S, 3), unit
    normals (S, 3) and areas (S,).  The samples of one patch in one cell form a group, with
    the area-weighted mean point and unit mean normal.  Around each group, the groups of its
    patch in its own and the 26 cells around are fitted, weighted by area, with a linear
    normal field n(x) = n0 + J (x - x0) in the plane of their points (least squares, the
    points' direction of least spread left out); the group's curvature is J's largest singular
    value, the largest principal curvature (1 / r on a sphere or across a cylinder of radius
    r; noise finer than a cell averages out).  A group whose normals cancel (their
    area-weighted sum shorter than half their area: the surface folds back within the cell)
    gets infinite curvature and is left out of the others' fits; a group of no area
    (degenerate triangles alone) gets 0 and weighs nothing in them.  Returns (mean points (G,
    3), curvature (G,) in 1 / model units, the group (S,) of each sample).  measure (S,) bool:
    fit only the groups holding a sample marked (the others' curvature is 0, unmeasured: they
    serve as neighbours); None: all."""
    lo = cells.min(axis=0, initial=0) - 1
    span = cells.max(axis=0, initial=0) - lo + 2
    linear = ((cells[:, 0] - lo[0]) * span[1] + (cells[:, 1] - lo[1])) * span[2] + (cells[:, 2] - lo[2])
    order = np.lexsort((linear, patch))
    key_patch, key_cell = patch[order], linear[order]
    first = np.flatnonzero(np.r_[True, (key_patch[1:] != key_patch[:-1]) | (key_cell[1:] != key_cell[:-1])])
    group = np.empty(cells.shape[0], dtype=np.int64)
    sizes = np.diff(np.r_[first, order.size])
    group[order] = np.repeat(np.arange(first.size), sizes)
    area = np.add.reduceat(weight[order], first)
    # A group of degenerate triangles alone has no area: its plain mean point, and no curvature.
    weighted = np.add.reduceat(points[order] * weight[order, None], first)
    mean_point = np.where(area[:, None] > 0, weighted / np.where(area > 0, area, 1.0)[:, None],
                          np.add.reduceat(points[order], first) / sizes[:, None])
    normal_sum = np.add.reduceat(normals[order] * weight[order, None], first)
    length = np.linalg.norm(normal_sum, axis=1)
    folded = length < 0.5 * area
    unit = normal_sum / np.where(length > 0, length, 1.0)[:, None]
    fitted = np.ones(first.size, dtype=bool)
    if measure is not None:
        fitted = np.logical_or.reduceat(measure[order], first)
    curvature = _fitted_curvature(key_patch[first], key_cell[first], np.ascontiguousarray(span), mean_point, unit, area,
                                  folded, fitted)
    return mean_point, curvature, group


@nb.njit(cache=True)
def _fitted_curvature(group_patch, group_cell, span, mean_point, unit, area, folded, fitted):
    """bent_cells' fit, group by group: the area-weighted means and second moments of the
    unfolded groups of the same patch in the 27 cells around (_lower_bound), the points' spread C
    and the normals' turn B, J = B C+ over C's two largest eigenvalues (those above 0.05 x
    the largest: a row of cells fits one direction), and J's largest singular value."""
    ng = group_patch.shape[0]
    out = np.empty(ng)
    around = np.empty(27, dtype=np.int64)
    spread, turn, inverse = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    field, square = np.empty((3, 3)), np.empty((3, 3))
    p0, n0 = np.empty(3), np.empty(3)
    for g in range(ng):
        if not fitted[g] or area[g] <= 0.0:  # unmeasured, or degenerate triangles alone (bent_cells)
            out[g] = 0.0
            continue
        if folded[g]:
            out[g] = np.inf
            continue
        k, total = 0, 0.0
        p0[:] = 0.0
        n0[:] = 0.0
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                # the dz = -1, 0, 1 cells are consecutive keys: one search, then a scan
                first = group_cell[g] + (dx * span[1] + dy) * span[2] - 1
                other = _lower_bound(group_patch, group_cell, group_patch[g], first)
                while other < ng and group_patch[other] == group_patch[g] and group_cell[other] <= first + 2:
                    if not folded[other]:
                        around[k] = other
                        k += 1
                        total += area[other]
                        for i in range(3):
                            p0[i] += area[other] * mean_point[other, i]
                            n0[i] += area[other] * unit[other, i]
                    other += 1
        p0 /= total
        n0 /= total
        spread[:] = 0.0
        turn[:] = 0.0
        for a in range(k):
            o = around[a]
            w = area[o] / total
            for i in range(3):
                for j in range(3):
                    spread[i, j] += w * (mean_point[o, i] - p0[i]) * (mean_point[o, j] - p0[j])
                    turn[i, j] += w * (unit[o, i] - n0[i]) * (mean_point[o, j] - p0[j])
        lam, vec = _symmetric_eigen(spread)
        inverse[:] = 0.0
        for e in range(1, 3):  # lam ascending: lam[0] is the direction across the surface
            if lam[e] > 0.05 * lam[2]:
                for i in range(3):
                    for j in range(3):
                        inverse[i, j] += vec[i, e] * vec[j, e] / lam[e]
        for i in range(3):
            for j in range(3):
                field[i, j] = turn[i, 0] * inverse[0, j] + turn[i, 1] * inverse[1, j] + turn[i, 2] * inverse[2, j]
        for i in range(3):
            for j in range(3):
                square[i, j] = field[0, i] * field[0, j] + field[1, i] * field[1, j] + field[2, i] * field[2, j]
        out[g] = np.sqrt(max(_symmetric_eigen(square)[0][2], 0.0))
    return out


@nb.njit(cache=True)
def _symmetric_eigen(m):
    """Eigenvalues (3,) ascending and eigenvectors (columns of (3, 3)) of a symmetric 3 x 3
    matrix, by cyclic Jacobi rotations."""
    a = m.copy()
    v = np.eye(3)
    for _ in range(50):
        off = a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2
        if off <= 1e-30 * (a[0, 0] ** 2 + a[1, 1] ** 2 + a[2, 2] ** 2) or off == 0.0:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if a[p, q] == 0.0:
                continue
            theta = (a[q, q] - a[p, p]) / (2 * a[p, q])
            t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1))
            c = 1 / np.sqrt(t * t + 1)
            s = t * c
            for r in range(3):  # a <- a J, then J^T a
                arp, arq = a[r, p], a[r, q]
                a[r, p], a[r, q] = c * arp - s * arq, s * arp + c * arq
            for r in range(3):
                apr, aqr = a[p, r], a[q, r]
                a[p, r], a[q, r] = c * apr - s * aqr, s * apr + c * aqr
            for r in range(3):
                vrp, vrq = v[r, p], v[r, q]
                v[r, p], v[r, q] = c * vrp - s * vrq, s * vrp + c * vrq
    lam = np.array([a[0, 0], a[1, 1], a[2, 2]])
    order = np.argsort(lam)
    return lam[order], v[:, order]


@nb.njit(cache=True)
def _lower_bound(group_patch, group_cell, patch, cell):
    """The first index whose (patch, cell) is not below (patch, cell) in the lexicographically
    sorted pairs (their number if none)."""
    lo, hi = 0, group_patch.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if group_patch[mid] < patch or (group_patch[mid] == patch and group_cell[mid] < cell):
            lo = mid + 1
        else:
            hi = mid
    return lo


def wall_asks(walls: ThinFeatures, size: float, layers: float, max_depth: int) -> tuple[FeatureAsks, list[str]]:
    """Asks for layers elements across each wall sample (is_wall, thickness t > 0) thinner than
    layers * size: depth ceil(log2(layers * size / t)), with the ring of one coarse cell (the
    samples lie on the wall's first side, a lattice row apart).  Walls that would need more
    than max_depth levels cannot have their layers: they are left to the thin-wall rounds,
    which refine near them only if the mesh loses them (asked to max_depth, a sliver of a CSG
    part 1e-7 thick came apart into more boundary components than the input's), and a note
    says so.  Returns the asks and the notes."""
    if max_depth < 1:
        return no_asks(), []
    need = np.full(walls.thickness.shape[0], max_depth + 1, dtype=np.int64)
    measured = walls.is_wall & (walls.thickness > 0) & (walls.thickness < layers * size)
    need[measured] = np.maximum(np.ceil(np.log2(layers * size / walls.thickness[measured]) - 1e-9), 1)
    thin = np.flatnonzero(need <= max_depth)
    too_deep = int(np.count_nonzero(measured & (need > max_depth)))
    notes = [f"{too_deep} samples of walls thinner than {layers:g} x size = {layers * size:.4g} would need more "
             f"than the {max_depth} levels below size that min_size allows: not asked"] if too_deep else []
    if thin.size == 0:
        return no_asks(), notes
    return FeatureAsks(walls.points[thin], need[thin], np.ones(thin.size, dtype=np.int64),
                       f"{thin.size} samples of walls thinner than {layers:g} x size = {layers * size:.4g} "
                       f"(thinnest {walls.thickness[thin].min():.4g})"), notes


def patch_asks(surface: Surface, frame: FatFrame, patch_sizes: tuple, max_depth: int,
               cut: SurfacePieces | None = None) -> tuple[FeatureAsks, list[str]]:
    """Asks for the long edges patch_sizes ((name, size), ...) asks on named patches of the
    boundary: the input's named groups if it has them, else the surface split at the default
    feature angle, named patch_1, patch_2, ... (boundary.surface_labels).  Each patch's
    triangles, cut to frame.h, ask ceil(log2(frame.h / size)) levels (at most max_depth) in
    the cells of frame's lattice they meet.  Returns the asks and notes on sizes not met (at
    least size: the boundary is nowhere coarser; below the floor max_depth allows).
    ParoctError for a name the surface does not have, listing those it has.  cut: as for
    curvature_asks."""
    if not patch_sizes:
        return no_asks(), []
    labels, names, angle = surface_labels(surface, None)
    known = list(names) if names else [f"patch_{k}" for k in range(1, int(labels.max(initial=0)) + 1)]
    cut = surface_pieces(surface, frame) if cut is None else cut
    piece_labels = labels[cut.owner]
    pieces, notes, asked = [], [], []
    for name, size in patch_sizes:
        if name not in known:
            shown = ", ".join(repr(n) for n in known[:20]) + (f" and {len(known) - 20} more" if len(known) > 20 else "")
            what = "named groups" if names else f"patches (no named groups: the surface split at {angle:g} degrees)"
            raise ParoctError(f"patch {name!r} is not one of the surface's {len(known)} {what}: {shown}")
        levels = int(np.ceil(np.log2(frame.h / size) - 1e-9))
        if levels < 1:
            notes.append(f"patch {name!r} asks size {size:.4g}, at least size = {frame.h:.4g}: the boundary is nowhere "
                         "coarser than size")
            continue
        if levels > max_depth:
            notes.append(f"patch {name!r} asks size {size:.4g}, below min_size: its elements are "
                         f"{frame.h / 2**max_depth:.4g}")
            levels = max_depth
        pieces.append((cut.corners[piece_labels == known.index(name) + 1], levels))
        asked.append(f"patch {name!r} asks {size:.4g}")
    return pieces_asks(frame, pieces, " and ".join(asked)), notes


def region_asks(surface: Surface, frame: FatFrame, regions: tuple, max_depth: int,
                cut: SurfacePieces | None = None) -> tuple[FeatureAsks, list[str]]:
    """Asks for the sizes that refinement regions (sizing.Box, sizing.Sphere) below frame.h
    ask, on the boundary inside them: the triangles cut to frame.h, the pieces with a corner
    or centroid in the region asking ceil(log2(frame.h / size)) levels (at most max_depth) in
    the cells of frame's lattice they meet.  Returns the asks and a note per such region.
    cut: as for curvature_asks."""
    small = [r for r in regions if r.size < frame.h]
    if not small:
        return no_asks(), []
    cut = surface_pieces(surface, frame) if cut is None else cut
    pieces, probes = cut.corners, cut.probes
    inside_pieces, notes, asked = [], [], []
    for region in small:
        what = f"a refinement {type(region).__name__.lower()} asks for size {region.size:.4g}, below size = {frame.h:.4g}"
        inside = (region.distance(probes) <= 0).reshape(-1, 4).any(axis=1)
        levels = min(int(np.ceil(np.log2(frame.h / region.size) - 1e-9)), max_depth)
        if max_depth < 1 or not inside.any():
            notes.append(f"{what}, the finest the interior lattice makes: its elements there are {frame.h:.4g}"
                         + ("" if max_depth < 1 else "; no boundary lies in it"))
            continue
        finest = frame.h / 2**levels
        notes.append(f"{what}: the boundary in it is refined to {finest:.4g}"
                     + (" (min_size)" if finest > region.size * (1 + 1e-9) else "")
                     + f", its interior elements stay at least size = {frame.h:.4g}, the finest the interior lattice makes")
        inside_pieces.append((pieces[inside], levels))
        asked.append(f"a refinement {type(region).__name__.lower()} asks {region.size:.4g}")
    return pieces_asks(frame, inside_pieces, " and ".join(asked)), notes


def function_asks(surface: Surface, frame: FatFrame, function, max_depth: int,
                  cut: SurfacePieces | None = None) -> tuple[FeatureAsks, list[str]]:
    """Asks for the sizes a size function h(x) (points (N, 3) -> sizes (N,)) gives below
    frame.h on the boundary: the triangles cut to frame.h, each piece asking ceil(log2(frame.h
    / h)) levels (at most max_depth) for the smallest h at its corners and centroid, in the
    cells of frame's lattice it meets.  Returns the asks and a note if any.  ParoctError if
    the function fails or returns other than positive sizes, one per point.  cut: as for
    curvature_asks."""
    if function is None or max_depth < 1:
        return no_asks(), []
    cut = surface_pieces(surface, frame) if cut is None else cut
    pieces, probes = cut.corners, cut.probes
    wanted = evaluated_size_function(function, probes, "points of the surface").reshape(-1, 4).min(axis=1)
    # Sizes of size or more (an infinite size: no bound there) ask nothing; the others 1..max_depth levels.
    levels = np.zeros(wanted.shape[0], dtype=np.int64)
    below = wanted < frame.h
    levels[below] = np.minimum(np.ceil(np.log2(frame.h / wanted[below]) - 1e-9), max_depth)
    asked = [(pieces[levels == level], level) for level in np.unique(levels[levels > 0]).tolist()]
    if not asked:
        return no_asks(), []
    note = (f"size_function asks down to {float(wanted.min()):.4g} on the boundary, below size = {frame.h:.4g}: the "
            f"boundary there is refined to {frame.h / 2**asked[-1][1]:.4g} at most, the interior stays at least size")
    return pieces_asks(frame, asked, "size_function asks"), [note]
