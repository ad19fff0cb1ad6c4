"""Emit the Freudenthal tets of octree leaves with globally numbered lattice vertices.

Vertices are identified by the Morton key of their lattice coordinates and numbered
in the order leaves first touch them (leaves in Morton order), so the numbering is
deterministic and spatially coherent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from numba import types
from numba.extending import overload

from .frame import CUBE_CORNERS
from .octant import morton_key
from .transitions import (
    CHAIN_IS_ODD,
    CHAIN_SPLITS,
    CHAINS,
    FACE_CENTRE_RULES,
    SPLIT_POINT_OFFSETS,
    TEMPLATE_COUNTS,
    TEMPLATE_TETS,
)

_EMPTY = np.int64(-1)
#: Number leaf corners through a dense index (4 bytes a lattice point, in bricks of 8^3,
#: BRICK_BITS: only the bricks that hold a leaf point, each at the resolution of its points,
#: found through a directory of 8 bytes a brick of the leaves' box) when directory and bricks
#: have at most this many slots per leaf, else through a hash table (16 bytes a slot, at
#: least 8 slots a leaf).  At 64 (256 bytes a leaf, which emits about six tets) the dense
#: index is 2x faster than hashing on graded meshes and the bands of curved parts at diag/160
#: (4-5x on locally refined bands, whose box is mostly empty); it is freed before stuffing
#: allocates its output.
DENSE_SLOTS_PER_LEAF = 64
_FIB = np.uint64(0x9E3779B97F4A7C15)
#: A brick of the dense index has 2**BRICK_BITS lattice points along each axis.  Bricks of
#: 4^3 left the large local bands' index a quarter as big (fea_part at diag/80: 106 MB for
#: 734 k vertices, 2.6 % of its slots used), but numbered them 3 % slower warm and no faster
#: cold (session 27).  Bricks at their points' resolution (session 29) take it to 16 MB, and
#: number it 1.5x faster: a coarse leaf's points then share a few cache lines.
BRICK_BITS = 3
_BRICK_SIDE = 1 << BRICK_BITS
_BRICK_SLOTS = 1 << (3 * BRICK_BITS)
#: Bits of a brick coordinate spread to every third bit: a point's Morton index in its brick.
_SPREAD = np.array([sum(((i >> b) & 1) << (3 * b) for b in range(BRICK_BITS)) for i in range(_BRICK_SIDE)],
                   dtype=np.int64)
#: Low bits of a brick directory entry holding the brick's resolution shift (0..BRICK_BITS).
_SHIFT_BITS = 2
_SHIFT_MASK = (1 << _SHIFT_BITS) - 1
assert BRICK_BITS <= _SHIFT_MASK


@nb.njit(cache=True, inline="always")
def _slot(key, bits):
    # Morton keys of nearby vertices are close: keep their low bits (cache locality for leaves
    # visited in Morton order) and fold the high bits in, so coarse vertices (keys with many
    # trailing zeros) still spread over the table.
    k = np.uint64(key)
    return np.int64((k ^ (k >> np.uint64(bits)) ^ ((k * _FIB) >> np.uint64(64 - bits))) & np.uint64((1 << bits) - 1))


@nb.njit(cache=True, inline="always")
def _box_brick(x, y, z, box_lo, bricks):
    """Index of the brick of the box (x-fastest order) holding a point of the box."""
    return ((((z - box_lo[2]) >> BRICK_BITS) * bricks[1] + ((y - box_lo[1]) >> BRICK_BITS)) * bricks[0]
            + ((x - box_lo[0]) >> BRICK_BITS))


def _axis_part(table, box_lo, stride, k, coordinate):
    """The part of a lattice point's coordinate along axis k in its lookup (_lookup): (brick
    part, Morton part), each summed over the three axes.  A lookup is separable by axis, so a
    leaf's eight corners take six parts, not 24 (corner numbering 1.5x faster, session 30).
    Dense index: the offset from box_lo split into the index of its brick along k times
    stride[k] (the box's brick strides, x fastest) and its bits below BRICK_BITS spread and
    shifted by k (a Morton index inside the brick); hash table: (0, the coordinate's part of
    morton_key)."""
    raise NotImplementedError("compiled only: see _overload_axis_part")


@overload(_axis_part, inline="always")
def _overload_axis_part(table, box_lo, stride, k, coordinate):
    if table.ndim == 1:
        def dense(table, box_lo, stride, k, coordinate):
            offset = coordinate - box_lo[k]
            return (offset >> BRICK_BITS) * stride[k], _SPREAD[offset & (_BRICK_SIDE - 1)] << k
        return dense
    return lambda table, box_lo, stride, k, coordinate: (np.int64(0), morton_key(coordinate, 0, 0) << k)


def _dense_slot(directory, brick, morton):
    """Slot in the dense index of the point at Morton index ``morton`` inside brick ``brick`` of
    the box, so leaves visited in Morton order touch few cache lines.  directory None: every
    brick of the box is in the index, in box order, with _BRICK_SLOTS slots; else
    directory[brick] gives its first slot and resolution shift (_brick_directory: only the
    bricks holding leaf points are in the index, a brick's points all at multiples of
    2**shift, so dropping the Morton index's low 3 * shift bits drops only zeros)."""
    raise NotImplementedError("compiled only: see _overload_dense_slot")


@overload(_dense_slot, inline="always")
def _overload_dense_slot(directory, brick, morton):
    if isinstance(directory, types.NoneType):
        # Chosen at compile time: the whole box costs no directory load per point.
        return lambda directory, brick, morton: (brick << (3 * BRICK_BITS)) | morton

    def through_directory(directory, brick, morton):
        entry = directory[brick]
        return (entry >> _SHIFT_BITS) + (morton >> (3 * (entry & _SHIFT_MASK)))
    return through_directory


@nb.njit(cache=True, inline="always")
def _resolution(offset_bits):
    """Largest shift up to BRICK_BITS such that offset_bits is a multiple of 2**shift."""
    shift = 0
    while shift < BRICK_BITS and (offset_bits >> shift) & 1 == 0:
        shift += 1
    return shift


@nb.njit(cache=True, inline="always")
def _place_brick(directory, b, shift, slots):
    """Give brick b slots for points of resolution shift (_brick_directory), from slot
    ``slots`` on, unless it has them already; returns the slots given so far.  A brick placed
    for coarser points is placed again (the table is empty yet: its first slots just go
    unused, fewer than an eighth of the brick's new ones)."""
    entry = directory[b]
    if entry < 0 or (entry & _SHIFT_MASK) > shift:
        directory[b] = (slots << _SHIFT_BITS) | shift
        slots += np.int64(1) << (3 * (BRICK_BITS - shift))
    return slots


@nb.njit(cache=True)
def _brick_directory(anchors, sides, prefix, box_lo, bricks):
    """The entry (n_bricks,) int64 of each brick of the box that holds a leaf point (corners,
    and for leaves of side >= 2 the split points at half sides) or a prefix point, -1 for the
    others: (first slot << _SHIFT_BITS) | shift, where every point in the brick lies at a
    multiple of 2**shift from box_lo (a multiple of the brick side) along each axis, so the
    brick has (_BRICK_SIDE >> shift)**3 slots, placed in the order the prefix and then the
    leaves first hold a point in them (close to Morton order, so leaves visit few cache lines).
    A brick of coarse leaves only (a band refined locally is mostly those) has a few slots,
    not _BRICK_SLOTS: fea_part's local band at diag/80 takes 4 M slots, not 28 M.
    Every point looked up must be such a point (as the numbering kernels' are): another point
    of a coarse brick shares a slot.  Returns (directory, slots in all)."""
    directory = np.full(bricks[0] * bricks[1] * bricks[2], -1, dtype=np.int64)
    slots = 0
    for i in range(prefix.shape[0]):
        slots = _place_brick(directory, _box_brick(prefix[i, 0], prefix[i, 1], prefix[i, 2], box_lo, bricks),
                             _resolution((prefix[i, 0] - box_lo[0]) | (prefix[i, 1] - box_lo[1])
                                         | (prefix[i, 2] - box_lo[2])), slots)
    lo = np.empty(3, dtype=np.int64)
    hi = np.empty(3, dtype=np.int64)
    for i in range(anchors.shape[0]):
        # The leaf's points lie in the bricks from its anchor's to its far corner's: one brick
        # for most small leaves; a leaf of side 16 or more skips the bricks between its
        # points (at 0, side / 2 and side along each axis).
        s = sides[i]
        bits = max(np.int64(1), s // 2)  # spacing of the leaf's points
        for k in range(3):
            lo[k] = (anchors[i, k] - box_lo[k]) >> BRICK_BITS
            hi[k] = (anchors[i, k] + s - box_lo[k]) >> BRICK_BITS
            bits |= anchors[i, k] - box_lo[k]
        shift = _resolution(bits)
        if lo[0] == hi[0] and lo[1] == hi[1] and lo[2] == hi[2]:  # most leaves: no loop
            slots = _place_brick(directory, (lo[2] * bricks[1] + lo[1]) * bricks[0] + lo[0], shift, slots)
            continue
        step = max(np.int64(1), (s // 2) >> BRICK_BITS)
        for bz in range(lo[2], hi[2] + 1, step):
            for by in range(lo[1], hi[1] + 1, step):
                for bx in range(lo[0], hi[0] + 1, step):
                    slots = _place_brick(directory, (bz * bricks[1] + by) * bricks[0] + bx, shift, slots)
    return directory, slots


def _lookup(table, bits, directory, brick, morton, next_id, add):
    """Id of the lattice point whose axis parts (_axis_part) sum to brick and morton in the
    vertex table, adding it as next_id when absent and ``add``; returns (id or -1, whether it
    was added).

    The table's type picks the lookup when the caller compiles, so each specialization holds
    one branch (a run-time test between the two made the dense loop 6x slower):
    1-D int32: the dense index (_dense_slot through the brick directory), holding id + 1, 0
    where empty (np.zeros maps fresh zero pages, where a fill with -1 wrote the whole index
    first: 61 ms for fea_part's 106 MB at diag/80, cold).
    2-D int64 (S, 2): open addressing on Morton keys, rows (key, id), key -1 where empty,
    S = 2**bits.
    """
    raise NotImplementedError("compiled only: see _overload_lookup")


@overload(_lookup, inline="always")
def _overload_lookup(table, bits, directory, brick, morton, next_id, add):
    if table.ndim == 1:
        def dense(table, bits, directory, brick, morton, next_id, add):
            s = _dense_slot(directory, brick, morton)
            vid = np.int64(table[s]) - 1
            if vid >= 0 or not add:
                return vid, False
            table[s] = next_id + 1
            return np.int64(next_id), True
        return dense

    def hashed(table, bits, directory, brick, morton, next_id, add):
        s = _probe(table, morton, bits)
        if table[s, 0] == morton:
            return table[s, 1], False
        if not add:
            return np.int64(-1), False
        table[s, 0] = morton
        table[s, 1] = next_id
        return np.int64(next_id), True
    return hashed


@nb.njit(cache=True, inline="always")
def _vertex_id(table, bits, stride, box_lo, directory, x, y, z, next_id, add):
    """_lookup of lattice point (x, y, z)."""
    bx, mx = _axis_part(table, box_lo, stride, 0, x)
    by, my = _axis_part(table, box_lo, stride, 1, y)
    bz, mz = _axis_part(table, box_lo, stride, 2, z)
    return _lookup(table, bits, directory, bx + by + bz, mx | my | mz, next_id, add)


@nb.njit(cache=True)
def _probe(table, key, bits):
    """Row of key in a hashed vertex table, or of the empty row where it would go (linear
    probing from _slot).  Not inlined: a loop inlined into the overload trips numba's SSA check."""
    mask = (np.int64(1) << bits) - 1
    s = _slot(key, bits)
    while table[s, 0] != key and table[s, 0] != _EMPTY:
        s = (s + 1) & mask
    return s


def _has_room(table, count):
    """True iff the vertex table may hold count entries without growing: always for a dense
    index, up to half its rows for a hash table."""
    raise NotImplementedError("compiled only: see _overload_has_room")


@overload(_has_room, inline="always")
def _overload_has_room(table, count):
    if table.ndim == 1:
        return lambda table, count: True
    return lambda table, count: 2 * count <= table.shape[0]


def _with_room(table, bits, count):
    """(table, bits) with room for count entries: a hash table doubled (_rehash) as often as
    needed; a dense index as it is."""
    raise NotImplementedError("compiled only: see _overload_with_room")


@overload(_with_room, inline="always")
def _overload_with_room(table, bits, count):
    if table.ndim == 1:
        return lambda table, bits, count: (table, bits)

    return lambda table, bits, count: _rehash_for(table, bits, count)


@nb.njit(cache=True)
def _rehash_for(table, bits, count):
    """A hash table doubled (_rehash) until it has room for count entries: (table, bits).
    Not inlined: a loop inlined into the overload trips numba's SSA check."""
    while 2 * count > table.shape[0]:
        table, bits = _rehash(table, bits)
    return table, bits


@nb.njit(cache=True, inline="always")
def _add(coords, count, x, y, z):
    """Store the coordinates of the vertex _vertex_id just added; returns the new count."""
    coords[count, 0] = x
    coords[count, 1] = y
    coords[count, 2] = z
    return count + 1


@nb.njit(cache=True)
def _number_points(table, bits, stride, box_lo, directory, points, start, coords, count):
    """Number points[start:] (P, 3) in order, each new one as the next id, until the table
    has no room for another: returns (first point not numbered, count).

    This and the two kernels below never reassign the table: their callers grow it between
    calls.  (Reassigned in the loop, even by a no-op, it cost numba's reference counting and
    reloads: 2.4 x the time of a loop that does not.)"""
    for i in range(start, points.shape[0]):
        if not _has_room(table, count + 1):
            return i, count
        x = points[i, 0]
        y = points[i, 1]
        z = points[i, 2]
        _, new = _vertex_id(table, bits, stride, box_lo, directory, x, y, z, count, True)
        if new:
            count = _add(coords, count, x, y, z)
    return points.shape[0], count


@nb.njit(cache=True)
def _number_corners(table, bits, stride, box_lo, directory, anchors, sides, start, corner_ids, coords, count):
    """Number the corners of leaves start.. into corner_ids (L, 8), as _number_points, from
    the six axis parts (_axis_part) of each leaf's two planes along each axis.  The lookups
    are inlined overloads: a compiled helper called per leaf with the arrays made this loop
    1.6-2.6x slower."""
    bricks_at = np.empty((3, 2), dtype=np.int64)
    morton_at = np.empty((3, 2), dtype=np.int64)
    for i in range(start, anchors.shape[0]):
        if not _has_room(table, count + 8):
            return i, count
        for k in range(3):
            for d in range(2):
                bricks_at[k, d], morton_at[k, d] = _axis_part(table, box_lo, stride, k, anchors[i, k] + d * sides[i])
        for c in range(8):
            dx, dy, dz = CUBE_CORNERS[c, 0], CUBE_CORNERS[c, 1], CUBE_CORNERS[c, 2]
            vid, new = _lookup(table, bits, directory, bricks_at[0, dx] + bricks_at[1, dy] + bricks_at[2, dz],
                               morton_at[0, dx] | morton_at[1, dy] | morton_at[2, dz], count, True)
            if new:
                count = _add(coords, count, anchors[i, 0] + sides[i] * dx, anchors[i, 1] + sides[i] * dy,
                             anchors[i, 2] + sides[i] * dz)
            corner_ids[i, c] = vid
    return anchors.shape[0], count


@nb.njit(cache=True, parallel=True)
def _face_centre_ids(table, bits, stride, box_lo, directory, anchors, sides, split_offsets, coarse, split_ids, eager,
                     eager_rule, minimal_rule, again):
    """split_ids[r, 12:18]: the ids of the face centres of leaf coarse[r] that are vertices
    already, -1 for the others; the table is only read, in parallel.  Returns asked (R,)
    uint8: bit p - 12 set where face centre p is not a vertex yet and the leaf's rule (the
    eager rule for leaves marked eager, else the minimal one; the rules read the leaf's edge
    midpoints, _edge_midpoint_ids) asks for it.  again: look up only the entries still -1,
    and ask nothing (after _add_face_centres)."""
    asked = np.zeros(coarse.shape[0], dtype=np.uint8)
    for r in nb.prange(coarse.shape[0]):
        i = coarse[r]
        rule = eager_rule if eager[i] else minimal_rule
        half = sides[i] // 2
        mask = 0
        for p in range(12, 18):
            if again and split_ids[r, p] >= 0:
                continue
            x = anchors[i, 0] + half * split_offsets[p, 0]
            y = anchors[i, 1] + half * split_offsets[p, 1]
            z = anchors[i, 2] + half * split_offsets[p, 2]
            vid, _ = _vertex_id(table, bits, stride, box_lo, directory, x, y, z, -1, False)
            split_ids[r, p] = vid
            if vid >= 0 or again:
                continue
            for g in range(rule.shape[1]):
                group = True
                for e in rule[p - 12, g]:
                    group &= split_ids[r, e] >= 0
                if group:
                    mask |= 1 << (p - 12)
                    break
        asked[r] = mask
    return asked


@nb.njit(cache=True)
def _add_face_centres(table, bits, stride, box_lo, directory, anchors, sides, split_offsets, coarse, split_ids, asked,
                      eager, phase, start, coords, count):
    """Number the asked face centres (_face_centre_ids) of the leaves coarse[start:] that
    phase 0 (leaves marked eager) or 1 (the others) handles, in order, as _number_points:
    each new one as the next id, one the same-size leaf across the face asked for first
    found."""
    for r in range(start, coarse.shape[0]):
        i = coarse[r]
        if asked[r] == 0 or eager[i] != (phase == 0):
            continue
        if not _has_room(table, count + 6):
            return r, count
        half = sides[i] // 2
        for p in range(12, 18):
            if asked[r] & (1 << (p - 12)) == 0:
                continue
            x = anchors[i, 0] + half * split_offsets[p, 0]
            y = anchors[i, 1] + half * split_offsets[p, 1]
            z = anchors[i, 2] + half * split_offsets[p, 2]
            vid, new = _vertex_id(table, bits, stride, box_lo, directory, x, y, z, count, True)
            if new:
                count = _add(coords, count, x, y, z)
            split_ids[r, p] = vid
    return coarse.shape[0], count


@nb.njit(cache=True, parallel=True)
def _edge_midpoint_ids(table, bits, stride, box_lo, directory, anchors, sides, split_offsets, coarse, split_ids):
    """split_ids[r, 0:12]: the ids of the cube-edge midpoints of leaf coarse[r], -1 where not
    a vertex.  A midpoint is a vertex only as a corner of finer leaves (never a face centre:
    in a 2:1 tree those lie at odd multiples of half a side in two coordinates, midpoints in
    one), so the table after the corners has them all and is only read, in parallel."""
    for r in nb.prange(coarse.shape[0]):
        i = coarse[r]
        half = sides[i] // 2
        for p in range(12):
            x = anchors[i, 0] + half * split_offsets[p, 0]
            y = anchors[i, 1] + half * split_offsets[p, 1]
            z = anchors[i, 2] + half * split_offsets[p, 2]
            vid, _ = _vertex_id(table, bits, stride, box_lo, directory, x, y, z, -1, False)
            split_ids[r, p] = vid


@nb.njit(cache=True)
def _number_corner_vertices(table, bits, anchors, sides, prefix, box_lo, stride, directory, extra):
    """The prefix points (P, 3) as ids 0..P-1, then the corners of the leaves in leaf order:
    (table, bits, corner_ids (L, 8) int32, coords with room for extra rows more, count).
    table: an empty vertex table (_lookup): the dense index of the box of bricks from box_lo
    at strides ``stride`` (_axis_part) through directory (_brick_directory), which then holds
    every vertex, or hashed with 2**bits rows, grown as it fills."""
    n = anchors.shape[0]
    corner_ids = np.empty((n, 8), dtype=np.int32)
    # Room for every prefix point and corner (untouched pages cost nothing).
    coords = np.empty((8 * n + prefix.shape[0] + extra, 3), dtype=np.int64)
    # np.int64, not 0: a literal 0 passed on would compile each callee once more (Literal[int](0)).
    count = np.int64(0)
    done = np.int64(0)
    while done < prefix.shape[0]:
        table, bits = _with_room(table, bits, count + 1)
        done, count = _number_points(table, bits, stride, box_lo, directory, prefix, done, coords, count)
    done = np.int64(0)
    while done < n:
        table, bits = _with_room(table, bits, count + 8)
        done, count = _number_corners(table, bits, stride, box_lo, directory, anchors, sides, done, corner_ids,
                                      coords, count)
    return table, bits, corner_ids, coords, count


@nb.njit(cache=True)
def _number_asked_face_centres(table, bits, stride, box_lo, directory, anchors, sides, split_offsets, coarse,
                               split_ids, asked, eager, coords, count):
    """The asked face centres (_face_centre_ids) numbered, first those of the leaves marked
    eager, then of the others, each in leaf order; returns (table, bits, the vertices'
    coordinates (V, 3): a view of coords)."""
    for phase in range(2):
        done = np.int64(0)  # not 0: see _number_corner_vertices
        while done < coarse.shape[0]:
            table, bits = _with_room(table, bits, count + 6)
            done, count = _add_face_centres(table, bits, stride, box_lo, directory, anchors, sides, split_offsets,
                                            coarse, split_ids, asked, eager, phase, done, coords, count)
    return table, bits, coords[:count]


@nb.njit(cache=True)
def _rehash(table, bits):
    """A hash vertex table with twice the rows, holding the same entries: (table, bits)."""
    new_bits = bits + 1
    grown = np.full((np.int64(1) << new_bits, 2), _EMPTY, dtype=np.int64)
    for s in range(table.shape[0]):
        key = table[s, 0]
        if key != _EMPTY:
            t = _probe(grown, key, new_bits)
            grown[t, 0] = key
            grown[t, 1] = table[s, 1]
    return grown, new_bits


@nb.njit(cache=True, inline="always")
def _chain_template(corner_ids, split_row, split_ids, i, c, chains, chain_splits, labels):
    """Fill labels (9,) with the vertex ids of chain c of leaf i (v0..v3, m01, m12, m23, m02,
    m13; -1 where no vertex) and return the chain's split mask."""
    for k in range(4):
        labels[k] = corner_ids[i, chains[c, k]]
    mask = 0
    r = split_row[i]
    for k in range(5):
        labels[4 + k] = -1 if r < 0 else split_ids[r, chain_splits[c, k]]
        if labels[4 + k] >= 0:
            mask |= 1 << k
    return mask


@nb.njit(cache=True, inline="always")
def _template_tet_kept(labels, tmpl, marked):
    for k in range(4):
        if marked[labels[tmpl[k]]]:
            return True
    return False


@nb.njit(cache=True, inline="always")
def _fat_tet_kept(corner_ids, i, chains, c, marked, ends_marked):
    """Whether fat tet c of leaf i (chain c's corners) has a marked vertex; ends_marked:
    whether its corner 0 or 7 is marked (every chain's ends)."""
    return ends_marked or marked[corner_ids[i, chains[c, 1]]] or marked[corner_ids[i, chains[c, 2]]]


@nb.njit(cache=True, parallel=True)
def _leaf_tets(corner_ids, split_row, split_ids, marked, chains, chain_odd, chain_splits, tmpl_tets, tmpl_counts):
    """Tets of every leaf, chain by chain from the transition templates, keeping those with a
    marked vertex (count, prefix sum, fill); -1 rows mark a mask without template.  A leaf
    without split points gives its six fat tets (template 0 of each chain) with a marked
    vertex straight from its corners, also where its corners 0 and 7 are both unmarked (a
    band's outer cells, 9 k of bunny's 31 k leaves at diag/80, took the templates' path:
    this kernel 2.3 -> 1.6 ms there)."""
    n = corner_ids.shape[0]
    counts = np.zeros(n + 1, dtype=np.int64)
    bad = np.zeros(n, dtype=np.bool_)
    for i in nb.prange(n):
        if split_row[i] < 0:
            ends_marked = marked[corner_ids[i, 0]] or marked[corner_ids[i, 7]]
            k = 0
            for c in range(6):  # the fat tets kept, as the fill below
                k += _fat_tet_kept(corner_ids, i, chains, c, marked, ends_marked)
            counts[i + 1] = k
            continue
        labels = np.empty(9, dtype=np.int64)
        k = 0
        for c in range(6):
            mask = _chain_template(corner_ids, split_row, split_ids, i, c, chains, chain_splits, labels)
            if tmpl_counts[mask] < 0:
                bad[i] = True
                continue
            for t in range(tmpl_counts[mask]):
                if _template_tet_kept(labels, tmpl_tets[mask, t], marked):
                    k += 1
        counts[i + 1] = k
    for i in range(n):  # the offsets, in place: numpy's cumsum would write another (L + 1,) array
        counts[i + 1] += counts[i]
    offsets = counts
    tets = np.empty((offsets[n], 4), dtype=np.int32)
    for i in nb.prange(n):
        k = offsets[i]
        if split_row[i] < 0:
            ends_marked = marked[corner_ids[i, 0]] or marked[corner_ids[i, 7]]
            for c in range(6):  # the fat tets kept (template 0 of each chain), as below
                if _fat_tet_kept(corner_ids, i, chains, c, marked, ends_marked):
                    tets[k, 0] = corner_ids[i, chains[c, 0]]
                    tets[k, 1] = corner_ids[i, chains[c, 2 if chain_odd[c] else 1]]
                    tets[k, 2] = corner_ids[i, chains[c, 1 if chain_odd[c] else 2]]
                    tets[k, 3] = corner_ids[i, chains[c, 3]]
                    k += 1
            continue
        labels = np.empty(9, dtype=np.int64)
        for c in range(6):
            mask = _chain_template(corner_ids, split_row, split_ids, i, c, chains, chain_splits, labels)
            if tmpl_counts[mask] < 0:
                continue
            for t in range(tmpl_counts[mask]):
                tmpl = tmpl_tets[mask, t]
                if _template_tet_kept(labels, tmpl, marked):
                    tets[k, 0] = labels[tmpl[0]]
                    tets[k, 1] = labels[tmpl[2] if chain_odd[c] else tmpl[1]]
                    tets[k, 2] = labels[tmpl[1] if chain_odd[c] else tmpl[2]]
                    tets[k, 3] = labels[tmpl[3]]
                    k += 1
    return tets, bad


@dataclass(frozen=True)
class LeafVertices:
    """Globally numbered vertices of the leaves of a 2:1-balanced octree.

    corner_ids: (L, 8) int32, corner c of leaf i at anchor + side * CUBE_CORNERS[c].
    split_row: (L,) int64, row of leaf i in split_ids, -1 for leaves of side 1.
    split_ids: (C, 18) int32, vertex id of each split point (transitions.SPLIT_POINT_OFFSETS),
    -1 where the point is not a vertex.
    coords: (V, 3) int64 lattice coordinates of the vertices (finest-level units).
    first_centre: the vertices from this id up are face centres that are no leaf's corner
    (numbered last; V if there are none): stuffing's quad rule on template faces puts them
    last (stuffing._quad_first_diagonal).
    """

    corner_ids: np.ndarray
    split_row: np.ndarray
    split_ids: np.ndarray
    coords: np.ndarray
    first_centre: int


@nb.njit(cache=True)
def _bounding_box(anchors, sides, prefix):
    """(lo (3,), hi (3,)) over the leaves' closures and the prefix points, in one pass (numpy's
    axis-0 min and max over (N, 3) cost 10x more)."""
    lo = anchors[0].copy()
    hi = anchors[0] + sides[0]
    for i in range(anchors.shape[0]):
        for k in range(3):
            lo[k] = min(lo[k], anchors[i, k])
            hi[k] = max(hi[k], anchors[i, k] + sides[i])
    for i in range(prefix.shape[0]):
        for k in range(3):
            lo[k] = min(lo[k], prefix[i, k])
            hi[k] = max(hi[k], prefix[i, k])
    return lo, hi


def number_vertices(anchors: np.ndarray, sides: np.ndarray, prefix: np.ndarray | None = None, *,
                    eager: bool | np.ndarray = True) -> LeafVertices:
    """Global vertex ids of leaf corners and of the transition points of coarse leaves.

    anchors: (L, 3) int64 leaf minimum corners, lattice units; sides: (L,) int64 leaf sides
    (powers of two).  The leaves must form a 2:1-balanced linear octree (or part of one),
    sorted by Morton key: a cube-edge midpoint of a leaf is a vertex iff it is a corner of
    another leaf.  Face centres (paroct.transitions): a face gets its centre if the minimal
    rule asks, or if the eager rule asks and a leaf sharing the face is marked in eager (bool
    for all leaves, or (L,) bool).  So the templates of every eager leaf are eager templates,
    the ones stuffing may cut (its quad rule never cycles on them), and the other leaves keep
    the minimal rule's fewer tets (down to 30 degrees).
    prefix: (P, 3) distinct leaf corners numbered first, as 0..P-1, so that arrays over an
    earlier numbering of them stay valid.
    """
    anchors = np.ascontiguousarray(anchors, dtype=np.int64)
    sides = np.ascontiguousarray(sides, dtype=np.int64)
    if anchors.ndim != 2 or anchors.shape[1] != 3 or sides.shape != (anchors.shape[0],):
        raise ValueError(f"anchors.shape = {anchors.shape}, sides.shape = {sides.shape}; expected (L, 3) and (L,)")
    prefix = np.zeros((0, 3), dtype=np.int64) if prefix is None else np.ascontiguousarray(prefix, dtype=np.int64)
    box_lo = np.zeros(3, dtype=np.int64)
    bricks = np.zeros(3, dtype=np.int64)
    budget = DENSE_SLOTS_PER_LEAF * anchors.shape[0]
    table = None
    if anchors.shape[0]:
        box_lo, box_hi = _bounding_box(anchors, sides, prefix)
        bricks = (box_hi - box_lo + _BRICK_SIDE) // _BRICK_SIDE
        n_bricks = np.prod(bricks.astype(np.float64))
        if _BRICK_SLOTS * n_bricks <= budget:
            table, bits, directory = np.zeros(_BRICK_SLOTS * int(n_bricks), dtype=np.int32), 0, None
        elif n_bricks <= budget:
            box_lo &= ~np.int64(_BRICK_SIDE - 1)  # bricks aligned: coarse leaves' points share few slots
            bricks = (box_hi - box_lo + _BRICK_SIDE) // _BRICK_SIDE
            # A box mostly empty, as around a band refined locally: only the bricks in use.
            directory, slots = _brick_directory(anchors, sides, prefix, box_lo, bricks)
            if 2 * directory.shape[0] + slots <= budget:  # an entry takes two slots' bytes
                table, bits = np.zeros(slots, dtype=np.int32), 0
    if table is None:  # hashing reads no directory (not even one that did not fit)
        bits = max(4, int(4 * anchors.shape[0] + prefix.shape[0] + 16 - 1).bit_length())
        table, directory = np.full((1 << bits, 2), _EMPTY, dtype=np.int64), np.zeros(0, dtype=np.int64)
    # A copy: broadcast_to's view is read-only, and numba compiles the numbering kernels again (4-5 s)
    # for a read-only array.
    eager = np.array(np.broadcast_to(np.asarray(eager, dtype=np.bool_), sides.shape))
    coarse = np.flatnonzero(sides >= 2)
    split_row = np.full(sides.shape[0], -1, dtype=np.int64)
    split_row[coarse] = np.arange(coarse.shape[0])
    stride = np.array([1, bricks[0], bricks[0] * bricks[1]], dtype=np.int64)
    table, bits, corner_ids, coords, count = _number_corner_vertices(table, bits, anchors, sides, prefix, box_lo,
                                                                     stride, directory, 6 * coarse.shape[0])
    first_centre = int(count)  # edge midpoints are corners of finer leaves: every corner is numbered
    split_ids = np.empty((coarse.shape[0], 18), dtype=np.int32)
    # Serial and parallel kernels called in turn from here, not one from another: a parallel
    # kernel called from a cached one segfaults when loaded from the cache (numba issue #8578).
    _edge_midpoint_ids(table, bits, stride, box_lo, directory, anchors, sides, SPLIT_POINT_OFFSETS, coarse, split_ids)
    # Face centres: a face gets its centre if the rule of a leaf sharing it asks.  The rules
    # read only the face's edges, the same for both leaves, and minimal asks imply eager asks,
    # so a leaf whose rule does not ask finds a centre only from an eager leaf, numbered in the
    # first phase.  So looking every centre up in parallel, numbering only the new asked ones
    # in order, then looking the rest up again gives the ids of a leaf-by-leaf numbering.
    rules = FACE_CENTRE_RULES["eager"], FACE_CENTRE_RULES["minimal"]
    asked = _face_centre_ids(table, bits, stride, box_lo, directory, anchors, sides, SPLIT_POINT_OFFSETS, coarse,
                             split_ids, eager, *rules, False)
    table, bits, coords = _number_asked_face_centres(table, bits, stride, box_lo, directory, anchors, sides,
                                                     SPLIT_POINT_OFFSETS, coarse, split_ids, asked, eager, coords,
                                                     count)
    _face_centre_ids(table, bits, stride, box_lo, directory, anchors, sides, SPLIT_POINT_OFFSETS, coarse, split_ids,
                     eager, *rules, True)
    return LeafVertices(corner_ids, split_row, split_ids, coords, first_centre)


def vertex_spacing(vertices: LeafVertices, sides: np.ndarray) -> np.ndarray:
    """Side (V,) int64 of the finest leaf whose closure holds each vertex (sides: (L,) of the
    leaves numbered by number_vertices): the smallest side of the leaves having it as a corner;
    for a face centre that is no leaf's corner, the side of the leaves sharing that face.
    Stuffing caps the warps of vertices shared with finer leaves by it."""
    return _vertex_spacing(vertices.corner_ids, vertices.split_row, vertices.split_ids,
                           np.ascontiguousarray(sides, dtype=np.int64), vertices.coords.shape[0])


@nb.njit(cache=True)
def _vertex_spacing(corner_ids, split_row, split_ids, sides, n_vertices):
    unset = np.iinfo(np.int64).max
    spacing = np.full(n_vertices, unset, dtype=np.int64)
    for i in range(corner_ids.shape[0]):
        for c in range(8):
            v = corner_ids[i, c]
            spacing[v] = min(spacing[v], sides[i])
    for i in range(corner_ids.shape[0]):
        r = split_row[i]
        if r >= 0:
            for p in range(split_ids.shape[1]):
                v = split_ids[r, p]
                if v >= 0 and spacing[v] == unset:
                    spacing[v] = sides[i]
    return spacing


def graded_tets(vertices: LeafVertices, marked: np.ndarray | None = None) -> np.ndarray:
    """The positively oriented tets (int32, 4 columns) of the leaves, in leaf order.

    Leaves without split points give their six Freudenthal (fat) tets; the others the
    transition templates of their chains.  With ``marked`` (V,) bool, only tets with a
    marked vertex are kept.
    """
    if marked is None:
        marked = np.ones(vertices.coords.shape[0], dtype=np.bool_)
    tets, bad = _leaf_tets(vertices.corner_ids, vertices.split_row, vertices.split_ids,
                           np.ascontiguousarray(marked, dtype=np.bool_), CHAINS, CHAIN_IS_ODD, CHAIN_SPLITS,
                           TEMPLATE_TETS, TEMPLATE_COUNTS)
    if bad.any():
        raise ValueError(f"{int(bad.sum())} leaves have a split pattern without template: the octree is not 2:1 balanced")
    return tets


def leaf_tets(anchors: np.ndarray, sides: np.ndarray, *, eager: bool | np.ndarray = True) -> tuple[np.ndarray, np.ndarray]:
    """All tets of the leaves of a 2:1-balanced octree (six fat tets per leaf without finer
    neighbours, transition templates otherwise).

    anchors: (L, 3) int64 leaf minimum corners, lattice units; sides: (L,) int64 leaf sides.
    Returns (vertex_coords (V, 3) int64 lattice units, tets (M, 4) int32).  For leaves of one
    size, tets 6i..6i+5 belong to leaf i.  eager: the leaves whose faces follow the eager
    face-centre rule (number_vertices).
    """
    vertices = number_vertices(anchors, sides, eager=eager)
    return vertices.coords, graded_tets(vertices)
