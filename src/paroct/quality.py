"""Per-tet quality: signed volume, normalized radius ratio 3r/R, dihedral angles.

3r/R is 1 for the regular tet and 3 sqrt(2/5) = 0.948683 for Todd's fat tet.  The
circumradius uses R = sqrt((aA + bB + cC)(aA + bB - cC)(aA - bB + cC)(-aA + bB + cC)) / (24 V)
with (a, A), (b, B), (c, C) the lengths of opposite edge pairs; the inradius r = 3V / area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

#: The six edges of a tet as vertex pairs, and for each the two vertices off it.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)
_OFF_EDGE = np.array([[2, 3], [1, 3], [1, 2], [0, 3], [0, 2], [0, 1]], dtype=np.int64)


@nb.njit(cache=True, inline="always")
def _sub(p, q):
    return (p[0] - q[0], p[1] - q[1], p[2] - q[2])


@nb.njit(cache=True, inline="always")
def _cross(u, v):
    return (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])


@nb.njit(cache=True, inline="always")
def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@nb.njit(cache=True, parallel=True)
def _tet_quality(points, tets, volume, radius_ratio, min_dihedral, max_dihedral):
    for t in nb.prange(tets.shape[0]):
        p = (points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
        e01 = _sub(p[1], p[0])
        e02 = _sub(p[2], p[0])
        e03 = _sub(p[3], p[0])
        vol = _dot(_cross(e01, e02), e03) / 6.0
        volume[t] = vol
        # Outward-ish face normals n_k of the face opposite vertex k (orientation-consistent).
        n0 = _cross(_sub(p[2], p[1]), _sub(p[3], p[1]))
        n1 = _cross(_sub(p[3], p[0]), _sub(p[2], p[0]))
        n2 = _cross(_sub(p[1], p[0]), _sub(p[3], p[0]))
        n3 = _cross(_sub(p[2], p[0]), _sub(p[1], p[0]))
        normals = (n0, n1, n2, n3)
        area = 0.0
        norms = np.empty(4)
        for k in range(4):
            norms[k] = math.sqrt(_dot(normals[k], normals[k]))
            area += 0.5 * norms[k]
        lo = 180.0
        hi = 0.0
        for e in range(6):
            k = _OFF_EDGE[e, 0]
            m = _OFF_EDGE[e, 1]
            # The dihedral angle at edge e lies between the faces opposite its two off-edge vertices.
            if norms[k] == 0.0 or norms[m] == 0.0:
                ang = 0.0
            else:
                c = -_dot(normals[k], normals[m]) / (norms[k] * norms[m])
                c = min(1.0, max(-1.0, c))
                ang = math.degrees(math.acos(c))
            lo = min(lo, ang)
            hi = max(hi, ang)
        if vol <= 0.0:
            lo = 0.0
            hi = 180.0
        min_dihedral[t] = lo
        max_dihedral[t] = hi
        # Opposite edge pairs (01, 23), (02, 13), (03, 12).
        l01 = math.sqrt(_dot(e01, e01))
        l02 = math.sqrt(_dot(e02, e02))
        l03 = math.sqrt(_dot(e03, e03))
        d12 = _sub(p[2], p[1])
        d13 = _sub(p[3], p[1])
        d23 = _sub(p[3], p[2])
        l12 = math.sqrt(_dot(d12, d12))
        l13 = math.sqrt(_dot(d13, d13))
        l23 = math.sqrt(_dot(d23, d23))
        a = l01 * l23
        b = l02 * l13
        c = l03 * l12
        prod = (a + b + c) * (a + b - c) * (a - b + c) * (-a + b + c)
        if vol <= 0.0 or prod <= 0.0 or area == 0.0:
            radius_ratio[t] = 0.0
        else:
            circum = math.sqrt(prod) / (24.0 * vol)
            inr = 3.0 * vol / area
            radius_ratio[t] = 3.0 * inr / circum


@dataclass(frozen=True)
class TetQuality:
    """Per-tet measures, each (M,) float64: signed volume (model units cubed), 3r/R,
    and smallest and largest dihedral angle in degrees (0 and 180 for non-positive volume)."""

    volume: np.ndarray
    radius_ratio: np.ndarray
    min_dihedral: np.ndarray
    max_dihedral: np.ndarray


def tet_quality(points: np.ndarray, tets: np.ndarray) -> TetQuality:
    """Quality of every tet.  points: (N, 3) float64; tets: (M, 4) integer vertex indices."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    m = tets.shape[0]
    out = TetQuality(np.empty(m), np.empty(m), np.empty(m), np.empty(m))
    if m:
        _tet_quality(points, tets, out.volume, out.radius_ratio, out.min_dihedral, out.max_dihedral)
    return out


@nb.njit(cache=True)
def tet_dihedral_angles(points, tets):
    """All six dihedral angles (M, 6) float64 in degrees, edge order TET_EDGES."""
    m = tets.shape[0]
    out = np.empty((m, 6))
    for t in range(m):
        p = (points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
        n0 = _cross(_sub(p[2], p[1]), _sub(p[3], p[1]))
        n1 = _cross(_sub(p[3], p[0]), _sub(p[2], p[0]))
        n2 = _cross(_sub(p[1], p[0]), _sub(p[3], p[0]))
        n3 = _cross(_sub(p[2], p[0]), _sub(p[1], p[0]))
        normals = (n0, n1, n2, n3)
        for e in range(6):
            k = _OFF_EDGE[e, 0]
            m2 = _OFF_EDGE[e, 1]
            nk = math.sqrt(_dot(normals[k], normals[k]))
            nm = math.sqrt(_dot(normals[m2], normals[m2]))
            if nk == 0.0 or nm == 0.0:
                out[t, e] = 0.0
            else:
                c = min(1.0, max(-1.0, -_dot(normals[k], normals[m2]) / (nk * nm)))
                out[t, e] = math.degrees(math.acos(c))
    return out
