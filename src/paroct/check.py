"""Check a tet mesh: validity, quality, boundary topology, and fidelity to a surface.

``check_mesh`` measures what any consumer of a tet mesh relies on: no inverted tets, every
interior face shared by exactly two tets from opposite sides, and a boundary that is a
closed 2-manifold.  Given the solid's surface it also compares volumes and measures the
two-sided Hausdorff distance between the mesh boundary and the surface, sampled at
triangle vertices, centroids and seeded random points, each measured exactly to the
nearest triangle of the other side (uniform-grid search, numba).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np

from .errors import ParoctError
from .features import triangle_normal
from .intersections import crossing_triangles
from .quality import tet_quality, unit_scaled
from .surface import Surface
from .topology import boundary_faces, match_faces, surface_topology
from .trigrid import triangle_grid

#: Below this sin^2 of the angle at a triangle's first vertex, the triangle is treated as its
#: three edges: then the error of the plane distance (eps / sin) and of the edge distance
#: (sin x edge length) are both about sqrt(eps) relative.
_SLIVER_SIN2 = 1e-16


@nb.njit(cache=True, inline="always")
def _segment_sq(px, py, pz, ax, ay, az, bx, by, bz):
    """Squared distance from p to the segment ab (a point if a == b)."""
    ux, uy, uz = bx - ax, by - ay, bz - az
    wx, wy, wz = px - ax, py - ay, pz - az
    uu = ux * ux + uy * uy + uz * uz
    t = 0.0
    if uu > 0.0:
        t = min(1.0, max(0.0, (wx * ux + wy * uy + wz * uz) / uu))
    dx, dy, dz = wx - t * ux, wy - t * uy, wz - t * uz
    return dx * dx + dy * dy + dz * dz


@nb.njit(cache=True)
def _point_triangle_sq(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Squared distance from p to the closed triangle abc; degenerate triangles are their edges."""
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    nn = nx * nx + ny * ny + nz * nz
    if nn > _SLIVER_SIN2 * (ux * ux + uy * uy + uz * uz) * (vx * vx + vy * vy + vz * vz):
        # Signs of the sub-triangle areas p'bc, p'ca, p'ab of the projection p' of p.
        qax, qay, qaz = ax - px, ay - py, az - pz
        qbx, qby, qbz = bx - px, by - py, bz - pz
        qcx, qcy, qcz = cx - px, cy - py, cz - pz
        wa = nx * (qby * qcz - qbz * qcy) + ny * (qbz * qcx - qbx * qcz) + nz * (qbx * qcy - qby * qcx)
        wb = nx * (qcy * qaz - qcz * qay) + ny * (qcz * qax - qcx * qaz) + nz * (qcx * qay - qcy * qax)
        wc = nx * (qay * qbz - qaz * qby) + ny * (qaz * qbx - qax * qbz) + nz * (qax * qby - qay * qbx)
        if wa >= 0.0 and wb >= 0.0 and wc >= 0.0:
            s = qax * nx + qay * ny + qaz * nz
            return s * s / nn
    d = _segment_sq(px, py, pz, ax, ay, az, bx, by, bz)
    d = min(d, _segment_sq(px, py, pz, bx, by, bz, cx, cy, cz))
    return min(d, _segment_sq(px, py, pz, cx, cy, cz, ax, ay, az))


@nb.njit(cache=True, parallel=True)
def _pair_distances(points, triangles, out):
    for i in nb.prange(points.shape[0]):
        t = triangles[i]
        out[i] = math.sqrt(_point_triangle_sq(points[i, 0], points[i, 1], points[i, 2],
                                              t[0, 0], t[0, 1], t[0, 2], t[1, 0], t[1, 1], t[1, 2],
                                              t[2, 0], t[2, 1], t[2, 2]))


def point_triangle_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Exact distance (Q,) float64 from each point (Q, 3) to its triangle (Q, 3, 3) (corners in rows).

    Degenerate triangles (repeated or collinear corners) are measured as their edges.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or triangles.shape != (points.shape[0], 3, 3):
        raise ValueError(f"points.shape = {points.shape}, triangles.shape = {triangles.shape}; expected (Q, 3), (Q, 3, 3)")
    out = np.empty(points.shape[0])
    if points.shape[0]:
        _pair_distances(points, triangles, out)
    return out


@nb.njit(cache=True, inline="always")
def _scan_cell(px, py, pz, c, start, items, vertices, faces, best, nearest):
    """(squared distance, triangle) of the nearest of cell c's triangles and (best, nearest),
    the earlier one on a tie."""
    for s in range(start[c], start[c + 1]):
        f = items[s]
        a = faces[f, 0]
        b = faces[f, 1]
        e = faces[f, 2]
        d = _point_triangle_sq(px, py, pz, vertices[a, 0], vertices[a, 1], vertices[a, 2],
                               vertices[b, 0], vertices[b, 1], vertices[b, 2],
                               vertices[e, 0], vertices[e, 1], vertices[e, 2])
        if d < best or (d == best and f < nearest):
            best = d
            nearest = f
    return best, nearest


@nb.njit(cache=True, parallel=True)
def _nearest_distances(queries, vertices, faces, origin, cell, dims, start, items, out, out_face):
    """Distance from each query (inside the grid box) to the nearest triangle (out), and that
    triangle (out_face: the smallest id among equally near ones), by growing cube shells.

    After the shell at Chebyshev radius r around the query's cell, every triangle not yet
    seen lies outside the box of cells within r, so at least as far as that box's nearest
    side that is not the grid's own side; stop once the best distance is within it.
    """
    for q in nb.prange(queries.shape[0]):
        px, py, pz = queries[q, 0], queries[q, 1], queries[q, 2]
        ci = min(dims[0] - 1, max(0, np.int64(math.floor((px - origin[0]) / cell))))
        cj = min(dims[1] - 1, max(0, np.int64(math.floor((py - origin[1]) / cell))))
        ck = min(dims[2] - 1, max(0, np.int64(math.floor((pz - origin[2]) / cell))))
        best = np.inf
        nearest = faces.shape[0]
        r = 0
        while True:
            i0, i1 = max(ci - r, 0), min(ci + r, dims[0] - 1)
            j0, j1 = max(cj - r, 0), min(cj + r, dims[1] - 1)
            k0, k1 = max(ck - r, 0), min(ck + r, dims[2] - 1)
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    base = (i * dims[1] + j) * dims[2]
                    if abs(i - ci) == r or abs(j - cj) == r:
                        for k in range(k0, k1 + 1):
                            best, nearest = _scan_cell(px, py, pz, base + k, start, items, vertices, faces, best,
                                                       nearest)
                    else:
                        if ck - r >= 0:
                            best, nearest = _scan_cell(px, py, pz, base + ck - r, start, items, vertices, faces,
                                                       best, nearest)
                        if r > 0 and ck + r < dims[2]:
                            best, nearest = _scan_cell(px, py, pz, base + ck + r, start, items, vertices, faces,
                                                       best, nearest)
            # Distance from the query to the unexplored part of the grid.
            gap = np.inf
            if i0 > 0:
                gap = min(gap, px - (origin[0] + i0 * cell))
            if i1 < dims[0] - 1:
                gap = min(gap, origin[0] + (i1 + 1) * cell - px)
            if j0 > 0:
                gap = min(gap, py - (origin[1] + j0 * cell))
            if j1 < dims[1] - 1:
                gap = min(gap, origin[1] + (j1 + 1) * cell - py)
            if k0 > 0:
                gap = min(gap, pz - (origin[2] + k0 * cell))
            if k1 < dims[2] - 1:
                gap = min(gap, origin[2] + (k1 + 1) * cell - pz)
            if gap == np.inf or best < gap * gap:  # strictly: a triangle as near beyond may have a smaller id
                break
            r += 1
        out[q] = math.sqrt(best)
        out_face[q] = nearest


def distances_to_triangles(queries: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Exact distance (Q,) float64 from each query point (Q, 3) to the nearest of the triangles.

    vertices: (V, 3) float64; faces: (F, 3) integer, F >= 1.  A uniform grid over the
    triangles and the queries (about one triangle per cell, at most 256 cells per axis)
    limits the triangles measured per query.
    """
    return nearest_triangles(queries, vertices, faces)[0]


def nearest_triangles(queries: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """distances_to_triangles' distances (Q,) float64, and the nearest triangle of each query
    (Q,) int64, the smallest index among equally near ones (so the same for any grid)."""
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if faces.shape[0] == 0:
        raise ValueError("no triangles to measure the distance to")
    out = np.empty(queries.shape[0])
    out_face = np.empty(queries.shape[0], dtype=np.int64)
    if queries.shape[0] == 0:
        return out, out_face
    origin, cell, dims, start, items = triangle_grid(vertices, faces, queries)
    _nearest_distances(queries, vertices, faces, origin, cell, dims, start, items, out, out_face)
    return out, out_face


@nb.njit(cache=True, parallel=True)
def _far_from(queries, points, origin, cell, radius, start, order, dims):
    """far_from_points' queries, in parallel chunks (each writes its own queries' entries)."""
    r2 = radius * radius
    n_queries = queries.shape[0]
    out = np.empty(n_queries, dtype=np.bool_)
    n_chunks = min(64, n_queries // 1024 + 1)
    for chunk in nb.prange(n_chunks):
        c = np.empty(3, dtype=np.int64)
        for q in range(chunk * n_queries // n_chunks, (chunk + 1) * n_queries // n_chunks):
            for k in range(3):
                c[k] = np.int64(math.floor((queries[q, k] - origin[k]) / cell))
            near = False
            for n in range(27):  # the query's own cell first: most queries have a point there
                m = (n + 13) % 27
                i, j, k = c[0] + m // 9 - 1, c[1] + m // 3 % 3 - 1, c[2] + m % 3 - 1
                if near or not (0 <= i < dims[0] and 0 <= j < dims[1] and 0 <= k < dims[2]):
                    continue
                key = (i * dims[1] + j) * dims[2] + k
                for s in range(start[key], start[key + 1]):
                    p = order[s]
                    d = 0.0
                    for a in range(3):
                        d += (points[p, a] - queries[q, a]) ** 2
                    if d <= r2:
                        near = True
                        break
            out[q] = not near
    return out


def far_from_points(queries: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Mask (Q,) of the query points (Q, 3) with no point of ``points`` (P, 3) within
    ``radius`` (Euclidean, model units).  A uniform grid of cells of side at least radius,
    and coarser if it would have more than max(2 P, 4096) cells: each query scans the points
    of its 27 surrounding cells, which hold every point within radius."""
    queries = np.ascontiguousarray(queries, dtype=np.float64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    if not radius > 0:
        raise ValueError(f"radius = {radius}: must be positive")
    if points.shape[0] == 0:
        return np.ones(queries.shape[0], dtype=bool)
    origin, cell, dims, start, order = _grid_cells(points, float(radius))
    return _far_from(queries, points, origin, cell, float(radius), start, order, dims)


@nb.njit(cache=True)
def _grid_cells(points, radius):
    """The grid of far_from_points: its origin (3,), cell side, dims (3,), and the points by
    cell (a counting sort: the points of cell key (row-major over dims) are
    order[start[key]:start[key + 1]]).  numpy's reductions along axis 0 of an (P, 3) array
    took longer than the whole query, and a sort of the keys longer than this."""
    lo = points[0].copy()
    hi = points[0].copy()
    for p in range(points.shape[0]):
        for a in range(3):
            lo[a] = min(lo[a], points[p, a])
            hi[a] = max(hi[a], points[p, a])
    cell = max(radius, (hi - lo).max() / 2**20)
    dims = np.empty(3, dtype=np.int64)
    while True:
        for a in range(3):
            dims[a] = np.int64(math.floor((hi[a] - lo[a]) / cell)) + 1
        if dims[0] * dims[1] * dims[2] <= max(2 * points.shape[0], 4096):
            break
        cell *= 1.25
    keys = np.empty(points.shape[0], dtype=np.int64)
    start = np.zeros(dims[0] * dims[1] * dims[2] + 1, dtype=np.int64)
    for p in range(points.shape[0]):
        key = 0
        for a in range(3):
            key = key * dims[a] + min(np.int64(math.floor((points[p, a] - lo[a]) / cell)), dims[a] - 1)
        keys[p] = key
        start[key + 1] += 1
    for key in range(start.shape[0] - 1):
        start[key + 1] += start[key]
    fill = start[:-1].copy()
    order = np.empty(points.shape[0], dtype=np.int64)
    for p in range(points.shape[0]):
        order[fill[keys[p]]] = p
        fill[keys[p]] += 1
    return lo, cell, dims, start, order


@nb.njit(cache=True)
def long_triangle_centres(vertices, faces, min_edge):
    """The triangles (K,) int64 of faces (F, 3) over vertices (V, 3) with an edge longer than
    min_edge, and their centroids (K, 3) (a shorter triangle's centroid is within min_edge / sqrt(3)
    of its vertices).  Two passes, no (F, 3, 3) gather."""
    limit = min_edge * min_edge
    long = np.zeros(faces.shape[0], dtype=np.bool_)
    for f in range(faces.shape[0]):
        for j in range(3):
            a, b = faces[f, j], faces[f, (j + 1) % 3]
            d = 0.0
            for i in range(3):
                d += (vertices[b, i] - vertices[a, i]) ** 2
            long[f] |= d > limit
    ids = np.flatnonzero(long)
    out = np.empty((ids.shape[0], 3))
    for k in range(ids.shape[0]):
        f = ids[k]
        for i in range(3):
            out[k, i] = (vertices[faces[f, 0], i] + vertices[faces[f, 1], i] + vertices[faces[f, 2], i]) / 3.0
    return ids, out


@nb.njit(cache=True, inline="always")
def _edge_turn(points, p, q, n_p, n_q):
    """(n_q - n_p) . (q - p): how far the surface's normal turns along edge p -> q."""
    return ((n_q[0] - n_p[0]) * (points[q, 0] - points[p, 0]) + (n_q[1] - n_p[1]) * (points[q, 1] - points[p, 1])
            + (n_q[2] - n_p[2]) * (points[q, 2] - points[p, 2]))


@nb.njit(cache=True, parallel=True)
def _chord_volumes(points, faces, point_faces, vertices, surface_faces, out):
    for f in nb.prange(faces.shape[0]):
        out[f] = 0.0
        if point_faces[faces[f, 0]] < 0 or point_faces[faces[f, 1]] < 0 or point_faces[faces[f, 2]] < 0:
            continue
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        # The unit normal under each vertex, each found once (in registers: no array a face).
        n_a = triangle_normal(vertices, surface_faces, point_faces[a])
        n_b = triangle_normal(vertices, surface_faces, point_faces[b])
        n_c = triangle_normal(vertices, surface_faces, point_faces[c])
        turn = (_edge_turn(points, a, b, n_a, n_b) + _edge_turn(points, b, c, n_b, n_c)
                + _edge_turn(points, c, a, n_c, n_a))
        ux, uy, uz = points[b, 0] - points[a, 0], points[b, 1] - points[a, 1], points[b, 2] - points[a, 2]
        vx, vy, vz = points[c, 0] - points[a, 0], points[c, 1] - points[a, 1], points[c, 2] - points[a, 2]
        area = 0.5 * math.sqrt((uy * vz - uz * vy) ** 2 + (uz * vx - ux * vz) ** 2 + (ux * vy - uy * vx) ** 2)
        out[f] = -area * turn / 24.0


def chord_volumes(points: np.ndarray, faces: np.ndarray, point_faces: np.ndarray, surface_vertices: np.ndarray,
                  surface_faces: np.ndarray) -> np.ndarray:
    """Estimated signed volume (F,) float64, model units cubed, between each boundary triangle
    of a mesh and the surface its vertices lie on: negative where the surface bulges out past
    the triangle (the mesh lacks that volume), positive where it dips in.

    points: (N, 3) mesh points; faces: (F, 3) boundary triangles, outward; point_faces: (N,)
    the surface triangle each point lies on (MeshResult.point_faces), an index into
    surface_faces (T, 3) over surface_vertices (V, 3), or -1: a face with such a vertex gets
    0.  Over a triangle whose vertices lie on it, the surface is taken as a quadratic height,
    zero at the vertices: its mean is a third of the sum of the heights at the edge midpoints
    (the edge bubbles lambda_i lambda_j average 1/12 and are 1/4 at their midpoint), and the
    height at the midpoint of edge p -> q, where the normal turns steadily from n_p to n_q,
    is (n_q - n_p) . (q - p) / 8: volume = -area / 24 x the sum over the edges, n the unit
    normal of the surface triangle each vertex lies on.  A faceted surface's kinks are
    underestimated (a chord across a kink of angle t lies L^2 t / 4 from it, the steady turn
    gives L^2 sin t / 6): summed over a mesh, 0.30-1.03 x the true volume error on 90 random
    unions and differences of boxes, spheres and cylinders that kept their topology (median
    0.68; docs/design.md, session 58).  ValueError on shapes or indices out of range.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    point_faces = np.ascontiguousarray(point_faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"faces.shape = {faces.shape}: must be (F, 3)")
    if point_faces.shape != (points.shape[0],):
        raise ValueError(f"len(point_faces) = {point_faces.shape[0]} but len(points) = {points.shape[0]}")
    surface_vertices = np.ascontiguousarray(surface_vertices, dtype=np.float64)
    surface_faces = np.ascontiguousarray(surface_faces, dtype=np.int64)
    if faces.size and (int(faces.min()) < 0 or int(faces.max()) >= points.shape[0]):
        raise ValueError(f"faces hold {int(faces.min())}..{int(faces.max())} but len(points) = {points.shape[0]}")
    if point_faces.size and (int(point_faces.min()) < -1 or int(point_faces.max()) >= surface_faces.shape[0]):
        raise ValueError(f"point_faces hold {int(point_faces.min())}..{int(point_faces.max())} but "
                         f"len(surface_faces) = {surface_faces.shape[0]}")
    if surface_faces.size and (int(surface_faces.min()) < 0 or int(surface_faces.max()) >= surface_vertices.shape[0]):
        raise ValueError(f"surface_faces hold {int(surface_faces.min())}..{int(surface_faces.max())} but "
                         f"len(surface_vertices) = {surface_vertices.shape[0]}")
    out = np.empty(faces.shape[0])
    _chord_volumes(points, faces, point_faces, surface_vertices, surface_faces, out)
    return out


def sample_triangles(vertices: np.ndarray, faces: np.ndarray, per_triangle: int = 3, seed: int = 0) -> np.ndarray:
    """Points (S, 3) on triangles: every used vertex, every centroid, and ``per_triangle``
    uniformly random points per triangle (numpy Generator with ``seed``, so repeatable)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    corners = vertices[faces]  # (F, 3, 3)
    parts = [vertices[np.unique(faces)], corners.mean(axis=1)]
    if per_triangle > 0 and faces.shape[0]:
        rng = np.random.default_rng(seed)
        r1 = np.sqrt(rng.random((faces.shape[0], per_triangle)))
        r2 = rng.random((faces.shape[0], per_triangle))
        bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=-1)  # (F, k, 3)
        parts.append(np.einsum("fkc,fcd->fkd", bary, corners).reshape(-1, 3))
    return np.concatenate(parts)


#: Against a surface, a mesh whose volume is off the solid's by more than this fraction, or
#: whose boundary is farther from the surface (either way) than this fraction of the diagonal,
#: fails: it is not a mesh of that solid.  mesh() refuses to return less than half the
#: volume; its meshes keep within 1 % unless they warn, and within 0.05 x the diagonal.
VOLUME_ERROR_LIMIT = 0.5
HAUSDORFF_LIMIT = 0.25


@dataclass(frozen=True)
class CheckReport:
    """Findings of check_mesh.  Lengths and volumes in model units, angles in degrees.

    Quality fields are over all tets (an inverted tet counts as dihedral angles 0 and 180,
    3r/R 0); they are NaN for an empty mesh.  ``boundary_*`` describe the triangles on
    exactly one tet.  The surface fields are None unless a surface was given; the
    surface_crossings counts the surface's triangles that cross another (a surface that
    intersects itself bounds no solid, crossing_at is one's centre); the
    Hausdorff distances are relative to the surface's bounding-box diagonal:
    ``hausdorff_to_surface`` is the largest distance from a mesh-boundary sample to the
    surface, ``hausdorff_to_mesh`` from a surface sample to the mesh boundary, and
    ``hausdorff_at`` the sample point that attains the larger one.
    """

    n_tets: int
    n_vertices: int
    n_unreferenced: int
    n_inverted: int
    min_dihedral: float
    max_dihedral: float
    min_radius_ratio: float
    volume: float
    overloaded_faces: int
    same_side_faces: int
    boundary_faces: int
    boundary_bad_edges: int
    boundary_bad_vertices: int
    boundary_components: int
    boundary_genus: int
    solid_volume: float | None = None
    surface_components: int | None = None
    surface_genus: int | None = None
    hausdorff_to_surface: float | None = None
    hausdorff_to_mesh: float | None = None
    hausdorff_at: tuple[float, float, float] | None = None
    surface_crossings: int | None = None
    crossing_at: tuple[float, float, float] | None = None

    @property
    def boundary_manifold(self) -> bool:
        """Every boundary edge in two boundary triangles of opposite orientation, every vertex one fan."""
        return self.boundary_bad_edges == 0 and self.boundary_bad_vertices == 0

    @property
    def volume_error(self) -> float | None:
        """(mesh volume - solid volume) / solid volume, or None without a surface."""
        if self.solid_volume is None:
            return None
        return (self.volume - self.solid_volume) / self.solid_volume

    @property
    def hausdorff(self) -> float | None:
        """Two-sided Hausdorff distance / surface diagonal, or None without a surface."""
        if self.hausdorff_to_surface is None or self.hausdorff_to_mesh is None:
            return None
        return max(self.hausdorff_to_surface, self.hausdorff_to_mesh)

    @property
    def ok(self) -> bool:
        """A usable mesh: tets, none inverted, conforming faces, closed manifold boundary."""
        return not self.problems()

    def problems(self) -> list[str]:
        """One line per failed requirement, with the numbers; empty if the mesh is ok."""
        out = []
        if self.n_tets == 0:
            out.append("the mesh has no tets")
        if self.n_inverted:
            out.append(f"{self.n_inverted} of {self.n_tets} tets are inverted or flat (signed volume <= 0)")
        if self.overloaded_faces:
            out.append(f"{self.overloaded_faces} faces are shared by more than two tets")
        if self.same_side_faces:
            out.append(f"{self.same_side_faces} faces have both their tets on the same side (inverted neighbour)")
        if self.boundary_bad_edges:
            out.append(f"boundary not closed and manifold: {self.boundary_bad_edges} of its edges are not in exactly "
                       "two oppositely oriented boundary triangles")
        if self.boundary_bad_vertices:
            out.append(f"boundary not manifold: at {self.boundary_bad_vertices} vertices the boundary triangles "
                       "do not form one closed fan")
        err = self.volume_error
        if err is not None and not abs(err) <= VOLUME_ERROR_LIMIT:
            out.append(f"the mesh's volume differs from the solid's by {100 * err:+.3g}% (more than "
                       f"{100 * VOLUME_ERROR_LIMIT:g}%): not a mesh of this solid?")
        if self.hausdorff is not None and self.hausdorff_at is not None and not self.hausdorff <= HAUSDORFF_LIMIT:
            x, y, z = self.hausdorff_at
            out.append(f"the mesh's boundary and the surface are {self.hausdorff:.3g} x the diagonal apart at "
                       f"({x:.6g}, {y:.6g}, {z:.6g}) (more than {HAUSDORFF_LIMIT:g}): not a mesh of this surface, or "
                       "part of it missing?")
        if self.surface_crossings and self.crossing_at is not None:
            x, y, z = self.crossing_at
            out.append(f"the surface intersects itself: {self.surface_crossings} of its triangles cross others, one "
                       f"centred at ({x:.6g}, {y:.6g}, {z:.6g}); no mesh fills it as a solid")
        return out

    def format(self) -> str:
        """The report as printable lines."""
        lines = [
            f"tets {self.n_tets}, vertices {self.n_vertices} ({self.n_unreferenced} unreferenced)",
            f"inverted tets {self.n_inverted}",
            f"dihedral angles {self.min_dihedral:.4g} .. {self.max_dihedral:.4g} deg, min 3r/R {self.min_radius_ratio:.4g}",
            f"volume {self.volume:.6g}",
            f"faces shared by more than two tets {self.overloaded_faces}, with both tets on one side {self.same_side_faces}",
            f"boundary {self.boundary_faces} triangles, {self.boundary_components} components, genus {self.boundary_genus}, "
            + ("closed manifold" if self.boundary_manifold else
               f"NOT manifold ({self.boundary_bad_edges} bad edges, {self.boundary_bad_vertices} bad vertices)"),
        ]
        err, at = self.volume_error, self.hausdorff_at
        if err is not None and at is not None:  # both set with a surface
            lines.append(f"solid volume {self.solid_volume:.6g}, mesh volume error {100 * err:+.3f}%")
            lines.append(f"surface {self.surface_components} components, genus {self.surface_genus}")
            x, y, z = at
            lines.append(f"Hausdorff distance {self.hausdorff:.4g} x diagonal (mesh->surface {self.hausdorff_to_surface:.4g}, "
                         f"surface->mesh {self.hausdorff_to_mesh:.4g}), largest at ({x:.6g}, {y:.6g}, {z:.6g})")
        problems = self.problems()
        lines.extend(f"FAIL: {p}" for p in problems)
        lines.append("ok" if not problems else f"{len(problems)} problems")
        return "\n".join(lines)


def validated_mesh(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """points (N, 3) float64 and tets (M, 4) int64 as contiguous arrays, or ParoctError for
    wrong shapes or types, indices out of range and NaN coordinates on tet vertices."""
    try:
        points, tets = np.asarray(points), np.asarray(tets)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise ParoctError(f"points and tets must be (N, 3) and (M, 4) arrays ({exc})") from None
    if points.ndim != 2 or points.shape[1] != 3 or points.dtype.kind not in "iuf":
        raise ParoctError(f"points.shape = {points.shape} ({points.dtype}), expected (N, 3) numbers")
    if tets.ndim != 2 or tets.shape[1] != 4:
        raise ParoctError(f"tets.shape = {tets.shape}, expected (M, 4)")
    if tets.size and not np.issubdtype(tets.dtype, np.integer):
        raise ParoctError(f"tets.dtype = {tets.dtype}, expected integers")
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    if tets.size and (tets.min() < 0 or tets.max() >= points.shape[0]):
        raise ParoctError(f"tet vertex indices span {tets.min()}..{tets.max()} but there are {points.shape[0]} points")
    points = np.ascontiguousarray(points, dtype=np.float64)
    bad = ~np.isfinite(points[np.unique(tets)]).all(axis=1) if tets.size else np.zeros(0, dtype=bool)
    if bad.any():
        raise ParoctError(f"{int(bad.sum())} tet vertices have a NaN or infinite coordinate")
    return points, tets


def check_mesh(
    points: np.ndarray,
    tets: np.ndarray,
    surface: Surface | None = None,
    *,
    samples_per_triangle: int = 3,
    seed: int = 0,
) -> CheckReport:
    """Validity, quality and boundary topology of a tet mesh, and its fidelity to ``surface``.

    points: (N, 3) float64 model units; tets: (M, 4) integer vertex indices, positively
    oriented.  surface: the solid the mesh should fill; then the report holds the solid
    volume and the two-sided Hausdorff distance between the mesh boundary and the surface
    (see sample_triangles for the samples, ``samples_per_triangle`` random ones per
    triangle drawn with ``seed``).  Raises ParoctError for malformed arrays (wrong shapes,
    indices out of range, NaN coordinates on tet vertices).
    """
    points, tets = validated_mesh(points, tets)
    # Measured at a power-of-two scale (exact) that keeps squared areas of parts 1e-100 or
    # 1e100 across in range; volumes are scaled back.
    points, scale = unit_scaled(points)
    n = points.shape[0]
    m = tets.shape[0]
    q = tet_quality(points, tets)
    neighbour, overloaded, same_side = match_faces(tets)
    faces = boundary_faces(tets, neighbour)
    topo = surface_topology(faces, n)
    referenced = np.unique(tets).shape[0] if m else 0
    empty = m == 0
    fields: dict[str, Any] = dict(
        n_tets=int(m),
        n_vertices=int(n),
        n_unreferenced=int(n - referenced),
        n_inverted=int(np.count_nonzero(q.volume <= 0.0)),
        min_dihedral=float("nan") if empty else float(q.min_dihedral.min()),
        max_dihedral=float("nan") if empty else float(q.max_dihedral.max()),
        min_radius_ratio=float("nan") if empty else float(q.radius_ratio.min()),
        volume=float(np.sum(q.volume)) / scale / scale / scale,
        overloaded_faces=int(overloaded),
        same_side_faces=int(same_side),
        boundary_faces=int(faces.shape[0]),
        boundary_bad_edges=int(topo.bad_edges),
        boundary_bad_vertices=int(topo.bad_vertices),
        boundary_components=int(topo.components),
        boundary_genus=int(topo.genus),
    )
    if surface is not None:
        fields.update(_surface_fields(points, faces, surface, scale, samples_per_triangle, seed))
    return CheckReport(**fields)


def _surface_fields(points, faces, surface: Surface, scale: float, per_triangle: int, seed: int) -> dict:
    """Solid volume, the surface's self-crossings (intersections.crossing_triangles) and the two
    directed Hausdorff distances (relative to the diagonal); points are the mesh's scaled by
    ``scale``, the surface is scaled alike."""
    crossing = np.flatnonzero(crossing_triangles(surface.vertices, surface.faces, np.arange(surface.faces.shape[0])) >= 0)
    at = (tuple(float(c) for c in surface.vertices[surface.faces[crossing[0]]].mean(axis=0)) if crossing.size else None)
    out = dict(solid_volume=float(surface.volume), surface_components=int(surface.components),
               surface_genus=int(surface.genus), surface_crossings=int(crossing.size), crossing_at=at)
    diagonal = surface.diagonal * scale
    surface_faces = np.asarray(surface.faces, dtype=np.int64)
    vertices = surface.vertices * scale if scale != 1.0 else surface.vertices
    if faces.shape[0] == 0:  # no boundary to compare: the whole surface is missed
        far = np.inf
        out.update(hausdorff_to_surface=far, hausdorff_to_mesh=far,
                   hausdorff_at=tuple(float(c) for c in surface.vertices[0]))
        return out
    on_mesh = sample_triangles(points, faces, per_triangle, seed)
    on_surface = sample_triangles(vertices, surface_faces, per_triangle, seed)
    to_surface = distances_to_triangles(on_mesh, vertices, surface_faces)
    to_mesh = distances_to_triangles(on_surface, points, faces)
    i, j = int(np.argmax(to_surface)), int(np.argmax(to_mesh))
    at = on_mesh[i] if to_surface[i] >= to_mesh[j] else on_surface[j]
    out.update(hausdorff_to_surface=float(to_surface[i] / diagonal), hausdorff_to_mesh=float(to_mesh[j] / diagonal),
               hausdorff_at=tuple(float(c) / scale for c in at))
    return out


def canonical_form(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh up to numbering: points (N, 3) in lexicographic order, and tets (M, 4) int64 as
    rows of the sorted ranks of their points in that order, the rows sorted.  Two meshes of
    distinct points are the same up to the order of points, tets and tet corners iff their
    forms are equal (array_equal)."""
    points = np.asarray(points, dtype=np.float64)
    order = np.lexsort(points.T[::-1])
    rank = np.empty(points.shape[0], dtype=np.int64)
    rank[order] = np.arange(points.shape[0])
    rows = np.sort(rank[np.asarray(tets, dtype=np.int64)], axis=1)
    return points[order], rows[np.lexsort(rows.T[::-1])]


def mesh_metrics(points: np.ndarray, tets: np.ndarray, surface: Surface) -> dict:
    """One set of figures for any tet mesh of ``surface`` (the benchmark's measurement).

    Tets are first oriented as most of them are (other meshers' conventions differ); then
    ``inverted`` counts those of the other sign or zero volume.  Returns a dict: tets,
    vertices, min / 1st-percentile / max dihedral (degrees), min and mean 3r/R, the fraction
    with 3r/R < 0.3, inverted, volume error (relative), Hausdorff distance / diagonal (two
    sided, sampled, exact point-to-triangle), closed (boundary a closed 2-manifold and faces
    conforming), topology kept (boundary components and genus equal the surface's).
    """
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    q = tet_quality(points, tets)
    if tets.shape[0] and (q.volume < 0).sum() > tets.shape[0] / 2:
        tets = tets[:, [0, 2, 1, 3]]
        q = tet_quality(points, tets)
    report = check_mesh(points, tets, surface)
    volume_error, hausdorff = report.volume_error, report.hausdorff
    assert volume_error is not None and hausdorff is not None  # check_mesh with a surface sets both
    good = q.volume > 0
    return {
        "tets": int(tets.shape[0]),
        "vertices": int(report.n_vertices - report.n_unreferenced),
        "min_dihedral": float(q.min_dihedral.min()) if tets.size else float("nan"),
        "p1_dihedral": float(np.percentile(q.min_dihedral, 1)) if tets.size else float("nan"),
        "max_dihedral": float(q.max_dihedral.max()) if tets.size else float("nan"),
        "min_radius_ratio": float(q.radius_ratio.min()) if tets.size else float("nan"),
        "mean_radius_ratio": float(q.radius_ratio[good].mean()) if good.any() else float("nan"),
        "frac_radius_ratio_below_0.3": float((q.radius_ratio < 0.3).mean()) if tets.size else float("nan"),
        "inverted": int((~good).sum()),
        "volume_error": float(volume_error),
        "hausdorff": float(hausdorff),
        "closed": bool(report.boundary_manifold and report.overloaded_faces == 0 and report.same_side_faces == 0),
        "topology_kept": bool((report.boundary_components, report.boundary_genus)
                              == (report.surface_components, report.surface_genus)),
    }
