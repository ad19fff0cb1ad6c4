"""Exact crossings of lattice rows with the surface: classification and cut points.

The surface is snapped once to an integer grid of ``2**snap_bits`` units per lattice
unit (coordinates below 2**COORD_BITS), and everything after that is exact on the
snapped surface:

* A row is a lattice line parallel to one of the seven edge directions d.  An integer
  change of basis T (``frame.row_basis``) maps d to e_1, so the row is {(t, p2, p3)}
  with integer p2, p3 and every direction runs through the same kernel.
* A row hits a triangle iff the row point lies inside the triangle's projection on
  (p2, p3): three exact integer orientation tests, ties broken by simulation of
  simplicity (the row is moved to (p2 + eps, p3 + eps**2)), which is watertight: a row
  through a shared edge or vertex hits exactly one of the triangles around it, counted
  once, and triangles seen edge-on are never hit.
* The crossing position t along the row is a rational; its lattice cell
  j = floor(t) is decided exactly (128-bit sign of a sum of products) when the float
  estimate is within a unit of a lattice point.

A lattice point q on a row is inside iff the winding number, the sum over crossings in
cells j < q of +1 (entering, triangle normal against d) or -1 (leaving), is positive.
That is the winding number of the point q - eps d: points exactly on the surface get a
consistent side.  The crossings in cell j are the cut points of the lattice edge (j, j + 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from .frame import EDGE_DIRECTIONS, FatFrame, row_basis
from .octant import MAX_LEVEL, lower_bound, lower_bound_near, morton_key
from .octree import TRIANGLE_CHUNKS, FaceBuckets, written_slots

#: Snapped coordinates, and their images under the row bases, stay below 2**(COORD_BITS + 1)
#: in magnitude; orientations then fit in int64 and positions in the 128-bit helper.
COORD_BITS = 28
#: Row and cell indices are packed into one int64 key with this many bits each.
_KEY_BITS = 21
_KEY_OFFSET = np.int64(1) << (_KEY_BITS - 1)


def snap_bits(frame: FatFrame) -> int:
    """Sub-lattice resolution: a lattice unit is 2**snap_bits snapped units."""
    return COORD_BITS - frame.levels


def snap_surface(frame: FatFrame, vertices: np.ndarray) -> np.ndarray:
    """Surface vertices (V, 3) in lattice coordinates, rounded to integers of 2**-snap_bits units."""
    u = frame.to_lattice(vertices) * float(1 << snap_bits(frame))
    limit = float(1 << COORD_BITS)
    if not (np.all(u >= 0) and np.all(u < limit)):
        raise ValueError("surface vertex outside the frame's root cube")
    return np.rint(u).astype(np.int64)


@nb.njit(cache=True, inline="always")
def _orient2d(ax, ay, bx, by, px, py):
    """Sign (+1/-1, never 0) of orient2d(a, b, p + (eps, eps**2)); 0 only if a == b."""
    det = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    if det > 0:
        return 1, det
    if det < 0:
        return -1, det
    if by != ay:
        return (1 if ay > by else -1), det
    if bx != ax:
        return (1 if bx > ax else -1), det
    return 0, det


@nb.njit(cache=True, inline="always")
def _mul_split(w, d):
    """w * d as hi * 2**32 + lo with 0 <= lo < 2**32, for |w| < 2**62 and |d| < 2**30."""
    w_hi = w >> 32
    w_lo = w & 0xFFFFFFFF
    low = w_lo * d
    hi = w_hi * d + (low >> 32)
    return hi, low & 0xFFFFFFFF


@nb.njit(cache=True, inline="always")
def sign_sum_of_products(w0, d0, w1, d1, w2, d2):
    """Exact sign of w0*d0 + w1*d1 + w2*d2 for |w| < 2**60 and |d| < 2**30 (int64 inputs)."""
    h0, l0 = _mul_split(w0, d0)
    h1, l1 = _mul_split(w1, d1)
    h2, l2 = _mul_split(w2, d2)
    lo = l0 + l1 + l2
    hi = h0 + h1 + h2 + (lo >> 32)
    lo = lo & 0xFFFFFFFF
    if hi > 0:
        return 1
    if hi < 0:
        return -1
    return 1 if lo > 0 else 0


@nb.njit(cache=True, inline="always")
def _row_range(lo, hi, unit_bits):
    """Integer rows r with lo <= r * 2**unit_bits <= hi."""
    unit = np.int64(1) << unit_bits
    first = -((-lo) >> unit_bits)  # ceil division for a power of two
    last = hi >> unit_bits
    return first, last, unit


@nb.njit(cache=True, inline="always")
def _hit(tri, r2, r3, unit):
    """Crossing of row (r2, r3) with a triangle (3, 3) int64 in row coordinates.

    Returns (hit, orientation sign of the projection, position numerator over D as float,
    weights w_a, w_b, w_c, D) where the position t = (w_a a_0 + w_b b_0 + w_c c_0) / D.
    """
    px = r2 * unit
    py = r3 * unit
    sa, wa = _orient2d(tri[1, 1], tri[1, 2], tri[2, 1], tri[2, 2], px, py)
    sb, wb = _orient2d(tri[2, 1], tri[2, 2], tri[0, 1], tri[0, 2], px, py)
    sc, wc = _orient2d(tri[0, 1], tri[0, 2], tri[1, 1], tri[1, 2], px, py)
    if sa == 0 or sb == 0 or sc == 0 or sa != sb or sb != sc:
        return False, 0, 0.0, wa, wb, wc, 0
    dd = wa + wb + wc
    t = (float(wa) * float(tri[0, 0]) + float(wb) * float(tri[1, 0]) + float(wc) * float(tri[2, 0])) / float(dd)
    return True, sa, t, wa, wb, wc, dd


@nb.njit(cache=True, inline="always")
def _cell_of(tri, t, wa, wb, wc, dd, unit_bits):
    """Exact lattice cell j = floor(t / unit) of a crossing and its fraction t / unit - j in [0, 1)."""
    unit = np.int64(1) << unit_bits
    scaled = t / float(unit)
    j = np.int64(np.floor(scaled))
    rem = t - float(j) * float(unit)
    if rem < 2.0 or rem > float(unit) - 2.0:
        m = np.int64(np.floor(scaled + 0.5))
        mu = m * unit
        s = sign_sum_of_products(wa, tri[0, 0] - mu, wb, tri[1, 0] - mu, wc, tri[2, 0] - mu)
        if dd < 0:
            s = -s
        j = m if s >= 0 else m - 1
    frac = scaled - float(j)
    if frac < 0.0:
        frac = 0.0
    if frac >= 1.0:
        frac = np.nextafter(1.0, 0.0)
    return j, frac


@nb.njit(cache=True, inline="always")
def _column_span(tri, py):
    """(lowest, highest) coordinate 2, as floats, of the triangle's projection (coordinates 1
    and 2) on the line coordinate 1 = py; (inf, -inf) if it misses the line."""
    lo = np.inf
    hi = -np.inf
    for i in range(3):
        j = (i + 1) % 3
        y1, z1, y2, z2 = tri[i, 1], tri[i, 2], tri[j, 1], tri[j, 2]
        if min(y1, y2) <= py <= max(y1, y2):
            if y1 == y2:
                lo = min(lo, float(min(z1, z2)))
                hi = max(hi, float(max(z1, z2)))
            else:
                z = float(z1) + float(z2 - z1) * (float(py - y1) / float(y2 - y1))
                lo = min(lo, z)
                hi = max(hi, z)
    return lo, hi


@nb.njit(cache=True, inline="always")
def _pack(r2, r3, j):
    return ((r2 + _KEY_OFFSET) << (2 * _KEY_BITS)) | ((r3 + _KEY_OFFSET) << _KEY_BITS) | (j + _KEY_OFFSET)


@nb.njit(cache=True, inline="always")
def _load_triangle(coords, triangles, f, tri, unit_bits):
    """Copy triangle f (row coordinates) into tri (3, 3); returns the rows (r2a..r2b, r3a..r3b)
    its projection's box spans and the row spacing."""
    for k in range(3):
        for i in range(3):
            tri[k, i] = coords[triangles[f, k], i]
    r2a, r2b, unit = _row_range(min(tri[0, 1], tri[1, 1], tri[2, 1]), max(tri[0, 1], tri[1, 1], tri[2, 1]), unit_bits)
    r3a, r3b, unit = _row_range(min(tri[0, 2], tri[1, 2], tri[2, 2]), max(tri[0, 2], tri[1, 2], tri[2, 2]), unit_bits)
    return r2a, r2b, r3a, r3b, unit


@nb.njit(cache=True, inline="always")
def _column_rows(tri, r2, unit, r3a, r3b):
    """The rows r3 (first..last, empty if last < first) of column r2 whose points lie within one
    snapped unit of the projection's span there; the exact test decides each.  The float span
    is off by under 1e-6 units (coordinates below 2**30, three roundings), and a row the exact
    test hits lies in the closed span (the simulated perturbation is infinitesimal), so the
    unit of margin loses no hit.  (A row of margin on each side tested 20 rows a hit on CAD
    parts with long slanted triangles.)"""
    z_lo, z_hi = _column_span(tri, r2 * unit)
    if z_lo > z_hi:
        return np.int64(1), np.int64(0)
    return max(r3a, np.int64(np.ceil((z_lo - 1.0) / unit))), min(r3b, np.int64(np.floor((z_hi + 1.0) / unit)))


#: Rows in a triangle's box up to which the box is _row_bounds' bound on its hits.
SMALL_BOX_ROWS = 4


@nb.njit(cache=True, parallel=True)
def _row_bounds(coords, triangles, unit_bits, bounds):
    """bounds[f] = the rows _row_hits tests for triangle f (vertex ids (F, 3) into coords
    (V, 3), row coordinates), a cheap bound on its hits: the rows in its projection's box if
    they are few (the usual case on fine tessellations, mostly none), else those of each
    column within the projection's span (_column_rows).  The box comes from six coordinates
    read straight into registers: through _load_triangle's (3, 3) copy this pass took 1.35x
    longer on armadillo, whose 86 k triangles mostly hold no row."""
    n = triangles.shape[0]
    n_chunks = min(n, TRIANGLE_CHUNKS)
    for chunk in nb.prange(n_chunks):
        tri = np.empty((3, 3), dtype=np.int64)
        for f in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            a, b, c = triangles[f, 0], triangles[f, 1], triangles[f, 2]
            r2a, r2b, _ = _row_range(min(coords[a, 1], coords[b, 1], coords[c, 1]),
                                     max(coords[a, 1], coords[b, 1], coords[c, 1]), unit_bits)
            r3a, r3b, _ = _row_range(min(coords[a, 2], coords[b, 2], coords[c, 2]),
                                     max(coords[a, 2], coords[b, 2], coords[c, 2]), unit_bits)
            box = max(r2b - r2a + 1, 0) * max(r3b - r3a + 1, 0)
            if box <= SMALL_BOX_ROWS:
                bounds[f] = box
                continue
            _, _, _, _, unit = _load_triangle(coords, triangles, f, tri, unit_bits)
            rows = 0
            for r2 in range(r2a, r2b + 1):
                first, last = _column_rows(tri, r2, unit, r3a, r3b)
                rows += max(last - first + 1, 0)
            bounds[f] = rows


@nb.njit(cache=True, parallel=True)
def _row_hits(coords, triangles, unit_bits, offsets, keys, fracs, signs, faces, counts):
    """Crossings of every triangle (vertex ids (F, 3) into coords (V, 3), row coordinates)
    with the rows its projection covers: written from offsets[f] on (offsets: the prefix
    sums of _row_bounds, so each thread owns its triangles' slots), counts[f] = their number.
    """
    n = triangles.shape[0]
    n_chunks = min(n, TRIANGLE_CHUNKS)
    for chunk in nb.prange(n_chunks):
        tri = np.empty((3, 3), dtype=np.int64)
        for f in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            r2a, r2b, r3a, r3b, unit = _load_triangle(coords, triangles, f, tri, unit_bits)
            k = offsets[f]
            for r2 in range(r2a, r2b + 1):
                first, last = _column_rows(tri, r2, unit, r3a, r3b)
                for r3 in range(first, last + 1):
                    hit, s, t, wa, wb, wc, dd = _hit(tri, r2, r3, unit)
                    if not hit:
                        continue
                    j, frac = _cell_of(tri, t, wa, wb, wc, dd, unit_bits)
                    keys[k] = _pack(r2, r3, j)
                    fracs[k] = frac
                    # Projection orientation +1 means the normal points along +d: the row leaves the solid.
                    signs[k] = -s
                    faces[k] = f
                    k += 1
            counts[f] = k - offsets[f]


@nb.njit(cache=True)
def in_row_coordinates(points, basis):
    """basis @ p for every point (N, 3) int64 (numpy's integer matmul has no fast path: it
    cost armadillo 0.75 ms a call, 26 calls a mesh)."""
    out = np.empty_like(points)
    for i in range(points.shape[0]):
        for r in range(3):
            out[i, r] = basis[r, 0] * points[i, 0] + basis[r, 1] * points[i, 1] + basis[r, 2] * points[i, 2]
    return out


@dataclass(frozen=True)
class RowCrossings:
    """Crossings of the rows of one edge direction, sorted by (row, cell, fraction).

    direction: index into EDGE_DIRECTIONS.  keys: (C,) int64 packed (row p2, row p3, cell j).
    fracs: (C,) float64 position within the cell, [0, 1).  signs: (C,) int8, +1 entering the
    solid along the direction, -1 leaving.  faces: (C,) int32 the triangle crossed.
    row_box: (3,) int64 (lowest p2, lowest p3, number of p3) of the box of rows crossed, in
    the keys' offset units; row_starts: (R + 1,) int32, the crossings of row r (numbered
    row-major over the box) are [row_starts[r], row_starts[r + 1]); empty where the rows were
    too sparse in their box to index (then searches find them, _row_span).
    """

    direction: int
    keys: np.ndarray
    fracs: np.ndarray
    signs: np.ndarray
    faces: np.ndarray
    row_box: np.ndarray
    row_starts: np.ndarray


def row_crossings(frame: FatFrame, snapped: np.ndarray, faces: np.ndarray, direction: int,
                  face_ids: np.ndarray | None = None) -> RowCrossings:
    """All crossings of lattice rows parallel to EDGE_DIRECTIONS[direction] with the snapped
    surface, or only with the triangles faces[face_ids] (ascending ids; the crossings' faces
    still index ``faces``).  Such a subset gives exactly the full crossings in every cell
    whose closed cube meets no other triangle."""
    T = row_basis(direction)
    coords = in_row_coordinates(np.ascontiguousarray(snapped, dtype=np.int64), T)
    triangles = np.ascontiguousarray(faces if face_ids is None else np.take(faces, face_ids, axis=0), dtype=np.int64)
    bits = snap_bits(frame)
    # Count, prefix-sum, fill, with a cheap bound (the rows tested) as the count: the exact
    # tests run once, and the unwritten slots are dropped after.
    bounds = np.empty(triangles.shape[0], dtype=np.int64)
    _row_bounds(coords, triangles, bits, bounds)
    some, crossing, triangles, offsets = _triangles_to_fill(triangles, bounds, SPARSE_CROSSING)
    if some:
        face_ids = crossing if face_ids is None else np.take(face_ids, crossing)
    room = int(offsets[-1])
    keys = np.empty(room, dtype=np.int64)
    fracs = np.empty(room, dtype=np.float64)
    signs = np.empty(room, dtype=np.int8)
    hit_faces = np.empty(room, dtype=np.int32)
    counts = np.empty(triangles.shape[0], dtype=np.int64)
    _row_hits(coords, triangles, bits, offsets, keys, fracs, signs, hit_faces, counts)
    written = written_slots(offsets, counts)
    # The row index holds int32 positions: more crossings than that take the argsort path.
    max_rows = ROW_SORT_BOX * written.shape[0] + ROW_SORT_FLOOR if written.shape[0] < 2**31 else -1
    order, row_box, row_starts = _row_order(keys, fracs, hit_faces, written, max_rows)
    if order.shape[0] != written.shape[0]:
        # Rows spread thinly over their box: a comparison sort.  Not a stable sort (3-4x
        # slower): _order_cells orders each run of equal keys by (fraction, face), and a
        # triangle crosses a row's cell once, so the order is the same.  Ties break on the
        # position in faces[face_ids], the same order as on faces (ascending ids).
        order = written[np.argsort(keys[written])]
        _order_cells(keys, fracs, hit_faces, order)
    no_ids = np.empty(0, dtype=np.int64)
    keys, fracs, signs, hit_faces = _gather_crossings(order, keys, fracs, signs, hit_faces,
                                                      no_ids if face_ids is None else face_ids, face_ids is not None)
    return RowCrossings(direction, keys, fracs, signs, hit_faces, row_box, row_starts)


@nb.njit(cache=True)
def _triangles_to_fill(triangles, bounds, sparse):
    """The triangles (F, 3) the fill visits, with their slots: (whether only some are kept,
    their positions (K,) int64 in triangles (empty if all are kept), the triangles (K, 3),
    offsets (K + 1,) of their bounds' prefix sums).  On a tessellation finer than the rows
    most triangles' boxes hold no row (armadillo at diag/40: 1-5 k of 86 k): when those with a
    row (bounds > 0) are fewer than sparse x F, only they are kept, in order (so the
    crossings' order is the same).  (numpy's flatnonzero, two takes and cumsum took 140 of
    bunny's 520 us a direction at diag/40.)"""
    n = bounds.shape[0]
    k = 0
    for f in range(n):
        k += bounds[f] > 0
    some = k < sparse * n
    m = k if some else n
    kept = np.empty(k if some else 0, dtype=np.int64)
    out = np.empty((m, 3), dtype=np.int64) if some else triangles
    offsets = np.empty(m + 1, dtype=np.int64)
    offsets[0] = 0
    j = 0
    for f in range(n):
        if some and bounds[f] == 0:
            continue
        if some:
            kept[j] = f
            for i in range(3):
                out[j, i] = triangles[f, i]
        offsets[j + 1] = offsets[j] + bounds[f]
        j += 1
    return some, kept, out, offsets


@nb.njit(cache=True, parallel=True)
def _gather_crossings(order, keys, fracs, signs, faces, face_ids, by_ids):
    """The crossings at order (C,) in the fill's slots, as (keys, fracs, signs, faces) in one
    parallel pass; faces through face_ids when by_ids (the fill numbered a subset).  (numpy's
    four fancy-index gathers and the id map took 9 of tray_bottom's 392 ms at diag/40.)"""
    n = order.shape[0]
    out_keys = np.empty(n, dtype=np.int64)
    out_fracs = np.empty(n, dtype=np.float64)
    out_signs = np.empty(n, dtype=np.int8)
    out_faces = np.empty(n, dtype=np.int32)
    for i in nb.prange(n):
        s = order[i]
        out_keys[i] = keys[s]
        out_fracs[i] = fracs[s]
        out_signs[i] = signs[s]
        out_faces[i] = face_ids[faces[s]] if by_ids else faces[s]
    return out_keys, out_fracs, out_signs, out_faces


#: row_crossings fills in only the triangles whose boxes hold a row when they are fewer than
#: this fraction of the triangles: gathering them costs less than visiting the others again
#: (per direction, bunny diag/40 at half its triangles 385 -> 330 us, fandisk at a third
#: 610 -> 450 us, armadillo at a tenth 2.6 -> 1.6 ms).
SPARSE_CROSSING = 0.9
#: row_crossings orders its crossings by a counting sort over the box of their rows when
#: the box holds at most ROW_SORT_BOX rows a crossing (plus ROW_SORT_FLOOR), else by argsort.
#: A row holds a few crossings, and the rows crossed fill much of their box on every corpus
#: model (tray_bottom diag/40: 90 k crossings in 45 k rows of a 52 k-row box).
ROW_SORT_BOX = 4
ROW_SORT_FLOOR = 4096


@nb.njit(cache=True)
def _row_order(keys, fracs, faces, written, max_rows):
    """The slots ``written`` in order of (key, fraction, face), and the index of their rows in
    that order (RowCrossings.row_box, row_starts); an empty order and index if the box of
    their rows holds more than max_rows rows.  A counting sort by row (the key's high bits,
    (r2, r3), numbered row-major over their box) groups them; _order_cells then moves each
    only within its row, a few crossings.  The order argsort and _order_cells give (a
    triangle crosses a row's cell once: no ties)."""
    n = written.shape[0]
    lo2 = lo3 = np.int64(1) << 62
    hi2 = hi3 = np.int64(-1)
    for i in range(n):
        r2, r3 = _row_of(keys[written[i]])
        lo2, hi2, lo3, hi3 = min(lo2, r2), max(hi2, r2), min(lo3, r3), max(hi3, r3)
    if n == 0:  # a box of no rows
        return written.copy(), np.array([0, 0, 1], dtype=np.int64), np.zeros(1, dtype=np.int32)
    width = hi3 - lo3 + 1
    n_rows = (hi2 - lo2 + 1) * width
    if n_rows > max_rows:
        return np.empty(0, dtype=np.int64), np.zeros(3, dtype=np.int64), np.empty(0, dtype=np.int32)
    start = np.zeros(n_rows + 1, dtype=np.int32)  # kept as the row index: int32 halves it
    for i in range(n):
        r2, r3 = _row_of(keys[written[i]])
        start[(r2 - lo2) * width + r3 - lo3 + 1] += 1
    for r in range(n_rows):
        start[r + 1] += start[r]
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        r2, r3 = _row_of(keys[written[i]])
        r = (r2 - lo2) * width + r3 - lo3
        order[start[r]] = written[i]
        start[r] += 1
    for r in range(n_rows, 0, -1):  # each row's end is now where the next row starts
        start[r] = start[r - 1]
    start[0] = 0
    _order_cells(keys, fracs, faces, order)
    return order, np.array([lo2, lo3, width], dtype=np.int64), start


@nb.njit(cache=True, inline="always")
def _row_of(key):
    """The row (r2, r3) of a crossing's key, each offset by _KEY_OFFSET (its high bits; the low
    _KEY_BITS are the cell)."""
    return key >> (2 * _KEY_BITS), (key >> _KEY_BITS) & ((np.int64(1) << _KEY_BITS) - 1)


@nb.njit(cache=True)
def _order_cells(keys, fracs, faces, order):
    """Sort ``order`` by (key, fraction, face) with an insertion sort.  Given an order already
    sorted by key (argsort), or grouped by row in row order (_row_order), each crossing moves
    only within its cell or row, which hold a crossing or two (np.lexsort on the three
    columns cost half of row_crossings)."""
    for i in range(1, order.shape[0]):
        o = order[i]
        j = i
        while j > 0 and (keys[order[j - 1]] > keys[o]
                         or (keys[order[j - 1]] == keys[o]
                             and (fracs[order[j - 1]] > fracs[o]
                                  or (fracs[order[j - 1]] == fracs[o] and faces[order[j - 1]] > faces[o])))):
            order[j] = order[j - 1]
            j -= 1
        order[j] = o


def crossing_points(frame: FatFrame, crossings: RowCrossings, which: np.ndarray) -> np.ndarray:
    """Space points (K, 3) of the crossings at indices which (K,): the row (p2, p3) and cell j
    of each key back to lattice coordinates, plus its fraction along the row's direction."""
    key = crossings.keys[which]
    mask = (np.int64(1) << _KEY_BITS) - 1
    tu = np.stack([(key & mask) - _KEY_OFFSET,
                   ((key >> _KEY_BITS) & mask) - _KEY_OFFSET,
                   ((key >> (2 * _KEY_BITS)) & mask) - _KEY_OFFSET], axis=1)[:, [0, 2, 1]]
    u = np.linalg.solve(row_basis(crossings.direction).astype(np.float64), tu.T.astype(np.float64)).T
    return frame.to_space(u + crossings.fracs[which][:, None] * EDGE_DIRECTIONS[crossings.direction])


#: Crossings of a row less than this many cells apart are summed together when the winding
#: number is checked: their float fractions may be out of their exact order.
WINDING_TIE = 1e-9


def first_winding_outside(crossings: RowCrossings, points: np.ndarray | None = None) -> int:
    """Index of the first crossing after which the winding number along its row is neither 0
    nor 1, or -1 if there is none.  Along any line, a closed oriented surface that bounds a
    solid without intersecting itself is entered and left in turn (nested shells included: a
    cavity is left, then an island in it entered), so such a crossing shows parts that
    overlap or fold through one another, whose winding numbers are 2 or -1.  points (N, 3)
    int64: only the rows through these lattice points are read (crossings of a subset of the
    triangles hold whole rows only where the subset holds every triangle over them)."""
    if points is None:
        return int(_first_winding_outside(crossings.keys, crossings.fracs, crossings.signs, WINDING_TIE))
    rows = _row_keys(row_basis(crossings.direction), np.ascontiguousarray(points, dtype=np.int64))
    row_mask = ~((np.int64(1) << _KEY_BITS) - 1)
    read = np.flatnonzero(np.isin(crossings.keys & row_mask, rows))
    bad = _first_winding_outside(crossings.keys[read], crossings.fracs[read], crossings.signs[read], WINDING_TIE)
    return int(read[bad]) if bad >= 0 else -1


@nb.njit(cache=True)
def _row_keys(basis, points):
    """The row part of each lattice point's key (_point_key with the cell bits cleared)."""
    row_mask = ~((np.int64(1) << _KEY_BITS) - 1)
    out = np.empty(points.shape[0], dtype=np.int64)
    for i in range(points.shape[0]):
        out[i] = _point_key(basis, points, i) & row_mask
    return out


@nb.njit(cache=True)
def _first_winding_outside(keys, fracs, signs, tie):
    row_mask = ~((np.int64(1) << _KEY_BITS) - 1)
    n = keys.shape[0]
    winding = 0
    i = 0
    while i < n:
        if i == 0 or (keys[i] & row_mask) != (keys[i - 1] & row_mask):
            winding = 0
        j = i + 1
        step = np.int64(signs[i])
        while j < n and (keys[j] & row_mask) == (keys[i] & row_mask) and \
                np.float64(keys[j] - keys[j - 1]) + (fracs[j] - fracs[j - 1]) <= tie:
            step += signs[j]
            j += 1
        winding += step
        if winding < 0 or winding > 1:
            return i
        i = j
    return -1


def winding_numbers(crossings: RowCrossings, points: np.ndarray) -> np.ndarray:
    """Winding number (N,) int32 of each lattice point (moved by -eps along the direction)."""
    points = np.ascontiguousarray(points, dtype=np.int64)
    out = np.empty(points.shape[0], dtype=np.int32)
    _winding_numbers(crossings.keys, crossings.row_box, crossings.row_starts, _sign_sums(crossings.signs),
                     row_basis(crossings.direction), points, out)
    return out


@nb.njit(cache=True)
def _sign_sums(signs):
    """Prefix sums (C + 1,) int64 of the crossings' signs (int8), from 0.  (numpy's cumsum of
    int8 into int64 took 18 us on bunny's 5 k x-crossings at diag/80, most of a call.)"""
    out = np.empty(signs.shape[0] + 1, dtype=np.int64)
    out[0] = 0
    for i in range(signs.shape[0]):
        out[i + 1] = out[i] + signs[i]
    return out


@nb.njit(cache=True, inline="always")
def _point_key(basis, points, i):
    """Packed key (row, cell) of lattice point i on the rows of the basis's direction: the row
    (p2, p3) = basis rows 1, 2 applied to it, the cell t = basis row 0."""
    x, y, z = points[i, 0], points[i, 1], points[i, 2]
    return _pack(basis[1, 0] * x + basis[1, 1] * y + basis[1, 2] * z,
                 basis[2, 0] * x + basis[2, 1] * y + basis[2, 2] * z,
                 basis[0, 0] * x + basis[0, 1] * y + basis[0, 2] * z)


@nb.njit(cache=True, inline="always")
def _row_start_key(key):
    """The smallest key of a key's row (its cell field zeroed: cell -_KEY_OFFSET)."""
    return (key >> _KEY_BITS) << _KEY_BITS


@nb.njit(cache=True, parallel=True)
def _winding_numbers(keys, row_box, row_starts, csum, basis, points, out):
    """out[i] = sum of the crossing signs (prefix sums csum) on point i's row in cells before
    it: the row's crossings from _row_span, the point's cell by a binary search among them
    (rows hold a few crossings)."""
    m = points.shape[0]
    n_chunks = min(m // 256 + 1, 64)
    for chunk in nb.prange(n_chunks):
        start = 0
        for i in range(chunk * m // n_chunks, (chunk + 1) * m // n_chunks):
            key = _point_key(basis, points, i)
            start, end = _row_span(keys, row_box, row_starts, key, start)
            out[i] = csum[lower_bound(keys, key, start, end)] - csum[start]


@nb.njit(cache=True, inline="always")
def _row_span(keys, row_box, row_starts, key, hint):
    """(first, end): the crossings on key's row are keys[first:end] (first == end: none).
    Read from the row index (RowCrossings.row_starts), or where there is none found by
    galloping from hint, the previous row's first (points and edges come in leaf order, near
    in space).  Galloping from one point's row to the next point's crossed most of the keys
    where points come in leaf order and keys in row order: with the index, the edge cuts of
    a fea_part mesh at diag/80 took 41 -> 21 ms and its winding numbers 39 -> 10 ms."""
    if row_starts.shape[0] == 0:
        first = lower_bound_near(keys, _row_start_key(key), hint)
        return first, lower_bound_near(keys, _row_start_key(key) + (np.int64(1) << _KEY_BITS), first)
    r2, r3 = _row_of(key)
    a, b = r2 - row_box[0], r3 - row_box[1]
    r = a * row_box[2] + b
    if a < 0 or b < 0 or b >= row_box[2] or r >= row_starts.shape[0] - 1:
        return np.int64(0), np.int64(0)
    return np.int64(row_starts[r]), np.int64(row_starts[r + 1])


#: Edges a thread takes at a time in _edge_cuts: their outputs and start points stay in its
#: cache while the seven directions' crossings are looked up.
EDGE_BLOCK = 1024


@nb.njit(cache=True, parallel=True)
def _edge_cuts(keys, fracs, crossed, row_starts, row_boxes, bases, present, points, starts, start_inside, dirs, out,
               status, out_faces):
    """For each edge e with dirs[e] >= 0, from points[starts[e]] one step along direction
    dirs[e]: out[e] = the crossing in its cell nearest the inside end, else a crossing exactly
    at its far end (fraction 1), else the midpoint with status[e] = 1; out_faces[e] = the
    triangle crossed there, -1 at a midpoint.  keys, fracs, crossed (the crossings'
    triangles), row_starts: tuples over the directions of their RowCrossings' arrays;
    row_boxes (D, 3) and bases (D, 3, 3) theirs stacked; present (D,): which directions have
    crossings.  Edges of dirs -1 are left alone.  Returns the number of edges whose direction
    has none (those are left alone too).

    The edges go in blocks of EDGE_BLOCK, each block direction by direction.  A pass a
    direction over all edges, as before, wrote each edge's outputs a cache line apart from
    the last and read the start points from memory seven times: featuretype's 60 k cut edges
    at diag/80 took 6.0 ms that way, 3.2 ms in blocks (2 threads; same outputs)."""
    m = starts.shape[0]
    n_directions = bases.shape[0]
    n_blocks = (m + EDGE_BLOCK - 1) // EDGE_BLOCK
    absent = np.zeros(n_blocks, dtype=np.int64)
    for block in nb.prange(n_blocks):
        lo, hi = block * EDGE_BLOCK, min(m, (block + 1) * EDGE_BLOCK)
        # The block's edges grouped by direction, in order (a counting sort).
        at = np.zeros(n_directions + 1, dtype=np.int64)
        for e in range(lo, hi):
            if dirs[e] >= 0:
                at[dirs[e] + 1] += 1
        for d in range(n_directions):
            if not present[d]:
                absent[block] += at[d + 1]
                at[d + 1] = 0
        for d in range(n_directions):
            at[d + 1] += at[d]
        ends = at[1:].copy()
        grouped = np.empty(hi - lo, dtype=np.int64)
        for e in range(lo, hi):
            if dirs[e] >= 0 and present[dirs[e]]:
                grouped[at[dirs[e]]] = e
                at[dirs[e]] += 1
        first_of = 0
        for d in range(n_directions):
            if ends[d] > first_of:
                _cut_edges_of_direction(keys[d], fracs[d], crossed[d], row_starts[d], row_boxes[d], bases[d],
                                        points, starts, start_inside, grouped[first_of:ends[d]], out, status,
                                        out_faces)
            first_of = ends[d]
    return absent.sum()


@nb.njit(cache=True, inline="always")
def _cut_edges_of_direction(keys, fracs, crossed, row_starts, row_box, basis, points, starts, start_inside, edges,
                            out, status, out_faces):
    """_edge_cuts for the edges ``edges`` of one direction, its crossings' arrays given."""
    first = 0
    for e in edges:
        key = _point_key(basis, points, starts[e])
        first, end = _row_span(keys, row_box, row_starts, key, first)
        lo = lower_bound(keys, key, first, end)
        hi = lower_bound(keys, key + 1, lo, end)  # keys are integers: key + 1 is cell t + 1
        status[e] = 0
        if hi > lo:
            at = lo if start_inside[starts[e]] else hi - 1
            out[e] = fracs[at]
            out_faces[e] = crossed[at]
        elif hi < end and keys[hi] == key + 1 and fracs[hi] == 0.0:
            out[e] = 1.0
            out_faces[e] = crossed[hi]
        else:
            out[e] = 0.5
            out_faces[e] = -1
            status[e] = 1


def edge_cut_fractions(crossings: RowCrossings, starts: np.ndarray,
                       start_inside: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut point of each lattice edge (start, start + d) along the crossings' direction d.

    starts: (E, 3) int64 lattice points; start_inside: (E,) bool class of the start point
    (the other end has the other class).  Returns (fractions (E,) in [0, 1] from start to
    end, unresolved (E,) int8 = 1 where the rows found no crossing, which only happens for
    edges with an endpoint exactly on the surface, resolved here to the midpoint, and the
    triangle (E,) int32 each cut point lies on: an index into the faces crossed, -1 at a
    midpoint).
    """
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    out = np.empty(starts.shape[0], dtype=np.float64)
    status = np.empty(starts.shape[0], dtype=np.int8)
    faces = np.empty(starts.shape[0], dtype=np.int32)
    add_edge_cut_fractions({crossings.direction: crossings}, starts, np.arange(starts.shape[0]), start_inside,
                           np.full(starts.shape[0], crossings.direction, dtype=np.int8), out, status, faces)
    return out, status, faces


def add_edge_cut_fractions(crossings: dict[int, RowCrossings], points: np.ndarray, starts: np.ndarray, inside: np.ndarray,
                           dirs: np.ndarray, fracs: np.ndarray, status: np.ndarray, faces: np.ndarray) -> None:
    """edge_cut_fractions of the edges e with dirs[e] >= 0, each along its direction, written
    to fracs[e], status[e] and faces[e] in place: edge e starts at points[starts[e]] (points
    (N, 3) int64 lattice points, inside (N,) their classes); crossings: {direction:
    RowCrossings} holding every direction of dirs; edges of dirs -1 are left alone."""
    n_directions = EDGE_DIRECTIONS.shape[0]
    none = RowCrossings(-1, np.empty(0, dtype=np.int64), np.empty(0), np.empty(0, dtype=np.int8),
                        np.empty(0, dtype=np.int32), np.array([0, 0, 1], dtype=np.int64), np.empty(0, dtype=np.int32))
    rows = [crossings.get(d, none) for d in range(n_directions)]
    present = np.array([d in crossings for d in range(n_directions)])

    def each(name: str, dtype) -> tuple:
        # One array type over the directions: the kernel indexes the tuple by direction.
        return tuple(np.ascontiguousarray(getattr(r, name), dtype=dtype) for r in rows)

    absent = _edge_cuts(each("keys", np.int64), each("fracs", np.float64), each("faces", np.int32),
                        each("row_starts", np.int32), np.stack([r.row_box for r in rows]), ROW_BASES, present,
                        points, np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(inside, dtype=np.bool_),
                        np.ascontiguousarray(dirs, dtype=np.int8), fracs, status, faces)
    if absent:
        raise ValueError(f"{absent} edges lie along directions without crossings (given: {sorted(crossings)})")


#: row_basis of every edge direction, stacked (D, 3, 3).
ROW_BASES = np.stack([row_basis(d) for d in range(EDGE_DIRECTIONS.shape[0])])


@nb.njit(cache=True, inline="always")
def _orient3d(ax, ay, az, bx, by, bz, cx, cy, cz, dx, dy, dz):
    """Six times the signed volume of (a, b, c, d), in floats."""
    bx, by, bz = bx - ax, by - ay, bz - az
    cx, cy, cz = cx - ax, cy - ay, cz - az
    dx, dy, dz = dx - ax, dy - ay, dz - az
    return bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx)


@nb.njit(cache=True, inline="always")
def _segment_hit(ax, ay, az, bx, by, bz, tri):
    """Parameter t in [0, 1] where the segment a + t (b - a) crosses the triangle tri (3, 3),
    or -1.0 if it does not (floats; a hit through an edge of the triangle may be missed or
    found twice, which only changes which crossing is chosen)."""
    d0 = _orient3d(ax, ay, az, tri[0, 0], tri[0, 1], tri[0, 2], tri[1, 0], tri[1, 1], tri[1, 2], tri[2, 0], tri[2, 1], tri[2, 2])
    d1 = _orient3d(bx, by, bz, tri[0, 0], tri[0, 1], tri[0, 2], tri[1, 0], tri[1, 1], tri[1, 2], tri[2, 0], tri[2, 1], tri[2, 2])
    if (d0 > 0 and d1 > 0) or (d0 < 0 and d1 < 0) or d0 == d1:
        return -1.0
    s0 = _orient3d(ax, ay, az, bx, by, bz, tri[0, 0], tri[0, 1], tri[0, 2], tri[1, 0], tri[1, 1], tri[1, 2])
    s1 = _orient3d(ax, ay, az, bx, by, bz, tri[1, 0], tri[1, 1], tri[1, 2], tri[2, 0], tri[2, 1], tri[2, 2])
    s2 = _orient3d(ax, ay, az, bx, by, bz, tri[2, 0], tri[2, 1], tri[2, 2], tri[0, 0], tri[0, 1], tri[0, 2])
    if not ((s0 >= 0 and s1 >= 0 and s2 >= 0) or (s0 <= 0 and s1 <= 0 and s2 <= 0)):
        return -1.0
    return min(max(d0 / (d0 - d1), 0.0), 1.0)


@nb.njit(cache=True, parallel=True)
def _bucket_boxes(bucket_faces, triangles, slack):
    """Boxes (J, 6) (lo xyz, hi xyz) of the triangles at each bucket position, grown by slack:
    the edges of a bucket scan them in order, from contiguous memory."""
    boxes = np.empty((bucket_faces.shape[0], 6))
    for j in nb.prange(bucket_faces.shape[0]):
        tri = triangles[bucket_faces[j]]
        for i in range(3):
            boxes[j, i] = min(tri[0, i], tri[1, i], tri[2, i]) - slack
            boxes[j, 3 + i] = max(tri[0, i], tri[1, i], tri[2, i]) + slack
    return boxes


@nb.njit(cache=True, parallel=True)
def _segment_cuts(bucket_keys, offsets, bucket_faces, triangles, coords, starts, ends, start_inside,
                  cell_bits, key_shift, out, status, out_faces):
    boxes = _bucket_boxes(bucket_faces, triangles, _BOX_SLACK)
    # Scalars, not small arrays: five allocations an edge, and a call per triangle tried,
    # were most of the kernel.
    for e in nb.prange(starts.shape[0]):
        p, q = starts[e], ends[e]
        ax, ay, az = float(coords[p, 0]), float(coords[p, 1]), float(coords[p, 2])
        bx, by, bz = float(coords[q, 0]), float(coords[q, 1]), float(coords[q, 2])
        # The cell holding the midpoint holds the whole edge: edges lie in one leaf of this
        # level or finer.  On a cell face either neighbour's bucket has the faces.
        cx = ((coords[p, 0] + coords[q, 0]) >> (cell_bits + 1)) << cell_bits
        cy = ((coords[p, 1] + coords[q, 1]) >> (cell_bits + 1)) << cell_bits
        cz = ((coords[p, 2] + coords[q, 2]) >> (cell_bits + 1)) << cell_bits
        key = morton_key(cx << key_shift, cy << key_shift, cz << key_shift)
        k = np.searchsorted(bucket_keys, key)
        best = -1.0
        crossed = -1
        if k < bucket_keys.shape[0] and bucket_keys[k] == key:
            for j in range(offsets[k], offsets[k + 1]):
                if (boxes[j, 0] > max(ax, bx) or boxes[j, 1] > max(ay, by) or boxes[j, 2] > max(az, bz)
                        or boxes[j, 3] < min(ax, bx) or boxes[j, 4] < min(ay, by) or boxes[j, 5] < min(az, bz)):
                    continue
                t = _segment_hit(ax, ay, az, bx, by, bz, triangles[bucket_faces[j]])
                if t < 0:
                    continue
                # The crossing nearest the inside end, as for unit edges.
                if best < 0 or (t < best if start_inside[e] else t > best):
                    best = t
                    crossed = bucket_faces[j]
        status[e] = 0
        if best < 0:
            best = 0.5
            status[e] = 1
        out[e] = best
        out_faces[e] = crossed


#: Lattice units by which a triangle's box must miss an edge's box to be skipped untested: far
#: above the rounding of _segment_hit, whose near misses may count as hits.
_BOX_SLACK = 1e-6


@nb.njit(cache=True, parallel=True)
def _lattice_triangles(snapped, faces, unit):
    """The triangles (F, 3, 3) float64 in lattice coordinates: snapped[faces] / unit, without
    numpy's (F, 3, 3) int64 gather first (2.3 ms of fea_part's 21 at diag/40)."""
    out = np.empty((faces.shape[0], 3, 3))
    for f in nb.prange(faces.shape[0]):
        for k in range(3):
            for i in range(3):
                out[f, k, i] = snapped[faces[f, k], i] / unit
    return out


def segment_cut_fractions(buckets: FaceBuckets, frame: FatFrame, snapped: np.ndarray, faces: np.ndarray,
                          coords: np.ndarray, starts: np.ndarray, ends: np.ndarray,
                          start_inside: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut point of each edge (coords[starts[e]], coords[ends[e]]) that is not a unit lattice
    edge: coarser lattice edges and the edges of transition templates, each inside one leaf
    no coarser than the buckets' level.

    The triangles tried are those of the bucket (octree.face_buckets) holding the edge; the
    crossing is found in floats (the ends' classes are exact, from rows), and the one nearest
    the inside end is taken.  Returns (fractions (E,) in [0, 1] from start to end,
    unresolved (E,) int8 = 1 where no crossing was found: midpoint, and the triangle (E,)
    int32 crossed there, an index into faces, -1 at a midpoint).
    """
    out = np.empty(starts.shape[0], dtype=np.float64)
    status = np.empty(starts.shape[0], dtype=np.int8)
    crossed = np.empty(starts.shape[0], dtype=np.int32)
    triangles = _lattice_triangles(np.ascontiguousarray(snapped, dtype=np.int64), np.ascontiguousarray(faces),
                                   float(1 << snap_bits(frame)))
    _segment_cuts(buckets.keys, buckets.offsets, buckets.faces, triangles, np.ascontiguousarray(coords, dtype=np.int64),
                  np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(ends, dtype=np.int64),
                  np.ascontiguousarray(start_inside, dtype=np.bool_), frame.levels - buckets.level,
                  MAX_LEVEL - frame.levels, out, status, crossed)
    return out, status, crossed
