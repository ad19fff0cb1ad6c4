"""Isosurface stuffing on the fat lattice (Labelle & Shewchuk, SIGGRAPH 2007).

Input: the lattice tets around and inside the solid, every lattice vertex classified
inside (+) or outside (-), and the cut point of every edge whose ends differ.

1. Warp: a cut point *violates* an end of its edge when it lies closer to it than
   alpha times the edge length (alpha_long = 0.24999 for long edges, alpha_short =
   0.41189 for short ones).  Every violated vertex moves to its closest violating cut
   point and becomes a surface vertex (0); cut points on edges touching a warped
   vertex disappear.  Warps are decided from the original positions, all at once.
2. Stencils: each lattice tet keeps the part of itself on the + side, split into tets
   by the stencil of its sign pattern; quadrilateral faces are split by the parity
   rule so that neighbouring tets agree.  Tets with no + vertex are dropped.

For the BCC lattice this proves every dihedral angle in [10.7, 164.8] degrees, for any
positions of the cut points (Labelle & Shewchuk, Theorem 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from .frame import LATTICE_TO_SPACE
from .quality import _COS_HI, _COS_LO, _RATIO, _degrees, _degrees_above, _degrees_below, _gather, _measure_block
from .topology import int32_ids, touching

ALPHA_LONG = 0.24999
ALPHA_SHORT = 0.41189
#: Dihedral angles (degrees) Labelle & Shewchuk prove for these alphas on a uniform BCC band;
#: a band that changes level is measured against them (mesher: refine where a tet falls outside).
DIHEDRAL_BOUND = (10.7, 164.8)

_EDGE_PAIRS = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
#: Direction index of a positive edge vector by its sign bits (x | y << 1 | z << 2); -1: not an edge.
_DIRECTION_OF_BITS = np.array([-1, 0, 1, 3, 2, 4, 5, 6], dtype=np.int64)


@nb.njit(cache=True, inline="always")
def _is_mixed(ids, i, classes):
    """True iff the vertices ids[i, :] are not all of one class."""
    first = classes[ids[i, 0]]
    for c in range(1, ids.shape[1]):
        if classes[ids[i, c]] != first:
            return True
    return False


@nb.njit(cache=True, parallel=True)
def mixed_rows(ids, classes):
    """Mask (N,) of the rows of vertex ids (N, K) (tets, cells' corners) whose vertices are
    not all of one class."""
    out = np.empty(ids.shape[0], dtype=np.bool_)
    for i in nb.prange(ids.shape[0]):
        out[i] = _is_mixed(ids, i, classes)
    return out


#: Chunks of tets (or cells) the parallel kernels hand to the threads.
TET_CHUNKS = 64


#: Tets from which collect_cut_edges chains runs of tets in parallel: below, the second
#: thread's heads (4 bytes a vertex) and the merge cost more than they save.  Two runs were
#: already faster from 22 k tets (bunny's band at diag/40: 0.55 -> 0.35 ms; the small parts
#: 1.5-4 % faster warm, as fast cold), so the threshold is 2**13, not session 26's 2**17.
PARALLEL_CUT_EDGE_TETS = 1 << 13


def collect_cut_edges(tets, inside, coords):
    """Unique lattice edges of tets whose ends differ in class (tets of one class are skipped:
    gathering the others first wrote 16 bytes a tet to fresh pages, fea_part diag/40 3.5 k
    page faults).

    Returns (starts (E,) vertex ids, ends (E,), directions (E,) int8 index into EDGE_DIRECTIONS,
    then the lookup table (head, upper, chain): the edges whose smaller end is a are
    head[a], chain[head[a]], ... down to -1, and upper[e] is the larger end of edge e
    (_edge_of); end - start = EDGE_DIRECTIONS[direction] for the unit lattice edges, whose
    ends are ordered so; direction -1 for other edges (of coarser lattices or transition
    templates).  Edges are numbered in the order the tets first hold them.

    Duplicates are found by chaining each edge to the previous edge with the same smaller
    end (a hash table whose buckets are the vertices), and those chains are the lookup
    table, so nothing is sized by the tet-edge occurrences (each edge is in 4-6 tets).
    Bucketing the occurrences by a counting sort first took twice as long, half of it
    first-touch page faults (fea_part diag/40: 62 -> 35 ms standalone); a counting sort of
    the edges by smaller end for the table took tray_bottom diag/40 three (E,) arrays more.
    """
    if coords.shape[0] >= 1 << 31 or 4 * tets.shape[0] >= 1 << 31:
        raise ValueError(f"collect_cut_edges chains hold int32: at most 2**31 vertices and 2**29 tets, "
                         f"len(coords) = {coords.shape[0]}, len(tets) = {tets.shape[0]}")
    n_chunks = 1 if tets.shape[0] < PARALLEL_CUT_EDGE_TETS else nb.get_num_threads()
    lower, upper, chain, head = _chain_cut_edges(int32_ids(tets), inside, coords.shape[0], n_chunks)
    starts, ends, dirs = _oriented_edges(lower, upper, coords)
    return starts, ends, dirs, head, upper, chain


#: Cube corner (CUBE_CORNERS index: x + 2 y + 4 z) at the far end of each edge direction.
_CORNER_OF_DIRECTION = np.array([np.flatnonzero(_DIRECTION_OF_BITS == d)[0] for d in range(7)], dtype=np.int64)


def cell_cut_edges(corner_ids: np.ndarray, inside: np.ndarray) -> tuple:
    """collect_cut_edges' result (starts, ends, directions, head, upper, chain) for the cut
    cells of a one-level lattice, read from the cells rather than their tets, the edges in
    another order: by cell, then by direction (EDGE_DIRECTIONS).  corner_ids: (K, 8) the
    cells' corners (CUBE_CORNERS order), every cell with corners of both classes that the
    lattice has; inside: (V,) the corners' classes.

    Every edge of the cells' Freudenthal tets is (a, a + d), d one of the seven 0/1
    directions, and lies in the cell anchored at a; a cut edge's every cell has corners of
    both classes, so that cell is one of these, and each cut edge is found once, there.  The
    tets' way finds each edge in its 4-6 tets and keeps the first (plate_holes at diag/80:
    2.3 ms with the tets' emission, against 0.3 ms here)."""
    corner_ids = np.ascontiguousarray(corner_ids, dtype=np.int32)
    starts, ends, dirs = _cell_cut_edges(corner_ids, np.ascontiguousarray(inside, dtype=np.bool_),
                                         _CORNER_OF_DIRECTION)
    head, upper, chain = _edge_table(starts, ends, inside.shape[0])
    return starts, ends, dirs, head, upper, chain


@nb.njit(cache=True, parallel=True)
def _cell_cut_edges(corner_ids, inside, corner_of_direction):
    """cell_cut_edges' edges: starts, ends (E,) int64 and directions (E,) int8, counted per
    chunk of cells, prefix-summed, then filled (each thread its own chunks' rows)."""
    k = corner_ids.shape[0]
    n_chunks = min(k, TET_CHUNKS)
    first = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in nb.prange(n_chunks):
        m = 0
        for i in range(c * k // n_chunks, (c + 1) * k // n_chunks):
            a = inside[corner_ids[i, 0]]
            for d in range(7):
                m += inside[corner_ids[i, corner_of_direction[d]]] != a
        first[c + 1] = m
    for c in range(n_chunks):
        first[c + 1] += first[c]
    starts = np.empty(first[n_chunks], dtype=np.int64)
    ends = np.empty(first[n_chunks], dtype=np.int64)
    dirs = np.empty(first[n_chunks], dtype=np.int8)
    for c in nb.prange(n_chunks):
        m = first[c]
        for i in range(c * k // n_chunks, (c + 1) * k // n_chunks):
            v = corner_ids[i, 0]
            for d in range(7):
                w = corner_ids[i, corner_of_direction[d]]
                if inside[w] != inside[v]:
                    starts[m] = v
                    ends[m] = w
                    dirs[m] = d
                    m += 1
    return starts, ends, dirs


@nb.njit(cache=True)
def _edge_table(starts, ends, n_vertices):
    """collect_cut_edges' lookup table (head (V,), upper (E,), chain (E,) int32) of the edges
    starts[e]-ends[e]: each edge chained to the one before with the same smaller end."""
    head = np.full(n_vertices, -1, dtype=np.int32)
    upper = np.empty(starts.shape[0], dtype=np.int32)
    chain = np.empty(starts.shape[0], dtype=np.int32)
    for e in range(starts.shape[0]):
        a = min(starts[e], ends[e])
        upper[e] = max(starts[e], ends[e])
        chain[e] = head[a]
        head[a] = e
    return head, upper, chain


@nb.njit(cache=True, parallel=True)
def _chain_cut_edges(tets, inside, n_vertices, n_chunks):
    """The distinct mixed edges in order of first occurrence, (lower (E,) int32: the smaller
    end; upper (E,) int32: the larger end; chain (E,) int32 and head (V,) int32:
    collect_cut_edges' lookup table).

    n_chunks runs of tets are chained in parallel, each with its own heads into its own part
    of the arrays (4 slots a tet); then each run's edges not in an earlier run are moved
    down and chained in order (about a fifth of the work: each edge is in 4-6 tets).  The
    result is that of one run, for any n_chunks."""
    m = tets.shape[0]
    head = np.full(n_vertices, -1, dtype=np.int32)
    heads = np.full((n_chunks - 1, n_vertices), -1, dtype=np.int32)
    # A tet has at most 4 edges whose ends differ.  Only the pages written are touched.
    lower = np.empty(4 * m, dtype=np.int32)
    upper = np.empty(4 * m, dtype=np.int32)
    chain = np.empty(4 * m, dtype=np.int32)
    ends = np.empty(n_chunks, dtype=np.int64)
    for c in nb.prange(n_chunks):
        t0 = m * c // n_chunks
        ends[c] = _chain_tets(tets, inside, t0, m * (c + 1) // n_chunks, head if c == 0 else heads[c - 1],
                              lower, upper, chain, 4 * t0)
    n = ends[0]
    for c in range(1, n_chunks):
        for s in range(4 * (m * c // n_chunks), ends[c]):  # never below n: earlier runs fill at most 4 a tet
            a, b = lower[s], upper[s]
            if _edge_of(head, upper, chain, a, b) >= 0:
                continue
            lower[n] = a
            upper[n] = b
            chain[n] = head[a]
            head[a] = n
            n += 1
    return lower[:n], upper[:n], chain[:n], head


@nb.njit(cache=True, inline="always")
def _chain_tets(tets, inside, t0, t1, head, lower, upper, chain, n):
    """Chain the distinct mixed edges of tets t0..t1-1 from slot n on (see _chain_cut_edges);
    returns the slot after the last."""
    for t in range(t0, t1):
        if not _is_mixed(tets, t, inside):
            continue
        for e in range(6):
            p = tets[t, _EDGE_PAIRS[e, 0]]
            q = tets[t, _EDGE_PAIRS[e, 1]]
            if inside[p] == inside[q]:
                continue
            a = min(p, q)
            b = max(p, q)
            if _edge_of(head, upper, chain, a, b) >= 0:
                continue
            lower[n] = a
            upper[n] = b
            chain[n] = head[a]
            head[a] = n
            n += 1
    return n


@nb.njit(cache=True, inline="always")
def _coords_less(coords, a, b):
    """Whether point a's lattice coordinates come before b's lexicographically (x, then y,
    then z; the smaller id where they are equal, which a lattice's distinct points never
    are): the order that breaks the ties of the cut edges' directions and of the warps, the
    same however the points are numbered."""
    for i in range(3):
        if coords[a, i] != coords[b, i]:
            return coords[a, i] < coords[b, i]
    return a < b


@nb.njit(cache=True, inline="always")
def _lattice_level(coords, a):
    """log2 of the coarsest spacing whose lattice holds point a (64 at the origin)."""
    m = coords[a, 0] | coords[a, 1] | coords[a, 2]
    if m == 0:
        return 64
    k = 0
    while (m & 1) == 0:
        m >>= 1
        k += 1
    return k


@nb.njit(cache=True, parallel=True)
def _oriented_edges(lower, upper, coords):
    """starts, ends (E,) int64 and directions (E,) int8 of collect_cut_edges from
    _chain_cut_edges' ends: each edge from its end of lexicographically smaller lattice
    coordinates (_coords_less), which for a vector with no negative component is the end it
    points away from.  So an edge's direction, and the float cut point found along it,
    follow its ends' places alone, not their ids or the order of the tets."""
    n = lower.shape[0]
    starts = np.empty(n, dtype=np.int64)
    ends = np.empty(n, dtype=np.int64)
    dirs = np.empty(n, dtype=np.int8)  # 7 of 8 bytes a cut edge spared, read once a direction
    for i in nb.prange(n):
        p, q = np.int64(lower[i]), np.int64(upper[i])
        if _coords_less(coords, q, p):
            p, q = q, p
        dx = coords[q, 0] - coords[p, 0]
        dy = coords[q, 1] - coords[p, 1]
        dz = coords[q, 2] - coords[p, 2]
        bits3 = (1 if dx > 0 else 0) | (2 if dy > 0 else 0) | (4 if dz > 0 else 0)
        starts[i] = p
        ends[i] = q
        dirs[i] = _DIRECTION_OF_BITS[bits3] if _lattice_step(dx, dy, dz, 1) else -1
    return starts, ends, dirs


@nb.njit(cache=True, inline="always")
def _edge_of(head, upper, chain, a, b):
    """Number of the edge (a, b), a < b, in collect_cut_edges' table, or -1.  A table may
    cover only the first vertices (a band's: its cut edges all lie among them); a vertex
    past its head array has no cut edge."""
    if a >= head.shape[0]:
        return -1
    s = head[a]
    while s >= 0 and upper[s] != b:
        s = chain[s]
    return s


@nb.njit(cache=True)
def _warp(coords, starts, ends, distance, violated):
    """Warp target per vertex (V,) int64: the cut edge (index) of its closest violating cut
    point, or -1 (_violations: which end each cut violates, at what distance); of cut points
    at the same distance, the one on the edge whose other end comes first (_coords_less)."""
    best = np.full(coords.shape[0], np.inf)
    target = np.full(coords.shape[0], -1, dtype=np.int64)
    for e in range(starts.shape[0]):
        if violated[e] < 0:
            continue
        v, w = (starts[e], ends[e]) if violated[e] == 0 else (ends[e], starts[e])
        tie = distance[e] == best[v] and _coords_less(coords, w, _other_end(starts, ends, target[v], v))
        if distance[e] < best[v] or tie:
            best[v] = distance[e]
            target[v] = e
    return target


@nb.njit(cache=True, inline="always")
def _other_end(starts, ends, e, v):
    """The end of cut edge e that is not v."""
    return ends[e] if starts[e] == v else starts[e]


@nb.njit(cache=True, parallel=True)
def _violations(coords, starts, ends, fracs, spacing, to_space, h, alpha_long, alpha_short):
    """Which end of each cut edge its cut point violates (E,) int8: 0 the start (fracs[e] below
    the start's reach, _end_reaches), 1 the end (1 - fracs[e] below the end's), -1 neither;
    and the distance (E,) from that end in space units (h times the edge's length through
    to_space; inf for neither).  Never both: reaches are at most alpha_short < 1/2.

    One (E,) float64 array where the lengths and the two reaches took three (tray_bottom
    diag/40: 5.5 k fresh pages -> 1.8 k)."""
    n = starts.shape[0]
    distance = np.empty(n)
    violated = np.empty(n, dtype=np.int8)
    for e in nb.prange(n):
        a = starts[e]
        b = ends[e]
        f = fracs[e]
        start_reach, end_reach = _end_reaches(coords, a, b, spacing, alpha_long, alpha_short)
        violated[e] = 0 if f < start_reach else (1 if 1.0 - f < end_reach else -1)
        distance[e] = np.inf
        if violated[e] >= 0:
            distance[e] = (f if violated[e] == 0 else 1.0 - f) * (_space_length(coords, a, b, to_space) * h)
    return distance, violated


@nb.njit(cache=True, inline="always")
def _space_length(coords, a, b, to_space):
    """Length of the lattice segment ab in space units of h: |to_space (coords[b] - coords[a])|."""
    d0 = coords[b, 0] - coords[a, 0]
    d1 = coords[b, 1] - coords[a, 1]
    d2 = coords[b, 2] - coords[a, 2]
    length = 0.0
    for i in range(3):
        x = to_space[i, 0] * d0 + to_space[i, 1] * d1 + to_space[i, 2] * d2
        length += x * x
    return np.sqrt(length)


@nb.njit(cache=True, inline="always")
def _end_reaches(coords, a, b, spacing, alpha_long, alpha_short):
    """Warp reach (as fractions of the edge) of the ends a and b of a cut edge (see
    warp_targets): alpha of the edge's kind, times the finest spacing at the end over the
    edge's (1 at most)."""
    d0 = coords[b, 0] - coords[a, 0]
    d1 = coords[b, 1] - coords[a, 1]
    d2 = coords[b, 2] - coords[a, 2]
    scale = _edge_spacing(coords, a, b)
    if scale > 0:
        long = (d0 != 0) + (d1 != 0) + (d2 != 0) == 2
        alpha = alpha_long if long else alpha_short
    else:  # a template edge off the lattices, in a leaf of side 2 g (g: gcd of |d|)
        alpha = alpha_long
        g = abs(d0)
        for c in (abs(d1), abs(d2)):
            while c:
                g, c = c, g % c
        scale = 2 * g
    return alpha * min(1.0, spacing[a] / scale), alpha * min(1.0, spacing[b] / scale)


@dataclass(frozen=True)
class CutEdges:
    """Tet edges whose ends differ in class.  starts, ends: (E,) vertex ids; directions: (E,)
    as collect_cut_edges gives them (-1 off the unit lattice edges); fracs: (E,) cut position from
    start, in [0, 1]; points: (E, 3) space positions of the cut points; table: the lookup
    of collect_cut_edges (first, last, partner, edge) finding an edge from its two ends;
    faces: (E,) int32 the surface triangle each cut point lies on (-1 where no crossing was
    found: a midpoint), or None for cuts not taken from a surface."""

    starts: np.ndarray
    ends: np.ndarray
    directions: np.ndarray
    fracs: np.ndarray
    points: np.ndarray
    table: tuple
    faces: np.ndarray | None = None


def warp_targets(cuts: CutEdges, coords: np.ndarray, h: float, spacing: np.ndarray | None = None) -> np.ndarray:
    """Index into the cut edges of the cut point each vertex warps to, or -1; (V,) int64.

    coords: (V, 3) lattice coordinates of the vertices (u, finest spacing 1); h: the finest
    long edge.  A cut point violates an end of its edge when it lies closer to it than alpha
    times the edge length: alpha_long for long lattice edges (any spacing), alpha_short for
    short ones (Labelle & Shewchuk), alpha_long for transition-template edges off the
    lattices.  spacing (V,): side of the finest leaf at each vertex (vertex_spacing; default 1
    everywhere, a one-level band); a vertex shared with finer leaves warps only within alpha
    times the length its edge has at that finer spacing, so the fine fat tets around it keep
    the warps Labelle & Shewchuk's proof allows.  docs/thin_study measured this rule where the
    band changes level: 0.11 % of the cut transition leaves made a tet outside [10.7, 164.8].
    """
    if spacing is None:
        spacing = np.ones(coords.shape[0], dtype=np.int64)
    distance, violated = _violations(coords, cuts.starts, cuts.ends, cuts.fracs, spacing, LATTICE_TO_SPACE, float(h),
                                     ALPHA_LONG, ALPHA_SHORT)
    return _warp(coords, cuts.starts, cuts.ends, distance, violated)


#: Three tets (8, 3, 4) splitting a triangular prism, per choice of quad diagonals.
#: Prism vertices 0, 1, 2 (bottom) and 3, 4, 5 (top, 3 + i above i); quad i is
#: (i, i+1, 4+i, 3+i) mod 3 and bit i of the index picks its diagonal: 0 joins bottom i to
#: top i+1, 1 joins bottom i+1 to top i.  The two cyclic choices (0 and 7) admit no
#: triangulation and hold -1.  Found by brute force over triples of tets, which
#: tests/naive.py keeps (prism_triangulations) and the tests compare (a search at import
#: cost every process 20 ms).
PRISM_TETS = np.array([
    [[-1, -1, -1, -1], [-1, -1, -1, -1], [-1, -1, -1, -1]],
    [[0, 1, 2, 3], [1, 2, 3, 5], [1, 3, 4, 5]],
    [[0, 1, 2, 4], [0, 2, 3, 4], [2, 3, 4, 5]],
    [[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5]],
    [[0, 1, 2, 5], [0, 1, 4, 5], [0, 3, 4, 5]],
    [[0, 1, 2, 5], [0, 1, 3, 5], [1, 3, 4, 5]],
    [[0, 1, 2, 4], [0, 2, 4, 5], [0, 3, 4, 5]],
    [[-1, -1, -1, -1], [-1, -1, -1, -1], [-1, -1, -1, -1]],
], dtype=np.int64)


@nb.njit(cache=True, inline="always")
def _bcc(u0, u1, u2, i):
    """Coordinate i of lattice point u in doubled BCC coordinates y = 2 M u (integers;
    all even on the cube grid, all odd at cube centres); see frame.LATTICE_TO_SPACE."""
    if i == 0:
        return u0 + u1 - u2
    if i == 1:
        return -u0 + u1 + u2
    return u0 - u1 + u2


@nb.njit(cache=True, inline="always")
def _lattice_step(dx, dy, dz, s):
    """True iff (dx, dy, dz) is s or -s times a Freudenthal edge direction (a vector of
    {0, 1}^3 other than 0): an edge of the lattice of spacing s."""
    if dx == 0 and dy == 0 and dz == 0:
        return False
    pos = (dx == 0 or dx == s) and (dy == 0 or dy == s) and (dz == 0 or dz == s)
    neg = (dx == 0 or dx == -s) and (dy == 0 or dy == -s) and (dz == 0 or dz == -s)
    return pos or neg


@nb.njit(cache=True, inline="always")
def _edge_spacing(coords, a, b):
    """s > 0 if the segment ab is an edge of the Freudenthal lattice of spacing s (b - a is
    +-s times a direction of {0, 1}^3), else 0."""
    dx = coords[b, 0] - coords[a, 0]
    dy = coords[b, 1] - coords[a, 1]
    dz = coords[b, 2] - coords[a, 2]
    s = max(abs(dx), abs(dy), abs(dz))
    return s if _lattice_step(dx, dy, dz, s) else 0


@nb.njit(cache=True, inline="always")
def _face_spacing(coords, a, b, e):
    """The spacing s (a power of two) of the lattice whose Freudenthal triangulation has the
    triangle (a, b, e) as a face: its corners are multiples of s and its three edges are
    lattice edges of spacing s; 0 if there is none (a face of a transition template that
    crosses the lattices, such as corner, corner, face centre of a coarse leaf)."""
    s = _edge_spacing(coords, a, b)
    if s == 0 or (s & (s - 1)) != 0 or _edge_spacing(coords, a, e) != s or _edge_spacing(coords, b, e) != s:
        return 0
    for i in range(3):
        if coords[a, i] % s != 0:
            return 0
    return s


@nb.njit(cache=True, inline="always")
def _vertex_before(coords, a, b, first_centre):
    """The order of the template quad rule: leaf corners (ids below first_centre) before face
    centres that are no leaf's corner, each by lattice coordinates (_coords_less)."""
    if (a >= first_centre) != (b >= first_centre):
        return b >= first_centre
    return _coords_less(coords, a, b)


@nb.njit(cache=True)  # called, not inlined: see the end of the docstring
def _quad_first_diagonal(coords, a, b, e, first_centre):
    """Diagonal of the quad (a, b, cut(b, e), cut(a, e)) on face (a, b, e), a and b inside.

    True: the diagonal joins a to cut(b, e); False: b to cut(a, e).  It depends on the face
    alone, so the two tets sharing the face agree.  On a face of the Freudenthal lattice of
    some spacing s (_face_spacing; every face when the band is one level), Labelle &
    Shewchuk's rule in that lattice's coordinates u / s, as in Epic's and Zheng's
    implementations: if ab is short, the diagonal joins the cut on the face's long edge to
    the inside vertex off that edge; if ab is long, the parity rule: with k the number of
    coordinates in which a exceeds cut(b, e), take a-cut(b, e) when k is odd for an edge of
    grid corners, even for an edge of cube centres (the exact test compares 2a with b + e,
    as the rule does not depend on where the cut lies on the open edge).  On any other face
    (transition templates), the diagonal at the vertex that comes first in _vertex_before:
    leaf corners before the face centres that are no leaf's corner (ids from first_centre
    up: number_vertices numbers those last), then by lattice coordinates.  Which points are
    no leaf's corner keeps the quads of a prism from cycling, which an order of the
    coordinates alone does not (docs/design.md, "Toward partitions by Morton ranges");
    the coordinates make the choice the same however the corners are numbered.

    Inlined by numba at its four call sites in _stencil_tet, it made _stencils take 46 s to
    compile; called, 7 s, and _stencils runs as fast (it only runs on cut tets).
    """
    s = _face_spacing(coords, a, b, e)
    if s == 0:
        return _vertex_before(coords, a, b, first_centre)
    a0, a1, a2 = coords[a, 0] // s, coords[a, 1] // s, coords[a, 2] // s
    b0, b1, b2 = coords[b, 0] // s, coords[b, 1] // s, coords[b, 2] // s
    e0, e1, e2 = coords[e, 0] // s, coords[e, 1] // s, coords[e, 2] // s
    a_sum = a0 + a1 + a2
    if ((a_sum - b0 - b1 - b2) & 1) != 0:  # ab short (grid corner to cube centre)
        return ((a_sum - e0 - e1 - e2) & 1) != 0  # ae short too: the long edge is be
    k = 0
    for i in range(3):
        if 2 * _bcc(a0, a1, a2, i) > _bcc(b0, b1, b2, i) + _bcc(e0, e1, e2, i):
            k += 1
    corners = (a_sum & 1) == 0
    return (k & 1) == (1 if corners else 0)


@nb.njit(cache=True, inline="always")
def _cut_id(table, n_lattice, p, q):
    head, upper, chain = table
    return n_lattice + _edge_of(head, upper, chain, min(p, q), max(p, q))


@nb.njit(cache=True, inline="always")
def _emit(out, k, v0, v1, v2, v3):
    out[k, 0] = v0
    out[k, 1] = v1
    out[k, 2] = v2
    out[k, 3] = v3
    return k + 1


@nb.njit(cache=True, inline="always")
def _sign_pattern(tets, t, signs, plus, zero, minus):
    """Split tet t's vertices by sign into plus, zero, minus; returns their counts (n_p, n_z, n_m)."""
    n_p = 0
    n_z = 0
    n_m = 0
    for i in range(4):
        v = tets[t, i]
        if signs[v] > 0:
            plus[n_p] = v
            n_p += 1
        elif signs[v] < 0:
            minus[n_m] = v
            n_m += 1
        else:
            zero[n_z] = v
            n_z += 1
    return n_p, n_z, n_m


@nb.njit(cache=True, inline="always")
def _prism_choice(coords, plus, minus, n_p, prism, first_centre):
    """Quad diagonals (PRISM_TETS index) of the prism of a ++-- or +++- tet; -1 when the three
    quads' rules cycle, which they never do on lattice tets of any spacing and transition
    templates (tests/test_stuffing.py tries every tet and outside vertex of random octrees).

    ++--: prism (a, cut ac, cut ad | b, cut bc, cut bd); quads 0 = (a, cut ac, cut bc, b) and
    2 = (cut ad, a, b, cut bd) lie on the faces abc and abd, quad 1 on the cut surface is free:
    the two face rules leave it one non-cyclic choice.  +++-: prism (p0, p1, p2 | their cuts to
    the minus vertex), every quad on a face of the tet."""
    choice = 0
    if n_p == 2:
        a = plus[0]
        b = plus[1]
        if not _quad_first_diagonal(coords, a, b, minus[0], first_centre):
            choice |= 1
        if _quad_first_diagonal(coords, a, b, minus[1], first_centre):
            choice |= 4
        if prism[choice, 0, 0] < 0:
            choice |= 2
        return choice
    for i in range(3):
        if not _quad_first_diagonal(coords, plus[i], plus[(i + 1) % 3], minus[0], first_centre):
            choice |= 1 << i
    return choice if prism[choice, 0, 0] >= 0 else -1


@nb.njit(cache=True, inline="always")
def _stencil_size(n_p, n_z, n_m):
    """Number of tets the stencil of a sign pattern emits (see _stencil_tet)."""
    if n_p == 0:
        return 0
    if n_m == 0 or n_p == 1:
        return 1
    if n_p == 2 and n_z == 1:
        return 2
    return 3  # the prisms: ++-- and +++-


@nb.njit(cache=True, inline="always")
def _tet_stencil_size(tets, t, signs):
    """Number of tets lattice tet t's stencil emits, from its sign pattern (counts only,
    without branches: _sign_pattern lists the vertices too)."""
    n_p = 0
    n_m = 0
    for i in range(4):
        s = signs[tets[t, i]]
        n_p += s > 0
        n_m += s < 0
    return _stencil_size(n_p, 4 - n_p - n_m, n_m)


@nb.njit(cache=True, parallel=True)
def _stencil_offsets(tets, signs):
    """Offsets (T + 1,) int64 of the lattice tets' stencils, each counted from its sign
    pattern alone: lattice tet t's tets are out[offsets[t]:offsets[t + 1]].  (Counts in an
    array of their own, then numpy's cumsum, wrote 8 more bytes a lattice tet to fresh pages.)"""
    n = tets.shape[0]
    offsets = np.empty(n + 1, dtype=np.int64)
    offsets[0] = 0
    n_chunks = min(n, 256)
    for chunk in nb.prange(n_chunks):
        for t in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            offsets[t + 1] = _tet_stencil_size(tets, t, signs)
    for t in range(n):
        offsets[t + 1] += offsets[t]
    return offsets


@nb.njit(cache=True, parallel=True)
def _chunk_starts(tets, signs, n_chunks):
    """starts (n_chunks + 1,) int64: the first output row of each chunk of the lattice tets
    (chunk c: tets c * T // n_chunks up to the next chunk's), starts[-1] the total; what
    _stencil_offsets gives at the chunks' first tets, without a row per lattice tet (8 bytes a
    lattice tet of fresh pages that only mending reads)."""
    n = tets.shape[0]
    starts = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in nb.prange(n_chunks):
        total = 0
        for t in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            total += _tet_stencil_size(tets, t, signs)
        starts[c + 1] = total
    for c in range(n_chunks):
        starts[c + 1] += starts[c]
    return starts


@nb.njit(cache=True, inline="always")
def _stencil_tet(t, tets, signs, coords, first_centre, table, n_lattice, prism, out, k, scratch):
    """Write the stencil tets of lattice tet t, with two or three vertices inside and one or
    two outside (the quads and prisms; _stencils does the other patterns), from out[k] on;
    returns how many (2 or 3), or -3 if the quad rule gave a prism cyclic diagonals and none
    were written (which it must never do; the caller raises, as a parallel loop cannot)."""
    plus = scratch[0]
    zero = scratch[1]
    minus = scratch[2]
    pv = scratch[3]
    n_p, n_z, n_m = _sign_pattern(tets, t, signs, plus, zero, minus)
    if n_p == 2 and n_z == 1:
        a = plus[0]
        b = plus[1]
        z = zero[0]
        e = minus[0]
        cae = _cut_id(table, n_lattice, a, e)
        cbe = _cut_id(table, n_lattice, b, e)
        if _quad_first_diagonal(coords, a, b, e, first_centre):
            _emit(out, k, z, a, b, cbe)
            _emit(out, k + 1, z, a, cbe, cae)
        else:
            _emit(out, k, z, a, b, cae)
            _emit(out, k + 1, z, b, cbe, cae)
        return 2
    # Prisms: 2 + and 2 -, or 3 + and 1 -, laid out as PRISM_TETS expects.
    if n_p == 2:
        for i in range(2):
            pv[3 * i] = plus[i]
            pv[3 * i + 1] = _cut_id(table, n_lattice, plus[i], minus[0])
            pv[3 * i + 2] = _cut_id(table, n_lattice, plus[i], minus[1])
    else:
        for i in range(3):
            pv[i] = plus[i]
            pv[3 + i] = _cut_id(table, n_lattice, plus[i], minus[0])
    choice = _prism_choice(coords, plus, minus, n_p, prism, first_centre)
    if choice < 0:
        return -3
    for i in range(3):
        _emit(out, k + i, pv[prism[choice, i, 0]], pv[prism[choice, i, 1]], pv[prism[choice, i, 2]], pv[prism[choice, i, 3]])
    return 3


@nb.njit(cache=True)
def _stencils(tets, signs, coords, first_centre, table, n_lattice, prism, start, out, touched):
    """Stencil tets of the lattice tets, in order, into out from row ``start`` on; touched[k]
    is False for output tets that are untouched lattice tets.  Returns the number of lattice
    tets whose prism came out with cyclic diagonals (must be 0).

    Serial: _stencil_tet must be inlined (called, it cost 140 ns a tet), and inlined into a
    parallel loop it tripled the compile time (34 s).  _stencils_in_chunks runs this kernel on
    chunks in parallel instead: 2.5-3 x faster on two cores (round_rod at diag/80, 4.6 M
    lattice tets: 237 against 93 ms).  The tets are oriented in a pass of their own (_orient):
    orienting each here as it is written took plate_holes at diag/80 2.9 against 1.9 ms."""
    cyclic = 0
    scratch = np.empty((4, 6), dtype=np.int64)
    k = start
    for t in range(tets.shape[0]):
        s0, s1, s2, s3 = signs[tets[t, 0]], signs[tets[t, 1]], signs[tets[t, 2]], signs[tets[t, 3]]
        lowest = min(min(s0, s1), min(s2, s3))
        highest = max(max(s0, s1), max(s2, s3))
        # The patterns of one tet here, not through _stencil_tet: a pass through it cost about
        # 40 ns even for these (round_rod's band at diag/40, 0.71 M lattice tets, four fifths
        # of them such: 15.1 -> 4.2 ms).
        if highest <= 0:
            continue  # no vertex inside: no tet
        if lowest >= 0:
            for i in range(4):  # no vertex outside: copied, touched if a vertex is warped
                out[k, i] = tets[t, i]
            touched[k] = lowest == 0
            k += 1
            continue
        if (s0 > 0) + (s1 > 0) + (s2 > 0) + (s3 > 0) == 1:
            # One vertex inside: each outside vertex moves to the cut on its edge to it
            # (orientation kept).
            a = tets[t, 0] if s0 > 0 else (tets[t, 1] if s1 > 0 else (tets[t, 2] if s2 > 0 else tets[t, 3]))
            for i in range(4):
                v = tets[t, i]
                out[k, i] = _cut_id(table, n_lattice, a, v) if signs[v] < 0 else v
            touched[k] = True
            k += 1
            continue
        n = _stencil_tet(t, tets, signs, coords, first_centre, table, n_lattice, prism, out, k, scratch)
        if n < 0:
            cyclic += 1
            n = -n
        for i in range(k, k + n):
            touched[i] = True
        k += n
    return cyclic


@nb.njit(cache=True, parallel=True)
def _stencils_in_chunks(tets, signs, coords, first_centre, table, n_lattice, prism, starts, out, touched):
    """_stencils over chunks of the lattice tets in parallel (chunk c: tets c * T // C up to
    the next chunk's, written from out[starts[c]] on, C = len(starts) - 1: _chunk_starts), each
    chunk writing only its own rows of out, so the result is the same.  The serial kernel is
    called, not inlined, so the parallel loop compiles in seconds."""
    n = tets.shape[0]
    n_chunks = starts.shape[0] - 1
    cyclic = np.zeros(max(n_chunks, 1), dtype=np.int64)
    for c in nb.prange(n_chunks):
        a = c * n // n_chunks
        b = (c + 1) * n // n_chunks
        cyclic[c] = _stencils(tets[a:b], signs, coords, first_centre, table, n_lattice, prism, starts[c], out, touched)
    return cyclic.sum()


@nb.njit(cache=True, inline="always")
def _volume6(points, lattice_points, tets, t, reference):
    """Six times the signed volume of tet t: at points (V + E, 3), where stuffing put its
    vertices, or (reference) before the warps, its lattice vertices (ids below V) at
    lattice_points (V, 3) and its cut points (which do not move) at points.

    The array is picked once a vertex, then its row read: picked a coordinate at a time (one
    choice of two arrays per read), a serial loop such as _star_score's compiled 12-30 x
    slower than the same body in a parallel one (plate_holes at diag/80, 117 k tets: 17
    against 0.6 ms)."""
    n = lattice_points.shape[0] if reference else 0
    v = tets[t, 0]
    at = lattice_points if v < n else points
    o0, o1, o2 = at[v, 0], at[v, 1], at[v, 2]
    v = tets[t, 1]
    at = lattice_points if v < n else points
    ax, ay, az = at[v, 0] - o0, at[v, 1] - o1, at[v, 2] - o2
    v = tets[t, 2]
    at = lattice_points if v < n else points
    bx, by, bz = at[v, 0] - o0, at[v, 1] - o1, at[v, 2] - o2
    v = tets[t, 3]
    at = lattice_points if v < n else points
    cx, cy, cz = at[v, 0] - o0, at[v, 1] - o1, at[v, 2] - o2
    return ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)


@nb.njit(cache=True, inline="always")
def _orient_tet(points, lattice_points, tets, t):
    """Order tet t (a stencil piece of a lattice tet) so that it is positive before the warps,
    when it is a proper part of its lattice tet; returns its signed volume after them (six
    times): not positive means the warps folded or flattened it."""
    if _volume6(points, lattice_points, tets, t, True) < 0:
        tmp = tets[t, 2]
        tets[t, 2] = tets[t, 3]
        tets[t, 3] = tmp
    return _volume6(points, lattice_points, tets, t, False)


@nb.njit(cache=True, parallel=True)
def _orient(points, lattice_points, tets, touched):
    """Orient every touched tet by its volume before the warps (_orient_tet); returns how many
    are not positive after them.  (Untouched lattice tets are positive by construction.)
    Orienting by the warped volume instead would turn a folded tet into a positive one that
    overlaps its neighbours."""
    folded = 0
    for t in nb.prange(tets.shape[0]):
        if touched[t] and _orient_tet(points, lattice_points, tets, t) <= 0:
            folded += 1
    return folded


def _warped(lattice_points: np.ndarray, inside: np.ndarray, cuts: CutEdges,
            targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (V + E, 3): the lattice vertices where the warps put them, then the cut points;
    and signs (V,) int8: +1 inside, -1 outside, 0 warped onto the surface."""
    return _warped_points(lattice_points, cuts.points, targets), _signs(inside, targets)


@nb.njit(cache=True, parallel=True)
def _warped_points(lattice_points, cut_points, targets):
    """_warped's points in one parallel pass (numpy's concatenate and boolean gather, with the
    signs, took 25 ms on a 1.2 M-tet band)."""
    n = lattice_points.shape[0]
    points = np.empty((n + cut_points.shape[0], 3))
    for v in nb.prange(n):
        w = targets[v]
        for i in range(3):
            points[v, i] = cut_points[w, i] if w >= 0 else lattice_points[v, i]
    for e in nb.prange(cut_points.shape[0]):
        for i in range(3):
            points[n + e, i] = cut_points[e, i]
    return points


@nb.njit(cache=True, parallel=True)
def _signs(inside, targets):
    """Signs (V,) int8 of the lattice vertices: +1 inside, -1 outside, 0 warped (targets >= 0)."""
    signs = np.empty(inside.shape[0], dtype=np.int8)
    for v in nb.prange(inside.shape[0]):
        signs[v] = 0 if targets[v] >= 0 else (1 if inside[v] else -1)
    return signs


def stuff(lattice_points: np.ndarray, coords: np.ndarray, tets: np.ndarray, inside: np.ndarray,
          cuts: CutEdges, targets: np.ndarray, *, flat_ok: bool = False, first_centre: int | None = None,
          with_offsets: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Warp and fill: the stuffed mesh (points (N, 3) float64, tets (M, 4) int32), unused points
    kept, and offsets (T + 1,) int64: lattice tet t's tets are tets[offsets[t]:offsets[t + 1]]
    (None unless with_offsets: only mending, restuff, reads them).

    lattice_points: (V, 3) space positions of the lattice vertices; coords: (V, 3) their
    lattice coordinates; tets: (T, 4) lattice tets; inside: (V,) class of each vertex;
    cuts: the cut edges of these tets; targets: warp_targets(cuts, coords, h).
    Points V.. V+E-1 are the cut points (only those still on a +/- edge are used).  Every tet
    is oriented as its piece of the lattice tet is before the warps, so one the warps fold
    has negative volume.  A flat or folded tet is a bug on a one-level band (AssertionError);
    flat_ok keeps it, for a band that changes level, whose caller measures every tet and
    mends or refines where one is bad (retarget_warps).  first_centre: the vertices from
    this id up are face centres that are no leaf's corner (LeafVertices.first_centre; None:
    there are none), which the quad rule on template faces puts last (_quad_first_diagonal).
    """
    points, signs = _warped(lattice_points, inside, cuts, targets)
    out, offsets = _stencils_of(points, lattice_points, coords, int32_ids(tets), signs, cuts, flat_ok,
                                _first_centre(first_centre, lattice_points), with_offsets)
    return points, out, offsets


def _first_centre(first_centre: int | None, lattice_points: np.ndarray) -> int:
    return lattice_points.shape[0] if first_centre is None else int(first_centre)


def _stencils_of(points, lattice_points, coords, tets, signs, cuts: CutEdges, flat_ok: bool, first_centre: int,
                 with_offsets: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """The stencil tets (M, 4) int32 of the lattice tets (T, 4), in order, oriented (stuff),
    and if with_offsets, offsets (T + 1,): lattice tet t's are out[offsets[t]:offsets[t + 1]]
    (else None)."""
    n_chunks = min(tets.shape[0], TET_CHUNKS)
    if with_offsets:
        offsets = _stencil_offsets(tets, signs)
        starts = np.take(offsets, np.arange(n_chunks + 1) * tets.shape[0] // max(n_chunks, 1))
    else:
        offsets, starts = None, _chunk_starts(tets, signs, n_chunks)
    out = np.empty((int(starts[-1]), 4), dtype=np.int32)
    touched = np.empty(out.shape[0], dtype=np.bool_)
    if _stencils_in_chunks(tets, signs, coords, first_centre, cuts.table, lattice_points.shape[0], PRISM_TETS, starts,
                           out, touched):
        raise AssertionError("cyclic prism diagonals: the quad rule must never produce them")
    folded = _orient(points, lattice_points, out, touched)
    if folded and not flat_ok:
        raise AssertionError(f"stuffing produced {folded} flat or folded tets")
    return out, offsets


def restuff(lattice_points: np.ndarray, coords: np.ndarray, tets: np.ndarray, inside: np.ndarray, cuts: CutEdges,
            targets: np.ndarray, out: np.ndarray, new_targets: np.ndarray, *, offsets: np.ndarray,
            flat_ok: bool = False, points: np.ndarray | None = None, flags: np.ndarray | None = None,
            rows: np.ndarray | None = None,
            first_centre: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """stuff(..., new_targets), given out, offsets = stuff(..., targets)[1:]: only the lattice
    tets with a vertex whose warp changed are stuffed again; the others' tets move up or down
    in out, in place, and so do their flags (M,) uint8 (any per-tet bytes of the caller's;
    None: none).  out, offsets and flags are overwritten: the results are them, or views of
    them, unless the new tets are more (rare: warps changed to mend bad tets mostly cut
    fewer), and then new arrays.  (A copy into new arrays, as before, faulted in 63 MB a call
    on fea_part's 2.7 M tets at diag/80, and was the mesh's peak.)  points: stuff's
    points for new_targets if the caller has them (retarget_warps updates stuff's in place),
    else computed.  rows: the lattice tets with a vertex whose warp changed, ascending, if the
    caller has them (Retargeted.rows), else found by a scan of every lattice tet.
    first_centre: as for stuff.

    Returns (points, tets (M', 4) int32, again, offsets, flags (M',)): the same points, tets
    and offsets as stuff with new_targets; again: the indices (ascending) of the tets stuffed
    again, whose flags are 0, the others' kept.
    """
    tets = int32_ids(tets)
    if offsets.shape[0] != tets.shape[0] + 1 or offsets[-1] != out.shape[0]:
        raise ValueError(f"len(offsets) = {offsets.shape[0]} ending at {offsets[-1]}, but {tets.shape[0]} lattice tets "
                         f"stuffed into len(out) = {out.shape[0]}")
    flags = np.zeros(out.shape[0], dtype=np.uint8) if flags is None else flags
    if flags.shape != (out.shape[0],) or flags.dtype != np.uint8:
        raise ValueError(f"flags: shape {flags.shape}, dtype {flags.dtype}; expected ({out.shape[0]},) uint8")
    if points is None:
        points = _warped_points(lattice_points, cuts.points, new_targets)
    signs = _signs(inside, new_targets)
    if rows is None:
        rows = np.flatnonzero(touching(tets, new_targets != targets))
    again, again_offsets = _stencils_of(points, lattice_points, coords, np.take(tets, rows, axis=0), signs, cuts,
                                        flat_ok, _first_centre(first_centre, lattice_points), True)
    assert again_offsets is not None  # asked for
    shift = _row_shifts(offsets, rows, again_offsets)
    total = int(offsets[-1] + shift[-1])
    if total > out.shape[0]:
        out = np.concatenate([out, np.empty((total - out.shape[0], 4), dtype=np.int32)])
        flags = np.concatenate([flags, np.zeros(total - flags.shape[0], dtype=np.uint8)])
    _move_kept(out, flags, offsets, rows, shift)
    _shift_offsets(offsets, rows, shift)
    starts = np.take(offsets, rows)
    _place_again(out, flags, starts, again, again_offsets)
    stuffed = np.repeat(starts - again_offsets[:-1], np.diff(again_offsets)) + np.arange(again_offsets[-1])
    return points, out[:total], stuffed, offsets, flags[:total]


def _row_shifts(offsets: np.ndarray, rows: np.ndarray, again_offsets: np.ndarray) -> np.ndarray:
    """shift (R + 1,) int64: how far the tets after lattice tets rows[:j] (sorted) move once
    those have again_offsets' counts instead of offsets' (what their new counts add)."""
    shift = np.zeros(rows.shape[0] + 1, dtype=np.int64)
    np.cumsum(np.diff(again_offsets) - (np.take(offsets, rows + 1) - np.take(offsets, rows)), out=shift[1:])
    return shift


@nb.njit(cache=True)
def _move_rows(out, flags, start, end, shift):
    """Rows start..end - 1 of out and flags moved by shift, overlap-safe (memmove)."""
    step = -1 if shift > 0 else 1
    first, last = (end - 1, start - 1) if shift > 0 else (start, end)
    for i in range(first, last, step):
        for k in range(4):
            out[i + shift, k] = out[i, k]
        flags[i + shift] = flags[i]


@nb.njit(cache=True)
def _move_kept(out, flags, offsets, rows, shift):
    """Move the tets of the lattice tets between rows (sorted; runs of them, each one block of
    out) by shift (_row_shifts: block j by shift[j]).  Blocks moving up go
    first, from the last; then those moving down, from the first: a block's destination then
    never holds tets not yet moved (destinations keep the blocks' order, and a block moving
    up ends before the next block moving down starts)."""
    n_rows = rows.shape[0]
    n = offsets.shape[0] - 1
    start = np.empty(n_rows + 1, dtype=np.int64)
    end = np.empty(n_rows + 1, dtype=np.int64)
    for j in range(n_rows + 1):
        start[j] = offsets[0 if j == 0 else rows[j - 1] + 1]
        end[j] = offsets[rows[j] if j < n_rows else n]
    for j in range(n_rows, -1, -1):
        if shift[j] > 0:
            _move_rows(out, flags, start[j], end[j], shift[j])
    for j in range(n_rows + 1):
        if shift[j] < 0:
            _move_rows(out, flags, start[j], end[j], shift[j])


@nb.njit(cache=True, parallel=True)
def _shift_offsets(offsets, rows, shift):
    """offsets (T + 1,), in place, once lattice tets rows (sorted) have their new counts
    (_row_shifts' shift: what rows[:j] add); in chunks of lattice tets, each starting from the
    shift of the rows before it."""
    n = offsets.shape[0] - 1
    n_chunks = min(n, TET_CHUNKS)
    for c in nb.prange(n_chunks):
        t0 = c * n // n_chunks
        j = np.searchsorted(rows, t0)
        for t in range(t0, (c + 1) * n // n_chunks):
            offsets[t] += shift[j]
            if j < rows.shape[0] and rows[j] == t:
                j += 1
    offsets[n] += shift[rows.shape[0]]


@nb.njit(cache=True)
def _place_again(out, flags, starts, again, again_offsets):
    """The tets stuffed again, again[again_offsets[j]:again_offsets[j + 1]], into out from
    starts[j] on, their flags 0."""
    for j in range(starts.shape[0]):
        for i in range(again_offsets[j + 1] - again_offsets[j]):
            for k in range(4):
                out[starts[j] + i, k] = again[again_offsets[j] + i, k]
            flags[starts[j] + i] = 0


@nb.njit(cache=True)
def _star_score(star, tets, signs, points, lattice_points, coords, first_centre, table, prism, lo, hi):
    """(worst violation of [lo, hi] in degrees, smallest 3r/R) over the stencil tets
    of the lattice tets star, stuffed with these signs and points (lattice vertices where the
    warps put them, then the cut points); a tet folded or flattened by the warps (see
    _orient_tet; or with an angle of 0 or 180 degrees) or a cyclic prism violates by 180.
    Calls _stencils rather than inlining _stencil_tet again, which would cost most of a
    minute of compile time."""
    local = tets[star]
    total = 0
    for t in range(star.shape[0]):
        total += _tet_stencil_size(local, t, signs)
    out = np.empty((total, 4), dtype=np.int32)
    touched = np.empty(out.shape[0], dtype=np.bool_)
    if _stencils(local, signs, coords, first_centre, table, lattice_points.shape[0], prism, np.int64(0), out, touched):
        return 180.0, 0.0
    worst = 0.0
    thinnest = 1.0
    cos_lo = math.cos(math.radians(lo))
    cos_hi = math.cos(math.radians(hi))
    corners = np.empty((12, 1))
    measured = np.empty((4, 1))
    for k in range(out.shape[0]):
        if not touched[k]:
            continue  # a whole lattice tet no cut or warp touches
        if _orient_tet(points, lattice_points, out, k) <= 0:
            return 180.0, 0.0
        _gather(points, out, k, 1, corners)
        _measure_block(corners, 1, measured)
        # Angles in [lo, hi] add nothing to worst (acos only near or past a bound).
        if _degrees_below(measured[_COS_HI, 0], cos_lo, lo) or _degrees_above(measured[_COS_LO, 0], cos_hi, hi):
            small = _degrees(measured[_COS_HI, 0])
            large = _degrees(measured[_COS_LO, 0])
            if small <= 0.0 or large >= 180.0:
                return 180.0, 0.0  # flat to rounding
            worst = max(worst, lo - small, large - hi)
        thinnest = min(thinnest, measured[_RATIO, 0])
    return worst, thinnest


@nb.njit(cache=True)
def _set_warp(v, e, signs, targets, points, lattice_points, inside):
    """Warp lattice vertex v onto the cut point of cut edge e, or (e = -1) put it back."""
    n_lattice = lattice_points.shape[0]
    targets[v] = e
    signs[v] = 0 if e >= 0 else (1 if inside[v] else -1)
    for c in range(3):
        points[v, c] = points[n_lattice + e, c] if e >= 0 else lattice_points[v, c]


@nb.njit(cache=True)
def _retarget(vertices, visit, star_first, stars, option_first, options, tets, signs, targets, points,
              lattice_points, inside, coords, first_centre, table, prism, lo, hi, min_ratio, sweeps):
    """Greedy local search: for each vertex whose star has a stencil tet outside [lo, hi] or
    with 3r/R below min_ratio, the warp (none, or onto the cut point of one of its cut edges)
    that brings the star's worst violation lowest, ties to the largest smallest 3r/R (needles:
    their angles can be good), then to the option tried first; sweeps until nothing changes.
    Each sweep visits vertices[visit[0]], vertices[visit[1]], ... (vertices: sorted ids;
    visit: retarget_warps' order of their coordinates).  Changes signs, targets and points in
    place.  Returns whether the last sweep moved no vertex (settled).

    A vertex whose star's vertices have not moved since it was last visited is skipped: its
    star scores as then, and the choice it made then (the first best) stays the first best.
    So once a sweep moves none, every vertex holds the first best warp for the warps around
    it, and a search over any of them from there moves none either (Retargeted.settled)."""
    n = vertices.shape[0]
    moved_at = np.zeros(n, dtype=np.int64)  # the move count just after vertices[i] last moved
    visited_at = np.full(n, -1, dtype=np.int64)  # the move count when vertices[i] was last visited
    moves = 0
    moved = 0
    for _ in range(sweeps):
        moved = 0
        for i in visit:
            v = vertices[i]
            star = stars[star_first[i]:star_first[i + 1]]
            if visited_at[i] >= 0 and not _star_moved_since(star, tets, vertices, moved_at, visited_at[i]):
                continue
            worst, thinnest = _star_score(star, tets, signs, points, lattice_points, coords, first_centre, table,
                                          prism, lo, hi)
            visited_at[i] = moves
            if worst <= 0 and thinnest >= min_ratio:
                continue
            current = targets[v]
            best, best_thinnest, best_target = worst, thinnest, current
            for j in range(option_first[i], option_first[i + 1] + 1):
                e = options[j] if j < option_first[i + 1] else -1
                if e == current:
                    continue
                _set_warp(v, e, signs, targets, points, lattice_points, inside)
                w, r = _star_score(star, tets, signs, points, lattice_points, coords, first_centre, table, prism,
                                   lo, hi)
                if w < best or (w == best and r > best_thinnest):
                    best, best_thinnest, best_target = w, r, e
            _set_warp(v, best_target, signs, targets, points, lattice_points, inside)
            if best_target != current:
                moved += 1
                moves += 1
                moved_at[i] = moves
                visited_at[i] = moves
        if moved == 0:
            break
    return moved == 0


@nb.njit(cache=True)
def _star_moved_since(star, tets, vertices, moved_at, since):
    """Whether a vertex of the tets star (rows of tets) is one of vertices (sorted) that
    moved after move count since (_retarget)."""
    for t in star:
        for k in range(4):
            i = np.searchsorted(vertices, tets[t, k])
            if i < vertices.shape[0] and vertices[i] == tets[t, k] and moved_at[i] > since:
                return True
    return False


@nb.njit(cache=True)
def _group_by_vertex(vertices, marked, owners):
    """Rows of owners (N, K) grouped by the marked vertices they hold (vertices: the marked
    ones, sorted): group i, the rows holding vertices[i], is grouped[first[i]:first[i + 1]],
    column by column, each column's rows in order (count, prefix sum, fill).  Returns
    (first (G + 1,), grouped) int64."""
    first = np.zeros(vertices.shape[0] + 1, dtype=np.int64)
    for c in range(owners.shape[1]):
        for r in range(owners.shape[0]):
            if marked[owners[r, c]]:
                first[np.searchsorted(vertices, owners[r, c]) + 1] += 1
    for i in range(vertices.shape[0]):
        first[i + 1] += first[i]
    fill = first[:-1].copy()
    grouped = np.empty(first[-1], dtype=np.int64)
    for c in range(owners.shape[1]):
        for r in range(owners.shape[0]):
            if marked[owners[r, c]]:
                i = np.searchsorted(vertices, owners[r, c])
                grouped[fill[i]] = r
                fill[i] += 1
    return first, grouped


@nb.njit(cache=True)
def _star_options(vertices, star_first, stars, tets, coords, head, upper, chain):
    """The cut edges of each vertex, in order of their other ends' lattice coordinates
    (_coords_less): group i, those of vertices[i], is options[first[i]:first[i + 1]].  The
    order, the one retarget_warps tries them in and its first best among equals, follows the
    points, not their ids.  Each vertex's edges are found through the edge table
    (collect_cut_edges' head, upper, chain) from the tets of its star
    (stars[star_first[i]:star_first[i + 1]], rows of tets): every cut edge is an edge of
    the tets it came from.  Returns (first (G + 1,), options) int64."""
    n = vertices.shape[0]
    first = np.zeros(n + 1, dtype=np.int64)
    found = np.empty(0, dtype=np.int64)
    longest = 0
    for i in range(n):
        longest = max(longest, star_first[i + 1] - star_first[i])
    edges = np.empty(3 * longest, dtype=np.int64)  # a vertex's distinct edges so far, in order
    others = np.empty(3 * longest, dtype=np.int64)  # their other ends
    for fill in range(2):
        if fill:
            for i in range(n):
                first[i + 1] += first[i]
            found = np.empty(first[n], dtype=np.int64)
        for i in range(n):
            v = vertices[i]
            m = 0
            for t in stars[star_first[i]:star_first[i + 1]]:
                for k in range(4):
                    w = tets[t, k]
                    if w == v:
                        continue
                    e = _edge_of(head, upper, chain, min(v, w), max(v, w))
                    if e < 0:
                        continue
                    j = m  # insertion into the few edges so far
                    while j > 0 and _coords_less(coords, w, others[j - 1]):
                        j -= 1
                    if j > 0 and others[j - 1] == w:
                        continue
                    for q in range(m, j, -1):
                        edges[q] = edges[q - 1]
                        others[q] = others[q - 1]
                    edges[j] = e
                    others[j] = w
                    m += 1
            if fill:
                found[first[i]:first[i] + m] = edges[:m]
            else:
                first[i + 1] = m
    return first, found


#: Passes over the candidate vertices retarget_warps makes at most.
RETARGET_SWEEPS = 4


@dataclass(frozen=True)
class Retargeted:
    """What retarget_warps found.  targets: (V,) int64 the new warp targets; changed: how many
    vertices warp elsewhere; rows: (R,) int64 ascending, the lattice tets with such a vertex
    (restuff's rows); searched: (S,) int64 ascending, the vertices searched (those of the
    lattice tets that gave the bad tets); settled: whether the search's last sweep moved
    none of them.  A settled search leaves each searched vertex at the first best warp for
    the warps around it, so searching any of them again, with no other warp changed, moves
    none (retarget_warps' settled skips that search)."""

    targets: np.ndarray
    changed: int
    rows: np.ndarray
    searched: np.ndarray
    settled: bool


def _coords_order(coords: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """The permutation (len(vertices),) int64 that puts vertices in lexicographic order of
    their lattice coordinates coords (V, 3) (x, then y, then z: _coords_less's order)."""
    c = np.take(coords, vertices, axis=0)
    return np.lexsort((c[:, 2], c[:, 1], c[:, 0])).astype(np.int64)


def _bad_tet_vertices(tets: np.ndarray, offsets: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """The vertices (ascending, int64) of the lattice tets (T, 4) that stuffed tets ``bad`` (indices
    into stuff's output, whose lattice tet t's tets start at offsets[t]) came from: the vertices
    retarget_warps searches."""
    owners = np.searchsorted(offsets, bad, side="right") - 1
    return np.unique(np.take(tets, owners, axis=0).ravel()).astype(np.int64)


def retarget_warps(lattice_points: np.ndarray, coords: np.ndarray, tets: np.ndarray, inside: np.ndarray,
                   cuts: CutEdges, targets: np.ndarray, bad: np.ndarray, min_ratio: float = 0.0, *,
                   offsets: np.ndarray, points: np.ndarray | None = None,
                   settled: np.ndarray | None = None, first_centre: int | None = None) -> Retargeted:
    """Mend stuffed tets outside DIHEDRAL_BOUND (and needles: 3r/R below min_ratio) by choosing
    other warps near them.

    Where the band changes level the Labelle-Shewchuk warp rule proves nothing, and a few
    stuffed tets fall outside the bound (docs/design.md, "Thin features").  A warp moves one
    lattice vertex and changes only the stencils of the lattice tets around it (its star),
    so each vertex of the lattice tets that gave the bad tets may instead warp onto the cut
    point of any of its cut edges, or not at all; the choice that leaves its star's worst
    angle least outside the bound is kept (_retarget), among equals the one with the fattest
    star by 3r/R.  The vertices are visited, and their cut edges tried, in order of lattice
    coordinates, so the result is the same however the points are numbered (a partition
    numbers its own).  Tets the warps would fold count as outside.  Arguments as for stuff, and
    bad: indices of the bad tets (outside the bound or needles) in stuff's output, offsets:
    stuff's (where each lattice tet's tets start in it); points: stuff's points, if the caller
    has them, which are then updated in place to the new warps (restuff takes them), saving a
    copy of (V + E, 3); else they are computed.  settled: the vertices (ascending) of the
    caller's last search if it settled and no warp changed since (Retargeted.searched): when
    every vertex to search is among them, the search is known to move none and is skipped
    (the result's targets are then targets itself).  first_centre: as for stuff.
    Returns a Retargeted (the new warp targets, the lattice tets to stuff again for them:
    restuff's rows); the caller stuffs again and measures: this is a search, it certifies
    nothing.
    """
    tets = int32_ids(tets)
    vertices = _bad_tet_vertices(tets, offsets, bad)
    if settled is not None and np.isin(vertices, settled).all():
        return Retargeted(targets, 0, np.empty(0, dtype=np.int64), vertices, True)
    new = targets.copy()
    if points is None:
        points = _warped_points(lattice_points, cuts.points, targets)
    signs = _signs(inside, targets)
    marked = np.zeros(lattice_points.shape[0], dtype=np.bool_)
    marked[vertices] = True
    rows = np.flatnonzero(touching(tets, marked))
    star_first, star_rows = _group_by_vertex(vertices, marked, np.take(tets, rows, axis=0))
    stars = rows[star_rows]
    # The vertices are visited, and their cut edges tried, in order of coordinates: the
    # search's greedy choices then follow the points, however they are numbered.
    option_first, options = _star_options(vertices, star_first, stars, tets, coords, *cuts.table)
    settled = _retarget(vertices, _coords_order(coords, vertices), star_first, stars, option_first, options, tets,
                        signs, new, points, lattice_points, inside, coords, _first_centre(first_centre, lattice_points),
                        cuts.table, PRISM_TETS, DIHEDRAL_BOUND[0], DIHEDRAL_BOUND[1], float(min_ratio),
                        RETARGET_SWEEPS)
    # Only the searched vertices move; the lattice tets to stuff again are their stars.
    moved = np.take(new, vertices) != np.take(targets, vertices)
    in_moved_star = np.repeat(moved, np.diff(star_first))
    rows_again = np.unique(np.compress(in_moved_star, stars))
    return Retargeted(new, int(np.count_nonzero(moved)), rows_again, vertices, bool(settled))
