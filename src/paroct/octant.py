"""Single-octant bit functions (the layer of p4est's p8est_bits.h).

An octant is an anchor (its minimum corner, integer coordinates in [0, 2**MAX_LEVEL))
and a level; its side is ``2**(MAX_LEVEL - level)``.  The root cube is level 0.
Octants are named by the Morton key of their anchor (bits interleaved x, y, z from
the lowest bit up); sorting by (key, level) puts every octant after its ancestors
and before its descendants, and a linear octree is a sorted array of such keys.

Coordinates here are octree coordinates; a frame with ``levels`` finest levels
turns them into lattice units by ``>> (MAX_LEVEL - levels)``.
"""

from __future__ import annotations

import numba as nb
import numpy as np

#: Deepest level; anchors fit in MAX_LEVEL bits, Morton keys in 3 * MAX_LEVEL bits.
MAX_LEVEL = 19
#: Largest coordinate a Morton key can hold (vertices of the root cube reach 2**MAX_LEVEL).
KEY_BITS_PER_AXIS = 21


@nb.njit(cache=True, inline="always")
def _spread_bits(v):
    """Insert two zero bits above each of the low 21 bits of v."""
    v = v & 0x1FFFFF
    v = (v | (v << 32)) & 0x1F00000000FFFF
    v = (v | (v << 16)) & 0x1F0000FF0000FF
    v = (v | (v << 8)) & 0x100F00F00F00F00F
    v = (v | (v << 4)) & 0x10C30C30C30C30C3
    v = (v | (v << 2)) & 0x1249249249249249
    return v


@nb.njit(cache=True, inline="always")
def _compact_bits(v):
    """Inverse of _spread_bits: gather every third bit of v."""
    v = v & 0x1249249249249249
    v = (v ^ (v >> 2)) & 0x10C30C30C30C30C3
    v = (v ^ (v >> 4)) & 0x100F00F00F00F00F
    v = (v ^ (v >> 8)) & 0x1F0000FF0000FF
    v = (v ^ (v >> 16)) & 0x1F00000000FFFF
    v = (v ^ (v >> 32)) & 0x1FFFFF
    return v


@nb.njit(cache=True, inline="always")
def morton_key(x, y, z):
    """Morton key of integer coordinates 0 <= x, y, z < 2**21: bit i of x goes to bit 3i."""
    return _spread_bits(np.int64(x)) | (_spread_bits(np.int64(y)) << 1) | (_spread_bits(np.int64(z)) << 2)


@nb.njit(cache=True, inline="always")
def morton_coords(key):
    """Coordinates (x, y, z) of a Morton key; inverse of morton_key."""
    return _compact_bits(key), _compact_bits(key >> 1), _compact_bits(key >> 2)


@nb.njit(cache=True, inline="always")
def octant_len(level):
    """Side of an octant of ``level`` in octree coordinates: 2**(MAX_LEVEL - level)."""
    return np.int64(1) << (MAX_LEVEL - level)


@nb.njit(cache=True, inline="always")
def octant_last_key(key, level):
    """Key of the last finest-level descendant of the octant: all its key bits below the level set."""
    return key | ((np.int64(1) << (3 * (MAX_LEVEL - level))) - 1)


@nb.njit(cache=True, inline="always")
def octant_parent_key(key, level):
    """Anchor key of the parent of an octant at ``level`` >= 1 (the parent is at level - 1)."""
    return key & ~((np.int64(1) << (3 * (MAX_LEVEL - level + 1))) - 1)


@nb.njit(cache=True, inline="always")
def octant_child_id(key, level):
    """Which child (0..7, bits x | y << 1 | z << 2) of its parent an octant at ``level`` >= 1 is."""
    return (key >> (3 * (MAX_LEVEL - level))) & 7


@nb.njit(cache=True, inline="always")
def octant_is_ancestor(key_a, level_a, key_b, level_b):
    """True iff octant a is a strict ancestor of octant b: a is coarser and contains b."""
    if level_a >= level_b:
        return False
    shift = 3 * (MAX_LEVEL - level_a)
    return (key_a >> shift) == (key_b >> shift)


@nb.njit(cache=True, inline="always")
def octant_overlaps(key_a, level_a, key_b, level_b):
    """True iff octants a and b share interior: one equals or contains the other."""
    shift = 3 * (MAX_LEVEL - min(level_a, level_b))
    return (key_a >> shift) == (key_b >> shift)


@nb.njit(cache=True)
def morton_keys(coords):
    """Morton keys (N,) int64 of integer coordinates (N, 3)."""
    n = coords.shape[0]
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        out[i] = morton_key(coords[i, 0], coords[i, 1], coords[i, 2])
    return out


@nb.njit(cache=True)
def morton_decode(keys):
    """Integer coordinates (N, 3) int64 of Morton keys (N,); inverse of morton_keys."""
    n = keys.shape[0]
    out = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        x, y, z = morton_coords(keys[i])
        out[i, 0] = x
        out[i, 1] = y
        out[i, 2] = z
    return out


@nb.njit(cache=True)
def is_ascending(values):
    """True iff values (N,) never decrease: values[i] <= values[i + 1] for every i."""
    for i in range(values.shape[0] - 1):
        if values[i + 1] < values[i]:
            return False
    return True


#: Arrays of at least this many int64 values are sorted by radix_sorted, shorter by np.sort.
RADIX_MIN = 2048
#: Bits a pass of radix_sorted sorts by: 2048 counters stay in the L1 cache.
RADIX_BITS = 11


@nb.njit(cache=True)
def radix_sorted(values):
    """values (N,) int64 in ascending order (a new array): a least-significant-digit radix
    sort, RADIX_BITS a pass, over only the bits in which the values differ from the smallest
    (as uint64, so any int64 range fits); the bits below all of those are skipped, so Morton
    keys of one level (their low 3 (MAX_LEVEL - level) bits zero) take a pass per 11 bits of
    the levels they span.  np.sort took 40-53 ns a key on the 0.05-0.4 M surface cell keys
    of fea_part at diag/80 (this VM's numpy sorts int64 without SIMD); this, 15-25."""
    n = values.shape[0]
    src = np.empty(n, dtype=np.uint64)
    if n == 0:
        return values.copy()
    low = values[0]
    for i in range(n):
        low = min(low, values[i])
    base = np.uint64(low)
    spread = np.uint64(0)
    for i in range(n):
        src[i] = np.uint64(values[i]) - base
        spread |= src[i]
    first = 0  # the lowest bit in which any value differs from the smallest
    while first < 64 and (spread >> np.uint64(first)) & np.uint64(1) == 0:
        first += 1
    dst = np.empty(n, dtype=np.uint64)
    count = np.empty(1 << RADIX_BITS, dtype=np.int64)
    mask = np.uint64((1 << RADIX_BITS) - 1)
    shift = first
    while shift < 64 and (spread >> np.uint64(shift)) != 0:
        count[:] = 0
        for i in range(n):
            count[np.int64((src[i] >> np.uint64(shift)) & mask)] += 1
        total = 0
        for b in range(1 << RADIX_BITS):
            c = count[b]
            count[b] = total
            total += c
        for i in range(n):
            b = np.int64((src[i] >> np.uint64(shift)) & mask)
            dst[count[b]] = src[i]
            count[b] += 1
        src, dst = dst, src
        shift += RADIX_BITS
    out = np.empty(n, dtype=np.int64)
    for i in range(n):
        out[i] = np.int64(src[i] + base)
    return out


def sort_values(values: np.ndarray) -> np.ndarray:
    """values (N,) integers in ascending order, a new array: radix_sorted for int64 of at
    least RADIX_MIN values, else np.sort."""
    return radix_sorted(values) if values.dtype == np.int64 and values.shape[0] >= RADIX_MIN else np.sort(values)


def sorted_unique(values: np.ndarray) -> np.ndarray:
    """The distinct values of a 1-D integer array, ascending.

    Sort and compare neighbours: for Morton keys this is 10-50x faster than np.unique,
    whose hash-based path (numpy >= 2.3) hashes such keys poorly.  Input already in order
    (parents of sorted keys, as balance has them) is not sorted again: np.sort took 13 ns a
    key on it (tray_bottom diag/40: 270 k band cells' parents, 3.5 ms), the check takes 1.
    """
    s = np.asarray(values).ravel()
    if not is_ascending(s):
        s = sort_values(s)
    if s.size == 0:
        return s
    keep = np.empty(s.shape[0], dtype=bool)
    keep[0] = True
    np.not_equal(s[1:], s[:-1], out=keep[1:])
    return np.compress(keep, s)  # 1.5x faster than s[keep]


def ancestor_keys(keys: np.ndarray, level: int) -> np.ndarray:
    """Anchor keys (N,) of the ancestors at ``level`` of octants of that level or finer
    (keys (N,)): the key bits below the level cleared.  An octant of ``level`` is its own."""
    return np.asarray(keys) & ~((np.int64(1) << (3 * (MAX_LEVEL - level))) - 1)


@nb.njit(cache=True, inline="always")
def lower_bound(keys, key, lo, hi):
    """First index in keys[lo:hi] (sorted) whose key is >= key, or hi."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if keys[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True, inline="always")
def lower_bound_near(keys, key, hint):
    """lower_bound(keys, key, 0, len(keys)) by galloping from index hint (0 <= hint <= len):
    O(log d) for an answer d places away, and the probes stay near the hint in memory."""
    n = keys.shape[0]
    if hint < n and keys[hint] < key:
        lo = hint + 1  # keys[lo - 1] < key
        step = 1
        while lo + step - 1 < n and keys[lo + step - 1] < key:
            lo += step
            step *= 2
        return lower_bound(keys, key, lo, min(lo + step - 1, n))
    hi = hint  # keys[hi] >= key, or hi == n
    step = 1
    while hi - step >= 0 and keys[hi - step] >= key:
        hi -= step
        step *= 2
    return lower_bound(keys, key, max(hi - step, 0), hi)


def sorted_lookup(sorted_keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where each value sits in sorted_keys (1-D int64, ascending, distinct): (index (N,) into
    sorted_keys, valid where found; found (N,) bool).  Searches gallop from the previous
    value's place (values come mostly sorted: Morton keys of leaves), not np.isin's sort of
    both arrays nor a binary search over all keys each."""
    values = np.ascontiguousarray(values, dtype=np.int64)
    at = np.zeros(values.shape[0], dtype=np.int64)
    found = np.zeros(values.shape[0], dtype=bool)
    if sorted_keys.shape[0]:
        _lookup_near(np.ascontiguousarray(sorted_keys, dtype=np.int64), values, at, found)
    return at, found


@nb.njit(cache=True, parallel=True)
def _lookup_near(keys, values, at, found):
    m = values.shape[0]
    n_chunks = min(m // 1024 + 1, 64)
    for chunk in nb.prange(n_chunks):
        hint = 0
        for i in range(chunk * m // n_chunks, (chunk + 1) * m // n_chunks):
            hint = lower_bound_near(keys, values[i], hint)
            at[i] = min(hint, keys.shape[0] - 1)
            found[i] = keys[at[i]] == values[i]


def octants_in_cells(keys: np.ndarray, cells: np.ndarray, level: int) -> np.ndarray:
    """Mask (N,) of the octants (keys (N,)) whose anchor lies in one of the cells of ``level``
    (sorted distinct keys): for an octant of that level or finer, its ancestor there is one
    of them."""
    return sorted_lookup(cells, ancestor_keys(keys, level))[1]
