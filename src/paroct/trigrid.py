"""A uniform grid over triangles: each cell lists the triangles whose bounding box meets it.

The search structure of the exact distance queries (check.nearest_triangles) and of the
self-intersection test (intersections.crossing_triangles).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .surface import bounding_box

#: Largest number of grid cells along one axis of the triangle search grid.
_MAX_CELLS_PER_AXIS = 256


def triangle_grid(vertices: np.ndarray, faces: np.ndarray, extra: np.ndarray | None = None) -> tuple:
    """A uniform grid over the triangles (and the points ``extra`` (Q, 3), if given), about one
    triangle per cell, at most _MAX_CELLS_PER_AXIS cells an axis: (origin (3,), cell side,
    dims (3,), start, items), the triangles whose bounding box meets cell c (row-major over
    dims) being items[start[c]:start[c + 1]].  vertices float64, faces int64, F >= 1."""
    lo, hi, _ = bounding_box(vertices)  # of every vertex: loaded surfaces use all theirs
    if extra is not None and len(extra):
        lo, hi = np.minimum(lo, extra.min(axis=0)), np.maximum(hi, extra.max(axis=0))
    extent = hi - lo
    longest = float(extent.max())
    if longest == 0.0:
        longest = 1.0
    cell = max(float(np.prod(np.maximum(extent, 1e-9 * longest)) / faces.shape[0]) ** (1 / 3),
               longest / _MAX_CELLS_PER_AXIS)
    # Pad the box by a little so that rounding in the cell index never leaves a point outside.
    origin = lo - 0.5 * cell
    dims = np.maximum(1, np.ceil((extent + cell) / cell).astype(np.int64))
    start, items = _bin_triangles(vertices, faces, origin, cell, dims)
    return origin, cell, dims, start, items


@nb.njit(cache=True)
def _bin_triangles(vertices, faces, origin, cell, dims):
    """CSR lists of the triangles whose bounding box meets each grid cell: (start (C + 1,), items)."""
    nf = faces.shape[0]
    lo = np.empty((nf, 3), dtype=np.int64)
    hi = np.empty((nf, 3), dtype=np.int64)
    n_cells = dims[0] * dims[1] * dims[2]
    start = np.zeros(n_cells + 1, dtype=np.int64)
    for f in range(nf):
        for k in range(3):
            mn = min(vertices[faces[f, 0], k], vertices[faces[f, 1], k], vertices[faces[f, 2], k])
            mx = max(vertices[faces[f, 0], k], vertices[faces[f, 1], k], vertices[faces[f, 2], k])
            lo[f, k] = min(dims[k] - 1, max(0, np.int64(math.floor((mn - origin[k]) / cell))))
            hi[f, k] = min(dims[k] - 1, max(0, np.int64(math.floor((mx - origin[k]) / cell))))
        for i in range(lo[f, 0], hi[f, 0] + 1):
            for j in range(lo[f, 1], hi[f, 1] + 1):
                for k in range(lo[f, 2], hi[f, 2] + 1):
                    start[(i * dims[1] + j) * dims[2] + k + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(start[n_cells], dtype=np.int64)
    for f in range(nf):
        for i in range(lo[f, 0], hi[f, 0] + 1):
            for j in range(lo[f, 1], hi[f, 1] + 1):
                for k in range(lo[f, 2], hi[f, 2] + 1):
                    c = (i * dims[1] + j) * dims[2] + k
                    items[fill[c]] = f
                    fill[c] += 1
    return start, items
