"""The finish of a stuffed mesh held in ranges (partition.mesh_in_ranges), after its pinch
repair (range_pinches): what mesher._finish measures and compacts on the whole mesh, done
by each range over its own tets, with only boundary faces, counts and the points its tets
use leaving it.

1. Quality and volume: each range summarizes its tets (quality.summarize), and the
   summaries are reduced (quality.merged_summaries: extremes and sums).
2. Boundary (range_pinches.owned_boundary and fans_by_owners, shared with the pinch
   repair): each range's faces that may lie on the boundary go to the range owning their
   smallest vertex id, which keeps those no other range sent; each face then goes on to the
   owners of its vertices, which take their fans.
3. Topology: each owner counts its own vertices, finds which are not manifold, counts the
   edges whose smaller vertex id it owns (only where some vertex's faces are not one fan),
   and labels the components of the faces it holds; two labels that meet at a vertex the
   owner does not own are joined by that vertex's owner (an exchange of the interface's
   vertices only), and the joined labels are the components.
4. Missed parts: each owner marks the surface vertices and long triangles' centres near
   the boundary points it holds; those no owner marks are missed (mesher.boundary_misses).
5. Compaction: each range sends the ids of the points its tets use to their owners, which
   number them (owners.owned_ids: each owner its distinct ids in ascending order, then an
   exclusive scan of the owners' counts; lattice vertices first, then cut points, as the
   ids run); each range renumbers its tets with the ids read back and writes its points'
   positions and surface triangles into the result.

The result is mesher._finish's on the ranges' tets joined in range order: the same points,
tets, point triangles, quality, topology and missed parts; the volume is summed in another
order (equal up to rounding), and the boundary faces come in their owners' order.  Here a
send is a list append; between workers each step is one exchange.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numba as nb
import numpy as np

from .check import far_from_points, long_triangle_centres
from .mesher import FAT_RADIUS_RATIO, MISS_REACH
from .quality import TetSummary, merged_summaries, summarize
from .owners import owned_ids, rows_by_owner
from .range_pinches import BoundaryFaces, OwnerFans, RangeTets, fans_by_owners
from .repair import renumbered
from .surface import Surface, bounding_box
from .topology import SurfaceTopology, component_roots, local_vertex_ids, nonmanifold_of_fans, union, used_vertices


@dataclass(frozen=True)
class RangeFinish:
    """finish_in_ranges' result.  points (N, 3) float64 and tets (M, 4) int32: the compacted
    mesh; boundary (B, 3) int32: its boundary faces, oriented outward, in their owners'
    order; point_faces (N,) int32: the surface triangle each point lies on (-1: none);
    summary: the tets' quality (quality.TetSummary); topology: the boundary's;
    missed_vertices, missed_faces: the surface vertices and long triangles the boundary
    misses (ascending; mesher.boundary_misses)."""

    points: np.ndarray
    tets: np.ndarray
    boundary: np.ndarray
    point_faces: np.ndarray
    summary: TetSummary
    topology: SurfaceTopology
    missed_vertices: np.ndarray
    missed_faces: np.ndarray


def finish_in_ranges(parts: Sequence[RangeTets], owned: Sequence[BoundaryFaces], point_faces: Sequence[np.ndarray],
                     n_vertices: int, surface: Surface, size: float,
                     fans: Sequence[OwnerFans] | None = None) -> RangeFinish:
    """The finish (the module's steps) of the ranges' tets: parts (in range order), their
    pinches repaired, core without the vertices of removed tets; owned: their boundary held
    by its owners (range_pinches.owned_boundary; owners among 0..len(owned)-1), and fans its
    fans_by_owners if the caller has them;
    point_faces[r] (K_r,) int32: the surface triangle of each of part r's points (-1: none);
    mesh ids below n_vertices are lattice vertices, the others cut points; size: the band's
    longest edge (what the missed-part test measures in)."""
    n_ranges = len(owned)
    summary = merged_summaries([summarize(p.points, p.tets, p.core, FAT_RADIUS_RATIO) for p in parts])
    topology = topology_by_owners(owned, fans_by_owners(owned, n_ranges) if fans is None else fans)
    missed_vertices, missed_faces = misses_by_owners(owned, parts, surface, size)
    compaction = compact_by_owners(parts, point_faces, n_vertices, n_ranges)
    tets = [renumbered(p.tets, new_id) for p, new_id in zip(parts, compaction.new_ids)]
    boundary = []
    for held in owned:  # each face's new ids from the range that sent it
        n = held.faces.shape[0]
        boundary.append(_from_senders(held, compaction.new_ids, np.repeat(np.arange(n), 3),
                                      np.tile(np.arange(3), n)).reshape(n, 3))
    return RangeFinish(compaction.points, np.concatenate(tets) if tets else np.zeros((0, 4), dtype=np.int32),
                       np.concatenate(boundary) if boundary else np.zeros((0, 3), dtype=np.int32),
                       compaction.point_faces, summary, topology, missed_vertices, missed_faces)


def _from_senders(held: BoundaryFaces, columns: Sequence[np.ndarray], face: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """columns[r][i] of each held face's corner (face, corner (K,)), read from the range r that
    sent the face at its local id i there (columns[r]: (K_r, ...) over range r's points)."""
    sender = held.sender[face]
    out = np.empty((face.shape[0], *columns[0].shape[1:]), dtype=columns[0].dtype)
    for r in np.unique(sender):
        rows = np.flatnonzero(sender == r)
        out[rows] = columns[r][held.local[face[rows], corner[rows]]]
    return out


def topology_by_owners(owned: Sequence[BoundaryFaces], fans: Sequence[OwnerFans]) -> SurfaceTopology:
    """topology.surface_topology of the mesh boundary held by owners (boundary_by_owners'),
    from each owner's faces around its vertices (fans: fans_by_owners'; the module's
    step 3)."""
    n_faces = sum(held.faces.shape[0] for held in owned)
    if n_faces == 0:
        return SurfaceTopology(0, 0, 0, 0, 0, 0, 0)
    n_used = bad_vertices = 0
    one_fan = True  # every vertex's faces one fan: then every edge is in two faces run opposite ways
    for o, held in enumerate(fans):
        own = held.owner_of == o
        n_used += int(np.count_nonzero(own))
        bad_vertices += int(np.count_nonzero(nonmanifold_of_fans(held.fans) & own))
        one_fan &= bool(np.all(held.fans[own] >= 0))
    if one_fan:
        n_edges, bad_edges = 3 * n_faces // 2, 0
    else:
        counted = [_owned_edges(held.local, held.vertex_of, held.owner_of == o) for o, held in enumerate(fans)]
        n_edges, bad_edges = sum(n for n, _ in counted), sum(bad for _, bad in counted)
    components = _joined_components(fans)
    return SurfaceTopology(n_faces, n_used, n_edges, bad_edges, bad_vertices, components, n_used - n_edges + n_faces)


def _owned_edges(local: np.ndarray, vertex_of: np.ndarray, own: np.ndarray) -> tuple[int, int]:
    """The edges of the faces (local ids) whose smaller mesh id is an own vertex (its owner
    holds every face around it, so every face with the edge): their number, and how many are
    not in exactly two faces run opposite ways (topology.edge_multiplicities' test)."""
    p, q = local.ravel(), np.roll(local, -1, axis=1).ravel()
    forward = vertex_of[p] < vertex_of[q]
    low, high = np.where(forward, p, q), np.where(forward, q, p)
    mine = own[low]
    pairs, inverse = np.unique(np.stack([low[mine], high[mine]], axis=1), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    count = np.bincount(inverse, minlength=pairs.shape[0])
    forward_count = np.bincount(inverse, weights=forward[mine], minlength=pairs.shape[0])
    return int(pairs.shape[0]), int(np.count_nonzero((count != 2) | (forward_count != 1)))


def _joined_components(fans: Sequence[OwnerFans]) -> int:
    """The components of the boundary from the owners' faces around their vertices: each
    owner's components are labels; each vertex an owner holds but does not own is sent, with
    its label, to its owner, which joins that label with its own label of the vertex; the
    joined labels are counted."""
    labels, first = [], [0]
    for held in fans:
        roots = component_roots(held.local, held.vertex_of.shape[0])
        is_root = roots == np.arange(roots.shape[0])
        labels.append(first[-1] + (np.cumsum(is_root) - 1)[roots])  # the roots numbered in order
        first.append(first[-1] + int(np.count_nonzero(is_root)))
    inbox: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in fans]
    for o, (held, label) in enumerate(zip(fans, labels)):
        foreign = np.flatnonzero(held.owner_of != o)
        for p, rows in rows_by_owner(held.owner_of[foreign], len(fans)):
            inbox[p].append((held.vertex_of[foreign[rows]], label[foreign[rows]]))
    joined = [(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))]
    for held, label, received in zip(fans, labels, inbox):
        if not received:
            continue
        order = np.argsort(held.vertex_of)
        for ids, their_labels in received:  # the owner holds every face around its vertices: it has them all
            joined.append((label[order[np.searchsorted(held.vertex_of, ids, sorter=order)]], their_labels))
    return _joined_count(first[-1], *(np.concatenate(column) for column in zip(*joined)))


@nb.njit(cache=True)
def _joined_count(n_labels, a, b):
    """The sets left of labels 0..n_labels-1 once a[i] and b[i] are joined for every i."""
    parent = np.arange(n_labels)
    for i in range(a.shape[0]):
        union(parent, a[i], b[i])
    return np.count_nonzero(parent == np.arange(n_labels))  # the roots


def misses_by_owners(owned: Sequence[BoundaryFaces], parts: Sequence[RangeTets], surface: Surface,
                     size: float) -> tuple[np.ndarray, np.ndarray]:
    """mesher.boundary_misses over owners' boundary faces (boundary_by_owners' of the parts):
    the surface vertices and long triangles (by their centres) with no boundary point within
    MISS_REACH x size, each owner testing those in its points' box widened by that reach
    (the others are farther from its points).  The points' positions come from the ranges
    that sent the faces."""
    n = surface.vertices.shape[0]
    reach = MISS_REACH * size
    long, centres = long_triangle_centres(surface.vertices, surface.faces, size)
    queries = np.concatenate([surface.vertices, centres])
    far = np.ones(queries.shape[0], dtype=bool)
    positions = [p.points for p in parts]
    for held in owned:
        if held.faces.shape[0] == 0:
            continue
        points = _from_senders(held, positions, *np.divmod(_first_uses(held.faces), 3))  # each boundary point once
        lo, hi, _ = bounding_box(points)  # one pass: numpy's axis-0 reductions stride
        near_box = np.all((queries >= lo - reach) & (queries <= hi + reach), axis=1)
        rows = np.flatnonzero(near_box & far)
        far[rows] = far_from_points(queries[rows], points, reach)
    return np.flatnonzero(far[:n]), long[far[n:]]


def _first_uses(faces: np.ndarray) -> np.ndarray:
    """The position (B,) in faces.ravel() (F, 3) where each distinct id is first used, in order
    of first use."""
    local, vertex_of = local_vertex_ids(faces)
    first = np.empty(vertex_of.shape[0], dtype=np.int64)
    flat = local.ravel()
    first[flat[::-1]] = np.arange(flat.shape[0] - 1, -1, -1)  # the last write is the first use
    return first


@dataclass(frozen=True)
class Compaction:
    """compact_by_owners' result: points (N, 3) float64 and point_faces (N,) int32 of the
    compacted mesh, and new_ids[r] (K_r,) int32: the new id of each of range r's points
    (-1: its tets do not use it)."""

    points: np.ndarray
    point_faces: np.ndarray
    new_ids: list[np.ndarray]


def compact_by_owners(parts: Sequence[RangeTets], point_faces: Sequence[np.ndarray], n_vertices: int,
                      n_ranges: int) -> Compaction:
    """The points the parts' tets use, numbered as mesher._compact numbers them on the joined
    mesh (the module's step 5): the used lattice vertices, then the used cut points, each by
    owners.owned_ids over their mesh ids (an owner's mesh ids follow on from the previous
    owner's, so the order is the ids').  The result's points and triangles are written from
    every range that uses them; one two ranges place or put on a surface triangle
    differently is an AssertionError: stuffing in ranges must agree where they meet."""
    used = [np.flatnonzero(used_vertices(p.tets, p.ids.shape[0])) for p in parts]
    lattice = [p.ids[u] < n_vertices for p, u in zip(parts, used)]
    vertex_ids, n_used = owned_ids([p.ids[u[k]] for p, u, k in zip(parts, used, lattice)],
                                   [p.owners[u[k]] for p, u, k in zip(parts, used, lattice)], n_ranges)
    cut_ids, n_cuts = owned_ids([p.ids[u[~k]] for p, u, k in zip(parts, used, lattice)],
                                [p.owners[u[~k]] for p, u, k in zip(parts, used, lattice)], n_ranges)
    points = np.empty((n_used + n_cuts, 3))
    faces = np.empty(n_used + n_cuts, dtype=np.int32)
    new_ids = []
    for part, triangles, u, k, v, c in zip(parts, point_faces, used, lattice, vertex_ids, cut_ids):
        new_id = np.full(part.ids.shape[0], -1, dtype=np.int32)
        new_id[u[k]], new_id[u[~k]] = v, n_used + c
        points[new_id[u]], faces[new_id[u]] = part.points[u], triangles[u]
        new_ids.append(new_id)
    for part, triangles, u, new_id in zip(parts, point_faces, used, new_ids):
        if not (np.array_equal(points[new_id[u]], part.points[u]) and np.array_equal(faces[new_id[u]], triangles[u])):
            raise AssertionError("ranges place a point they share differently")
    return Compaction(points, faces, new_ids)


__all__ = ["Compaction", "RangeFinish", "compact_by_owners", "finish_in_ranges", "misses_by_owners",
           "topology_by_owners"]
