"""Closure templates for coarse leaves next to finer ones (2:1-balanced octrees).

A coarse leaf whose neighbours are finer has lattice vertices in the middle of some of its
cube edges (corners of the finer leaves).  Following docs/transitions.md (where the table
was found by exhaustive search and verified on all 628 leaf-pattern orbits under both rules):

* a face-centre rule decides which leaf faces get their centre as a vertex (a point of the
  finer lattice, decided from the face's four cube edges, so the decision never spreads).
  A finer face always has it (it is a corner of the finer leaves).  Otherwise, *minimal*:
  the two face edges at one of the face's off-diagonal corners are split; *eager*: any face
  edge is split (FACE_CENTRE_RULES; lattice.number_vertices applies eager to the faces of
  marked leaves, minimal to the rest);
* each of the leaf's six Freudenthal tets, written as its chain v0 = 0, v1, v2, v3 = 7 of
  corners sorted by popcount, is replaced by the template of its 5-bit split mask
  ``e01 | e12 << 1 | e23 << 2 | e02 << 3 | e13 << 4`` (e01, e12, e23 cube edges, e02 and
  e13 face diagonals whose midpoints are face centres; the main diagonal e03 is never
  split and the leaf centre never used).

Under the minimal rule 25 masks occur, with dihedral angles in [30, 120] degrees (30 exactly
where a lone split cube edge bisects a tet) and 3r/R >= 0.5444; under the eager rule 13,
in [35.26, 120], for more tets (more face centres).  No Steiner points: every vertex is a
corner, an edge midpoint or a face centre of the leaf.
"""

from __future__ import annotations

import numpy as np

#: Template vertex labels: 0..3 the chain corners v0..v3, then the midpoints
#: 4 = m01, 5 = m12, 6 = m23 (cube edges), 7 = m02, 8 = m13 (face centres).
V0, V1, V2, V3, M01, M12, M23, M02, M13 = range(9)

#: The 25 masks with a template meeting [30, 135] degrees, each tet positively oriented in
#: space for the chain (0, 1, 3, 7) (docs/transitions.md, TABLE).
TEMPLATES: dict[int, tuple[tuple[int, int, int, int], ...]] = {
    0: ((0, 1, 2, 3),),
    1: ((0, 2, 3, 4), (2, 1, 3, 4)),
    2: ((0, 2, 3, 5), (1, 0, 3, 5)),
    4: ((0, 1, 2, 6), (1, 0, 3, 6)),
    5: ((0, 3, 4, 6), (1, 2, 4, 6), (2, 0, 4, 6), (3, 1, 4, 6)),
    8: ((1, 0, 3, 7), (2, 1, 3, 7)),
    9: ((0, 3, 4, 7), (2, 1, 3, 7), (3, 1, 4, 7)),
    10: ((1, 0, 3, 7), (2, 3, 7, 5), (3, 1, 7, 5)),
    11: ((0, 3, 4, 7), (2, 3, 7, 5), (3, 1, 4, 5), (3, 4, 7, 5)),
    12: ((1, 0, 3, 7), (1, 2, 7, 6), (3, 1, 7, 6)),
    13: ((0, 3, 4, 7), (1, 2, 7, 6), (3, 1, 4, 7), (3, 1, 7, 6)),
    16: ((0, 1, 2, 8), (0, 2, 3, 8)),
    17: ((0, 2, 3, 8), (1, 2, 4, 8), (2, 0, 4, 8)),
    18: ((0, 1, 5, 8), (0, 2, 3, 8), (2, 0, 5, 8)),
    20: ((0, 1, 2, 8), (0, 3, 8, 6), (2, 0, 8, 6)),
    21: ((0, 3, 8, 6), (1, 2, 4, 8), (2, 0, 4, 8), (2, 0, 8, 6)),
    22: ((0, 1, 5, 8), (0, 3, 8, 6), (2, 0, 5, 6), (5, 0, 8, 6)),
    24: ((0, 1, 7, 8), (1, 2, 7, 8), (2, 3, 7, 8), (3, 0, 7, 8)),
    25: ((0, 4, 7, 8), (1, 2, 7, 8), (2, 3, 7, 8), (3, 0, 7, 8), (4, 1, 7, 8)),
    26: ((0, 1, 7, 8), (2, 3, 7, 8), (2, 7, 5, 8), (3, 0, 7, 8), (7, 1, 5, 8)),
    27: ((0, 4, 7, 8), (2, 3, 7, 8), (2, 7, 5, 8), (3, 0, 7, 8), (4, 1, 5, 8), (7, 4, 5, 8)),
    28: ((0, 1, 7, 8), (1, 2, 7, 8), (2, 7, 8, 6), (3, 0, 7, 8), (7, 3, 8, 6)),
    29: ((0, 4, 7, 8), (1, 2, 7, 8), (2, 7, 8, 6), (3, 0, 7, 8), (4, 1, 7, 8), (7, 3, 8, 6)),
    30: ((0, 1, 7, 8), (2, 7, 5, 6), (3, 0, 7, 8), (7, 1, 5, 8), (7, 3, 8, 6), (5, 7, 8, 6)),
    31: ((0, 4, 7, 8), (2, 7, 5, 6), (3, 0, 7, 8), (4, 1, 5, 8), (7, 3, 8, 6), (7, 4, 5, 8), (5, 7, 8, 6)),
}
#: The masks that occur under the eager face-centre rule (all 25 occur under the minimal one).
EAGER_MASKS = (0, 8, 9, 16, 20, 24, 25, 26, 27, 28, 29, 30, 31)
MAX_TEMPLATE_TETS = 7


def _template_arrays() -> tuple[np.ndarray, np.ndarray]:
    tets = np.zeros((32, MAX_TEMPLATE_TETS, 4), dtype=np.int64)
    counts = np.full(32, -1, dtype=np.int64)
    for mask, entry in TEMPLATES.items():
        counts[mask] = len(entry)
        tets[mask, : len(entry)] = entry
    return tets, counts


#: TEMPLATE_TETS[mask, :TEMPLATE_COUNTS[mask]] are the template's tets (labels as above);
#: TEMPLATE_COUNTS[mask] = -1 for a mask without a template.
TEMPLATE_TETS, TEMPLATE_COUNTS = _template_arrays()

#: The six Freudenthal chains 0 -> v1 -> v2 -> 7 (cube corners c at (c & 1, c >> 1 & 1, c >> 2 & 1)).
CHAINS = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]], dtype=np.int64)
#: Chains that are negatively oriented in space: swap two vertices of every template tet.
CHAIN_IS_ODD = np.array([False, True, True, False, False, True])


def split_point_index(c: int, d: int) -> int:
    """Index 0..17 of the midpoint of cube corners c, d: 0..11 for the cube edge along axis k
    at the other two coordinates (4 k + packed bits), 12..17 for the centre of face
    (axis k, side b) as 12 + 2 k + b when c, d are a face diagonal."""
    diff = c ^ d
    axes = [k for k in range(3) if diff >> k & 1]
    if len(axes) == 1:
        k = axes[0]
        others = [(c >> i) & 1 for i in range(3) if i != k]
        return 4 * k + others[0] + 2 * others[1]
    if len(axes) == 2:
        k = 3 - axes[0] - axes[1]
        return 12 + 2 * k + ((c >> k) & 1)
    raise ValueError(f"corners {c}, {d} are not a cube edge or face diagonal")


def _split_point_offsets() -> np.ndarray:
    """Offsets (18, 3) of the split points from the leaf anchor, in half sides."""
    out = np.zeros((18, 3), dtype=np.int64)
    for c in range(8):
        for d in range(8):
            if bin(c ^ d).count("1") in (1, 2):
                out[split_point_index(c, d)] = [((c >> i) & 1) + ((d >> i) & 1) for i in range(3)]
    return out


#: SPLIT_POINT_OFFSETS[i]: position of split point i at anchor + (side / 2) * offset.
SPLIT_POINT_OFFSETS = _split_point_offsets()
#: FACE_EDGES[f]: the four cube-edge split points bounding face f (f = 2 k + b).
FACE_EDGES = np.array(
    [[i for i in range(12) if SPLIT_POINT_OFFSETS[i, f // 2] == 2 * (f % 2)] for f in range(6)], dtype=np.int64
)
#: CHAIN_SPLITS[c]: split points of chain c's e01, e12, e23, e02, e13.
CHAIN_SPLITS = np.array(
    [[split_point_index(ch[i], ch[j]) for i, j in ((0, 1), (1, 2), (2, 3), (0, 2), (1, 3))] for ch in CHAINS],
    dtype=np.int64,
)


def _face_corner_edges() -> np.ndarray:
    """(6, 2, 2): for face f = 2 k + b, at each of its two off-diagonal corners q (in-plane bits
    (1, 0) and (0, 1); the face diagonal of the Freudenthal tets joins (0, 0) and (1, 1)), the
    split points of the two face edges meeting at q."""
    out = np.zeros((6, 2, 2), dtype=np.int64)
    for f in range(6):
        k, b = divmod(f, 2)
        i, j = [a for a in range(3) if a != k]
        for n, (bi, bj) in enumerate(((1, 0), (0, 1))):
            q = (b << k) | (bi << i) | (bj << j)
            out[f, n] = [split_point_index(q, q ^ (1 << i)), split_point_index(q, q ^ (1 << j))]
    return out


#: Face-centre rules as groups of cube-edge split points: FACE_CENTRE_RULES[rule][f] (G, K)
#: lists G groups of K edges of face f, and the face gets its centre when every edge of some
#: group is split (or when the face is finer).  "minimal": the two edges at an off-diagonal
#: corner; "eager": any one edge.
FACE_CENTRE_RULES = {"minimal": _face_corner_edges(), "eager": FACE_EDGES[:, :, None].copy()}
