"""Pinch repair of a stuffed mesh held in ranges (partition.mesh_in_ranges): each range keeps
its tets, and only what lies on the boundary or near a pinch leaves it.

1. Each range finds the faces of its tets that can lie on the mesh boundary and that no other
   tet of it has (range_boundary): its part of the boundary, and the faces it shares with
   other ranges.
2. Each such face goes to the range owning its smallest vertex id, which drops those that
   two ranges sent: the rest are the boundary.  Each boundary face then goes to the owners
   of its vertices, and each owner finds which of its vertices are not manifold: the
   pinches, as repair.remove_pinches finds them on the whole mesh (pinches_by_owners).
3. Each range gives the tets around the pinches (tets_near, out to repair.PINCH_RINGS rings),
   which are repaired cluster by cluster (repair.repair_near_pinches), and drops those
   removed.

So no range's whole mesh moves, and the boundary is never in one place; here a send is a
list append, between workers each step is one exchange.  The kept tets are the ones
remove_pinches keeps of the ranges' tets joined in range order (tests/test_repair.py).
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
    repair.stuffed_boundary); points (K, 3) float64 their positions; owners (K,) int64 the
    range owning each (0..n_ranges-1, a function of the point: every range holding it agrees)."""

    ids: np.ndarray
    tets: np.ndarray
    core: np.ndarray
    points: np.ndarray
    owners: np.ndarray

    def __post_init__(self):
        k = self.ids.shape[0]
        if self.tets.ndim != 2 or self.tets.shape[1] != 4 or self.core.shape != (k,) or self.points.shape != (k, 3) \
                or self.owners.shape != (k,):
            raise ValueError(f"len(ids) = {k}, tets.shape = {self.tets.shape}, core.shape = {self.core.shape}, "
                             f"points.shape = {self.points.shape}, owners.shape = {self.owners.shape}; expected "
                             f"(M, 4), ({k},), ({k}, 3) and ({k},)")


def range_boundary(part: RangeTets) -> tuple[np.ndarray, np.ndarray]:
    """Faces (F, 3) int64 (mesh ids, oriented outward) of the range's tets that have no core
    vertex and that no other tet of the range has: its part of the mesh boundary and the faces
    it shares with other ranges; and the owner (F, 3) of each of their vertices."""
    faces = stuffed_boundary(part.tets, part.core)
    return part.ids[faces], part.owners[faces]


def pinches_by_owners(boundaries: Sequence[tuple[np.ndarray, np.ndarray]], n_ranges: int) -> np.ndarray:
    """The pinches (ascending mesh ids) from the ranges' boundaries (range_boundary's, in range
    order), found by the ranges owning the faces and vertices (the module's step 2): the
    non-manifold vertices of the mesh boundary (topology.nonmanifold_vertices), which no
    range holds whole."""
    inbox: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(n_ranges)]
    for faces, owners in boundaries:  # each face to the owner of its smallest vertex id
        _send(inbox, owners[np.arange(faces.shape[0]), np.argmin(faces, axis=1)], faces, owners)
    fans_inbox: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(n_ranges)]
    for received in inbox:
        if not received:
            continue
        faces, owners = (np.concatenate(parts) for parts in zip(*received))
        kept = _unmatched(faces)  # those two ranges sent are no boundary
        faces, owners = faces[kept], owners[kept]
        for k in range(3):  # each boundary face to each distinct owner of its vertices, once
            new = np.ones(faces.shape[0], dtype=bool) if k == 0 else (owners[:, k] != owners[:, 0])
            if k == 2:
                new &= owners[:, 2] != owners[:, 1]
            _send(fans_inbox, owners[new, k], faces[new], owners[new])
    pinched = [np.zeros(0, dtype=np.int64)]
    for o, received in enumerate(fans_inbox):
        if not received:
            continue
        faces, owners = (np.concatenate(parts) for parts in zip(*received))
        local, vertex_of = local_vertex_ids(faces)
        owner_of = np.empty(vertex_of.shape[0], dtype=owners.dtype)
        owner_of[local.ravel()] = owners.ravel()
        # Only its own vertices: it has all their faces, not all of the others'.
        bad = nonmanifold_of_fans(vertex_fans(local, vertex_of.shape[0]))
        pinched.append(vertex_of[bad & (owner_of == o)])
    return np.sort(np.concatenate(pinched))


def _send(inbox: list[list[tuple[np.ndarray, np.ndarray]]], to: np.ndarray, faces: np.ndarray,
          owners: np.ndarray) -> None:
    """Append each range's rows of (faces, owners) (F, 3) to its inbox: to (F,) the range."""
    if to.size and to.min() == to.max():  # one range (the usual case for most faces' owners)
        inbox[int(to[0])].append((faces, owners))
        return
    order = np.argsort(to, kind="stable")
    bounds = np.searchsorted(to[order], np.arange(len(inbox) + 1))
    for r in np.flatnonzero(np.diff(bounds)):
        rows = order[bounds[r]:bounds[r + 1]]
        inbox[r].append((faces[rows], owners[rows]))


def _unmatched(faces: np.ndarray) -> np.ndarray:
    """Mask (F,) of the faces (mesh ids) whose vertex set no other face has."""
    local, vertex_of = local_vertex_ids(faces)
    return unmatched_faces(local, vertex_of.shape[0])


def tets_near(part: RangeTets, marked: np.ndarray) -> np.ndarray:
    """Rows (ascending) of the range's tets with a vertex among marked (mesh ids)."""
    return np.flatnonzero(touching(part.tets, np.isin(part.ids, marked)))


def repair_pinches_in_ranges(parts: Sequence[RangeTets], n_ranges: int,
                             rings: int = PINCH_RINGS) -> list[np.ndarray] | None:
    """The kept mask (M_r,) of each range's tets (parts, in range order; owners among
    0..n_ranges-1) after the pinch repair, or None if it must run on the whole mesh (a
    cluster's worklist leaves the stars around the pinches in every order:
    repair.local_repair's fallback, never seen on a mesher's mesh).  The tets kept are those
    remove_pinches keeps of the parts' tets joined in range order, points ranked by position
    (repair.PINCH_ORDERS)."""
    kept = [np.ones(p.tets.shape[0], dtype=bool) for p in parts]
    bad = pinches_by_owners([range_boundary(p) for p in parts], n_ranges)
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


__all__ = ["RangeTets", "pinches_by_owners", "range_boundary", "repair_pinches_in_ranges", "tets_near"]
