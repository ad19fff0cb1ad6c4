"""Algorithms over linear octrees (the layer of p4est's p8est_algorithms.h).

A linear octree is a pair of arrays ``keys`` (N,) int64 (Morton keys of the anchors,
see :mod:`paroct.octant`) and ``levels`` (N,) int8, sorted by key, with no octant
overlapping another.  The algorithms follow Sundar, Sampath & Biros, "Bottom-up
construction and 2:1 balance refinement of linear octrees in parallel", SIAM J.
Sci. Comput. 30 (2008).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from numba.cpython.unsafe.numbers import trailing_zeros

from .frame import FatFrame
from .octant import (
    MAX_LEVEL,
    ancestor_keys,
    morton_coords,
    morton_decode,
    morton_key,
    octant_is_ancestor,
    octant_last_key,
    octant_len,
    octant_overlaps,
    octant_parent_key,
    sorted_lookup,
    sorted_unique,
)


@nb.njit(cache=True)
def tree_is_sorted(keys, levels):
    """True iff (key, level) pairs are in ascending order: ancestors precede descendants."""
    for i in range(1, keys.shape[0]):
        if keys[i] < keys[i - 1] or (keys[i] == keys[i - 1] and levels[i] <= levels[i - 1]):
            return False
    return True


@nb.njit(cache=True)
def tree_is_linear(keys, levels):
    """True iff the tree is sorted and no octant overlaps its successor (hence none overlaps any other)."""
    if not tree_is_sorted(keys, levels):
        return False
    for i in range(1, keys.shape[0]):
        if octant_overlaps(keys[i - 1], levels[i - 1], keys[i], levels[i]):
            return False
    return True


@nb.njit(cache=True)
def tree_is_complete(keys, levels):
    """True iff the tree is linear and its octants tile the root cube: each starts where the last ended."""
    if keys.shape[0] == 0 or not tree_is_linear(keys, levels):
        return False
    expected = np.int64(0)
    for i in range(keys.shape[0]):
        if keys[i] != expected:
            return False
        expected = octant_last_key(keys[i], levels[i]) + 1
    return expected == (np.int64(1) << (3 * MAX_LEVEL))


@nb.njit(cache=True)
def linearize(keys, levels):
    """Drop every octant that is an ancestor of its successor in a sorted array (keep the finest).

    Returns a boolean mask (N,) of the octants kept.  Input must satisfy tree_is_sorted.
    """
    n = keys.shape[0]
    keep = np.ones(n, dtype=np.bool_)
    for i in range(n - 1):
        if octant_is_ancestor(keys[i], levels[i], keys[i + 1], levels[i + 1]):
            keep[i] = False
    return keep


def octant_lattice_anchors(keys: np.ndarray, frame: FatFrame) -> np.ndarray:
    """Anchors (N, 3) int64 of octants in lattice units of the frame's finest level."""
    anchors = morton_decode(keys)
    anchors >>= MAX_LEVEL - frame.levels  # in place: a shifted copy cost a fresh (N, 3) array
    return anchors


_DROP, _LEAF, _SPLIT = 0, 1, 2


@nb.njit(cache=True)
def _depth_first(box_lo, box_hi, frame_levels, level):
    """Octants from a depth-first descent from the root, children in Morton order (so sorted):
    _meets_box says whether to _DROP an octant, keep it as a _LEAF or _SPLIT it into its eight
    children.  Returns (keys (N,) int64, levels (N,) int8)."""
    out_keys = np.empty(1024, dtype=np.int64)
    out_levels = np.empty(1024, dtype=np.int8)
    stack_keys = np.empty(8 * (MAX_LEVEL + 1), dtype=np.int64)
    stack_levels = np.empty(8 * (MAX_LEVEL + 1), dtype=np.int64)
    stack_keys[0] = 0
    stack_levels[0] = 0
    top, n = _descend(box_lo, box_hi, frame_levels, level, stack_keys, stack_levels, 1, out_keys, out_levels, 0)
    while top > 0:  # the output filled up: double it and go on
        out_keys = np.concatenate((out_keys, np.empty(n, dtype=np.int64)))
        out_levels = np.concatenate((out_levels, np.empty(n, dtype=np.int8)))
        top, n = _descend(box_lo, box_hi, frame_levels, level, stack_keys, stack_levels, top, out_keys, out_levels, n)
    return out_keys[:n].copy(), out_levels[:n].copy()


@nb.njit(cache=True)
def _descend(box_lo, box_hi, frame_levels, level, stack_keys, stack_levels, top, out_keys, out_levels, n):
    """_depth_first's descent from the stack (top entries) until it is empty or the output
    (n octants written) is full; returns (top, n).  Its own kernel, so that the loop never
    reassigns the output arrays (that cost numba's reference counting and reloads in the loop)."""
    while top > 0 and n < out_keys.shape[0]:
        top -= 1
        key = stack_keys[top]
        lev = stack_levels[top]
        action = _meets_box(key, lev, box_lo, box_hi, frame_levels, level)
        if action == _SPLIT:
            step = 3 * (MAX_LEVEL - lev - 1)
            for c in range(7, -1, -1):
                stack_keys[top] = key | (np.int64(c) << step)
                stack_levels[top] = lev + 1
                top += 1
        elif action == _LEAF:
            out_keys[n] = key
            out_levels[n] = lev
            n += 1
    return top, n


@nb.njit(cache=True)
def _meets_box(key, lev, lo, hi, frame_levels, level):
    """Split down to ``level`` the octants whose parallelepiped meets the box (lattice-scaled space)."""
    shift = MAX_LEVEL - frame_levels
    ax, ay, az = morton_coords(key)
    ax >>= shift
    ay >>= shift
    az >>= shift
    side = float(np.int64(1) << (frame_levels - lev))
    # Each row of LATTICE_TO_SPACE is a permutation of (1/2, 1/2, -1/2): over the cube
    # anchor + [0, side]^3 a space coordinate spans [c - side/2, c + side].
    c0 = 0.5 * (ax + ay - az)
    c1 = 0.5 * (-ax + ay + az)
    c2 = 0.5 * (ax - ay + az)
    if (c0 + side < lo[0] or c0 - side / 2 > hi[0] or c1 + side < lo[1] or c1 - side / 2 > hi[1]
            or c2 + side < lo[2] or c2 - side / 2 > hi[2]):
        return _DROP
    return _LEAF if lev == level else _SPLIT


def uniform_leaves(frame: FatFrame, box_min: np.ndarray, box_max: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """All octants of ``level`` whose parallelepiped meets the space box, as a sorted linear octree.

    Returns (keys (N,) int64, levels (N,) int8).
    """
    if not 0 <= level <= frame.levels:
        raise ValueError(f"level = {level} is outside 0..{frame.levels}")
    lo = (np.asarray(box_min, dtype=np.float64) - frame.origin) / frame.h
    hi = (np.asarray(box_max, dtype=np.float64) - frame.origin) / frame.h
    return _depth_first(lo, hi, np.int64(frame.levels), np.int64(level))


#: Separating axes a triangle is tested on besides the three box axes: its normal and the
#: cross products of its three edges with the three box axes (Akenine-Moller 2001).
_SAT_AXES = 10


@nb.njit(cache=True, inline="always")
def _triangle_axes(tri, half, axes, low, high, reach):
    """Fill the separating-axis data of a triangle (3, 3) against cubes of half side ``half``:
    axes (10, 3) (normal, then edge k x box axis j), the triangle's projection [low, high] on
    each and the cube's half extent ``reach`` on each.  Then a cube of centre c meets the
    triangle iff no axis a has low - a.c > reach or high - a.c < -reach (and the boxes overlap).
    Projections of absolute coordinates (below 2**19 lattice units) are off by about 1e-10 of
    the axis's length, well inside the 1e-7 x side margin the callers widen cubes by."""
    for k in range(3):
        j = (k + 1) % 3
        ex = tri[j, 0] - tri[k, 0]
        ey = tri[j, 1] - tri[k, 1]
        ez = tri[j, 2] - tri[k, 2]
        for i in range(3):
            row = 1 + 3 * k + i
            axes[row, i] = 0.0
            axes[row, (i + 1) % 3] = -(ez, ex, ey)[i]
            axes[row, (i + 2) % 3] = (ey, ez, ex)[i]
    e0 = (tri[1, 0] - tri[0, 0], tri[1, 1] - tri[0, 1], tri[1, 2] - tri[0, 2])
    e1 = (tri[2, 0] - tri[1, 0], tri[2, 1] - tri[1, 1], tri[2, 2] - tri[1, 2])
    axes[0, 0] = e0[1] * e1[2] - e0[2] * e1[1]
    axes[0, 1] = e0[2] * e1[0] - e0[0] * e1[2]
    axes[0, 2] = e0[0] * e1[1] - e0[1] * e1[0]
    for a in range(_SAT_AXES):
        p0 = axes[a, 0] * tri[0, 0] + axes[a, 1] * tri[0, 1] + axes[a, 2] * tri[0, 2]
        p1 = axes[a, 0] * tri[1, 0] + axes[a, 1] * tri[1, 1] + axes[a, 2] * tri[1, 2]
        p2 = axes[a, 0] * tri[2, 0] + axes[a, 1] * tri[2, 1] + axes[a, 2] * tri[2, 2]
        low[a] = min(p0, p1, p2)
        high[a] = max(p0, p1, p2)
        reach[a] = half * (abs(axes[a, 0]) + abs(axes[a, 1]) + abs(axes[a, 2]))


@nb.njit(cache=True, inline="always")
def _cube_meets_triangle(tri, axes, low, high, reach, cx, cy, cz, half):
    """True iff the closed cube of centre (cx, cy, cz) and half side ``half`` meets the triangle
    whose _triangle_axes data these are: the separating-axis test, float.  Callers widen the
    cube by a margin so that rounding can only add cubes."""
    if min(tri[0, 0], tri[1, 0], tri[2, 0]) > cx + half or max(tri[0, 0], tri[1, 0], tri[2, 0]) < cx - half:
        return False
    if min(tri[0, 1], tri[1, 1], tri[2, 1]) > cy + half or max(tri[0, 1], tri[1, 1], tri[2, 1]) < cy - half:
        return False
    if min(tri[0, 2], tri[1, 2], tri[2, 2]) > cz + half or max(tri[0, 2], tri[1, 2], tri[2, 2]) < cz - half:
        return False
    for a in range(_SAT_AXES):
        centre = axes[a, 0] * cx + axes[a, 1] * cy + axes[a, 2] * cz
        if low[a] - centre > reach[a] or high[a] - centre < -reach[a]:
            return False
    return True


@nb.njit(cache=True, inline="always")
def _slab_span(tri, a, b, a0, a1):
    """(lowest, highest) coordinate b of the triangle's projection on coordinates a, b within
    the slab a0 <= a <= a1; (inf, -inf) if it misses the slab."""
    lo, hi = np.inf, -np.inf
    for i in range(3):
        if a0 <= tri[i, a] <= a1:
            lo = min(lo, tri[i, b])
            hi = max(hi, tri[i, b])
        j = (i + 1) % 3
        pa, pb, qa, qb = tri[i, a], tri[i, b], tri[j, a], tri[j, b]
        for wall in (a0, a1):
            if min(pa, qa) < wall < max(pa, qa):
                x = pb + (qb - pb) * ((wall - pa) / (qa - pa))
                lo = min(lo, x)
                hi = max(hi, x)
    return lo, hi


#: Most chunks a parallel pass over triangles is split into (each thread owns whole chunks).
TRIANGLE_CHUNKS = 64
#: Cells in a triangle's box up to which _surface_cell_hits tests them all.
SMALL_BOX_CELLS = 8


@nb.njit(cache=True, parallel=True)
def _surface_cell_hits(snapped, faces, snap_bits, cell_bits, offsets, keys, key_faces, counts, bitmap):
    """The cells of side 2**cell_bits lattice units that each triangle meets (Morton keys at
    lattice resolution), written from offsets[f] on with face f, counts[f] = their number.

    Two passes over the same loop (count, prefix sum, fill: each thread owns its triangles'
    slots).  With empty offsets, counts[f] = the cells tested for triangle f, a cheap bound:
    the exact tests run once, in the fill.

    Or, with non-empty bitmaps (B, W) (each row one bit per cell, by Morton index of the cell
    coordinates), one pass in B chunks of triangles, each setting the bits of the cells its
    triangles meet in its own row and testing no cell already set there (most cells meet
    several triangles); offsets, keys, key_faces and counts are then unused."""
    marking = bitmap.shape[0] > 0
    bounding = offsets.shape[0] == 0 and not marking
    unit = float(np.int64(1) << snap_bits)
    side = float(np.int64(1) << cell_bits)
    margin = 1e-7 * side
    half = 0.5 * side + margin  # the cells are tested widened by the margin
    n = faces.shape[0]
    n_chunks = bitmap.shape[0] if marking else min(n, TRIANGLE_CHUNKS)
    for chunk in nb.prange(n_chunks):
        bits = bitmap[min(np.int64(chunk), bitmap.shape[0] - 1)]  # this chunk's row (unused unless marking)
        tri = np.empty((3, 3))
        axes = np.empty((_SAT_AXES, 3))
        low = np.empty(_SAT_AXES)
        high = np.empty(_SAT_AXES)
        reach = np.empty(_SAT_AXES)
        cell = np.empty(3, dtype=np.int64)
        c0 = np.empty(3, dtype=np.int64)
        c1 = np.empty(3, dtype=np.int64)
        for f in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            start = 0 if bounding or marking else offsets[f]
            m = start
            for k in range(3):
                for i in range(3):
                    tri[k, i] = snapped[faces[f, k], i] / unit
            for i in range(3):
                # Cells whose widened box meets the triangle's box (exact in floats: side is a power of two).
                c0[i] = np.int64(np.floor((min(tri[0, i], tri[1, i], tri[2, i]) - 2 * margin) / side))
                c1[i] = np.int64(np.floor((max(tri[0, i], tri[1, i], tri[2, i]) + 2 * margin) / side))
            if c0[0] == c1[0] and c0[1] == c1[1] and c0[2] == c1[2]:
                # The triangle lies inside one cell (the usual case for fine tessellations): the cell
                # meets it, no test needed.
                if c0[0] >= 0 and c0[1] >= 0 and c0[2] >= 0:
                    if marking:
                        _set_cell_bit(bits, c0[0], c0[1], c0[2])
                        continue
                    if not bounding:
                        keys[m] = morton_key(c0[0] << cell_bits, c0[1] << cell_bits, c0[2] << cell_bits)
                        key_faces[m] = f
                    m += 1
                if not marking:
                    counts[f] = m - start
                continue
            # Walk the columns along the axis k where the triangle's plane is steepest: over a
            # column the plane spans a short range of k (|n_k| is the largest normal component),
            # so a slanted triangle costs O(area) cells, not O(box volume).
            nx = (tri[1, 1] - tri[0, 1]) * (tri[2, 2] - tri[0, 2]) - (tri[1, 2] - tri[0, 2]) * (tri[2, 1] - tri[0, 1])
            ny = (tri[1, 2] - tri[0, 2]) * (tri[2, 0] - tri[0, 0]) - (tri[1, 0] - tri[0, 0]) * (tri[2, 2] - tri[0, 2])
            nz = (tri[1, 0] - tri[0, 0]) * (tri[2, 1] - tri[0, 1]) - (tri[1, 1] - tri[0, 1]) * (tri[2, 0] - tri[0, 0])
            normal = (nx, ny, nz)
            ready = False  # the axes are set up at the first cell tested (marking tests few)
            k = 0
            if abs(ny) > abs(normal[k]):
                k = 1
            if abs(nz) > abs(normal[k]):
                k = 2
            a, b = (k + 1) % 3, (k + 2) % 3
            # In a box of a few cells, testing each costs less than narrowing the columns' ranges.
            steep = abs(normal[k]) > 0.0 and (c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1) * (c1[2] - c0[2] + 1) > SMALL_BOX_CELLS
            offset = normal[0] * tri[0, 0] + normal[1] * tri[0, 1] + normal[2] * tri[0, 2]
            for ca in range(max(c0[a], 0), c1[a] + 1):
                # Only the columns the triangle's projection meets in this slab of a (widened as
                # the cells are): a long slanted triangle covers a small part of its box.
                cb0, cb1 = max(c0[b], 0), c1[b]
                if c1[a] - c0[a] > 1 and c1[b] - c0[b] > 1:
                    b_lo, b_hi = _slab_span(tri, a, b, ca * side - 2 * margin, (ca + 1) * side + 2 * margin)
                    cb0 = max(cb0, np.int64(np.floor((b_lo - 2 * margin) / side)))
                    cb1 = min(cb1, np.int64(np.floor((b_hi + 2 * margin) / side)))
                for cb in range(cb0, cb1 + 1):
                    k0, k1 = max(c0[k], 0), c1[k]
                    if steep:
                        zmin, zmax = np.inf, -np.inf
                        for da in range(2):
                            for db in range(2):
                                pa = (ca + da) * side + (2 * da - 1) * 2 * margin
                                pb = (cb + db) * side + (2 * db - 1) * 2 * margin
                                z = (offset - normal[a] * pa - normal[b] * pb) / normal[k]
                                zmin = min(zmin, z)
                                zmax = max(zmax, z)
                        k0 = max(k0, np.int64(np.floor((zmin - 2 * margin) / side)))
                        k1 = min(k1, np.int64(np.floor((zmax + 2 * margin) / side)))
                    if bounding:
                        m += max(k1 - k0 + 1, 0)
                        continue
                    for ck in range(k0, k1 + 1):
                        cell[a] = ca
                        cell[b] = cb
                        cell[k] = ck
                        if marking and _cell_bit(bits, cell[0], cell[1], cell[2]):
                            continue
                        if not ready:
                            _triangle_axes(tri, half, axes, low, high, reach)
                            ready = True
                        if not _cube_meets_triangle(tri, axes, low, high, reach, cell[0] * side + 0.5 * side,
                                                    cell[1] * side + 0.5 * side, cell[2] * side + 0.5 * side, half):
                            continue
                        if marking:
                            _set_cell_bit(bits, cell[0], cell[1], cell[2])
                            continue
                        keys[m] = morton_key(cell[0] << cell_bits, cell[1] << cell_bits, cell[2] << cell_bits)
                        key_faces[m] = f
                        m += 1
            if not marking:
                counts[f] = m - start


@nb.njit(cache=True, parallel=True)
def written_slots(offsets, counts):
    """Indices (sum counts,) of the slots a count-and-fill kernel wrote: counts[f] of them from
    offsets[f] on, in order."""
    starts = np.empty(counts.shape[0] + 1, dtype=np.int64)
    starts[0] = 0
    for f in range(counts.shape[0]):
        starts[f + 1] = starts[f] + counts[f]
    out = np.empty(starts[-1], dtype=np.int64)
    for f in nb.prange(counts.shape[0]):
        for k in range(counts[f]):
            out[starts[f] + k] = offsets[f] + k
    return out


def _surface_cell_keys(snapped: np.ndarray, faces: np.ndarray, snap_bits: int, cell_bits: int) -> tuple[np.ndarray, np.ndarray]:
    """Morton keys (octree coordinates at lattice resolution) of the cells of side
    2**cell_bits lattice units that each triangle meets, with repeats, triangle by triangle,
    and the index into faces of the triangle that listed each."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    bounds = np.empty(faces.shape[0], dtype=np.int64)
    none, no_bitmap = np.empty(0, dtype=np.int64), np.empty((0, 1), dtype=np.uint64)
    _surface_cell_hits(snapped, faces, snap_bits, cell_bits, none, none, none, bounds, no_bitmap)
    offsets = np.zeros(faces.shape[0] + 1, dtype=np.int64)
    np.cumsum(bounds, out=offsets[1:])
    keys = np.empty(int(offsets[-1]), dtype=np.int64)
    key_faces = np.empty(keys.shape[0], dtype=np.int64)
    counts = np.empty(faces.shape[0], dtype=np.int64)
    _surface_cell_hits(snapped, faces, snap_bits, cell_bits, offsets, keys, key_faces, counts, no_bitmap)
    written = written_slots(offsets, counts)
    return np.take(keys, written), np.take(key_faces, written)  # np.take: 5x a fancy index


def surface_cells(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, snap_bits: int, level: int) -> np.ndarray:
    """Sorted keys of the octants of ``level`` whose closed cube (in u) meets a triangle.

    snapped: (V, 3) int64 surface vertices in lattice units * 2**snap_bits.  Exact up to a
    relative margin of 1e-7 of the cell side, on the side of listing more cells: an octant not
    listed contains no surface point, so all its points have one inside/outside class.
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if not surface_bitmap_fits(level, faces.shape[0]):
        keys, _ = _surface_cell_keys(snapped, faces, snap_bits, frame.levels - level)
        return sorted_unique(keys) << (3 * (MAX_LEVEL - frame.levels))
    # A row per thread (any number gives the same union).
    bitmaps = np.zeros((max(1, min(nb.get_num_threads(), faces.shape[0])), (1 << (3 * level)) >> 6), dtype=np.uint64)
    none = np.empty(0, dtype=np.int64)
    _surface_cell_hits(snapped, faces, snap_bits, frame.levels - level, none, none, none, none, bitmaps)
    return _set_bits(np.bitwise_or.reduce(bitmaps, axis=0)) << (3 * (MAX_LEVEL - level))


#: Bits per triangle (and a floor) up to which surface_cells marks a bitmap of all the cells
#: of its level rather than listing and sorting each triangle's cells (16 bytes a cell, 3-4
#: cells a triangle on a lattice of the boundary size).
BITMAP_BITS_PER_FACE = 512
BITMAP_MIN_BITS = 1 << 21


def surface_bitmap_fits(level: int, n_faces: int) -> bool:
    """Whether surface_cells of ``level`` marks a bitmap of its 8**level cells."""
    return level_bitmap_fits(level, n_faces, BITMAP_BITS_PER_FACE)


def level_bitmap_fits(level: int, count: int, bits_per_item: int) -> bool:
    """Whether a bitmap of the 8**level cells of ``level`` is kept rather than ``count``
    items sorted: at most bits_per_item cells an item, or BITMAP_MIN_BITS (and at least one
    64-bit word, with indices below 2**62)."""
    return 2 <= level and 3 * level < 62 and (1 << (3 * level)) <= max(BITMAP_MIN_BITS, bits_per_item * count)


@nb.njit(cache=True, inline="always")
def _cell_bit(bitmap, x, y, z):
    """Whether the bit of cell (x, y, z) is set; cells past the bitmap's (a bitmap of
    8**level >= 64 bits holds exactly the cells of coordinates below 2**level) read as set,
    so they are never tested or marked."""
    i = morton_key(x, y, z)
    return i >= 64 * bitmap.shape[0] or (bitmap[i >> 6] >> np.uint64(i & 63)) & np.uint64(1) != 0


@nb.njit(cache=True, inline="always")
def _set_cell_bit(bitmap, x, y, z):
    i = morton_key(x, y, z)
    if i < 64 * bitmap.shape[0]:
        bitmap[i >> 6] |= np.uint64(1) << np.uint64(i & 63)


@nb.njit(cache=True)
def _set_bits(bitmap):
    """Indices (ascending, int64) of the set bits of a bitmap (uint64 words, bit i of word w
    is index 64 w + i)."""
    n = 0
    for w in range(bitmap.shape[0]):
        word = bitmap[w]
        while word:
            word &= word - np.uint64(1)
            n += 1
    out = np.empty(n, dtype=np.int64)
    n = 0
    for w in range(bitmap.shape[0]):
        word = bitmap[w]
        while word:  # a set bit at a time, its index by the CPU's trailing-zero count
            out[n] = 64 * w + trailing_zeros(word)
            n += 1
            word &= word - np.uint64(1)
    return out


#: Cells of a level per key up to which unique_level_keys marks a bitmap of them all rather
#: than sorting the keys: a sort took 10-20 ns a key, the bitmap (zeroed, set, read back)
#: about 0.04 ns a cell.  At 216 cells a key it was 1.6x faster (round_rod's balance at
#: diag/80), at 455 as fast.
BITMAP_BITS_PER_KEY = 256


def unique_level_keys(keys: np.ndarray, level: int) -> np.ndarray:
    """sorted_unique of keys (N,) int64 of octants of one level (any order, repeats).  Where
    the level's 8**level cells are few against the keys (BITMAP_BITS_PER_KEY a key, or
    BITMAP_MIN_BITS), their bits are set in a bitmap and read back in order instead: the
    band's 72 k cell keys at bunny's diag/80, 1.3 ms sorted, take 0.26."""
    keys = np.asarray(keys, dtype=np.int64)
    if not level_bitmap_fits(level, keys.size, BITMAP_BITS_PER_KEY):
        return sorted_unique(keys)
    shift = 3 * (MAX_LEVEL - level)
    return _set_bits(_bitmap_of(keys, shift, (1 << (3 * level)) >> 6)) << shift


@nb.njit(cache=True)
def _bitmap_of(keys, shift, n_words):
    """Bitmap (n_words,) uint64 with bit keys[i] >> shift set for every i."""
    bitmap = np.zeros(n_words, dtype=np.uint64)
    for i in range(keys.shape[0]):
        b = keys[i] >> shift
        bitmap[b >> 6] |= np.uint64(1) << np.uint64(b & 63)
    return bitmap


@dataclass(frozen=True)
class FaceBuckets:
    """The triangles meeting each surface cell of one level: keys (K,) sorted octree keys of
    the cells (surface_cells), faces[offsets[k]:offsets[k + 1]] the indices (into the faces
    array) of the triangles meeting cell k, in increasing order."""

    level: int
    keys: np.ndarray
    offsets: np.ndarray
    faces: np.ndarray


def face_buckets(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, snap_bits: int, level: int) -> FaceBuckets:
    """surface_cells of ``level`` with the triangles that meet each (same margin)."""
    keys, face_ids = _surface_cell_keys(snapped, faces, snap_bits, frame.levels - level)
    order = np.argsort(keys, kind="stable")  # faces were listed in increasing order
    keys, face_ids = keys[order], face_ids[order]
    first = np.ones(keys.shape[0], dtype=bool)
    first[1:] = keys[1:] != keys[:-1]
    starts = np.nonzero(first)[0]
    offsets = np.append(starts, keys.shape[0]).astype(np.int64)
    return FaceBuckets(level, keys[starts] << (3 * (MAX_LEVEL - frame.levels)), offsets, face_ids)


def faces_meeting_cells(buckets: FaceBuckets, cells: np.ndarray, n_faces: int) -> np.ndarray:
    """Mask (n_faces,) of the triangles that meet one of ``cells`` (keys of buckets.level,
    any order, repeats allowed; a cell that is not a surface cell has no bucket and meets none)."""
    at, found = sorted_lookup(buckets.keys, cells)
    marked = np.zeros(buckets.keys.shape[0], dtype=bool)
    marked[at[found]] = True
    at = np.flatnonzero(marked)
    counts = buckets.offsets[at + 1] - buckets.offsets[at]
    # Index ranges offsets[at]:offsets[at + 1], concatenated.
    pos = np.repeat(buckets.offsets[at] - np.cumsum(counts) + counts, counts) + np.arange(int(counts.sum()))
    mine = np.zeros(n_faces, dtype=bool)
    mine[buckets.faces[pos]] = True
    return mine


@nb.njit(cache=True)
def octants_holding(keys, level, cells):
    """Mask (N,) of the octants that hold a cell: keys (N,) sorted octants of one ``level``
    (so disjoint), cells (C,) sorted keys of finer octants.  One merge pass, O(N + C)."""
    out = np.zeros(keys.shape[0], dtype=np.bool_)
    j = 0
    for i in range(keys.shape[0]):
        while j < cells.shape[0] and cells[j] < keys[i]:
            j += 1
        out[i] = j < cells.shape[0] and cells[j] <= octant_last_key(keys[i], level)
    return out


@nb.njit(cache=True)
def octants_within(keys, levels, outer_keys, outer_levels):
    """Mask (N,) of the octants equal to or inside one of the outer octants.  keys, levels:
    sorted by key; outer_keys, outer_levels: sorted by key and pairwise disjoint, so only the
    last outer octant anchored at or before an octant can hold it.  One merge pass."""
    out = np.zeros(keys.shape[0], dtype=np.bool_)
    j = 0
    for i in range(keys.shape[0]):
        while j < outer_keys.shape[0] and outer_keys[j] <= keys[i]:
            j += 1
        if j > 0 and outer_levels[j - 1] <= levels[i]:
            out[i] = octant_last_key(keys[i], levels[i]) <= octant_last_key(outer_keys[j - 1], outer_levels[j - 1])
    return out


def refine_to_level(keys: np.ndarray, level_from: int, level_to: int) -> np.ndarray:
    """All descendants at ``level_to`` of sorted octants at ``level_from``, sorted."""
    depth = level_to - level_from
    if depth < 0:
        raise ValueError(f"level_to = {level_to} < level_from = {level_from}")
    # The Morton keys of the 8**depth offsets of a cube's descendants, in order, are the
    # integers below 8**depth (interleaving maps the cube's offsets onto them), shifted to
    # level_to.  (Keying a meshgrid of the offsets and sorting took 75-240 us a call.)
    offsets = np.arange(np.int64(8) ** depth, dtype=np.int64) << np.int64(3 * (MAX_LEVEL - level_to))
    return (np.asarray(keys, dtype=np.int64)[:, None] | offsets[None, :]).ravel()


def complete_from_seeds(keys: np.ndarray, levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The coarsest complete linear octree in which every seed is a leaf or refined (an octant
    is split iff a seed is a strict descendant of it).

    keys, levels: seed octants sorted by key (duplicates and overlaps allowed, levels in any
    order among equal keys).  Returns (keys (N,) int64, levels (N,) int8).
    The seeds with no strict descendant among the seeds are leaves (_finest_seeds); the gaps
    between them, as runs of finest-level keys, are cut into aligned octants greedily from
    their start, each the largest that fits: those are the coarsest, since the parent of each
    reaches past its gap (Sundar, Sampath & Biros 2008, CompleteRegion, finds the same octants
    by descending from the nearest common ancestor).  Count, prefix sum, fill over chunks of
    seeds, so the work is linear in the output and parallel.
    """
    leaf_keys, leaf_levels = _finest_seeds(np.asarray(keys, dtype=np.int64), np.asarray(levels, dtype=np.int8))
    return _fill_gaps(leaf_keys, leaf_levels)


@nb.njit(cache=True)
def _finest_seeds(keys, levels):
    """The seeds (sorted keys) that have no strict descendant among them, one per key: at each
    key the finest level, kept iff the next key lies past its last key.  (A seed anchored
    strictly inside another is finer, so the next key decides.)  linearize's rule, for seeds
    whose levels come in any order among equal keys (balance's stable sort by key alone), and
    packed rather than masked."""
    n = keys.shape[0]
    out_keys = np.empty(n, dtype=np.int64)
    out_levels = np.empty(n, dtype=np.int8)
    m = 0
    i = 0
    while i < n:
        lev = levels[i]
        j = i + 1
        while j < n and keys[j] == keys[i]:
            lev = max(lev, levels[j])
            j += 1
        if j == n or keys[j] > octant_last_key(keys[i], lev):
            out_keys[m] = keys[i]
            out_levels[m] = lev
            m += 1
        i = j
    return out_keys[:m], out_levels[:m]


@nb.njit(cache=True, inline="always")
def _largest_fitting(start, end):
    """Level of the largest octant anchored at finest key ``start`` (aligned to it) whose keys
    stay below ``end`` > start."""
    lev = 0
    while (start & ((np.int64(1) << (3 * (MAX_LEVEL - lev))) - 1)) != 0 or end - start < (
            np.int64(1) << (3 * (MAX_LEVEL - lev))):
        lev += 1
    return lev


@nb.njit(cache=True, inline="always")
def _gap_start(keys, levels, i):
    """First finest key after leaf i - 1 (0 for i = 0)."""
    return np.int64(0) if i == 0 else octant_last_key(keys[i - 1], levels[i - 1]) + 1


#: Chunks of leaves _fill_gaps hands to the threads.
_GAP_CHUNKS = 64


@nb.njit(cache=True, parallel=True)
def _fill_gaps(keys, levels):
    """The leaves (sorted, disjoint) and the coarsest octants filling the gaps before each and
    after the last, in key order: (keys (N,) int64, levels (N,) int8)."""
    n = keys.shape[0]
    end = np.int64(1) << (3 * MAX_LEVEL)
    n_chunks = min(n + 1, _GAP_CHUNKS)
    offsets = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in nb.prange(n_chunks):
        count = 0
        for i in range(c * (n + 1) // n_chunks, (c + 1) * (n + 1) // n_chunks):
            at = _gap_start(keys, levels, i)
            stop = keys[i] if i < n else end
            while at < stop:
                at += np.int64(1) << (3 * (MAX_LEVEL - _largest_fitting(at, stop)))
                count += 1
            count += i < n
        offsets[c + 1] = count
    for c in range(n_chunks):
        offsets[c + 1] += offsets[c]
    out_keys = np.empty(offsets[n_chunks], dtype=np.int64)
    out_levels = np.empty(offsets[n_chunks], dtype=np.int8)
    for c in nb.prange(n_chunks):
        k = offsets[c]
        for i in range(c * (n + 1) // n_chunks, (c + 1) * (n + 1) // n_chunks):
            at = _gap_start(keys, levels, i)
            stop = keys[i] if i < n else end
            while at < stop:
                lev = _largest_fitting(at, stop)
                out_keys[k] = at
                out_levels[k] = lev
                k += 1
                at += np.int64(1) << (3 * (MAX_LEVEL - lev))
            if i < n:
                out_keys[k] = keys[i]
                out_levels[k] = levels[i]
                k += 1
    return out_keys, out_levels


@nb.njit(cache=True)
def _parent_keys(keys, levels, level):
    """Parent keys of the octants at ``level``."""
    out = np.empty(keys.shape[0], dtype=np.int64)
    m = 0
    for i in range(keys.shape[0]):
        if levels[i] == level:
            out[m] = octant_parent_key(keys[i], level)
            m += 1
    return out[:m]


@nb.njit(cache=True)
def _insulation_parents(parents, level):
    """The 26 neighbours (level - 1, inside the root) of the parents (level - 1) of octants at ``level``.

    Splitting a parent makes all eight children leaves of ``level``, so each of them needs its
    neighbours at ``level - 1`` or finer: those are the parent's same-size neighbours.
    Parents near each other in key order share most of their neighbours: a neighbour already
    in a small direct-mapped table of those listed is not listed again, so the list holds
    each about once instead of about twelve times (round_rod diag/80), and the dedupe that
    follows sorts that much less (the list may still repeat keys, in any order).
    """
    side = octant_len(level - 1)
    root = np.int64(1) << MAX_LEVEL
    out = np.empty(26 * parents.shape[0] + 1, dtype=np.int64)
    listed = np.full(_LISTED_SLOTS, -1, dtype=np.int64)
    m = 0
    for i in range(parents.shape[0]):
        x, y, z = morton_coords(parents[i])
        for dz in range(-1, 2):
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    if dx == 0 and dy == 0 and dz == 0:
                        continue
                    nx = x + dx * side
                    ny = y + dy * side
                    nz = z + dz * side
                    if nx < 0 or ny < 0 or nz < 0 or nx >= root or ny >= root or nz >= root:
                        continue
                    key = morton_key(nx, ny, nz)
                    slot = (key * _FIBONACCI_MULTIPLIER) >> np.int64(64 - _LISTED_BITS) & (_LISTED_SLOTS - 1)
                    if listed[slot] == key:
                        continue
                    listed[slot] = key
                    out[m] = key
                    m += 1
    return out[:m]


#: _insulation_parents' table of listed keys: 2^15 slots (256 KiB, in the L2 cache).
_LISTED_BITS = 15
_LISTED_SLOTS = 1 << _LISTED_BITS
#: Knuth's multiplicative hash, 2^64 / golden ratio as a signed int64 (wraps like uint64).
_FIBONACCI_MULTIPLIER = np.int64(-7046029254386353131)


def balance(keys: np.ndarray, levels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The coarsest complete 2:1-balanced octree refining the given octants (face, edge and corner balance).

    Ripple propagation from the finest level up (Sundar, Sampath & Biros 2008, Sec. 4): an
    octant of level l splits its parent, so the parent's 26 neighbours (level l - 1) must be
    leaves or refined; those seeds then propagate from level l - 1.  Input: octants (not necessarily
    linear or complete), any order.  Returns (keys, levels) sorted, complete and balanced.
    """
    keys = np.asarray(keys, dtype=np.int64)
    levels = np.asarray(levels, dtype=np.int8)
    seeds_k, seeds_l = [keys], [levels]
    added = np.zeros(0, dtype=np.int64)  # seeds at the visited level, added by the finer one
    for level in range(int(levels.max(initial=0)), 1, -1):
        # The octants at this level: the input's and the seeds the finer level added.
        split = np.concatenate([_parent_keys(keys, levels, level), ancestor_keys(added, level - 1)])
        added = unique_level_keys(_insulation_parents(sorted_unique(split), level), level - 1)
        seeds_k.append(added)
        seeds_l.append(np.full(added.shape[0], level - 1, dtype=np.int8))
    all_k = np.concatenate(seeds_k)
    all_l = np.concatenate(seeds_l)
    # complete_from_seeds needs keys sorted, levels in any order among equal keys; the seeds are
    # a few sorted runs, which a stable (merge) sort takes in near-linear time.
    order = np.argsort(all_k, kind="stable")
    return complete_from_seeds(np.take(all_k, order), np.take(all_l, order))


@nb.njit(cache=True)
def tree_is_balanced(keys, levels):
    """True iff no two leaves that touch (share a face, edge or corner) differ by more than one level.

    Checked from the finer side: a point of each of the 26 same-size neighbour cells of a leaf
    of level l must lie in a leaf of level >= l - 1 (a coarser leaf touching it contains one of
    those cells whole).  Input must be complete (tree_is_complete).
    """
    root = np.int64(1) << MAX_LEVEL
    for i in range(keys.shape[0]):
        x, y, z = morton_coords(keys[i])
        side = octant_len(levels[i])
        for dz in range(-1, 2):
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    if dx == 0 and dy == 0 and dz == 0:
                        continue
                    # A probe point in the neighbouring region: one unit outside, anywhere along the touching part.
                    px = x - 1 if dx < 0 else (x + side if dx > 0 else x)
                    py = y - 1 if dy < 0 else (y + side if dy > 0 else y)
                    pz = z - 1 if dz < 0 else (z + side if dz > 0 else z)
                    if px < 0 or py < 0 or pz < 0 or px >= root or py >= root or pz >= root:
                        continue
                    j = np.searchsorted(keys, morton_key(px, py, pz), side="right") - 1
                    if levels[j] < levels[i] - 1:
                        return False
    return True
