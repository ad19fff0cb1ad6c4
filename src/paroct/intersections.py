"""Where a triangle surface crosses itself: pairs of triangles with no common vertex of which
one has an edge through the other's interior.

Every sign is taken only where floating point decides it: a 3x3 determinant counts when its
magnitude exceeds 1e-14 times its permanent (the sum of its terms' magnitudes; Shewchuk's
first filter for orient3d is 7.8e-16 times it), so a crossing found is certain, and a
touching or nearly touching pair is not reported.  A fold between neighbouring triangles
(sharing a vertex or an edge) is not looked for.

The lattice rows catch most overlaps for free (rays.first_winding_outside); this test is
for the triangles they cannot see, the ones a mesh misses (a spike through the far side),
so it runs on a few triangles against all, through a uniform grid (trigrid.triangle_grid).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .trigrid import triangle_grid

#: A determinant is certain when its magnitude exceeds this times its permanent.
_CERTAIN = 1e-14


@nb.njit(cache=True, inline="always")
def _orient(v, a, b, c, d):
    """Sign (+1, -1, or 0 where rounding could decide it) of det[b - a, c - a, d - a] over the
    rows of v (V, 3)."""
    bx, by, bz = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
    cx, cy, cz = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
    dx, dy, dz = v[d, 0] - v[a, 0], v[d, 1] - v[a, 1], v[d, 2] - v[a, 2]
    t1, t2 = bx * (cy * dz), bx * (cz * dy)
    t3, t4 = by * (cz * dx), by * (cx * dz)
    t5, t6 = bz * (cx * dy), bz * (cy * dx)
    det = (t1 - t2) + (t3 - t4) + (t5 - t6)
    bound = _CERTAIN * (abs(t1) + abs(t2) + abs(t3) + abs(t4) + abs(t5) + abs(t6))
    return 1 if det > bound else (-1 if det < -bound else 0)


@nb.njit(cache=True)
def _edge_crosses(v, p, q, a, b, c):
    """Whether segment pq certainly passes through the interior of triangle abc: p and q on
    strictly opposite sides of its plane, and the line pq strictly inside its three edges."""
    sp = _orient(v, a, b, c, p)
    sq = _orient(v, a, b, c, q)
    if sp == 0 or sq == 0 or sp == sq:
        return False
    s1 = _orient(v, p, q, a, b)
    s2 = _orient(v, p, q, b, c)
    s3 = _orient(v, p, q, c, a)
    return s1 != 0 and s1 == s2 and s2 == s3


@nb.njit(cache=True)
def _one_side(v, faces, f, g):
    """Whether triangle g's corners lie certainly on one side of triangle f's plane."""
    s0 = _orient(v, faces[f, 0], faces[f, 1], faces[f, 2], faces[g, 0])
    s1 = _orient(v, faces[f, 0], faces[f, 1], faces[f, 2], faces[g, 1])
    s2 = _orient(v, faces[f, 0], faces[f, 1], faces[f, 2], faces[g, 2])
    return s0 != 0 and s0 == s1 and s1 == s2


@nb.njit(cache=True)
def _cross(v, faces, f, g):
    """Whether triangles f and g (no vertex in common) certainly cross.

    Called, not inlined into _first_crossing, and so are its callees but _orient: it runs
    only on the pairs past the box and cell tests, and inlined, its 36 signs made that
    parallel kernel take 47 s to compile (12 s now) for no speed measurable here."""
    if _one_side(v, faces, f, g) or _one_side(v, faces, g, f):  # most pairs: 3 or 6 signs, not 12 or more
        return False
    for i in range(3):
        if _edge_crosses(v, faces[f, i], faces[f, (i + 1) % 3], faces[g, 0], faces[g, 1], faces[g, 2]):
            return True
        if _edge_crosses(v, faces[g, i], faces[g, (i + 1) % 3], faces[f, 0], faces[f, 1], faces[f, 2]):
            return True
    return False


@nb.njit(cache=True, inline="always")
def _cell_range(vertices, faces, f, axis, origin, cell, dims):
    """The triangle's extent along an axis and the grid cells it spans there."""
    x0, x1, x2 = vertices[faces[f, 0], axis], vertices[faces[f, 1], axis], vertices[faces[f, 2], axis]
    lo, hi = min(x0, x1, x2), max(x0, x1, x2)
    first = min(dims[axis] - 1, max(0, np.int64(math.floor((lo - origin[axis]) / cell))))
    last = min(dims[axis] - 1, max(0, np.int64(math.floor((hi - origin[axis]) / cell))))
    return lo, hi, first, last


@nb.njit(cache=True, inline="always")
def _apart(vertices, faces, g, axis, lo, hi):
    y0, y1, y2 = vertices[faces[g, 0], axis], vertices[faces[g, 1], axis], vertices[faces[g, 2], axis]
    return max(y0, y1, y2) < lo or min(y0, y1, y2) > hi


@nb.njit(cache=True, inline="always")
def _first_shared_cell(vertices, faces, g, origin, cell, dims, i, j, m, i0, j0, m0):
    """Whether cell (i, j, m) is the first cell (lowest on every axis) that triangle g's box
    shares with the query's, whose first cell is (i0, j0, m0): each pair is tested in that
    cell alone.  (A CAD part's long triangles share many cells: tray_bottom's 4.5 k
    triangles are binned 61 k times, and its pairs were tested over and over.)"""
    return (i == max(i0, _cell_range(vertices, faces, g, 0, origin, cell, dims)[2])
            and j == max(j0, _cell_range(vertices, faces, g, 1, origin, cell, dims)[2])
            and m == max(m0, _cell_range(vertices, faces, g, 2, origin, cell, dims)[2]))


@nb.njit(cache=True, parallel=True)
def _first_crossing(vertices, faces, queries, origin, cell, dims, start, items, out):
    """out[k] = the smallest triangle that certainly crosses triangle queries[k], or -1.
    Scalars only in the loop (a small array a query is an allocation a query)."""
    for k in nb.prange(queries.shape[0]):
        f = queries[k]
        x_lo, x_hi, i0, i1 = _cell_range(vertices, faces, f, 0, origin, cell, dims)
        y_lo, y_hi, j0, j1 = _cell_range(vertices, faces, f, 1, origin, cell, dims)
        z_lo, z_hi, m0, m1 = _cell_range(vertices, faces, f, 2, origin, cell, dims)
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        best = -1
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                for m in range(m0, m1 + 1):
                    cell_id = (i * dims[1] + j) * dims[2] + m
                    for s in range(start[cell_id], start[cell_id + 1]):
                        g = items[s]
                        if g == f or (best >= 0 and g >= best):
                            continue
                        p, q, r = faces[g, 0], faces[g, 1], faces[g, 2]
                        if a == p or a == q or a == r or b == p or b == q or b == r or c == p or c == q or c == r:
                            continue
                        if (_apart(vertices, faces, g, 0, x_lo, x_hi) or _apart(vertices, faces, g, 1, y_lo, y_hi)
                                or _apart(vertices, faces, g, 2, z_lo, z_hi)):
                            continue
                        if not _first_shared_cell(vertices, faces, g, origin, cell, dims, i, j, m, i0, j0, m0):
                            continue
                        if _cross(vertices, faces, f, g):
                            best = g
        out[k] = best


def crossing_triangles(vertices: np.ndarray, faces: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """For each triangle id in ``queries`` (K,), the smallest id of a triangle of ``faces``
    (F, 3) that certainly crosses it (see the module's rule), or -1: (K,) int64."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    queries = np.ascontiguousarray(queries, dtype=np.int64)
    out = np.full(queries.shape[0], -1, dtype=np.int64)
    if queries.shape[0] and faces.shape[0] > 1:
        origin, cell, dims, start, items = triangle_grid(vertices, faces)
        _first_crossing(vertices, faces, queries, origin, cell, dims, start, items, out)
    return out
