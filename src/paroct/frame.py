"""The fat frame: the one map between lattice coordinates u and space x.

Todd (1985) maps the Freudenthal/Kuhn triangulation of the integer grid by
``A = I - (n + 1 + sqrt(n + 1))^-1 e e^T``; for n = 3 that is ``A = I - e e^T / 6``
(formula (1) of the seed paper; its printed matrix has the sign of the
off-diagonal entries wrong).  Every image tet is congruent, 3r/R = 3/sqrt(10),
dihedral angles 60 and 90 degrees.  One more rotation ``R`` turns the mapped grid
into the body-centred-cubic (BCC) lattice of Labelle & Shewchuk (2007): the
axis-aligned cube grid of edge ``h`` plus the cube centres.  Then

    x = origin + h * R A u,    R A = LATTICE_TO_SPACE = 1/2 [[1, 1, -1], [-1, 1, 1], [1, -1, 1]]
    u = SPACE_TO_LATTICE (x - origin) / h,  SPACE_TO_LATTICE = [[1, 0, 1], [1, 1, 0], [0, 1, 1]]

Long tet edges (u-directions e_i + e_j) have length h and point along the x, z
and y axes; short edges (e_i and e_1 + e_2 + e_3) have length h sqrt(3)/2.
``h`` is the user's ``size``: the long edge at the finest octree level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

TODD_A = np.eye(3) - np.ones((3, 3)) / 6.0
LATTICE_TO_SPACE = 0.5 * np.array([[1.0, 1.0, -1.0], [-1.0, 1.0, 1.0], [1.0, -1.0, 1.0]])
SPACE_TO_LATTICE = np.array([[1, 0, 1], [1, 1, 0], [0, 1, 1]], dtype=np.int64)
ROTATION = LATTICE_TO_SPACE @ np.linalg.inv(TODD_A)

#: The seven edge directions of the Freudenthal triangulation, shape (7, 3) int64.
EDGE_DIRECTIONS = np.array(
    [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1]], dtype=np.int64
)
#: Index into EDGE_DIRECTIONS of the direction that maps to the +x axis.
X_AXIS_DIRECTION = 3

#: Corner c of a lattice cube sits at u = (c & 1, (c >> 1) & 1, (c >> 2) & 1).
CUBE_CORNERS = np.array([[(c >> i) & 1 for i in range(3)] for c in range(8)], dtype=np.int64)
#: The six Freudenthal tets of a cube (0, e_p1, e_p1 + e_p2, e for the permutations p),
#: as corner indices, each ordered to have positive volume in space.
FREUDENTHAL_TETS = np.array(
    [[0, 1, 3, 7], [0, 5, 1, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 6, 4, 7]], dtype=np.int64
)


def row_basis(direction: int) -> np.ndarray:
    """Unimodular integer matrix T (3, 3) with ``T @ EDGE_DIRECTIONS[direction] = e_1``
    (read-only, from ROW_BASES).

    Lattice lines parallel to an edge direction d become the rows {(t, p2, p3)} of the
    integer grid: ``T @ u`` gives the position t along the line and the row (p2, p3).
    Rows of T have entries in {-1, 0, 1}, so |T u| <= 2 max|u|.
    """
    return ROW_BASES[direction]


def _unimodular_basis(d: np.ndarray) -> np.ndarray:
    """T (3, 3) int64 with T @ d = e_1 and det T = 1, for d with 0/1 entries and a 1."""
    first = int(np.argmax(d))  # a coordinate where d is 1
    T = np.zeros((3, 3), dtype=np.int64)
    T[0, first] = 1
    others = [i for i in range(3) if i != first]
    for r, i in enumerate(others, start=1):
        T[r, i] = 1
        T[r, first] = -d[i]
    if round(np.linalg.det(T)) < 0:
        T[[1, 2]] = T[[2, 1]]
    return T


#: row_basis of each edge direction, shape (7, 3, 3) int64, read-only (the rays stages ask
#: for them a few dozen times per mesh).
ROW_BASES = np.stack([_unimodular_basis(d) for d in EDGE_DIRECTIONS])
ROW_BASES.setflags(write=False)


@dataclass(frozen=True)
class FatFrame:
    """Placement of the fat lattice in space.

    origin: (3,) float64, the space point of u = 0.
    h: float, long edge length at the finest level (the requested size), in model units.
    levels: int, the finest octree level; the root cube is [0, 2**levels)^3 in u.
    """

    origin: np.ndarray
    h: float
    levels: int

    def to_space(self, u: np.ndarray) -> np.ndarray:
        """Space points (N, 3) float64 of lattice points u (N, 3), any real dtype (any shape
        (..., 3): the result has u's shape)."""
        u = np.asarray(u)
        dtype = np.int64 if np.issubdtype(u.dtype, np.integer) else np.float64
        rows = np.ascontiguousarray(u.reshape(-1, 3), dtype=dtype)
        out = _to_space(rows, np.ascontiguousarray(self.origin, dtype=np.float64), float(self.h), LATTICE_TO_SPACE)
        return out.reshape(u.shape)

    def to_lattice(self, x: np.ndarray) -> np.ndarray:
        """Lattice coordinates (N, 3) float64 of space points x (N, 3)."""
        return ((np.asarray(x, dtype=np.float64) - self.origin) / self.h) @ SPACE_TO_LATTICE.T.astype(np.float64)


@nb.njit(cache=True, parallel=True)
def _to_space(u, origin, h, matrix):
    """origin + h * (u @ matrix.T) for u (N, 3), with numpy's rounding (the same sums in the
    same order) in one parallel pass: numpy's matmul on integer lattice coordinates converts
    and multiplies through temporaries (81 against 37 ms for 2 M points)."""
    out = np.empty((u.shape[0], 3))
    for i in nb.prange(u.shape[0]):
        space_point(origin, h, matrix, float(u[i, 0]), float(u[i, 1]), float(u[i, 2]), out, i)
    return out


@nb.njit(cache=True, inline="always")
def space_point(origin, h, matrix, a, b, c, out, i):
    """out[i] = the space point of lattice point (a, b, c), rounded as FatFrame.to_space."""
    for r in range(3):
        out[i, r] = origin[r] + h * (a * matrix[r, 0] + b * matrix[r, 1] + c * matrix[r, 2])


#: Lattice offset of the solid's bounding box from the root cube's corner, in units of h.
#: Non-dyadic so that CAD faces at round coordinates rarely pass exactly through lattice points.
_BOX_MARGIN = 1.1909830056250525


def fat_frame(bbox_min: np.ndarray, bbox_max: np.ndarray, size: float) -> FatFrame:
    """The frame of long edge ``size`` whose root cube holds the box with a margin.

    The box corner nearest the origin sits at u = 2 * _BOX_MARGIN, so at least two
    lattice layers lie outside the solid on every side.
    """
    bbox_min = np.asarray(bbox_min, dtype=np.float64)
    bbox_max = np.asarray(bbox_max, dtype=np.float64)
    origin = bbox_min - _BOX_MARGIN * size
    # Every u_i is a sum of two x components, each spanning at most (extent + 2 margin) / h.
    span = (bbox_max - bbox_min) / size + 2 * _BOX_MARGIN
    u_extent = max(span[0] + span[2], span[0] + span[1], span[1] + span[2])
    levels = max(1, int(np.ceil(np.log2(u_extent + 2.0))))
    return FatFrame(origin=origin, h=float(size), levels=levels)
