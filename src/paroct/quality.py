"""Per-tet quality: signed volume, normalized radius ratio 3r/R, dihedral angles.

3r/R is 1 for the regular tet and 3/sqrt(10) = 0.948683 for Todd's fat tet.  The
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


@nb.njit(cache=True, inline="always")
def _cosine(nkx, nky, nkz, ik, nmx, nmy, nmz, im):
    """Cosine of the dihedral angle between the faces with outward normals nk, nm (inverse
    lengths ik, im), clamped to [-1, 1]; 1 (angle 0) for a degenerate face (inverse length 0)."""
    if ik == 0.0 or im == 0.0:
        return 1.0
    c = -(nkx * nmx + nky * nmy + nkz * nmz) * ik * im
    return min(1.0, max(-1.0, c))


@nb.njit(cache=True, inline="always")
def _inverse(x):
    return 1.0 / x if x > 0.0 else 0.0


@nb.njit(cache=True, inline="always")
def _measure_tet(points, tets, t):
    """(signed volume, 3r/R, and the cosines of the six dihedral angles in TET_EDGES order) of
    tet t.  The cosine falls as the angle grows, so extremes are reduced over cosines and only
    they go through acos."""
    a = tets[t, 0]
    b = tets[t, 1]
    c = tets[t, 2]
    d = tets[t, 3]
    ax, ay, az = points[a, 0], points[a, 1], points[a, 2]
    bx, by, bz = points[b, 0] - ax, points[b, 1] - ay, points[b, 2] - az
    cx, cy, cz = points[c, 0] - ax, points[c, 1] - ay, points[c, 2] - az
    dx, dy, dz = points[d, 0] - ax, points[d, 1] - ay, points[d, 2] - az
    # Outward normals of the faces opposite vertices 0..3 (for positive volume).
    ex, ey, ez = cx - bx, cy - by, cz - bz
    fx, fy, fz = dx - bx, dy - by, dz - bz
    n0x, n0y, n0z = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    n1x, n1y, n1z = dy * cz - dz * cy, dz * cx - dx * cz, dx * cy - dy * cx
    n2x, n2y, n2z = by * dz - bz * dy, bz * dx - bx * dz, bx * dy - by * dx
    n3x, n3y, n3z = cy * bz - cz * by, cz * bx - cx * bz, cx * by - cy * bx
    vol = -(n3x * dx + n3y * dy + n3z * dz) / 6.0
    l0 = math.sqrt(n0x * n0x + n0y * n0y + n0z * n0z)
    l1 = math.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
    l2 = math.sqrt(n2x * n2x + n2y * n2y + n2z * n2z)
    l3 = math.sqrt(n3x * n3x + n3y * n3y + n3z * n3z)
    i0, i1, i2, i3 = _inverse(l0), _inverse(l1), _inverse(l2), _inverse(l3)
    # Edge (i, j) lies between the faces opposite the other two vertices.
    c01 = _cosine(n2x, n2y, n2z, i2, n3x, n3y, n3z, i3)
    c02 = _cosine(n1x, n1y, n1z, i1, n3x, n3y, n3z, i3)
    c03 = _cosine(n1x, n1y, n1z, i1, n2x, n2y, n2z, i2)
    c12 = _cosine(n0x, n0y, n0z, i0, n3x, n3y, n3z, i3)
    c13 = _cosine(n0x, n0y, n0z, i0, n2x, n2y, n2z, i2)
    c23 = _cosine(n0x, n0y, n0z, i0, n1x, n1y, n1z, i1)
    area = 0.5 * (l0 + l1 + l2 + l3)
    # Products of the lengths of opposite edge pairs (01, 23), (02, 13), (03, 12).
    gx, gy, gz = dx - cx, dy - cy, dz - cz
    p = math.sqrt((bx * bx + by * by + bz * bz) * (gx * gx + gy * gy + gz * gz))
    q = math.sqrt((cx * cx + cy * cy + cz * cz) * (fx * fx + fy * fy + fz * fz))
    r = math.sqrt((dx * dx + dy * dy + dz * dz) * (ex * ex + ey * ey + ez * ez))
    prod = (p + q + r) * (p + q - r) * (p - q + r) * (-p + q + r)
    if vol <= 0.0 or prod <= 0.0 or area == 0.0:
        ratio = 0.0
    else:  # 3 r / R with r = 3 V / area, R = sqrt(prod) / (24 V)
        ratio = 216.0 * vol * vol / (area * math.sqrt(prod))
    return vol, ratio, c01, c02, c03, c12, c13, c23


@nb.njit(cache=True, inline="always")
def _extreme_cosines(vol, c01, c02, c03, c12, c13, c23):
    """(largest, smallest) dihedral cosine: the smallest and largest angle; (1, -1), angles 0
    and 180, for a tet of non-positive volume."""
    if vol <= 0.0:
        return 1.0, -1.0
    return max(c01, c02, c03, c12, c13, c23), min(c01, c02, c03, c12, c13, c23)


@nb.njit(cache=True, inline="always")
def _degrees(cosine):
    return math.degrees(math.acos(cosine))


@nb.njit(cache=True, parallel=True)
def _tet_quality(points, tets, volume, radius_ratio, min_dihedral, max_dihedral):
    for t in nb.prange(tets.shape[0]):
        vol, ratio, c01, c02, c03, c12, c13, c23 = _measure_tet(points, tets, t)
        c_hi, c_lo = _extreme_cosines(vol, c01, c02, c03, c12, c13, c23)
        volume[t] = vol
        radius_ratio[t] = ratio
        min_dihedral[t] = _degrees(c_hi)
        max_dihedral[t] = _degrees(c_lo)


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
    tets = np.ascontiguousarray(tets)
    if tets.dtype not in (np.int32, np.int64):  # the kernels are compiled for these two
        tets = tets.astype(np.int64)
    m = tets.shape[0]
    out = TetQuality(np.empty(m), np.empty(m), np.empty(m), np.empty(m))
    if m:
        _tet_quality(points, tets, out.volume, out.radius_ratio, out.min_dihedral, out.max_dihedral)
    return out


@nb.njit(cache=True)
def tet_dihedral_angles(points, tets):
    """All six dihedral angles (M, 6) float64 in degrees, edge order TET_EDGES."""
    out = np.empty((tets.shape[0], 6))
    for t in range(tets.shape[0]):
        cosines = _measure_tet(points, tets, t)[2:]
        for i in range(6):
            out[t, i] = _degrees(cosines[i])
    return out


#: Number of chunks a summary is reduced over (each thread owns whole chunks).
_SUMMARY_CHUNKS = 64


@nb.njit(cache=True, parallel=True)
def _summarize(points, tets, core, fat_ratio, partial, fat_count):
    """Per-chunk extremes into partial (chunks, 7): min dihedral, max dihedral, min 3r/R,
    volume sum, min and max dihedral of tets with four core vertices, and (count) fat tets."""
    m = tets.shape[0]
    n_chunks = partial.shape[0]
    for c in nb.prange(n_chunks):
        lo = m * c // n_chunks
        hi = m * (c + 1) // n_chunks
        # Extremes as cosines: the smallest angle has the largest cosine.
        cmax, cmin, rmin, vsum, icmax, icmin = -1.0, 1.0, np.inf, 0.0, -1.0, 1.0
        fat = 0
        for t in range(lo, hi):
            vol, ratio, c01, c02, c03, c12, c13, c23 = _measure_tet(points, tets, t)
            c_hi, c_lo = _extreme_cosines(vol, c01, c02, c03, c12, c13, c23)
            cmax = max(cmax, c_hi)
            cmin = min(cmin, c_lo)
            rmin = min(rmin, ratio)
            vsum += vol
            if abs(ratio - fat_ratio) < 1e-9:
                fat += 1
            if core[tets[t, 0]] and core[tets[t, 1]] and core[tets[t, 2]] and core[tets[t, 3]]:
                icmax = max(icmax, c_hi)
                icmin = min(icmin, c_lo)
        partial[c, 0] = _degrees(cmax)
        partial[c, 1] = _degrees(cmin)
        partial[c, 2] = rmin
        partial[c, 3] = vsum
        partial[c, 4] = _degrees(icmax) if icmax >= icmin else 180.0
        partial[c, 5] = _degrees(icmin) if icmax >= icmin else 0.0
        fat_count[c] = fat


@dataclass(frozen=True)
class TetSummary:
    """Extremes over a mesh: dihedral angles (degrees), 3r/R, total signed volume, the
    dihedral range of the tets with four ``core`` vertices (nan if none) and how many tets
    have 3r/R within 1e-9 of ``fat_ratio``."""

    min_dihedral: float
    max_dihedral: float
    min_radius_ratio: float
    volume: float
    interior_min_dihedral: float
    interior_max_dihedral: float
    n_fat: int


def summarize(points: np.ndarray, tets: np.ndarray, core: np.ndarray, fat_ratio: float) -> TetSummary:
    """One parallel pass of tet_quality's measures, reduced (no per-tet arrays).
    points: (N, 3) float64; tets: (M, 4) int; core: (N,) bool."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets)
    if tets.dtype not in (np.int32, np.int64):
        tets = tets.astype(np.int64)
    n_chunks = max(1, min(_SUMMARY_CHUNKS, tets.shape[0]))
    partial = np.empty((n_chunks, 6))
    fat_count = np.zeros(n_chunks, dtype=np.int64)
    if tets.shape[0] == 0:
        nan = float("nan")
        return TetSummary(nan, nan, nan, 0.0, nan, nan, 0)
    _summarize(points, tets, np.ascontiguousarray(core, dtype=np.bool_), float(fat_ratio), partial, fat_count)
    imn, imx = float(partial[:, 4].min()), float(partial[:, 5].max())
    if imn > imx:  # no tet had four core vertices
        imn = imx = float("nan")
    return TetSummary(float(partial[:, 0].min()), float(partial[:, 1].max()), float(partial[:, 2].min()),
                      float(partial[:, 3].sum()), imn, imx, int(fat_count.sum()))
