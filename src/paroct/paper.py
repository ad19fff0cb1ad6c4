"""Table 1 of the seed paper (Todd's fat triangulation for 3-D meshing), recomputed, with errata.

Every number is measured here with the package's own kernels (quality.tet_quality,
quality.tet_dihedral_angles, lattice.leaf_tets) on explicitly built tets, next to its
closed form and the value the paper prints.  3r/R is the normalized radius ratio: 1 for
the regular tet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .frame import CUBE_CORNERS, FREUDENTHAL_TETS, LATTICE_TO_SPACE, TODD_A
from .lattice import leaf_tets
from .quality import TET_EDGES, tet_dihedral_angles, tet_quality

#: The five-tet split of the unit cube (corner indices as in frame.CUBE_CORNERS): four corner
#: tets at corners 1, 2, 4, 7, then the regular tet on corners 0, 3, 5, 6; positive volumes.
FIVE_TET_SPLIT = np.array([[0, 1, 3, 5], [0, 2, 6, 3], [0, 4, 5, 6], [3, 7, 6, 5], [0, 3, 6, 5]], dtype=np.int64)
#: A six-tet split of the unit cube that is not Kuhn's: corner tets at corners 1, 2, 4 and
#: three tets around the diagonal 0-7.  Its extreme ratios are the paper's 'cube' column.
SIX_TET_CORNER_SPLIT = np.array(
    [[0, 1, 3, 5], [0, 3, 2, 6], [0, 4, 5, 6], [0, 5, 3, 7], [0, 3, 6, 7], [0, 6, 5, 7]], dtype=np.int64
)
#: Todd's matrix as the paper prints it for n = 3: diagonal 5/6 as in A, off-diagonal +1/6 instead of -1/6.
PRINTED_A = 2.0 / 3.0 * np.eye(3) + np.ones((3, 3)) / 6.0


@dataclass(frozen=True)
class Row:
    """One recomputed quantity.  computed: measured here (NaN if not reproducible from the
    paper's description); exact: its closed form as text; paper: the printed value or ''."""

    key: str
    quantity: str
    computed: float
    exact: str
    paper: str
    note: str = ""


def _ratios(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """3r/R (M,) of tets (M, 4) on points (N, 3)."""
    return tet_quality(np.ascontiguousarray(points, dtype=np.float64), tets).radius_ratio


def cube_points(matrix: np.ndarray | None = None) -> np.ndarray:
    """The unit cube's corners (8, 3) float64 in CUBE_CORNERS order, mapped by ``matrix`` (3, 3)."""
    corners = CUBE_CORNERS.astype(np.float64)
    return corners if matrix is None else corners @ np.asarray(matrix, dtype=np.float64).T


def icosahedron() -> np.ndarray:
    """Vertices (12, 3) of the regular icosahedron of edge 2 centred at 0: cyclic (0, +-1, +-phi)."""
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    out = []
    for s1 in (1.0, -1.0):
        for s2 in (phi, -phi):
            out += [[0.0, s1, s2], [s1, s2, 0.0], [s2, 0.0, s1]]
    return np.array(out)


def icosahedral_tet() -> np.ndarray:
    """Points (4, 3) of the centre and one face of the icosahedron, positively ordered."""
    v = icosahedron()
    d = np.linalg.norm(v[:, None] - v[None], axis=-1)
    near = np.isclose(d, 2.0)  # the 30 edges
    a = 0
    b = int(np.nonzero(near[a])[0][0])
    c = int(np.nonzero(near[a] & near[b])[0][0])
    p = np.array([[0.0, 0.0, 0.0], v[a], v[b], v[c]])
    if np.linalg.det(p[1:] - p[0]) < 0:
        p[[2, 3]] = p[[3, 2]]
    return p


def regular_tet() -> np.ndarray:
    """Points (4, 3) of the regular tet on alternate cube corners, positively ordered."""
    return np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.0, 1.0, 1.0]])


def lattice_vertex_counts(n: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Edge neighbours and incident tets of every interior vertex of an n x n x n block of
    lattice cubes (unit sides, Freudenthal split, as the mesher emits them).

    Returns (degree (K,) int64, incident_tets (K,) int64) over the (n - 1)^3 interior vertices.
    """
    if n < 2:
        raise ValueError(f"n = {n}: a block needs n >= 2 cubes per side to have interior vertices")
    g = np.arange(n)
    anchors = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = leaf_tets(anchors, np.ones(anchors.shape[0], dtype=np.int64))
    tets = tets.astype(np.int64)
    nv = coords.shape[0]
    incident = np.bincount(tets.ravel(), minlength=nv)
    edges = np.sort(tets[:, TET_EDGES].reshape(-1, 2), axis=1)
    edges = np.unique(edges, axis=0)
    degree = np.bincount(edges.ravel(), minlength=nv)
    interior = np.all((coords > 0) & (coords < n), axis=1)
    return degree[interior], incident[interior]


def paper_table() -> list[Row]:
    """Table 1 of the paper and the numbers of its text, recomputed (see Row)."""
    rows = []
    all_k1 = FREUDENTHAL_TETS

    fat = _ratios(cube_points(TODD_A), all_k1)
    rows.append(Row("fat_max", "fat tet (K1 cube x A = I - ee^T/6), max 3r/R", float(fat.max()),
                    "3/sqrt(10)", "0.9487"))
    rows.append(Row("fat_min", "fat tet (K1 cube x A), min 3r/R", float(fat.min()),
                    "3/sqrt(10)", "0.9497", "misprint: the min cannot exceed the max; the 6 tets are congruent"))
    bcc = _ratios(cube_points(LATTICE_TO_SPACE), all_k1)
    rows.append(Row("fat_bcc_min", "fat tet in paroct's BCC frame (R A), min 3r/R", float(bcc.min()), "3/sqrt(10)", ""))
    rows.append(Row("fat_bcc_max", "fat tet in paroct's BCC frame (R A), max 3r/R", float(bcc.max()), "3/sqrt(10)", ""))
    printed = _ratios(cube_points(PRINTED_A), all_k1)
    rows.append(Row("printed_matrix", "K1 cube x printed A (+1/6 off-diagonal), min 3r/R", float(printed.min()),
                    "", "", "the printed sign does not give a fat triangulation"))

    rows.append(Row("icosahedral", "icosahedral inner tet (centre + a face), 3r/R",
                    float(_ratios(icosahedral_tet(), np.array([[0, 1, 2, 3]]))[0]), "", "0.9964"))
    rows.append(Row("icosahedral_gap", "icosahedral gap-filling tets, min 3r/R", float("nan"), "", "0.7681",
                    "not recomputed: the paper does not define the gap tets"))

    kuhn = _ratios(cube_points(), all_k1)
    rows.append(Row("kuhn_min", "six-tet Kuhn (K1) cube split, min 3r/R", float(kuhn.min()), "sqrt(6) - sqrt(3)", ""))
    rows.append(Row("kuhn_max", "six-tet Kuhn (K1) cube split, max 3r/R", float(kuhn.max()), "sqrt(6) - sqrt(3)",
                    "0.73205", "the paper's 'cube' column is another six-tet split, next rows"))
    corner6 = _ratios(cube_points(), SIX_TET_CORNER_SPLIT)
    rows.append(Row("six_corner_max", "six-tet cube split with 3 corner tets, max 3r/R", float(corner6.max()),
                    "sqrt(3) - 1", "0.73205"))
    rows.append(Row("six_corner_min", "six-tet cube split with 3 corner tets, min 3r/R", float(corner6.min()),
                    "2 sqrt(3) / (1 + sqrt(3) + 2 sqrt(2))", "0.62299"))
    five = _ratios(cube_points(), FIVE_TET_SPLIT)
    rows.append(Row("five_corner", "five-tet cube split, corner tets, min 3r/R", float(five[:4].min()), "sqrt(3) - 1", ""))
    rows.append(Row("five_centre", "five-tet cube split, central tet, 3r/R", float(five[4]), "1", ""))

    degree, incident = lattice_vertex_counts(6)
    uniform = degree.min() == degree.max() and incident.min() == incident.max()
    where = f"all {degree.size} interior vertices of a 6^3 block" if uniform else "varies between interior vertices"
    rows.append(Row("vertex_degree", "edges at an interior vertex of the fat lattice", float(degree.min()), "14", "14", where))
    rows.append(Row("vertex_tets", "tets at an interior vertex of the fat lattice", float(incident.min()), "24", "24", where))

    regular = tet_dihedral_angles(regular_tet(), np.array([[0, 1, 2, 3]]))
    rows.append(Row("regular_dihedral", "regular tet dihedral angle, degrees", float(regular.max()), "arccos(1/3)",
                    "72.221", "misprint: arccos(1/3) = 70.529"))
    angles = tet_dihedral_angles(cube_points(TODD_A), all_k1)
    rows.append(Row("fat_dihedral_min", "fat tet dihedral angles, smallest, degrees", float(angles.min()), "60", ""))
    rows.append(Row("fat_dihedral_max", "fat tet dihedral angles, largest, degrees", float(angles.max()), "90", ""))
    return rows


def paper_errata() -> list[str]:
    """The paper's errors found by the recomputation, one line each."""
    printed = float(_ratios(cube_points(PRINTED_A), FREUDENTHAL_TETS).min())
    return [
        "Formula (1) for n = 3 and n = 2: A = I - (n + 1 + sqrt(n + 1))^-1 e e^T has off-diagonal entries -1/6 "
        f"(n = 3) and -1/(3 + sqrt(3)) (n = 2); the printed matrices have +; with +1/6 the K1 tets have 3r/R {printed:.4f}.  "
        "The worked product mixes both: A e1 should be (5/6, -1/6, -1/6) and A (e1 + e2) (2/3, 2/3, -1/3).",
        "Fat tet 3r/R: Table 1's minimum 0.9497 should be 0.9487 (= max; all six tets are congruent).",
        "Fat tet derivation: the area is 4 x sqrt(2)/4 = sqrt(2) (printed 4 x sqrt(2)/2) and 1/R = 4/sqrt(5) "
        "(printed 1/sqrt(5)); the result is 3/sqrt(10) = (3/2) sqrt(2/5) = 0.948683, not 3 sqrt(2/5) = 1.897.",
        "Regular tet dihedral angle: arccos(1/3) = 70.53 degrees, not 72.221.",
        "Cube column: 0.73205 = sqrt(3) - 1 is a corner tet's ratio (the five-tet split's four corner tets); "
        "the six-tet Kuhn (K1) split has all six tets at sqrt(6) - sqrt(3) = 0.7174.  The printed "
        "0.73205 / 0.62299 pair belongs to a different six-tet split, with three corner tets.",
    ]


def format_paper_table() -> str:
    """The recomputed table and the errata as printable text."""
    rows = paper_table()
    width = max(len(r.quantity) for r in rows)
    head = f"{'quantity':<{width}}  {'recomputed':>10}  {'closed form':<38}  {'paper':>7}"
    lines = [head, "-" * len(head)]
    for r in rows:
        value = "-" if math.isnan(r.computed) else f"{r.computed:.6g}"
        line = f"{r.quantity:<{width}}  {value:>10}  {r.exact:<38}  {r.paper:>7}" + (f"  ({r.note})" if r.note else "")
        lines.append(line.rstrip())
    lines += ["", "Errata:"] + [f"- {e}" for e in paper_errata()]
    return "\n".join(lines)
