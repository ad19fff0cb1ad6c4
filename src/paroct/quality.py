"""Per-tet quality: signed volume, normalized radius ratio 3r/R, dihedral angles.

3r/R is 1 for the regular tet and 3/sqrt(10) = 0.948683 for Todd's fat tet.  The
circumradius uses R = sqrt((aA + bB + cC)(aA + bB - cC)(aA - bB + cC)(-aA + bB + cC)) / (24 V)
with (a, A), (b, B), (c, C) the lengths of opposite edge pairs; the inradius r = 3V / area.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numba as nb
import numpy as np

from .surface import bounding_box  # one pass: numpy's axis-0 reductions stride

#: The six edges of a tet as vertex pairs, and for each the two vertices off it.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


#: Extents of the points' box (model units) within which the measures' products (up to the
#: fourth power of an edge length) neither overflow nor lose digits to underflow; outside,
#: the points are measured scaled by a power of two (unit_scaled).
_SAFE_EXTENT = (2.0**-60, 2.0**60)


def unit_scaled(points: np.ndarray) -> tuple[np.ndarray, float]:
    """(points, 1.0) for points whose box extent is within _SAFE_EXTENT, else (points x s, s)
    for the power of two s that brings the extent into [0.5, 1): exact, so angles and 3r/R are
    those of the points as given, and volumes are s^3 times theirs.  A part of 1e-100 or
    1e100 across (the range paroct meshes) gave dihedral angles of 0 and 180 degrees unscaled."""
    if len(points) == 0:
        return points, 1.0
    lo, hi, _ = bounding_box(points)
    extent = float((hi - lo).max())
    if not (math.isfinite(extent) and extent > 0) or _SAFE_EXTENT[0] <= extent <= _SAFE_EXTENT[1]:
        return points, 1.0
    scale = math.ldexp(1.0, -math.frexp(extent)[1])
    return points * scale, scale


#: Tets measured per block.  A block's corner coordinates are gathered into contiguous rows
#: first, so the measuring loop has no indirect loads or branches and compiles to SIMD
#: (3x faster than measuring tet by tet on AVX2, with bit-identical results).
BLOCK = 128
#: Rows of a measured block (_measure_block): signed volume, 3r/R, largest and smallest
#: dihedral cosine (smallest and largest angle).
_VOL, _RATIO, _COS_HI, _COS_LO = 0, 1, 2, 3


@nb.njit(cache=True)
def _gather(points, tets, start, n, corners):
    """corners[3 k + i, j] = coordinate i of corner k of tet start + j, for j < n."""
    for j in range(n):
        for k in range(4):
            v = tets[start + j, k]
            corners[3 * k, j] = points[v, 0]
            corners[3 * k + 1, j] = points[v, 1]
            corners[3 * k + 2, j] = points[v, 2]


@nb.njit(cache=True, inline="always")
def _cosine(nkx, nky, nkz, lk, nmx, nmy, nmz, lm):
    """Cosine of the dihedral angle between the faces with outward normals nk, nm (lengths
    lk, lm), clamped to [-1, 1]; 1 (angle 0) for a degenerate face."""
    c = -(nkx * nmx + nky * nmy + nkz * nmz) / max(lk * lm, 1e-300)
    c = min(1.0, max(-1.0, c))
    return 1.0 if min(lk, lm) == 0.0 else c  # min, not `or`: a branch would stop SIMD


@nb.njit(cache=True, inline="always")
def _tet_measures(corners, j):
    """(signed volume, 3r/R (0 for non-positive volume), the six dihedral cosines in TET_EDGES
    order) of tet j of a gathered block (corners (12, BLOCK))."""
    ax, ay, az = corners[0, j], corners[1, j], corners[2, j]
    bx, by, bz = corners[3, j] - ax, corners[4, j] - ay, corners[5, j] - az
    cx, cy, cz = corners[6, j] - ax, corners[7, j] - ay, corners[8, j] - az
    dx, dy, dz = corners[9, j] - ax, corners[10, j] - ay, corners[11, j] - az
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
    # Edge (i, j) lies between the faces opposite the other two vertices.
    c01 = _cosine(n2x, n2y, n2z, l2, n3x, n3y, n3z, l3)
    c02 = _cosine(n1x, n1y, n1z, l1, n3x, n3y, n3z, l3)
    c03 = _cosine(n1x, n1y, n1z, l1, n2x, n2y, n2z, l2)
    c12 = _cosine(n0x, n0y, n0z, l0, n3x, n3y, n3z, l3)
    c13 = _cosine(n0x, n0y, n0z, l0, n2x, n2y, n2z, l2)
    c23 = _cosine(n0x, n0y, n0z, l0, n1x, n1y, n1z, l1)
    area = 0.5 * (l0 + l1 + l2 + l3)
    # Products of the lengths of opposite edge pairs (01, 23), (02, 13), (03, 12).
    gx, gy, gz = dx - cx, dy - cy, dz - cz
    p = math.sqrt((bx * bx + by * by + bz * bz) * (gx * gx + gy * gy + gz * gz))
    q = math.sqrt((cx * cx + cy * cy + cz * cz) * (fx * fx + fy * fy + fz * fz))
    r = math.sqrt((dx * dx + dy * dy + dz * dz) * (ex * ex + ey * ey + ez * ez))
    prod = (p + q + r) * (p + q - r) * (p - q + r) * (-p + q + r)
    # 3 r / R with r = 3 V / area, R = sqrt(prod) / (24 V).
    ratio = 216.0 * vol * vol / max(area * math.sqrt(max(prod, 0.0)), 1e-300)
    ratio = ratio if min(vol, min(prod, area)) > 0.0 else 0.0
    return vol, ratio, c01, c02, c03, c12, c13, c23


@nb.njit(cache=True)
def _measure_block(corners, n, out):
    """Measure the first n tets of a gathered block (corners (12, BLOCK)) into out (4, BLOCK),
    rows _VOL, _RATIO, _COS_HI, _COS_LO.  Extremes are (1, -1), angles 0 and 180, for
    non-positive volume.  The cosine falls as the angle grows, so extremes are reduced over
    cosines and only they go through acos.  (Storing all six cosines here would stop SIMD:
    too many output rows to check for aliasing.)"""
    for j in range(n):
        vol, ratio, c01, c02, c03, c12, c13, c23 = _tet_measures(corners, j)
        out[_VOL, j] = vol
        out[_RATIO, j] = ratio
        out[_COS_HI, j] = max(max(max(c01, c02), max(c03, c12)), max(c13, c23)) if vol > 0.0 else 1.0
        out[_COS_LO, j] = min(min(min(c01, c02), min(c03, c12)), min(c13, c23)) if vol > 0.0 else -1.0


@nb.njit(cache=True, inline="always")
def _measure_tets(points, tets, start, end, corners, out):
    """Gather and measure the block of tets from start (at most BLOCK, not past end) into out;
    returns how many."""
    n = min(BLOCK, end - start)
    _gather(points, tets, start, n, corners)
    _measure_block(corners, n, out)
    return n


@nb.njit(cache=True, inline="always")
def _degrees(cosine):
    return math.degrees(math.acos(cosine))


@nb.njit(cache=True, inline="always")
def _degrees_below(cosine, cos_bound, bound):
    """_degrees(cosine) < bound, from the cosine alone unless it is within 1e-9 of
    cos_bound = cos(bound) (acos is slow; the exact test decides near the bound)."""
    if cosine > cos_bound + 1e-9:
        return True
    if cosine < cos_bound - 1e-9:
        return False
    return _degrees(cosine) < bound


@nb.njit(cache=True, inline="always")
def _degrees_above(cosine, cos_bound, bound):
    """_degrees(cosine) > bound, as _degrees_below."""
    if cosine < cos_bound - 1e-9:
        return True
    if cosine > cos_bound + 1e-9:
        return False
    return _degrees(cosine) > bound


@nb.njit(cache=True, parallel=True)
def _tet_quality(points, tets, n_chunks, volume, radius_ratio, min_dihedral, max_dihedral):
    """Per-tet measures into volume .. max_dihedral (M,)."""
    m = tets.shape[0]
    for chunk in nb.prange(n_chunks):
        corners = np.empty((12, BLOCK))
        out = np.empty((4, BLOCK))
        end = m * (chunk + 1) // n_chunks
        for start in range(m * chunk // n_chunks, end, BLOCK):
            n = _measure_tets(points, tets, start, end, corners, out)
            for j in range(n):
                volume[start + j] = out[_VOL, j]
                radius_ratio[start + j] = out[_RATIO, j]
                min_dihedral[start + j] = _degrees(out[_COS_HI, j])
                max_dihedral[start + j] = _degrees(out[_COS_LO, j])


#: Flags outlier_flags gives a tet: a dihedral angle outside the bounds; else 3r/R below the floor.
OUTSIDE, NEEDLE = 1, 2


@nb.njit(cache=True, parallel=True)
def _outlier_flags(points, tets, skip, n_chunks, bounds, flags):
    """outlier_flags' kernel: each chunk of tets gathers the tets it measures into blocks of
    BLOCK (their vertex rows copied, then _gather), so skipped tets cost no measuring."""
    lo, hi, min_ratio = bounds[0], bounds[1], bounds[2]
    cos_lo = math.cos(math.radians(lo))
    cos_hi = math.cos(math.radians(hi))
    m = tets.shape[0]
    for chunk in nb.prange(n_chunks):
        corners = np.empty((12, BLOCK))
        out = np.empty((4, BLOCK))
        block = np.empty((BLOCK, 4), dtype=tets.dtype)
        rows = np.empty(BLOCK, dtype=np.int64)
        t = m * chunk // n_chunks
        end = m * (chunk + 1) // n_chunks
        while t < end:
            n = 0
            while t < end and n < BLOCK:
                if skip[tets[t, 0]] and skip[tets[t, 1]] and skip[tets[t, 2]] and skip[tets[t, 3]]:
                    flags[t] = 0
                else:
                    for k in range(4):
                        block[n, k] = tets[t, k]
                    rows[n] = t
                    n += 1
                t += 1
            _gather(points, block, 0, n, corners)
            _measure_block(corners, n, out)
            for j in range(n):
                # The smallest angle has the largest cosine; an angle above hi, a cosine below cos(hi).
                if _degrees_below(out[_COS_HI, j], cos_lo, lo) or _degrees_above(out[_COS_LO, j], cos_hi, hi):
                    flags[rows[j]] = OUTSIDE
                else:
                    flags[rows[j]] = NEEDLE if out[_RATIO, j] < min_ratio else 0


def outlier_flags(points: np.ndarray, tets: np.ndarray, skip: np.ndarray, lo: float, hi: float,
                  min_ratio: float) -> np.ndarray:
    """Flags (M,) uint8 of the tets: OUTSIDE with a dihedral angle below lo or above hi degrees
    (folded and flat ones included: 0 and 180 degrees, as tet_quality gives them), NEEDLE for
    the others with 3r/R below min_ratio, else 0: tet_quality's verdicts without its per-tet
    arrays or acos.  Tets whose four vertices are marked in skip (N,) bool are not measured
    and get 0."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets)
    if tets.dtype not in (np.int32, np.int64):
        tets = tets.astype(np.int64)
    flags = np.empty(tets.shape[0], dtype=np.uint8)
    points = unit_scaled(points)[0]
    if tets.shape[0]:
        _outlier_flags(points, tets, np.ascontiguousarray(skip, dtype=np.bool_), _chunks(tets.shape[0]),
                       np.array([lo, hi, min_ratio], dtype=np.float64), flags)
    return flags


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
        points, scale = unit_scaled(points)
        _tet_quality(points, tets, _chunks(m), out.volume, out.radius_ratio, out.min_dihedral, out.max_dihedral)
        if scale != 1.0:
            with np.errstate(over="ignore"):  # volumes beyond float64 (parts over 1e102 across) are inf
                for _ in range(3):  # scale**3 itself can underflow
                    out.volume[:] /= scale
    return out


@nb.njit(cache=True)
def tet_dihedral_angles(points, tets):
    """All six dihedral angles (M, 6) float64 in degrees, edge order TET_EDGES."""
    m = tets.shape[0]
    angles = np.empty((m, 6))
    corners = np.empty((12, BLOCK))
    for start in range(0, m, BLOCK):
        n = min(BLOCK, m - start)
        _gather(points, tets, start, n, corners)
        for j in range(n):
            cosines = _tet_measures(corners, j)[2:]
            for i in range(6):
                angles[start + j, i] = _degrees(cosines[i])
    return angles


#: Most chunks a pass over tets is split into (each thread owns whole chunks).
_MAX_CHUNKS = 64


def _chunks(m: int) -> int:
    return max(1, min(_MAX_CHUNKS, m // BLOCK))


@nb.njit(cache=True, parallel=True)
def _summarize(points, tets, core, fat_ratio, partial, fat_count):
    """Per-chunk extremes into partial (chunks, 6): min dihedral, max dihedral, min 3r/R,
    volume sum, min and max dihedral of tets with four core vertices, and (count) fat tets."""
    m = tets.shape[0]
    n_chunks = partial.shape[0]
    for chunk in nb.prange(n_chunks):
        corners = np.empty((12, BLOCK))
        out = np.empty((4, BLOCK))
        # Extremes as cosines: the smallest angle has the largest cosine.
        cmax, cmin, rmin, vsum, icmax, icmin = -1.0, 1.0, np.inf, 0.0, -1.0, 1.0
        fat = 0
        end = m * (chunk + 1) // n_chunks
        for start in range(m * chunk // n_chunks, end, BLOCK):
            n = _measure_tets(points, tets, start, end, corners, out)
            for j in range(n):
                c_hi, c_lo, ratio = out[_COS_HI, j], out[_COS_LO, j], out[_RATIO, j]
                cmax = max(cmax, c_hi)
                cmin = min(cmin, c_lo)
                rmin = min(rmin, ratio)
                vsum += out[_VOL, j]
                if abs(ratio - fat_ratio) < 1e-9:
                    fat += 1
                t = start + j
                if core[tets[t, 0]] & core[tets[t, 1]] & core[tets[t, 2]] & core[tets[t, 3]]:  # one branch, not four
                    icmax = max(icmax, c_hi)
                    icmin = min(icmin, c_lo)
        partial[chunk, 0] = _degrees(cmax)
        partial[chunk, 1] = _degrees(cmin)
        partial[chunk, 2] = rmin
        partial[chunk, 3] = vsum
        partial[chunk, 4] = _degrees(icmax) if icmax >= icmin else 180.0
        partial[chunk, 5] = _degrees(icmin) if icmax >= icmin else 0.0
        fat_count[chunk] = fat


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
    n_chunks = _chunks(tets.shape[0])
    partial = np.empty((n_chunks, 6))
    fat_count = np.zeros(n_chunks, dtype=np.int64)
    if tets.shape[0] == 0:
        nan = float("nan")
        return TetSummary(nan, nan, nan, 0.0, nan, nan, 0)
    points, scale = unit_scaled(points)
    _summarize(points, tets, np.ascontiguousarray(core, dtype=np.bool_), float(fat_ratio), partial, fat_count)
    imn, imx = float(partial[:, 4].min()), float(partial[:, 5].max())
    if imn > imx:  # no tet had four core vertices
        imn = imx = float("nan")
    return TetSummary(float(partial[:, 0].min()), float(partial[:, 1].max()), float(partial[:, 2].min()),
                      float(partial[:, 3].sum()) / scale / scale / scale, imn, imx, int(fat_count.sum()))


def merged_summaries(summaries: Sequence[TetSummary]) -> TetSummary:
    """summarize's summary of disjoint sets of tets joined, from theirs (a range's each): the
    extremes of their extremes and the sums of their counts and volumes (summed in their
    order, so the volume may differ from one pass's in the last bits).  NaN extremes (no
    tets, no core tet) are skipped."""

    def extreme(pick, values):
        values = [v for v in values if not math.isnan(v)]
        return pick(values) if values else float("nan")

    return TetSummary(extreme(min, [s.min_dihedral for s in summaries]),
                      extreme(max, [s.max_dihedral for s in summaries]),
                      extreme(min, [s.min_radius_ratio for s in summaries]),
                      sum((s.volume for s in summaries), 0.0),
                      extreme(min, [s.interior_min_dihedral for s in summaries]),
                      extreme(max, [s.interior_max_dihedral for s in summaries]),
                      sum(s.n_fat for s in summaries))
