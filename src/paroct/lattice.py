"""Emit the Freudenthal tets of octree leaves with globally numbered lattice vertices.

Vertices are identified by the Morton key of their lattice coordinates and numbered
in the order leaves first touch them (leaves in Morton order), so the numbering is
deterministic and spatially coherent.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .frame import CUBE_CORNERS, FREUDENTHAL_TETS
from .octant import morton_key

_EMPTY = np.int64(-1)
#: Number leaf corners through a dense box index when the box has at most this many
#: lattice points per leaf (12 bytes each), else through a hash table.
DENSE_SLOTS_PER_LEAF = 8
_FIB = np.uint64(0x9E3779B97F4A7C15)


@nb.njit(cache=True, inline="always")
def _slot(key, bits):
    # Morton keys of nearby vertices are close: keep their low bits (cache locality for leaves
    # visited in Morton order) and fold the high bits in, so coarse vertices (keys with many
    # trailing zeros) still spread over the table.
    k = np.uint64(key)
    return np.int64((k ^ (k >> np.uint64(bits)) ^ ((k * _FIB) >> np.uint64(64 - bits))) & np.uint64((1 << bits) - 1))


@nb.njit(cache=True)
def _insert(table_keys, table_vals, mask, key, slot, next_id):
    """Open-addressing insert from a first slot; returns (id of key, whether it was new)."""
    s = slot
    while True:
        k = table_keys[s]
        if k == key:
            return table_vals[s], False
        if k == _EMPTY:
            table_keys[s] = key
            table_vals[s] = next_id
            return next_id, True
        s = (s + 1) & mask


@nb.njit(cache=True)
def _number_corners(anchors, sides, box_lo, box_dims):
    """Vertex ids (L, 8) int32 of leaf corners and the lattice coordinates (V, 3) of the vertices.

    box_dims[0] > 0: every corner lies in the box box_lo + [0, box_dims), and its linear index
    there is a collision-free slot; otherwise slots come from _slot and the table grows.
    """
    n = anchors.shape[0]
    dense = box_dims[0] > 0
    if dense:
        size = box_dims[0] * box_dims[1] * box_dims[2]
        bits = 0
        mask = np.int64(-1)
    else:
        bits = 4
        while (np.int64(1) << bits) < 4 * n + 16:
            bits += 1
        size = np.int64(1) << bits
        mask = size - 1
    table_keys = np.full(size, _EMPTY, dtype=np.int64)
    table_vals = np.empty(size, dtype=np.int32)
    corner_ids = np.empty((n, 8), dtype=np.int32)
    coords = np.empty((4 * n + 16, 3), dtype=np.int64)
    count = 0
    for i in range(n):
        for c in range(8):
            x = anchors[i, 0] + sides[i] * CUBE_CORNERS[c, 0]
            y = anchors[i, 1] + sides[i] * CUBE_CORNERS[c, 1]
            z = anchors[i, 2] + sides[i] * CUBE_CORNERS[c, 2]
            key = morton_key(x, y, z)
            if dense:
                slot = (x - box_lo[0]) + box_dims[0] * ((y - box_lo[1]) + box_dims[1] * (z - box_lo[2]))
            else:
                slot = _slot(key, bits)
            vid, new = _insert(table_keys, table_vals, mask, key, slot, count)
            if new:
                if count == coords.shape[0]:
                    grown = np.empty((2 * count, 3), dtype=np.int64)
                    grown[:count] = coords
                    coords = grown
                coords[count, 0] = x
                coords[count, 1] = y
                coords[count, 2] = z
                count += 1
                if not dense and 2 * count > table_keys.shape[0]:
                    table_keys, table_vals, bits = _rehash(table_keys, table_vals, bits)
                    mask = (np.int64(1) << bits) - 1
            corner_ids[i, c] = vid
    return corner_ids, coords[:count].copy()


@nb.njit(cache=True)
def _rehash(table_keys, table_vals, bits):
    new_bits = bits + 1
    new_keys = np.full(np.int64(1) << new_bits, _EMPTY, dtype=np.int64)
    new_vals = np.empty(np.int64(1) << new_bits, dtype=np.int32)
    mask = (np.int64(1) << new_bits) - 1
    for s in range(table_keys.shape[0]):
        if table_keys[s] != _EMPTY:
            _insert(new_keys, new_vals, mask, table_keys[s], _slot(table_keys[s], new_bits), table_vals[s])
    return new_keys, new_vals, new_bits


@nb.njit(cache=True, inline="always")
def _tet_kept(corner_ids, i, t, marked):
    for k in range(4):
        if marked[corner_ids[i, FREUDENTHAL_TETS[t, k]]]:
            return True
    return False


@nb.njit(cache=True, parallel=True)
def _freudenthal_tets(corner_ids, marked):
    """Freudenthal tets of the leaves with at least one marked vertex (count, prefix sum, fill)."""
    n = corner_ids.shape[0]
    counts = np.zeros(n + 1, dtype=np.int64)
    for i in nb.prange(n):
        c = 0
        for t in range(6):
            if _tet_kept(corner_ids, i, t, marked):
                c += 1
        counts[i + 1] = c
    offsets = np.cumsum(counts)
    tets = np.empty((offsets[n], 4), dtype=np.int32)
    for i in nb.prange(n):
        k = offsets[i]
        for t in range(6):
            if _tet_kept(corner_ids, i, t, marked):
                for j in range(4):
                    tets[k, j] = corner_ids[i, FREUDENTHAL_TETS[t, j]]
                k += 1
    return tets


def number_corners(anchors: np.ndarray, sides: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global vertex ids of leaf corners.

    anchors: (L, 3) int64 leaf minimum corners, lattice units; sides: (L,) int64 leaf sides.
    Returns (corner_ids (L, 8) int32, corner c at anchor + side * CUBE_CORNERS[c];
    vertex_coords (V, 3) int64 lattice units).
    """
    anchors = np.ascontiguousarray(anchors, dtype=np.int64)
    sides = np.ascontiguousarray(sides, dtype=np.int64)
    if anchors.ndim != 2 or anchors.shape[1] != 3 or sides.shape != (anchors.shape[0],):
        raise ValueError(f"anchors.shape = {anchors.shape}, sides.shape = {sides.shape}; expected (L, 3) and (L,)")
    box_lo = np.zeros(3, dtype=np.int64)
    box_dims = np.zeros(3, dtype=np.int64)
    if anchors.shape[0]:
        box_lo = anchors.min(axis=0)
        box_dims = (anchors + sides[:, None]).max(axis=0) + 1 - box_lo
        if np.prod(box_dims.astype(np.float64)) > DENSE_SLOTS_PER_LEAF * anchors.shape[0]:
            box_dims = np.zeros(3, dtype=np.int64)
    return _number_corners(anchors, sides, box_lo, box_dims)


def freudenthal_tets(corner_ids: np.ndarray, marked: np.ndarray | None = None) -> np.ndarray:
    """The positively oriented Freudenthal tets (int32, 4 columns) of leaves with corner_ids (L, 8):
    all six per leaf, in leaf order, or with ``marked`` (V,) bool only those with a marked vertex."""
    corner_ids = np.ascontiguousarray(corner_ids)
    if marked is None:
        marked = np.ones(int(corner_ids.max(initial=-1)) + 1, dtype=np.bool_)
    return _freudenthal_tets(corner_ids, np.ascontiguousarray(marked, dtype=np.bool_))


def leaf_tets(anchors: np.ndarray, sides: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The six positively oriented Freudenthal tets of every leaf.

    anchors: (L, 3) int64 leaf minimum corners, lattice units; sides: (L,) int64 leaf sides.
    Returns (vertex_coords (V, 3) int64 lattice units, tets (6L, 4) int32), tets 6i..6i+5
    belonging to leaf i.
    """
    corner_ids, coords = number_corners(anchors, sides)
    return coords, freudenthal_tets(corner_ids)
