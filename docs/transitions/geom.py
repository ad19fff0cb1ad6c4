"""Shared geometry: lattice map, quality measures, exact overlap test."""
import itertools
import numpy as np

M = 0.5 * np.array([[1.0, 1.0, -1.0], [-1.0, 1.0, 1.0], [1.0, -1.0, 1.0]])
CORNERS = np.array([[(c >> i) & 1 for i in range(3)] for c in range(8)], dtype=np.int64)
FREUD = [(0, 1, 3, 7), (0, 5, 1, 7), (0, 3, 2, 7), (0, 2, 6, 7), (0, 4, 5, 7), (0, 6, 4, 7)]


def to_space(u):
    return np.asarray(u, dtype=float) @ M.T


def quality(P):
    """P (4,3) space points -> (min dihedral deg, max dihedral deg, 3r/R, signed volume)."""
    P = np.asarray(P, float)
    vol = np.dot(np.cross(P[1] - P[0], P[2] - P[0]), P[3] - P[0]) / 6.0
    # outward normals of faces opposite each vertex
    N = []
    A = []
    for k in range(4):
        o = [i for i in range(4) if i != k]
        n = np.cross(P[o[1]] - P[o[0]], P[o[2]] - P[o[0]])
        if np.dot(n, P[k] - P[o[0]]) > 0:
            n = -n
        A.append(np.linalg.norm(n) / 2)
        N.append(n / np.linalg.norm(n))
    angs = []
    for k, l in itertools.combinations(range(4), 2):
        c = np.clip(-np.dot(N[k], N[l]), -1, 1)
        angs.append(np.degrees(np.arccos(c)))
    r = 3 * abs(vol) / sum(A)
    # circumradius
    a = P[1:] - P[0]
    rhs = 0.5 * np.sum(a * a, axis=1)
    c = np.linalg.solve(a, rhs)
    R = np.linalg.norm(c)
    return min(angs), max(angs), 3 * r / R, vol


def qscore(P):
    """Single scalar: min over (mindih-30)/30, (135-maxdih)/45, (rr-0.4)/0.6 -- >=0 means bound met."""
    lo, hi, rr, v = quality(P)
    return lo, hi, rr


def sep_axes(A, B):
    ax = []
    for T in (A, B):
        for f in itertools.combinations(range(4), 3):
            ax.append(np.cross(T[f[1]] - T[f[0]], T[f[2]] - T[f[0]]))
    ea = [A[j] - A[i] for i, j in itertools.combinations(range(4), 2)]
    eb = [B[j] - B[i] for i, j in itertools.combinations(range(4), 2)]
    for e in ea:
        for f in eb:
            ax.append(np.cross(e, f))
    return ax


def interiors_overlap(A, B):
    """Exact for integer (or exactly representable) coordinates: do two tets' interiors meet?"""
    for n in sep_axes(A, B):
        if not np.any(n):
            continue
        pa = A @ n
        pb = B @ n
        if pa.max() <= pb.min() or pb.max() <= pa.min():
            return False
    return True
