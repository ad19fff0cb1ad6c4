"""Pinch repair of a stuffed mesh held in ranges (partition.mesh_in_ranges): each range keeps
its tets, and only what lies near the boundary or a pinch leaves it.

1. Each range finds the faces of its tets that can lie on the mesh boundary and that no other
   tet of it has (range_boundary): its part of the boundary, and the faces it shares with
   other ranges.
2. Joined, the faces that no other range has are the mesh boundary (boundary_of_ranges), and
   its non-manifold vertices are the pinches (pinched_vertices), as repair.remove_pinches
   finds them on the whole mesh.
3. Each range gives the tets around the pinches (tets_near, out to repair.PINCH_RINGS rings),
   which are repaired cluster by cluster (repair.repair_near_pinches), and drops those
   removed.

So the repair moves the boundary faces and the tets near pinches, never a range's whole mesh;
the joins are lists here, one exchange each between workers.  The kept tets are the ones
remove_pinches keeps of the ranges' tets joined in range order (tests/test_partition.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .repair import PINCH_RINGS, repair_near_pinches, stuffed_boundary, unmatched_faces
from .topology import local_vertex_ids, nonmanifold_of_fans, touching, vertex_fans


@dataclass(frozen=True)
class RangeTets:
    """One range's stuffed tets with what the repair reads of their points.  ids (K,) int64:
    the mesh's id of each of the range's points; tets (M, 4) int32 into ids; core (K,) bool:
    the points whose faces are all interior (unwarped inside lattice vertices; see
    repair.stuffed_boundary); points (K, 3) float64 their positions."""

    ids: np.ndarray
    tets: np.ndarray
    core: np.ndarray
    points: np.ndarray

    def __post_init__(self):
        k = self.ids.shape[0]
        if self.tets.ndim != 2 or self.tets.shape[1] != 4 or self.core.shape != (k,) or self.points.shape != (k, 3):
            raise ValueError(f"len(ids) = {k}, tets.shape = {self.tets.shape}, core.shape = {self.core.shape}, "
                             f"points.shape = {self.points.shape}; expected (M, 4), ({k},) and ({k}, 3)")


def range_boundary(part: RangeTets) -> np.ndarray:
    """Faces (F, 3) int64 (mesh ids, oriented outward) of the range's tets that have no core
    vertex and that no other tet of the range has: its part of the mesh boundary and the faces
    it shares with other ranges."""
    return part.ids[stuffed_boundary(part.tets, part.core)]


def boundary_of_ranges(faces: Sequence[np.ndarray]) -> np.ndarray:
    """The mesh boundary (F, 3): the faces of the ranges' boundaries (range_boundary's, in
    range order) whose vertex set no other range's has."""
    joined = np.concatenate([np.zeros((0, 3), dtype=np.int64)] + [np.asarray(f, dtype=np.int64) for f in faces])
    local, vertex_of = local_vertex_ids(joined)
    return np.compress(unmatched_faces(local, vertex_of.shape[0]), joined, axis=0)


def pinched_vertices(boundary: np.ndarray) -> np.ndarray:
    """The boundary's (F, 3) non-manifold vertices (ascending mesh ids): those whose faces do
    not form one fan (topology.nonmanifold_vertices)."""
    local, vertex_of = local_vertex_ids(np.asarray(boundary, dtype=np.int64))
    return np.sort(vertex_of[nonmanifold_of_fans(vertex_fans(local, vertex_of.shape[0]))])


def tets_near(part: RangeTets, marked: np.ndarray) -> np.ndarray:
    """Rows (ascending) of the range's tets with a vertex among marked (mesh ids)."""
    return np.flatnonzero(touching(part.tets, np.isin(part.ids, marked)))


def repair_pinches_in_ranges(parts: Sequence[RangeTets], rings: int = PINCH_RINGS) -> list[np.ndarray] | None:
    """The kept mask (M_r,) of each range's tets (parts, in range order) after the pinch
    repair, or None if it must run on the whole mesh (a cluster's worklist leaves the stars
    around the pinches in every order: repair.local_repair's fallback, never seen on a
    mesher's mesh).  The tets kept are those remove_pinches keeps of the parts' tets joined in
    range order, points ranked by position (repair.PINCH_ORDERS)."""
    kept = [np.ones(p.tets.shape[0], dtype=bool) for p in parts]
    bad = pinched_vertices(boundary_of_ranges([range_boundary(p) for p in parts]))
    if bad.size == 0:
        return kept
    rows = [tets_near(p, bad) for p in parts]
    region = bad
    for _ in range(rings):  # pinch_neighbourhood's rings, over the ranges
        region = np.unique(np.concatenate([p.ids[p.tets[r]].ravel() for p, r in zip(parts, rows)]))
        rows = [tets_near(p, region) for p in parts]
    near = np.concatenate([p.ids[p.tets[r]] for p, r in zip(parts, rows)])
    vertex_of, local = np.unique(near, return_inverse=True)  # ascending ids, as local_repair numbers them
    points = np.empty((vertex_of.shape[0], 3))
    for p, r in zip(parts, rows):
        used = p.tets[r].ravel()
        points[np.searchsorted(vertex_of, p.ids[used])] = p.points[used]
    alive = repair_near_pinches(local.reshape(near.shape), np.searchsorted(vertex_of, bad), np.isin(vertex_of, region),
                                points)
    if alive is None:
        return None
    for k, r, part_alive in zip(kept, rows, np.split(alive, np.cumsum([r.shape[0] for r in rows])[:-1])):
        k[r] = part_alive
    return kept


__all__ = ["RangeTets", "boundary_of_ranges", "pinched_vertices", "range_boundary", "repair_pinches_in_ranges",
           "tets_near"]
