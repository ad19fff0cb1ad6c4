"""Sharp edges and corners kept on the boundary, where the tets around them allow it.

Isosurface stuffing puts every boundary vertex on the surface (a cut point, or a lattice
vertex warped onto one), but none on a sharp edge: the boundary cuts across each sharp edge
and corner, a chamfer up to about one size wide, which is most of a CAD part's volume error
and much of its Hausdorff distance.  Here each boundary vertex on a seam between two
patches (boundary triangles of both around it) moves to the nearest point of the surface's
curve between those two patches, and each that borders three or more moves to the nearest
surface corner (a vertex three or more patches meet at; one mesh vertex a corner), if that
point is within ``reach``.  The patches are those of boundary.py: the input's named groups,
or the surface split at a feature angle, so the curves are the sharp edges, or the borders
the user drew.

A move is kept only if every tet around the vertex stays within the guard: dihedral angles
in [SNAP_MIN_ANGLE, SNAP_MAX_ANGLE] and 3r/R >= SNAP_MIN_RATIO, each relaxed to the star's
own worst before the move where that is already beyond (so a star never gets worse than it
was, nor than the guard); else 3/4, 1/2, then 1/4 of the way is tried (SNAP_FRACTIONS).
Vertices move one at a time, corners first, then by vertex id, each checked against the
positions already moved; those not at their target try again from where they are in up to
SNAP_SWEEPS sweeps in all (a neighbour's move may have made room).  Only positions change, and every tet keeps a positive volume, so
the mesh keeps its connectivity, its boundary topology and stuffing's angle bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from .boundary import BoundaryPatches
from .octant import sorted_unique
from .quality import _tet_measures
from .surface import Surface
from .topology import half_edge_twins, vertex_stars

#: The guard on the tets around a moved vertex (degrees, and 3r/R): stuffing's own bound is
#: [10.7, 164.8]; stars already beyond keep their worst.
SNAP_MIN_ANGLE, SNAP_MAX_ANGLE, SNAP_MIN_RATIO = 15.0, 150.0, 0.2
#: Fractions of the way to its target a vertex tries, in order.
SNAP_FRACTIONS = (1.0, 0.75, 0.5, 0.25)
#: Sweeps over the vertices not yet at their target.
SNAP_SWEEPS = 3


@dataclass(frozen=True)
class FeatureCurves:
    """Where a surface's patches meet.  segments: (E, 2) int64 surface vertex ids of the edges
    whose two triangles lie in different patches; pairs: (E, 2) int32 those two patches,
    smaller first; corners: (C,) int64 surface vertices whose triangles lie in three or more
    patches."""

    segments: np.ndarray
    pairs: np.ndarray
    corners: np.ndarray


def feature_curves(surface: Surface, labels: np.ndarray) -> FeatureCurves:
    """The curves and corners between the patches labels (F,) (from 1) of the surface's
    triangles, in the order of their edges' keys (smaller vertex, then larger).  Each edge of
    a closed surface has exactly two half-edges (topology.half_edge_twins)."""
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    n = np.int64(surface.vertices.shape[0])
    twin = half_edge_twins(faces, n)
    first = np.flatnonzero(np.arange(twin.shape[0]) < twin)  # each edge once, from its smaller half-edge
    start, end = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    first = first[np.argsort(np.minimum(start[first], end[first]) * n + np.maximum(start[first], end[first]))]
    second = twin[first]
    labels = np.asarray(labels, dtype=np.int32)
    a, b = labels[first // 3], labels[second // 3]
    cut = a != b
    segments = np.stack([start[first[cut]], end[first[cut]]], axis=1)
    pairs = np.stack([np.minimum(a[cut], b[cut]), np.maximum(a[cut], b[cut])], axis=1).astype(np.int32)
    return FeatureCurves(segments, pairs, _meeting_vertices(faces.ravel(), np.repeat(labels, 3), 3))


def _meeting_vertices(vertex: np.ndarray, label: np.ndarray, at_least: int) -> np.ndarray:
    """The distinct vertices among vertex (K,) that come with at least at_least distinct labels (K,)."""
    width = np.int64(label.max(initial=0)) + 1
    owner = sorted_unique(vertex.astype(np.int64) * width + label) // width  # ascending, a run per vertex
    first, count = _runs(owner)
    return owner[first[count >= at_least]]


def _runs(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The start (R,) and length (R,) of each run of equal values in values (N,)."""
    first = np.flatnonzero(np.r_[True, values[1:] != values[:-1]]) if values.size else np.zeros(0, dtype=np.int64)
    return first, np.diff(np.r_[first, values.size])


@dataclass(frozen=True)
class SnappedVertices:
    """snap_to_features' result.  points: (N, 3) float64, the mesh's points after the moves;
    moved: (K,) int64 the vertices that moved (all the way or part of it); tried: how many
    had a target within reach."""

    points: np.ndarray
    moved: np.ndarray
    tried: int


def snap_to_features(points: np.ndarray, tets: np.ndarray, boundary: BoundaryPatches, surface: Surface,
                     labels: np.ndarray, reach: float) -> SnappedVertices:
    """Move the boundary vertices of the mesh (points (N, 3), tets (M, 4) positively oriented)
    that border two or more of boundary's patches onto the surface's curves and corners between
    those patches (labels (F,): the patch of each surface triangle, as boundary was tagged),
    where within reach (model units) and where the guard allows (see the module's docstring).
    Returns the new points; the arrays given are not changed."""
    points = np.array(points, dtype=np.float64)  # a copy: moved in place below
    width = np.int64(max(int(boundary.n_patches), 1) + 1)
    # sorted_unique: np.unique hashed fea_part's 0.8 M (vertex, patch) keys at diag/40 in 24 ms.
    touching = sorted_unique(boundary.faces.astype(np.int64).ravel() * width + np.repeat(boundary.patches, 3))
    owner, patch = touching // width, (touching % width).astype(np.int32)
    first, count = _runs(owner)
    if not (count >= 2).any():  # no seam: a smooth part (a scan at 40 degrees), nothing to move
        return SnappedVertices(points, np.zeros(0, dtype=np.int64), 0)
    curves = feature_curves(surface, labels)
    vertices = np.ascontiguousarray(surface.vertices, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)

    # Corners: each surface corner takes the nearest vertex bordering three or more patches.
    multi = owner[first[count >= 3]]
    corner_of, corner_distance = _nearest_corners(vertices[curves.corners], points[multi], reach)
    keep = corner_of >= 0
    pick = np.lexsort((multi[keep], corner_distance[keep], corner_of[keep]))  # by corner, nearest first
    chosen_corner = corner_of[keep][pick]
    unique = np.r_[True, chosen_corner[1:] != chosen_corner[:-1]][:chosen_corner.size]
    corner_vertices = multi[keep][pick][unique]
    corner_targets = vertices[curves.corners[chosen_corner[unique]]]
    order = np.argsort(corner_vertices, kind="stable")
    corner_vertices, corner_targets = corner_vertices[order], corner_targets[order]

    # Seams: the nearest point of the curve between the vertex's two patches.
    two = first[count == 2]
    seam = owner[two]
    seam_keys = patch[two].astype(np.int64) * width + patch[two + 1]
    curve_keys = curves.pairs[:, 0].astype(np.int64) * width + curves.pairs[:, 1]
    by_key = np.argsort(curve_keys, kind="stable")
    targets, distance = _curve_targets(vertices, curves.segments[by_key], curve_keys[by_key], points[seam], seam_keys)
    near = distance <= reach
    seam, seam_targets = seam[near], targets[near]

    candidates = np.concatenate([corner_vertices, seam])
    goals = np.concatenate([corner_targets, seam_targets]).reshape(-1, 3)
    if not candidates.size:
        return SnappedVertices(points, np.zeros(0, dtype=np.int64), 0)
    star_start, star_tets, local = vertex_stars(tets, candidates, points.shape[0])
    moved = _move_guarded(points, tets, star_start, star_tets, candidates, local, goals,
                          np.array(SNAP_FRACTIONS), math.cos(math.radians(SNAP_MIN_ANGLE)),
                          math.cos(math.radians(SNAP_MAX_ANGLE)), SNAP_MIN_RATIO, SNAP_SWEEPS)
    return SnappedVertices(points, candidates[moved], int(candidates.size))


@nb.njit(cache=True)
def _nearest_corners(corners, queries, reach):
    """For each query point (K, 3): the index of the nearest corner (C, 3) within reach, or -1,
    and its distance.  Corners sorted by x bound each search to x +- reach."""
    order = np.argsort(corners[:, 0])
    xs = corners[order, 0]
    nearest = np.full(queries.shape[0], -1, dtype=np.int64)
    distance = np.full(queries.shape[0], np.inf)
    for k in range(queries.shape[0]):
        lo = np.searchsorted(xs, queries[k, 0] - reach)
        hi = np.searchsorted(xs, queries[k, 0] + reach, side="right")
        for s in range(lo, hi):
            c = order[s]
            d = math.sqrt((corners[c, 0] - queries[k, 0]) ** 2 + (corners[c, 1] - queries[k, 1]) ** 2
                          + (corners[c, 2] - queries[k, 2]) ** 2)
            if d <= reach and d < distance[k]:
                nearest[k], distance[k] = c, d
    return nearest, distance


@nb.njit(cache=True)
def _curve_targets(vertices, segments, keys, queries, query_keys):
    """For each query point (K, 3) with its patch pair key: the nearest point (K, 3) of the
    segments (E, 2) whose key (sorted, E) is the same, and its distance (inf if none)."""
    targets = np.empty((queries.shape[0], 3))
    distance = np.full(queries.shape[0], np.inf)
    for k in range(queries.shape[0]):
        lo = np.searchsorted(keys, query_keys[k])
        hi = np.searchsorted(keys, query_keys[k], side="right")
        for s in range(lo, hi):
            a, b = segments[s, 0], segments[s, 1]
            dx, dy, dz = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
            px, py, pz = queries[k, 0] - vertices[a, 0], queries[k, 1] - vertices[a, 1], queries[k, 2] - vertices[a, 2]
            dd = dx * dx + dy * dy + dz * dz
            t = 0.0 if dd == 0.0 else min(1.0, max(0.0, (px * dx + py * dy + pz * dz) / dd))
            cx, cy, cz = vertices[a, 0] + t * dx, vertices[a, 1] + t * dy, vertices[a, 2] + t * dz
            d = math.sqrt((cx - queries[k, 0]) ** 2 + (cy - queries[k, 1]) ** 2 + (cz - queries[k, 2]) ** 2)
            if d < distance[k]:
                distance[k] = d
                targets[k, 0], targets[k, 1], targets[k, 2] = cx, cy, cz
    return targets, distance


@nb.njit(cache=True)
def _star_extremes(points, tets, star, v, x, y, z, corners):
    """(largest dihedral cosine, smallest, smallest 3r/R, smallest volume) of the tets star
    with vertex v at (x, y, z)."""
    cos_hi, cos_lo, ratio_lo, vol_lo = -1.0, 1.0, np.inf, np.inf
    for s in range(star.shape[0]):
        t = star[s]
        for k in range(4):
            w = tets[t, k]
            corners[3 * k, 0] = x if w == v else points[w, 0]
            corners[3 * k + 1, 0] = y if w == v else points[w, 1]
            corners[3 * k + 2, 0] = z if w == v else points[w, 2]
        vol, ratio, c01, c02, c03, c12, c13, c23 = _tet_measures(corners, 0)
        cos_hi = max(cos_hi, max(max(max(c01, c02), max(c03, c12)), max(c13, c23)))
        cos_lo = min(cos_lo, min(min(min(c01, c02), min(c03, c12)), min(c13, c23)))
        ratio_lo = min(ratio_lo, ratio)
        vol_lo = min(vol_lo, vol)
    return cos_hi, cos_lo, ratio_lo, vol_lo


@nb.njit(cache=True)
def _move_guarded(points, tets, star_start, star_tets, candidates, local, targets, fractions,
                  cos_min_angle, cos_max_angle, min_ratio, sweeps):
    """Move each candidate vertex (in order) the first of fractions of the way to its target
    that keeps its star within the guard (module docstring), points changing in place; then
    again, up to sweeps times in all, the candidates not yet at their target, from where they
    are (a neighbour's move may have made room).  Returns which candidates moved (K,) bool."""
    moved = np.zeros(candidates.shape[0], dtype=np.bool_)
    arrived = np.zeros(candidates.shape[0], dtype=np.bool_)
    corners = np.empty((12, 1))
    for _ in range(sweeps):
        for i in range(candidates.shape[0]):
            if arrived[i]:
                continue
            v = candidates[i]
            star = star_tets[star_start[local[v]]:star_start[local[v] + 1]]
            hi0, lo0, r0, _ = _star_extremes(points, tets, star, v, points[v, 0], points[v, 1], points[v, 2], corners)
            cos_hi_limit = max(hi0, cos_min_angle)  # the smallest angle's cosine: the star's own if larger
            cos_lo_limit = min(lo0, cos_max_angle)
            ratio_limit = min(r0, min_ratio)
            for f in fractions:
                x = points[v, 0] + f * (targets[i, 0] - points[v, 0])
                y = points[v, 1] + f * (targets[i, 1] - points[v, 1])
                z = points[v, 2] + f * (targets[i, 2] - points[v, 2])
                if f == 1.0:
                    x, y, z = targets[i, 0], targets[i, 1], targets[i, 2]
                hi, lo, r, vol = _star_extremes(points, tets, star, v, x, y, z, corners)
                if vol > 0.0 and hi <= cos_hi_limit and lo >= cos_lo_limit and r >= ratio_limit:
                    points[v, 0], points[v, 1], points[v, 2] = x, y, z
                    moved[i] = True
                    arrived[i] = f == 1.0
                    break
    return moved
