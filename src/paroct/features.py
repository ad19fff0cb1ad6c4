"""Thin walls and narrow gaps of the solid, measured along the lattice rows.

Two consecutive crossings of a row, one entering and the next leaving the solid, span a
piece of material; leaving then entering spans a gap.  When the two crossed triangles
face each other (unit normals n_a . n_b < -0.5, so the pair is not the two sides of a
convex edge that the row merely clips), the piece is a wall and its thickness across
the wall is the row length times |n_a . d| (d the row's unit direction).  The seven
row directions of the lattice meet any wall within about 35 degrees of its normal.

This is the local feature size that grading refines to; for the uniform mesher it names
the thinnest feature when the mesh loses volume or topology.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .frame import EDGE_DIRECTIONS, LATTICE_TO_SPACE, FatFrame
from .rays import _KEY_BITS, RowCrossings, crossing_points

#: Two crossed triangles face each other when their unit normals have dot product below this.
FACING = -0.5


@nb.njit(cache=True)
def _facing_pairs(keys, fracs, signs, faces, normals, direction, step, facing):
    """Per consecutive crossing pair on a row: (first index, thickness, is_wall, the dot product
    of the two unit normals) where that product is below facing."""
    n = keys.shape[0]
    first = np.empty(n, dtype=np.int64)
    thick = np.empty(n)
    wall = np.empty(n, dtype=np.bool_)
    dots = np.empty(n)
    m = 0
    row_mask = ~((np.int64(1) << _KEY_BITS) - 1)
    for i in range(n - 1):
        if (keys[i] & row_mask) != (keys[i + 1] & row_mask) or signs[i] == signs[i + 1]:
            continue
        na = normals[faces[i]]
        nb_ = normals[faces[i + 1]]
        dot = na[0] * nb_[0] + na[1] * nb_[1] + na[2] * nb_[2]
        if dot >= facing:
            continue
        cells = (keys[i + 1] & ~row_mask) - (keys[i] & ~row_mask)
        length = (cells + fracs[i + 1] - fracs[i]) * step
        cos = abs(na[0] * direction[0] + na[1] * direction[1] + na[2] * direction[2])
        first[m] = i
        thick[m] = length * cos
        wall[m] = signs[i] > 0
        dots[m] = dot
        m += 1
    return first[:m], thick[:m], wall[:m], dots[:m]


@dataclass(frozen=True)
class ThinFeatures:
    """Thickness samples of walls and gaps.  thickness: (K,) model units; points: (K, 3) a
    point on the first wall of each sample; is_wall: (K,) True for material, False for gap;
    facing: (K,) the dot product of the two crossed triangles' unit normals (-1 where a
    sample was not measured along a row)."""

    thickness: np.ndarray
    points: np.ndarray
    is_wall: np.ndarray
    facing: np.ndarray

    def facing_below(self, limit: float) -> ThinFeatures:
        """The samples whose two sides face each other more squarely: facing below limit.  For
        a limit below the facing they were taken with, the same samples in the same order as
        thin_features with facing=limit (one pass of the rows serves both)."""
        keep = self.facing < limit
        return ThinFeatures(self.thickness[keep], self.points[keep], self.is_wall[keep], self.facing[keep])

    def thinnest_below(self, limit: float) -> tuple[list[str], float]:
        """The thinnest wall and the thinnest gap under limit, each as text ('wall 0.05 near (x,
        y, z)'), and the smaller thickness of the two (inf if neither)."""
        found, smallest = [], np.inf
        for walls, what in ((True, "wall"), (False, "gap")):
            hit = self.thinnest(walls)
            if hit is not None and hit[0] < limit:
                found.append(f"{what} {hit[0]:.4g} near ({hit[1][0]:.4g}, {hit[1][1]:.4g}, {hit[1][2]:.4g})")
                smallest = min(smallest, hit[0])
        return found, smallest

    def thinnest(self, walls: bool) -> tuple[float, np.ndarray] | None:
        """The smallest wall (or gap) thickness and where it is, or None if there is none."""
        sel = np.nonzero(self.is_wall == walls)[0]
        if sel.size == 0:
            return None
        i = sel[np.argmin(self.thickness[sel])]
        return float(self.thickness[i]), self.points[i]


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit outward normals (F, 3) of triangles (vertices (V, 3) float64, faces (F, 3) ids);
    zero for degenerate ones."""
    return _face_normals(np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64))


@nb.njit(cache=True, inline="always")
def triangle_normal(vertices, faces, f):
    """Unit normal (nx, ny, nz) of triangle f of faces (F, 3) over vertices (V, 3), by the
    right-hand rule; (0, 0, 0) if it is degenerate."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    ux, uy, uz = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
    vx, vy, vz = vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1], vertices[c, 2] - vertices[a, 2]
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    length = np.sqrt(nx * nx + ny * ny + nz * nz)
    if length == 0:
        length = 1.0
    return nx / length, ny / length, nz / length


@nb.njit(cache=True)
def _face_normals(vertices, faces):
    # One pass, no temporaries: numpy's cross over gathered rows took 5.5 ms on armadillo's
    # 86 k triangles, twice a pass that loses.
    out = np.empty((faces.shape[0], 3))
    for f in range(faces.shape[0]):
        out[f, 0], out[f, 1], out[f, 2] = triangle_normal(vertices, faces, f)
    return out


def thin_features(frame: FatFrame, crossings: dict, vertices: np.ndarray, faces: np.ndarray,
                  facing: float = FACING) -> ThinFeatures:
    """Wall and gap thickness samples from the crossings of the computed row directions; the
    two crossed triangles must have unit normals with dot product below ``facing``."""
    normals = face_normals(vertices, faces)
    parts = []
    rc: RowCrossings
    for d, rc in sorted(crossings.items()):
        vec = EDGE_DIRECTIONS[d] @ LATTICE_TO_SPACE.T
        step = float(np.linalg.norm(vec)) * frame.h
        first, thick, wall, dots = _facing_pairs(rc.keys, rc.fracs, rc.signs, rc.faces, normals, vec / np.linalg.norm(vec),
                                                 step, facing)
        if first.size == 0:
            continue
        parts.append((thick, crossing_points(frame, rc, first), wall, dots))
    if not parts:
        return ThinFeatures(np.zeros(0), np.zeros((0, 3)), np.zeros(0, dtype=bool), np.zeros(0))
    return ThinFeatures(*(np.concatenate(x) for x in zip(*parts)))
