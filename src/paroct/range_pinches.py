"""Pinch repair of a stuffed mesh held in ranges (partition.mesh_in_ranges): each range keeps
its tets, and only what lies on the boundary or near a pinch leaves it.

1. Each range finds the faces of its tets that can lie on the mesh boundary and that no other
   tet of it has (range_boundary): its part of the boundary, and the faces it shares with
   other ranges.
2. Each such face goes to the range owning its smallest vertex id, which drops those that
   two ranges sent: the rest are the boundary (boundary_by_owners; owned_boundary does steps
   1 and 2).  Each boundary face then goes to the owners of its vertices, which take the
   fans around their vertices (fans_by_owners; range_finish reads them too), and each owner
   finds which of its vertices are not manifold: the pinches, as repair.remove_pinches
   finds them on the whole mesh (pinches_by_owners).
3. Each range gives the tets around the pinches (tets_near, out to repair.PINCH_RINGS rings),
   which are repaired cluster by cluster (repair.repair_near_pinches), and drops those
   removed.

So no range's whole mesh moves, and the boundary is never in one place; here a send is a
list append, between workers each step is one exchange.  The kept tets are the ones
remove_pinches keeps of the ranges' tets joined in range order (tests/test_repair.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Sequence

import numpy as np

from .owners import rows_by_owner
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


class BoundaryFaces(NamedTuple):
    """Faces that one range holds of the mesh boundary, or that may lie on it: faces (F, 3)
    int64 mesh ids, oriented outward; owners (F, 3) the range owning each vertex; sender (F,)
    the range whose tets have the face, and local (F, 3) the face in that range's point
    numbering (what it reads the points' positions and new ids by)."""

    faces: np.ndarray
    owners: np.ndarray
    sender: np.ndarray
    local: np.ndarray


def range_boundary(part: RangeTets, r: int) -> BoundaryFaces:
    """The faces of range r's tets (part) that have no core vertex and that no other tet of
    the range has: its part of the mesh boundary and the faces it shares with other ranges."""
    faces = stuffed_boundary(part.tets, part.core)
    return BoundaryFaces(part.ids[faces], part.owners[faces], np.full(faces.shape[0], r, dtype=np.int32), faces)


def boundary_by_owners(boundaries: Sequence[BoundaryFaces], n_ranges: int) -> list[BoundaryFaces]:
    """The mesh boundary from the ranges' boundaries (range_boundary's, in range order), each
    face held once: by the range owning its smallest vertex id, which drops the faces two
    ranges sent (the module's step 2, first half).  Returns each range's faces, in the order
    received."""
    inbox: list[list[BoundaryFaces]] = [[] for _ in range(n_ranges)]
    for sent in boundaries:
        _send(inbox, sent.owners[np.arange(sent.faces.shape[0]), np.argmin(sent.faces, axis=1)], sent)
    owned = []
    for received in inbox:
        held = _joined(received)
        owned.append(_rows(held, _unmatched(held.faces)) if held.faces.shape[0] else held)
    return owned


def faces_around_owned(owned: Sequence[BoundaryFaces], n_ranges: int) -> list[BoundaryFaces]:
    """Each boundary face (boundary_by_owners', held once) sent to each distinct owner of its
    vertices, once: every range then holds every boundary face around each vertex it owns."""
    inbox: list[list[BoundaryFaces]] = [[] for _ in range(n_ranges)]
    for held in owned:
        owners = held.owners
        for k in range(3):
            new = np.ones(owners.shape[0], dtype=bool) if k == 0 else (owners[:, k] != owners[:, 0])
            if k == 2:
                new &= owners[:, 2] != owners[:, 1]
            _send(inbox, owners[new, k], _rows(held, new))
    return [_joined(received) for received in inbox]


class OwnerFans(NamedTuple):
    """What one owner holds of the boundary around its vertices (faces_around_owned's faces):
    local (F, 3) the faces in local vertex ids, numbered by first use; vertex_of (B,) the mesh
    id and owner_of (B,) the owner of each local vertex; fans (B,) topology.vertex_fans of
    them (right for its own vertices, whose faces it holds all)."""

    local: np.ndarray
    vertex_of: np.ndarray
    owner_of: np.ndarray
    fans: np.ndarray


def fans_by_owners(owned: Sequence[BoundaryFaces], n_ranges: int) -> list[OwnerFans]:
    """Each range's OwnerFans of the boundary held by its owners (boundary_by_owners')."""
    out = []
    for held in faces_around_owned(owned, n_ranges):
        local, vertex_of = local_vertex_ids(held.faces)
        owner_of = np.empty(vertex_of.shape[0], dtype=held.owners.dtype)
        owner_of[local.ravel()] = held.owners.ravel()
        out.append(OwnerFans(local, vertex_of, owner_of, vertex_fans(local, vertex_of.shape[0])))
    return out


def pinches_by_owners(fans: Sequence[OwnerFans]) -> np.ndarray:
    """The pinches (ascending mesh ids) of the mesh boundary, found by the ranges owning the
    vertices from their fans (fans_by_owners'; the module's step 2): the non-manifold
    vertices of the mesh boundary (topology.nonmanifold_vertices), which no range holds
    whole."""
    pinched = [np.zeros(0, dtype=np.int64)]
    for o, held in enumerate(fans):
        # Only its own vertices: it has all their faces, not all of the others'.
        pinched.append(held.vertex_of[nonmanifold_of_fans(held.fans) & (held.owner_of == o)])
    return np.sort(np.concatenate(pinched))


def _rows(faces: BoundaryFaces, rows: np.ndarray) -> BoundaryFaces:
    return BoundaryFaces(*(column[rows] for column in faces))


def _joined(parts: Sequence[BoundaryFaces]) -> BoundaryFaces:
    """The parts' faces one after another (none: empty arrays)."""
    if not parts:
        return BoundaryFaces(np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3), dtype=np.int64),
                             np.zeros(0, dtype=np.int32), np.zeros((0, 3), dtype=np.int32))
    return BoundaryFaces(*(np.concatenate(column) for column in zip(*parts)))


def _send(inbox: list[list[BoundaryFaces]], to: np.ndarray, faces: BoundaryFaces) -> None:
    """Append each range's rows of faces to its inbox: to (F,) the range of each row."""
    groups = rows_by_owner(to, len(inbox))
    if len(groups) == 1:  # one range (the usual case for most faces' owners): no copy
        inbox[groups[0][0]].append(faces)
        return
    for r, rows in groups:
        inbox[r].append(_rows(faces, rows))


def _unmatched(faces: np.ndarray) -> np.ndarray:
    """Mask (F,) of the faces (mesh ids) whose vertex set no other face has."""
    local, vertex_of = local_vertex_ids(faces)
    return unmatched_faces(local, vertex_of.shape[0])


def tets_near(part: RangeTets, marked: np.ndarray) -> np.ndarray:
    """Rows (ascending) of the range's tets with a vertex among marked (mesh ids)."""
    return np.flatnonzero(touching(part.tets, np.isin(part.ids, marked)))


def owned_boundary(parts: Sequence[RangeTets], n_ranges: int) -> list[BoundaryFaces]:
    """The mesh boundary of the parts' tets (in range order), held by its owners: each
    range's range_boundary through boundary_by_owners."""
    return boundary_by_owners([range_boundary(p, r) for r, p in enumerate(parts)], n_ranges)


def repair_pinches_in_ranges(parts: Sequence[RangeTets], n_ranges: int, fans: Sequence[OwnerFans] | None = None,
                             rings: int = PINCH_RINGS) -> list[np.ndarray] | None:
    """The kept mask (M_r,) of each range's tets (parts, in range order; owners among
    0..n_ranges-1) after the pinch repair, or None if it must run on the whole mesh (a
    cluster's worklist leaves the stars around the pinches in every order:
    repair.local_repair's fallback, never seen on a mesher's mesh).  fans: the owners' fans
    of their boundary (fans_by_owners of owned_boundary), if the caller has them.  The tets
    kept are those remove_pinches keeps of the parts' tets joined in range order, points
    ranked by position (repair.PINCH_ORDERS)."""
    kept = [np.ones(p.tets.shape[0], dtype=bool) for p in parts]
    bad = pinches_by_owners(fans_by_owners(owned_boundary(parts, n_ranges), n_ranges) if fans is None else fans)
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


__all__ = ["BoundaryFaces", "OwnerFans", "RangeTets", "boundary_by_owners", "faces_around_owned", "fans_by_owners",
           "owned_boundary", "pinches_by_owners", "range_boundary", "repair_pinches_in_ranges",
           "tets_near"]
