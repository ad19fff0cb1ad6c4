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
   the boundary points it holds; those no owner marks are missed (mesher._measure_misses).
5. Compaction: each range sends the points its tets use (id, position, surface triangle) to
   their owners; each owner keeps the distinct ones in ascending id, an exclusive scan of
   the owners' counts (lattice vertices first, then cut points, as the ids run) gives the
   first new id of each, and each range renumbers its tets with the ids read back.

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
from .range_pinches import BoundaryFaces, OwnerFans, RangeTets, fans_by_owners, owned_numbering
from .surface import Surface, bounding_box
from .topology import SurfaceTopology, component_roots, nonmanifold_of_fans, union, used_vertices


@dataclass(frozen=True)
class RangeFinish:
    """finish_in_ranges' result.  points (N, 3) float64 and tets (M, 4) int32: the compacted
    mesh; boundary (B, 3) int32: its boundary faces, oriented outward, in their owners'
    order; point_faces (N,) int32: the surface triangle each point lies on (-1: none);
    summary: the tets' quality (quality.TetSummary); topology: the boundary's;
    missed_vertices, missed_faces: the surface vertices and long triangles the boundary
    misses (ascending; mesher._measure_misses)."""

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
    tets = [_renumbered(p.tets, new_id) for p, new_id in zip(parts, compaction.new_ids)]
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


@nb.njit(cache=True, parallel=True)
def _renumbered(tets, new_id):
    """new_id[tets] (M, 4) int32, in one parallel pass."""
    out = np.empty(tets.shape, dtype=np.int32)
    for t in nb.prange(tets.shape[0]):
        for k in range(4):
            out[t, k] = new_id[tets[t, k]]
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
        for p in np.unique(held.owner_of[foreign]):
            rows = foreign[held.owner_of[foreign] == p]
            inbox[p].append((held.vertex_of[rows], label[rows]))
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
    """mesher._measure_misses over owners' boundary faces (boundary_by_owners' of the parts):
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
        _, first = owned_numbering(held)  # each boundary point once, from the first face using it
        points = _from_senders(held, positions, *np.divmod(first, 3))
        lo, hi, _ = bounding_box(points)  # one pass: numpy's axis-0 reductions stride
        near_box = np.all((queries >= lo - reach) & (queries <= hi + reach), axis=1)
        rows = np.flatnonzero(near_box & far)
        far[rows] = far_from_points(queries[rows], points, reach)
    return np.flatnonzero(far[:n]), long[far[n:]]


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
    mesh (ascending mesh id: lattice vertices, then cut points), by their owners (the module's
    step 5).  A point two ranges place or put on a surface triangle differently is an
    AssertionError: stuffing in ranges must agree where they meet."""
    inbox: list[list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = [[] for _ in range(n_ranges)]
    # What each range sent: its used rows by owner, where each owner's rows start, the owners,
    # and from which row on each owner put them.
    sent = []
    for part, faces in zip(parts, point_faces):
        used = np.flatnonzero(used_vertices(part.tets, part.ids.shape[0]))
        by_owner = np.argsort(part.owners[used], kind="stable")
        bounds = np.searchsorted(part.owners[used][by_owner], np.arange(n_ranges + 1))
        to = np.flatnonzero(np.diff(bounds)).tolist()
        starts = []
        for owner in to:
            rows = used[by_owner[bounds[owner]:bounds[owner + 1]]]
            starts.append(sum(ids.shape[0] for ids, _, _ in inbox[owner]))
            inbox[owner].append((part.ids[rows], part.points[rows], faces[rows]))
        sent.append((used[by_owner], bounds, to, starts))
    # Each owner numbers the distinct ids it received: ascending, its lattice vertices before its cut points.
    numbered = []
    for o, received in enumerate(inbox):
        ids, positions, triangles = (np.concatenate(column) for column in zip(*received)) if received else \
            (np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0, dtype=np.int32))
        distinct, first_row, row_of = np.unique(ids, return_index=True, return_inverse=True)
        row_of = row_of.ravel()
        if not (np.array_equal(positions, positions[first_row][row_of])
                and np.array_equal(triangles, triangles[first_row][row_of])):
            raise AssertionError(f"ranges place a point range {o} owns differently")
        numbered.append((row_of, positions[first_row], triangles[first_row], int(np.searchsorted(distinct, n_vertices))))
    vertices = np.array([k for *_, k in numbered], dtype=np.int64)
    cuts = np.array([position.shape[0] for _, position, _, _ in numbered], dtype=np.int64) - vertices
    first = np.concatenate([[0], np.cumsum(vertices)[:-1]])
    first_cut = int(vertices.sum()) + np.concatenate([[0], np.cumsum(cuts)[:-1]])
    new_of_row = []  # each owner's new id of each row it received
    for (row_of, _, _, k), f, fc in zip(numbered, first, first_cut):
        new_of_row.append(np.where(row_of < k, f + row_of, fc + row_of - k).astype(np.int32))
    new_ids = []
    for part, (rows, bounds, to, starts) in zip(parts, sent):
        new_id = np.full(part.ids.shape[0], -1, dtype=np.int32)
        for owner, at in zip(to, starts):  # read back from the owners
            count = int(bounds[owner + 1] - bounds[owner])
            new_id[rows[bounds[owner]:bounds[owner + 1]]] = new_of_row[owner][at:at + count]
        new_ids.append(new_id)
    blocks = [(o, slice(None, k)) for o, (*_, k) in enumerate(numbered)] + \
        [(o, slice(k, None)) for o, (*_, k) in enumerate(numbered)]  # all lattice vertices, then all cut points
    points = np.concatenate([numbered[o][1][block] for o, block in blocks])
    point_faces_out = np.concatenate([numbered[o][2][block] for o, block in blocks]).astype(np.int32)
    return Compaction(points, point_faces_out, new_ids)


__all__ = ["Compaction", "RangeFinish", "compact_by_owners", "finish_in_ranges", "misses_by_owners",
           "topology_by_owners"]
