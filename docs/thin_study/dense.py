"""Dense, worst-case-seeking sampler for stuffing across a one-level change of the band.

study.py cuts two-level octrees with random surfaces; random surfaces estimate rates but miss
worst cases.  This script takes every distinct lattice tet near a coarse/fine interface (template
tets, coarse BCC tets of coarse leaves touching fine ones, fine BCC tets sharing a vertex with
such a leaf; distinct up to translation, keyed also by the quad-rule decisions of its faces and
by the warp edges and reaches of its four vertices) and searches the cuts for its worst stencil
tets.  Three models of the surface near the tet:

* plane (default; the setting of Labelle & Shewchuk's theorem in the limit of a fine lattice):
  one plane decides signs, cut points and warps of the tet's whole neighbourhood.  Stage 1: every
  tet on a grid of planes (--normals on a Fibonacci sphere x --offsets); stage 2: the --top worst
  tets per category on a fine grid, then a pattern search from their --keep best planes.  For
  the production variant each worst case is re-run end to end through paroct.stuffing
  (collect_cut_edges, warp_targets with vertex_spacing, stuff) on its configuration.
* free: every cut fraction over its non-violating range [reach_start, 1 - reach_end], every
  warped vertex along any incident edge at any distance in [0, reach], all independent, on grids.
* signs: as free, but the signs of the tet's neighbourhood come from a plane, so a vertex warps
  only along edges to neighbours of the other sign.

Warps follow stuffing._warp (closest violating cut point, decided from unwarped positions) with
reaches from stuffing._edge_reach (checked equal) or a variant (VARIANTS).  Stencils are
production's: stuffing._stencil_tet (with _prism_choice, PRISM_TETS, _quad_first_diagonal) is
called for all 24 orders of the vertex ids, and the worst over them counts (on faces where the
rule falls back to the smaller vertex id, both diagonals); orders that make a cyclic prism are
skipped (production asserts they never occur) and counted.  A stencil tet the warps fold or
flatten (volume <= 0 when oriented as before the warps) counts as 0 / 180 degrees, as in
production's quality check.  Tets with a vertex on the block boundary are left out.

Run from the repository root, one core (results: docs/thin_study/README.md, "Dense sampling"):
    NUMBA_NUM_THREADS=1 python docs/thin_study/dense.py sanity                      # 30 s
    NUMBA_NUM_THREADS=1 python docs/thin_study/dense.py measure --random 50 --top 8  # 24 min
    NUMBA_NUM_THREADS=1 python docs/thin_study/dense.py measure --random 50 --top 8 \
        --variants "coarse cap + NL x0.5,coarse cap + NL never"                     # 9 min
    NUMBA_NUM_THREADS=1 python docs/thin_study/dense.py sanity --model free --budget 2e4 --gw 5 --gc 9
    NUMBA_NUM_THREADS=1 python docs/thin_study/dense.py sanity --model signs --budget 2e4 --gw 5 --gc 9 \
        --sign-normals 1000 --sign-offsets 48                                        # 3 min
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import sys
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numba as nb  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from paroct import lattice  # noqa: E402
from paroct.frame import LATTICE_TO_SPACE  # noqa: E402
from paroct.stuffing import (ALPHA_LONG, ALPHA_SHORT, PRISM_TETS, _edge_reach,  # noqa: E402
                             _face_spacing, _quad_first_diagonal, _stencil_tet, collect_cut_edges)
from study import emit, make_config, two_level_tree  # noqa: E402

LO, HI = 10.7, 164.8
EDGES = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
EDGE_INDEX = {p: k for k, p in enumerate(EDGES)}
CATS = ["template", "coarse BCC", "fine BCC near"]


# ----------------------------------------------------------------------------- warp reaches

def _gcd3(d):
    return math.gcd(math.gcd(abs(int(d[0])), abs(int(d[1]))), abs(int(d[2])))


def edge_info(d):
    """(spacing s > 0 of the lattice whose edge d is, or 0; alpha; scale) as in _edge_reach."""
    d = np.asarray(d, dtype=np.int64)
    s = int(max(abs(d)))
    nz = d[d != 0]
    lattice_edge = len(nz) > 0 and (np.all(nz == s) or np.all(nz == -s))
    if lattice_edge:
        alpha = ALPHA_LONG if len(nz) == 2 else ALPHA_SHORT
        return s, alpha, s
    return 0, ALPHA_LONG, 2 * _gcd3(d)


#: Variants: name -> function (d, spacing_v, v_in_transition_leaf, edge_of_template_tet) -> reach
#: (fraction of the edge) at v.  production: stuffing._edge_reach (alpha_long on non-lattice
#: template edges, the cap by vertex_spacing); NL xf: non-lattice edges' reach times f (0: never
#: warp along them); coarse cap: at a vertex of a transition leaf, coarse lattice edges reach only
#: alpha x the fine length (alpha / 2); tmpl-tet edges x0.75: study.py's lead, every edge of a
#: template tet (lattice ones too) times 0.75; "coarse cap + NL xf": both.
def _production(d, sp, vt, et):
    s, alpha, scale = edge_info(d)
    return alpha * min(1.0, sp / scale)


def _nl_scaled(f):
    def r(d, sp, vt, et):
        s, alpha, scale = edge_info(d)
        return alpha * min(1.0, sp / scale) * (f if s == 0 else 1.0)
    return r


def _coarse_cap(d, sp, vt, et):
    s, alpha, scale = edge_info(d)
    if vt and s >= 2:
        return alpha / s
    return alpha * min(1.0, sp / scale)


def _tmpl_edges_scaled(d, sp, vt, et):
    return _production(d, sp, vt, et) * (0.75 if et else 1.0)


def _coarse_cap_nl(f):
    def r(d, sp, vt, et):
        s, alpha, scale = edge_info(d)
        return _coarse_cap(d, sp, vt, et) * (f if s == 0 else 1.0)
    return r


VARIANTS = {
    "production": _production,
    "NL x0.75": _nl_scaled(0.75),
    "NL x0.5": _nl_scaled(0.5),
    "NL never": _nl_scaled(0.0),
    "coarse cap": _coarse_cap,
    "tmpl-tet edges x0.75": _tmpl_edges_scaled,
    "coarse cap + NL x0.5": _coarse_cap_nl(0.5),
    "coarse cap + NL never": _coarse_cap_nl(0.0),
}


# ----------------------------------------------------------------------------- configurations

def configs(n_random, seed):
    """(name, anchors, sides) of structured and random two-level trees."""
    out = []
    n = 4
    idx = np.indices((n,) * 3)
    h = n // 2
    for axis in range(3):
        for side in (0, 1):
            ref = idx[axis] >= h if side else idx[axis] < h
            out.append((f"slab{axis}{side}", *two_level_tree(n, ref)))
    for a, b in ((0, 1), (0, 2), (1, 2)):
        ref = (idx[a] >= h) & (idx[b] >= h)
        out.append((f"edge{a}{b}", *two_level_tree(n, ref)))
        out.append((f"edge{a}{b}~", *two_level_tree(n, ~ref)))
    ref = (idx[0] >= h) & (idx[1] >= h) & (idx[2] >= h)
    out.append(("corner", *two_level_tree(n, ref)))
    out.append(("corner~", *two_level_tree(n, ~ref)))
    rng = np.random.default_rng(seed)
    for i in range(n_random):
        out.append((f"random{i}", *make_config("random", rng, n)))
    return out


def uniform_config():
    return [("uniform", *two_level_tree(3, np.ones((3, 3, 3), dtype=bool)))]


def collect(cfgs, uniform=False):
    """Raw records: key -> dict(coords (4, 3) int, cat, stars [per vertex list of (d, sp, vt, et)],
    example).  Keyed by geometry up to translation, the quad decisions of all ordered face
    triples, and everything the reach variants read."""
    raw = {}
    for name, anchors, sides in cfgs:
        coords, tets, leaf, mask, chain, V = emit(anchors, sides)
        spacing = lattice.vertex_spacing(V, sides)
        nv = len(coords)
        n_root = int((anchors + sides[:, None]).max())
        on_root = ((coords == 0) | (coords == n_root)).any(1)
        trans_leaf = np.zeros(len(sides), dtype=bool)
        trans_leaf[leaf[mask != 0]] = True
        # vertices of transition leaves (corners and split points)
        vt = np.zeros(nv, dtype=bool)
        for L in np.nonzero(trans_leaf)[0]:
            vt[V.corner_ids[L]] = True
            r = V.split_row[L]
            s = V.split_ids[r]
            vt[s[s >= 0]] = True
        # vertices of coarse leaves, vertices of template tets
        coarse_v = np.zeros(nv, dtype=bool)
        for L in np.nonzero(sides == 2)[0]:
            coarse_v[V.corner_ids[L]] = True
            s = V.split_ids[V.split_row[L]]
            coarse_v[s[s >= 0]] = True
        tmpl_v = np.zeros(nv, dtype=bool)
        tmpl_v[tets[mask != 0].ravel()] = True
        # coarse leaves with a fine neighbour (a corner shared with a fine leaf)
        fine_nb = np.zeros(len(sides), dtype=bool)
        for L in np.nonzero(sides == 2)[0]:
            fine_nb[L] = (spacing[V.corner_ids[L]] == 1).any() or trans_leaf[L]
        near_v = np.zeros(nv, dtype=bool)  # vertices of coarse leaves with a fine neighbour
        for L in np.nonzero(fine_nb)[0]:
            near_v[V.corner_ids[L]] = True
            s = V.split_ids[V.split_row[L]]
            near_v[s[s >= 0]] = True
        tmpl_edges = set()
        for t in tets[mask != 0]:
            for i, j in EDGES:
                tmpl_edges.add((min(t[i], t[j]), max(t[i], t[j])))
        nbrs = [set() for _ in range(nv)]
        for t in tets:
            for i, j in EDGES:
                nbrs[t[i]].add(int(t[j]))
                nbrs[t[j]].add(int(t[i]))
        for ti, t in enumerate(tets):
            if on_root[t].any():
                continue
            if uniform:
                cat = "fine BCC near"
            elif mask[ti] != 0:
                cat = "template"
            elif sides[leaf[ti]] == 2:
                if not (fine_nb[leaf[ti]] or tmpl_v[t].any()):
                    continue
                cat = "coarse BCC"
            else:
                if not near_v[t].any():
                    continue
                cat = "fine BCC near"
            c = coords[t]
            stars = []
            for v in t:
                st = []
                for w in sorted(nbrs[v]):
                    d = tuple(int(x) for x in coords[w] - coords[v])
                    st.append((d, int(spacing[v]), bool(vt[v]), (min(v, w), max(v, w)) in tmpl_edges))
                stars.append(tuple(sorted(st)))
            dec = decisions(c)
            key = (cat, tuple(map(tuple, c - c[0])), dec, tuple(stars))
            if key not in raw:
                raw[key] = dict(coords=c.copy(), cat=cat, stars=stars, dec=dec,
                                example=(name, int(leaf[ti]), int(mask[ti]), int(chain[ti])),
                                spacing=[int(spacing[v]) for v in t], prod_check=(coords, spacing, t, nbrs))
    return raw


def decisions(c):
    """Quad decisions of the 24 ordered triples (a, b, e) of tet vertices: 0/1 production's rule
    on lattice faces, 2 where it falls back to vertex ids."""
    c = np.ascontiguousarray(c, dtype=np.int64)
    out = []
    for a, b, e in itertools.permutations(range(4), 3):
        if _face_spacing(c, a, b, e) == 0:
            out.append(2)
        else:
            out.append(int(_quad_first_diagonal(c, a, b, e)))
    return tuple(out)


def check_production_reach(raw):
    """The production variant must equal stuffing._edge_reach on every star edge."""
    n = 0
    for rec in list(raw.values())[:200]:
        coords, spacing, t, nbrs = rec["prod_check"]
        for i, v in enumerate(t):
            ws = np.array(sorted(nbrs[v]), dtype=np.int64)
            starts = np.full(len(ws), v, dtype=np.int64)
            _, sr, _ = _edge_reach(coords, starts, ws, spacing, LATTICE_TO_SPACE, ALPHA_LONG, ALPHA_SHORT)
            for k, w in enumerate(ws):
                d = coords[w] - coords[v]
                mine = _production(d, int(spacing[v]), False, False)
                assert abs(mine - sr[k]) < 1e-15, (d, mine, sr[k])
                n += 1
    return n


# ----------------------------------------------------------------------------- stencils

_STENCIL_CACHE = {}
#: Id orders skipped because they make a cyclic prism (counted over cache misses).
CYCLIC_ORDERS = [0]


def stencils(c, dec, signs):
    """Distinct output-tet lists (local point ids: 0..3 tet vertices, 4 + k the cut on EDGES[k])
    of production's _stencil_tet over the 24 orders of the vertex ids."""
    key = (dec, tuple(signs))
    if key in _STENCIL_CACHE:
        return _STENCIL_CACHE[key]
    results = set()
    scratch = np.empty((4, 6), dtype=np.int64)
    for perm in itertools.permutations(range(4)):
        # vertex i gets id perm[i]
        cp = np.empty((4, 3), dtype=np.int64)
        sg = np.empty(4, dtype=np.int8)
        for i in range(4):
            cp[perm[i]] = c[i]
            sg[perm[i]] = signs[i]
        tets = np.array([[perm[0], perm[1], perm[2], perm[3]]], dtype=np.int64)
        inside = sg > 0
        starts, ends, _, first, last, partner, edge = collect_cut_edges(tets, inside, cp)
        out = np.full((3, 4), -1, dtype=np.int32)
        r = _stencil_tet(0, tets, sg, cp, (first, last, partner, edge), 4, PRISM_TETS, out, 0, scratch)
        if r < 0:  # production asserts this never happens: such an id order cannot occur
            CYCLIC_ORDERS[0] += 1
            continue
        inv = {perm[i]: i for i in range(4)}
        rows = []
        for row in out:
            if row[0] < 0:
                continue
            loc = []
            for x in row:
                if x < 4:
                    loc.append(inv[int(x)])
                else:
                    e = int(x) - 4
                    p, q = inv[int(starts[e])], inv[int(ends[e])]
                    loc.append(4 + EDGE_INDEX[(min(p, q), max(p, q))])
            rows.append(tuple(loc))
        results.add(tuple(rows))
    res = sorted(results)
    _STENCIL_CACHE[key] = res
    return res


# ----------------------------------------------------------------------------- kernel

@nb.njit(cache=True, inline="always")
def _tet_extremes(P, R, i0, i1, i2, i3):
    """(min, max) dihedral angle (degrees) of tet (P[i0..i3]), oriented as it is at reference
    positions R; (0, 180) if folded or flat."""
    ax, ay, az = P[i0, 0], P[i0, 1], P[i0, 2]
    bx, by, bz = P[i1, 0] - ax, P[i1, 1] - ay, P[i1, 2] - az
    cx, cy, cz = P[i2, 0] - ax, P[i2, 1] - ay, P[i2, 2] - az
    dx, dy, dz = P[i3, 0] - ax, P[i3, 1] - ay, P[i3, 2] - az
    vol = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx)
    rx, ry, rz = R[i0, 0], R[i0, 1], R[i0, 2]
    ubx, uby, ubz = R[i1, 0] - rx, R[i1, 1] - ry, R[i1, 2] - rz
    ucx, ucy, ucz = R[i2, 0] - rx, R[i2, 1] - ry, R[i2, 2] - rz
    udx, udy, udz = R[i3, 0] - rx, R[i3, 1] - ry, R[i3, 2] - rz
    rvol = ubx * (ucy * udz - ucz * udy) - uby * (ucx * udz - ucz * udx) + ubz * (ucx * udy - ucy * udx)
    if rvol < 0:
        vol = -vol
        # swap c and d: outward normals below assume positive volume
        cx, cy, cz, dx, dy, dz = dx, dy, dz, cx, cy, cz
    if vol <= 1e-12:
        return 0.0, 180.0
    # outward normals of the faces opposite vertices 0..3 (positive volume)
    ex, ey, ez = cx - bx, cy - by, cz - bz
    fx, fy, fz = dx - bx, dy - by, dz - bz
    n0x, n0y, n0z = ey * fz - ez * fy, ez * fx - ex * fz, ex * fy - ey * fx
    n1x, n1y, n1z = dy * cz - dz * cy, dz * cx - dx * cz, dx * cy - dy * cx
    n2x, n2y, n2z = by * dz - bz * dy, bz * dx - bx * dz, bx * dy - by * dx
    n3x, n3y, n3z = cy * bz - cz * by, cz * bx - cx * bz, cx * by - cy * bx
    l0 = math.sqrt(n0x * n0x + n0y * n0y + n0z * n0z)
    l1 = math.sqrt(n1x * n1x + n1y * n1y + n1z * n1z)
    l2 = math.sqrt(n2x * n2x + n2y * n2y + n2z * n2z)
    l3 = math.sqrt(n3x * n3x + n3y * n3y + n3z * n3z)
    c01 = -(n0x * n1x + n0y * n1y + n0z * n1z) / (l0 * l1)
    c02 = -(n0x * n2x + n0y * n2y + n0z * n2z) / (l0 * l2)
    c03 = -(n0x * n3x + n0y * n3y + n0z * n3z) / (l0 * l3)
    c12 = -(n1x * n2x + n1y * n2y + n1z * n2z) / (l1 * l2)
    c13 = -(n1x * n3x + n1y * n3y + n1z * n3z) / (l1 * l3)
    c23 = -(n2x * n3x + n2y * n3y + n2z * n3z) / (l2 * l3)
    hi = max(c01, c02, c03, c12, c13, c23)
    lo = min(c01, c02, c03, c12, c13, c23)
    hi = min(1.0, max(-1.0, hi))
    lo = min(1.0, max(-1.0, lo))
    return math.degrees(math.acos(hi)), math.degrees(math.acos(lo))


@nb.njit(cache=True)
def scan(X0, cand, ncand, fr, nfr, outs, out_off):
    """Worst (min, argmin, max, argmax) of the output-tet dihedral angles over the product grid:
    vertex i at cand[i, 0:ncand[i]], cut k at fraction fr[k, 0:nfr[k]] from EDGES[k][0]
    (nfr[k] = 0: edge not cut); the worse over the stencil classes outs[out_off[c]:out_off[c+1]].
    arg*: flat index of the grid point (vertex indices first, then cut indices)."""
    radix = np.empty(10, dtype=np.int64)
    for i in range(4):
        radix[i] = ncand[i]
    for k in range(6):
        radix[4 + k] = max(nfr[k], 1)
    total = 1
    for i in range(10):
        total *= radix[i]
    ea = np.array([0, 0, 0, 1, 1, 2])
    eb = np.array([1, 2, 3, 2, 3, 3])
    P = np.zeros((10, 3))
    R = np.zeros((10, 3))
    for i in range(4):
        for c in range(3):
            R[i, c] = X0[i, c]
    idx = np.zeros(10, dtype=np.int64)
    best_mn, best_mx = 1e9, -1e9
    arg_mn, arg_mx = -1, -1
    ncls = out_off.shape[0] - 1
    for it in range(total):
        r = it
        for j in range(9, -1, -1):
            idx[j] = r % radix[j]
            r //= radix[j]
        for i in range(4):
            for c in range(3):
                P[i, c] = cand[i, idx[i], c]
        for k in range(6):
            if nfr[k] > 0:
                f = fr[k, idx[4 + k]]
                a, b = ea[k], eb[k]
                for c in range(3):
                    x = X0[a, c] + f * (X0[b, c] - X0[a, c])
                    P[4 + k, c] = x
                    R[4 + k, c] = x
        for cl in range(ncls):
            mn, mx = 1e9, -1e9
            for o in range(out_off[cl], out_off[cl + 1]):
                a1, a2 = _tet_extremes(P, R, outs[o, 0], outs[o, 1], outs[o, 2], outs[o, 3])
                mn = min(mn, a1)
                mx = max(mx, a2)
            if mn < best_mn:
                best_mn, arg_mn = mn, it
            if mx > best_mx:
                best_mx, arg_mx = mx, it
    return best_mn, arg_mn, best_mx, arg_mx


def decode(flat, radix):
    idx = []
    for r in reversed(radix):
        idx.append(flat % r)
        flat //= r
    return idx[::-1]


# ----------------------------------------------------------------------------- records

class Record:
    """A tet with warp options per vertex (directions in space, reaches) under one variant."""

    def __init__(self, raw, reach_fn):
        self.raw = raw
        self.c = raw["coords"]
        self.X0 = (self.c @ LATTICE_TO_SPACE.T).astype(np.float64)
        self.opts = []  # per vertex: list of (d lattice, vec space, reach)
        own = {}
        for i, st in enumerate(raw["stars"]):
            lst = []
            for d, sp, vt, et in st:
                r = reach_fn(np.array(d), sp, vt, et)
                lst.append((d, np.array(d) @ LATTICE_TO_SPACE.T, r))
                own[(i, d)] = r
            self.opts.append(lst)
        # reaches of the tet's own edges at each end
        self.er = np.zeros((6, 2))
        for k, (i, j) in enumerate(EDGES):
            dij = tuple(int(x) for x in self.c[j] - self.c[i])
            dji = tuple(-x for x in dij)
            self.er[k] = own[(i, dij)], own[(j, dji)]

    def key(self):
        return (self.raw["cat"], tuple(map(tuple, self.c - self.c[0])), self.raw["dec"],
                tuple(tuple(sorted((d, round(r, 12)) for d, _, r in lst if r > 0)) for lst in self.opts),
                tuple(np.round(self.er.ravel(), 12)))

    def can_warp(self, i):
        return any(r > 0 for _, _, r in self.opts[i])

    def candidates(self, i, gw):
        """Positions (P, 3) of vertex i warped: itself, then gw - 1 points (0, reach] per edge;
        and their labels (d, t)."""
        pos = [self.X0[i]]
        lab = [(None, 0.0)]
        ts = np.linspace(0, 1, gw)[1:]
        for d, vec, r in self.opts[i]:
            if r <= 0:
                continue
            for t in ts:
                pos.append(self.X0[i] + t * r * vec)
                lab.append((d, t * r))
        return np.array(pos), lab


def patterns():
    out = []
    for s in itertools.product((1, 0, -1), repeat=4):
        if 1 in s and any(x != 1 for x in s):
            out.append(s)
    return out


def grid_sizes(n_z, n_c, n_dirs, budget, gw_max, gc_max):
    """(gw, gc): points per warp direction (incl. 0) and per cut edge, largest with the product
    under budget (gc decreased first down to 5, then gw)."""
    gw, gc = gw_max, gc_max
    while True:
        size = (1 + n_dirs * (gw - 1)) ** n_z * gc ** n_c
        if size <= budget or (gw <= 2 and gc <= 2):
            return gw, gc
        if gc > 5 and (gc >= gw or gw <= 3):
            gc -= 2
        elif gw > 2:
            gw -= 1
        else:
            gc -= 1


def run_record(rec, budget, gw_max, gc_max, windows=None):
    """Worst min and max angles over all sign patterns of one record: list of result dicts."""
    results = []
    for s in patterns():
        zs = [i for i in range(4) if s[i] == 0]
        if any(not rec.can_warp(i) for i in zs):
            continue
        cut = [k for k, (i, j) in enumerate(EDGES) if s[i] * s[j] < 0]
        n_dirs = max((sum(1 for _, _, r in rec.opts[i] if r > 0) for i in zs), default=0)
        gw, gc = grid_sizes(len(zs), len(cut), n_dirs, budget, gw_max, gc_max)
        res = scan_pattern(rec, s, zs, cut, gw, gc)
        res["grid"] = (gw, gc)
        results.append(res)
    return results


def scan_pattern(rec, s, zs, cut, gw, gc, fixed=None):
    """Scan one sign pattern.  fixed: optional dict i -> (positions, labels) and k -> fractions
    overriding the grids (refinement)."""
    ncand = np.ones(4, dtype=np.int64)
    cands, labels = [], []
    for i in range(4):
        if fixed and ("v", i) in fixed:
            p, lab = fixed[("v", i)]
        elif s[i] == 0:
            p, lab = rec.candidates(i, gw)
        else:
            p, lab = rec.X0[i][None], [(None, 0.0)]
        cands.append(p)
        labels.append(lab)
        ncand[i] = len(p)
    cand = np.zeros((4, int(ncand.max()), 3))
    for i in range(4):
        cand[i, : ncand[i]] = cands[i]
    nfr = np.zeros(6, dtype=np.int64)
    frs = {}
    for k in cut:
        if fixed and ("e", k) in fixed:
            f = fixed[("e", k)]
        else:
            lo, hi = rec.er[k, 0], 1 - rec.er[k, 1]
            f = np.linspace(lo, hi, gc)
        frs[k] = f
        nfr[k] = len(f)
    fr = np.zeros((6, max(1, int(nfr.max()))))
    for k, f in frs.items():
        fr[k, : len(f)] = f
    classes = stencils(rec.c, rec.raw["dec"], s)
    outs = np.array([row for cl in classes for row in cl], dtype=np.int64).reshape(-1, 4)
    off = np.zeros(len(classes) + 1, dtype=np.int64)
    off[1:] = np.cumsum([len(cl) for cl in classes])
    mn, amn, mx, amx = scan(rec.X0, cand, ncand, fr, nfr, outs, off)
    radix = list(ncand) + [max(int(n), 1) for n in nfr]

    def describe(flat):
        idx = decode(int(flat), radix)
        warps = {i: labels[i][idx[i]] for i in range(4) if s[i] == 0}
        cuts = {EDGES[k]: float(frs[k][idx[4 + k]]) for k in cut}
        return idx, warps, cuts

    return dict(signs=s, min=mn, max=mx, argmin=describe(amn), argmax=describe(amx), n=int(np.prod(radix)),
                zs=zs, cut=cut, labels=labels, frs=frs)


def refine(rec, res, which, steps=2, n=9):
    """Rescan around the worst grid point (which: 'min' or 'max'): each warp kept on its edge,
    its distance and each cut fraction on n points over +-steps grid steps."""
    s, zs, cut = res["signs"], res["zs"], res["cut"]
    gw, gc = res["grid"]
    idx, warps, cuts = res["argmin" if which == "min" else "argmax"]
    fixed = {}
    for i in zs:
        d, dist = warps[i]
        opts = [(dd, vec, r) for dd, vec, r in rec.opts[i] if r > 0]
        if d is None:  # unwarped limit: try every edge near 0
            pos, lab = [rec.X0[i]], [(None, 0.0)]
            for dd, vec, r in opts:
                for t in np.linspace(0, steps / (gw - 1), n)[1:]:
                    pos.append(rec.X0[i] + t * r * vec)
                    lab.append((dd, t * r))
        else:
            vec, r = next((v, rr) for dd, v, rr in opts if dd == d)
            t0 = dist / r
            ts = np.clip(np.linspace(t0 - steps / (gw - 1), t0 + steps / (gw - 1), n), 0, 1)
            ts = np.unique(ts)
            pos = [rec.X0[i] + t * r * vec for t in ts]
            lab = [(d, t * r) for t in ts]
        fixed[("v", i)] = (np.array(pos), lab)
    for k in cut:
        lo, hi = rec.er[k, 0], 1 - rec.er[k, 1]
        h = (hi - lo) / (gc - 1) * steps
        f0 = cuts[EDGES[k]]
        fixed[("e", k)] = np.unique(np.clip(np.linspace(f0 - h, f0 + h, n), lo, hi))
    return scan_pattern(rec, s, zs, cut, gw, gc, fixed=fixed)


# ----------------------------------------------------------------------------- plane model

def stencil_table(rec):
    """For all 81 sign patterns: (pat_off (82,), cls_off, outs (K, 4)) with pattern p's classes
    pat_off[p]..pat_off[p+1] into cls_off, class c's tets outs[cls_off[c]:cls_off[c + 1]]
    (pattern index sum (s_i + 1) 3^i)."""
    pat_off = [0]
    cls_off = [0]
    outs = []
    for p in range(81):
        s = [(p // 3 ** i) % 3 - 1 for i in range(4)]
        if 1 in s and any(x != 1 for x in s):
            for cl in stencils(rec.c, rec.raw["dec"], s):
                outs.extend(cl)
                cls_off.append(len(outs))
        pat_off.append(len(cls_off) - 1)
    return (np.array(pat_off, dtype=np.int64), np.array(cls_off, dtype=np.int64),
            np.array(outs, dtype=np.int64).reshape(-1, 4))


def plane_arrays(rec):
    """Neighbours (4, D, 3) in space, their vectors from the vertex, reaches (4, D), counts (4,)
    of the warp edges (reach > 0) of each tet vertex; and the farthest warp distance."""
    D = max(1, max(sum(1 for _, _, r in lst if r > 0) for lst in rec.opts))
    W = np.zeros((4, D, 3))
    r = np.zeros((4, D))
    n = np.zeros(4, dtype=np.int64)
    far = 0.0
    for i, lst in enumerate(rec.opts):
        for d, vec, rr in lst:
            if rr > 0:
                W[i, n[i]] = rec.X0[i] + vec
                r[i, n[i]] = rr
                far = max(far, rr * np.linalg.norm(vec))
                n[i] += 1
    return W, r, n, far


@nb.njit(cache=True)
def plane_eval(nx, ny, nz, c, X0, W, wr, wn, pat_off, cls_off, outs, P, R, info):
    """(min, max) dihedral angle over the stencil tets of the tet cut by the plane n.x = c
    (inside: n.x < c), warps by production's rule (closest violating cut point among the
    vertex's warp edges), the worse over the stencil classes (vertex-id orders); (1e9, -1e9) if
    the tet is not cut or wholly outside.  info[0] gets the pattern index, info[1 + i] the warp
    edge of vertex i or -1."""
    f = np.empty(4)
    for i in range(4):
        f[i] = nx * X0[i, 0] + ny * X0[i, 1] + nz * X0[i, 2] - c
    pat = 0
    mult = 1
    n_plus = 0
    for i in range(4):
        inside = f[i] < 0
        best = 1e300
        be = -1
        bt = 0.0
        for j in range(wn[i]):
            fw = nx * W[i, j, 0] + ny * W[i, j, 1] + nz * W[i, j, 2] - c
            if (fw < 0) != inside:
                t = f[i] / (f[i] - fw)
                if t < wr[i, j]:
                    dx = W[i, j, 0] - X0[i, 0]
                    dy = W[i, j, 1] - X0[i, 1]
                    dz = W[i, j, 2] - X0[i, 2]
                    dist = t * math.sqrt(dx * dx + dy * dy + dz * dz)
                    if dist < best:
                        best = dist
                        be = j
                        bt = t
        info[1 + i] = be
        if be >= 0:
            for k in range(3):
                P[i, k] = X0[i, k] + bt * (W[i, be, k] - X0[i, k])
            sgn = 0
        else:
            for k in range(3):
                P[i, k] = X0[i, k]
            sgn = 1 if inside else -1
        if sgn == 1:
            n_plus += 1
        pat += (sgn + 1) * mult
        mult *= 3
        f[i] = f[i] if be < 0 else 0.0
        R[i, 0] = X0[i, 0]
        R[i, 1] = X0[i, 1]
        R[i, 2] = X0[i, 2]
        info[5 + i] = sgn
    info[0] = pat
    if n_plus == 0 or n_plus == 4:
        return 1e9, -1e9
    # cut points on the tet's +/- edges
    k = 0
    for a in range(4):
        for b in range(a + 1, 4):
            if info[5 + a] * info[5 + b] < 0:
                t = f[a] / (f[a] - f[b])
                for q in range(3):
                    x = X0[a, q] + t * (X0[b, q] - X0[a, q])
                    P[4 + k, q] = x
                    R[4 + k, q] = x
            k += 1
    mn, mx = 1e9, -1e9
    for cl in range(pat_off[pat], pat_off[pat + 1]):
        for o in range(cls_off[cl], cls_off[cl + 1]):
            a1, a2 = _tet_extremes(P, R, outs[o, 0], outs[o, 1], outs[o, 2], outs[o, 3])
            mn = min(mn, a1)
            mx = max(mx, a2)
    return mn, mx


@nb.njit(cache=True)
def fib_normals(n):
    out = np.empty((n, 3))
    ga = math.pi * (3.0 - math.sqrt(5.0))
    for i in range(n):
        z = 1.0 - (2.0 * i + 1.0) / n
        r = math.sqrt(max(0.0, 1.0 - z * z))
        out[i, 0] = r * math.cos(ga * i)
        out[i, 1] = r * math.sin(ga * i)
        out[i, 2] = z
    return out


@nb.njit(cache=True)
def plane_scan(normals, n_off, X0, W, wr, wn, pat_off, cls_off, outs, far, keep):
    """Grid over planes: every normal, n_off offsets across the range where the plane can cut the
    tet or warp one of its vertices.  Returns the keep best planes for the min angle and for the
    max angle: (mins (keep, 5): angle, nx, ny, nz, c; maxs (keep, 5))."""
    P = np.zeros((10, 3))
    R = np.zeros((10, 3))
    info = np.zeros(9, dtype=np.int64)
    mins = np.full((keep, 5), 1e9)
    maxs = np.full((keep, 5), -1e9)
    for a in range(normals.shape[0]):
        nx, ny, nz = normals[a, 0], normals[a, 1], normals[a, 2]
        lo, hi = 1e300, -1e300
        for i in range(4):
            v = nx * X0[i, 0] + ny * X0[i, 1] + nz * X0[i, 2]
            lo = min(lo, v)
            hi = max(hi, v)
        lo -= far
        hi += far
        for b in range(n_off):
            c = lo + (hi - lo) * (b + 0.5) / n_off
            mn, mx = plane_eval(nx, ny, nz, c, X0, W, wr, wn, pat_off, cls_off, outs, P, R, info)
            if mn < mins[keep - 1, 0]:
                j = keep - 1
                while j > 0 and mins[j - 1, 0] > mn:
                    mins[j] = mins[j - 1]
                    j -= 1
                mins[j, 0], mins[j, 1], mins[j, 2], mins[j, 3], mins[j, 4] = mn, nx, ny, nz, c
            if mx > maxs[keep - 1, 0]:
                j = keep - 1
                while j > 0 and maxs[j - 1, 0] < mx:
                    maxs[j] = maxs[j - 1]
                    j -= 1
                maxs[j, 0], maxs[j, 1], maxs[j, 2], maxs[j, 3], maxs[j, 4] = mx, nx, ny, nz, c
    return mins, maxs


@nb.njit(cache=True)
def plane_polish(start, sense, step_n, step_c, X0, W, wr, wn, pat_off, cls_off, outs, iters):
    """Pattern search from plane start (angle, nx, ny, nz, c): sense +1 lowers the min angle,
    -1 raises the max angle.  Returns the best (angle, nx, ny, nz, c)."""
    P = np.zeros((10, 3))
    R = np.zeros((10, 3))
    info = np.zeros(9, dtype=np.int64)
    best = start.copy()
    n = best[1:4].copy()
    c = best[4]
    for it in range(iters):
        # tangent basis at n
        ax0, ax1, ax2 = (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0)
        e1 = np.array([n[1] * ax2 - n[2] * ax1, n[2] * ax0 - n[0] * ax2, n[0] * ax1 - n[1] * ax0])
        e1 /= math.sqrt(e1[0] ** 2 + e1[1] ** 2 + e1[2] ** 2)
        e2 = np.array([n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0]])
        improved = False
        for m in range(6):
            nn = n.copy()
            cc = c
            if m < 2:
                nn = n + (1 - 2 * m) * step_n * e1
            elif m < 4:
                nn = n + (1 - 2 * (m - 2)) * step_n * e2
            else:
                cc = c + (1 - 2 * (m - 4)) * step_c
            nn /= math.sqrt(nn[0] ** 2 + nn[1] ** 2 + nn[2] ** 2)
            mn, mx = plane_eval(nn[0], nn[1], nn[2], cc, X0, W, wr, wn, pat_off, cls_off, outs, P, R, info)
            val = mn if sense > 0 else mx
            if (sense > 0 and val < best[0]) or (sense < 0 and val > best[0]):
                best[0] = val
                best[1], best[2], best[3], best[4] = nn[0], nn[1], nn[2], cc
                n = nn
                c = cc
                improved = True
                break
        if not improved:
            step_n *= 0.5
            step_c *= 0.5
            if step_n < 1e-9:
                break
    return best


def plane_describe(rec, arrs, plane):
    W, wr, wn, pat_off, cls_off, outs = arrs
    P = np.zeros((10, 3))
    R = np.zeros((10, 3))
    info = np.zeros(9, dtype=np.int64)
    mn, mx = plane_eval(plane[1], plane[2], plane[3], plane[4], rec.X0, W, wr, wn, pat_off, cls_off, outs, P, R, info)
    signs = [int(x) for x in info[5:9]]
    warps = {}
    lists = [[(d, r) for d, _, r in lst if r > 0] for lst in rec.opts]
    for i in range(4):
        e = int(info[1 + i])
        if e >= 0:
            d, r = lists[i][e]
            dist = np.linalg.norm(P[i] - rec.X0[i]) / np.linalg.norm(np.array(d) @ LATTICE_TO_SPACE.T)
            warps[i] = (d, round(float(dist), 4), round(float(r), 4))
    return dict(min=mn, max=mx, signs=signs, warps=warps, plane=[round(float(x), 6) for x in plane[1:]])


class PlaneRecord:
    def __init__(self, rec):
        self.rec = rec
        W, wr, wn, far = plane_arrays(rec)
        self.far = far
        self.arrs = (W, wr, wn) + stencil_table(rec)

    def scan(self, normals, n_off, keep):
        W, wr, wn, po, co, outs = self.arrs
        return plane_scan(normals, n_off, self.rec.X0, W, wr, wn, po, co, outs, self.far, keep)

    def polish(self, start, sense, step_n, step_c, iters=400):
        W, wr, wn, po, co, outs = self.arrs
        return plane_polish(start, sense, step_n, step_c, self.rec.X0, W, wr, wn, po, co, outs, iters)


def distinct_records(raws, reach_fn):
    """One Record per distinct key (tet shape, quad decisions, warp edges and reaches)."""
    recs = {}
    for raw in raws.values():
        r = Record(raw, reach_fn)
        recs.setdefault(r.key(), r)
    return list(recs.values())


def run_plane_variant(raws, reach_fn, args, label):
    """Stage 1: every tet on a coarse plane grid.  Stage 2: the args.top worst tets per category
    (by min and by max) on a fine grid, then pattern search from the best planes."""
    t0 = time.time()
    recs = distinct_records(raws, reach_fn)
    coarse = fib_normals(args.normals)
    fine = fib_normals(args.fine_normals)
    stage1 = []
    for rec in recs:
        pr = PlaneRecord(rec)
        mins, maxs = pr.scan(coarse, args.offsets, 1)
        stage1.append((rec, mins[0, 0], maxs[0, 0]))
    t1 = time.time() - t0
    out = dict(variant=label, records=len(recs), cats={})
    print(f"\n=== {label} (plane model): {len(recs)} distinct tets, stage 1 {t1:.0f} s", flush=True)
    for cat in CATS:
        rows = [x for x in stage1 if x[0].raw["cat"] == cat]
        if not rows:
            continue
        c_min = min(x[1] for x in rows)
        c_max = max(x[2] for x in rows)
        n_bad = sum(1 for x in rows if x[1] < LO or x[2] > HI)
        chosen = sorted(rows, key=lambda x: x[1])[: args.top] + sorted(rows, key=lambda x: -x[2])[: args.top]
        seen = set()
        best_mn, best_mx = (1e9, None, None), (-1e9, None, None)
        for rec, _, _ in chosen:
            if id(rec) in seen:
                continue
            seen.add(id(rec))
            pr = PlaneRecord(rec)
            mins, maxs = pr.scan(fine, args.fine_offsets, args.keep)
            step_n = 2.0 * math.sqrt(4 * math.pi / args.fine_normals)
            for k in range(args.keep):
                if mins[k, 0] < 1e8:
                    sc = 2.0 * (pr.far * 2 + 2) / args.fine_offsets
                    b = pr.polish(mins[k], 1, step_n, sc)
                    if b[0] < best_mn[0]:
                        best_mn = (b[0], pr, b)
                if maxs[k, 0] > -1e8:
                    sc = 2.0 * (pr.far * 2 + 2) / args.fine_offsets
                    b = pr.polish(maxs[k], -1, step_n, sc)
                    if b[0] > best_mx[0]:
                        best_mx = (b[0], pr, b)
        out["cats"][cat] = dict(tets=len(rows), coarse_min=c_min, coarse_max=c_max, coarse_outside=n_bad,
                                min=best_mn[0], max=best_mx[0],
                                min_case=case_text(best_mn[1], best_mn[2]), max_case=case_text(best_mx[1], best_mx[2]))
        print(f"  {cat:14s} tets {len(rows):6d}  coarse grid: [{c_min:7.3f}, {c_max:7.3f}], tets outside {n_bad:5d}"
              f"   refined worst: min {best_mn[0]:7.3f}  max {best_mx[0]:7.3f}", flush=True)
        print(f"     min: {out['cats'][cat]['min_case']}")
        if reach_fn is _production:
            print(f"          production end to end: {check_case(best_mn[1], best_mn[2], args.random, args.seed)}")
        print(f"     max: {out['cats'][cat]['max_case']}")
        if reach_fn is _production:
            print(f"          production end to end: {check_case(best_mx[1], best_mx[2], args.random, args.seed)}")
    out["seconds"] = round(time.time() - t0, 1)
    print(f"  ({out['seconds']} s)", flush=True)
    return out


def case_text(pr, plane):
    rec = pr.rec
    d = plane_describe(rec, pr.arrs, plane)
    ex = rec.raw["example"]
    rel = (rec.c - rec.c[0]).tolist()
    w = {i: f"{dd} at {dist} (reach {r})" for i, (dd, dist, r) in d["warps"].items()}
    return (f"{rec.raw['cat']}, mask {ex[2]} ({ex[0]}), tet u={rel} + {rec.c[0].tolist()}, spacing {rec.raw['spacing']}, "
            f"signs {sgn(d['signs'])}, warps {w}, min {d['min']:.3f} max {d['max']:.3f}, plane n, c = {d['plane']}")


# ----------------------------------------------------------------------------- plane-sign model

def sign_combos(rec, normals, n_off):
    """Distinct (original signs of the tet's vertices, per vertex the warp edges to neighbours of the
    other sign) over a grid of planes: the sign patterns a plane can give the tet's neighbourhood."""
    W, wr, wn, far = plane_arrays(rec)
    pts = [rec.X0] + [W[i, : wn[i]] for i in range(4)]
    allp = np.concatenate(pts)
    combos = set()
    for a in range(0, len(normals), 256):
        nrm = normals[a: a + 256]
        proj = nrm @ allp.T  # (N, K)
        lo = proj[:, :4].min(1) - far
        hi = proj[:, :4].max(1) + far
        for b in range(n_off):
            c = lo + (hi - lo) * (b + 0.5) / n_off
            inside = proj < c[:, None]
            for row in np.unique(inside, axis=0):
                sig = tuple(1 if x else -1 for x in row[:4])
                allowed = []
                k = 4
                for i in range(4):
                    allowed.append(tuple(j for j in range(wn[i]) if row[k + j] != row[i]))
                    k += wn[i]
                combos.add((sig, tuple(allowed)))
    return combos


def run_signs_record(rec, combos, budget, gw_max, gc_max):
    """Free cut fractions and warps (model 'free'), restricted to sign patterns a plane gives: a vertex
    warps only along an edge to a neighbour of the other sign.  Returns the scan results."""
    W, wr, wn, far = plane_arrays(rec)
    warp_opts = [[(d, vec, r) for d, vec, r in lst if r > 0] for lst in rec.opts]
    jobs = {}
    for sig, allowed in combos:
        choices = [[sig[i]] + ([0] if allowed[i] else []) for i in range(4)]
        for s in itertools.product(*choices):
            if 1 not in s or all(x == 1 for x in s):
                continue
            key = (s, tuple(allowed[i] if s[i] == 0 else () for i in range(4)))
            jobs[key] = True
    results = []
    for s, allowed in jobs:
        zs = [i for i in range(4) if s[i] == 0]
        cut = [k for k, (i, j) in enumerate(EDGES) if s[i] * s[j] < 0]
        n_dirs = max((len(allowed[i]) for i in zs), default=0)
        gw, gc = grid_sizes(len(zs), len(cut), n_dirs, budget, gw_max, gc_max)
        fixed = {}
        for i in zs:
            pos, lab = [rec.X0[i]], [(None, 0.0)]
            for j in allowed[i]:
                d, vec, r = warp_opts[i][j]
                for t in np.linspace(0, 1, gw)[1:]:
                    pos.append(rec.X0[i] + t * r * vec)
                    lab.append((d, t * r))
            fixed[("v", i)] = (np.array(pos), lab)
        res = scan_pattern(rec, s, zs, cut, gw, gc, fixed=fixed)
        res["grid"] = (gw, gc)
        results.append(res)
    return results


def run_signs_variant(raws, reach_fn, args, label, only=None):
    """Model 'signs' over the records (only: optional list of records)."""
    t0 = time.time()
    if only is None:
        recs = {}
        for raw in raws.values():
            r = Record(raw, reach_fn)
            recs.setdefault(r.key(), r)
        recs = list(recs.values())
    else:
        recs = only
    normals = fib_normals(args.sign_normals)
    worst = {}
    for rec in recs:
        combos = sign_combos(rec, normals, args.sign_offsets)
        for res in run_signs_record(rec, combos, args.budget, args.gw, args.gc):
            w = worst.setdefault(rec.raw["cat"], [(1e9, None, None), (-1e9, None, None)])
            if res["min"] < w[0][0]:
                w[0] = (res["min"], rec, res)
            if res["max"] > w[1][0]:
                w[1] = (res["max"], rec, res)
    print(f"\n=== {label} (plane-sign model): {len(recs)} tets, {time.time() - t0:.0f} s", flush=True)
    out = dict(variant=label, records=len(recs), cats={})
    for cat, (wmn, wmx) in worst.items():
        print(f"  {cat:14s} worst min {wmn[0]:7.3f}  worst max {wmx[0]:7.3f}")
        print(f"     min: {fmt_case(wmn[1], wmn[2], 'min')}")
        print(f"     max: {fmt_case(wmx[1], wmx[2], 'max')}")
        out["cats"][cat] = dict(min=wmn[0], max=wmx[0], min_case=fmt_case(wmn[1], wmn[2], "min"),
                                max_case=fmt_case(wmx[1], wmx[2], "max"))
    return out


# ----------------------------------------------------------------------------- end-to-end check

def production_run(cfg_name, plane, n_random, seed):
    """Stuff the named configuration, cut by the plane (nx, ny, nz, c), with paroct.stuffing end to end
    (collect_cut_edges, warp_targets with vertex_spacing, stuff with flat_ok); returns
    (coords, tets, offsets, out points, out tets, quality)."""
    from paroct.quality import tet_quality
    from paroct.stuffing import CutEdges, _stencils_of, _warped, warp_targets
    cfg = {name: (a, s) for name, a, s in (configs(n_random, seed) + uniform_config())}[cfg_name]
    anchors, sides = cfg
    V = lattice.number_vertices(anchors, sides)
    tets = np.ascontiguousarray(lattice.graded_tets(V)).astype(np.int64)
    coords = V.coords
    pts = coords @ LATTICE_TO_SPACE.T
    n = np.array(plane[:3])
    fv = pts @ n - plane[3]
    inside = fv < 0
    starts, ends, dirs, first, last, partner, edge = collect_cut_edges(tets, inside, coords)
    fracs = fv[starts] / (fv[starts] - fv[ends])
    cpts = pts[starts] + fracs[:, None] * (pts[ends] - pts[starts])
    cuts = CutEdges(starts, ends, dirs, fracs, cpts, (first, last, partner, edge))
    targets = warp_targets(cuts, coords, 1.0, lattice.vertex_spacing(V, sides))
    points, signs = _warped(pts, inside, cuts, targets)
    out, offsets = _stencils_of(points, pts, coords, tets, signs, cuts, True)
    return coords, tets, offsets, points, out, tet_quality(points, out)


def check_case(pr, plane, n_random, seed):
    """The worst case through production: the (min, max) angles production gives the output tets of
    every source tet with the record's vertex coordinates (same place, same configuration)."""
    rec = pr.rec
    coords, tets, offsets, points, out, q = production_run(rec.raw["example"][0], plane[1:], n_random, seed)
    key = {tuple(x) for x in rec.c.tolist()}
    found = []
    for t in range(len(tets)):
        if {tuple(x) for x in coords[tets[t]].tolist()} == key:
            sl = slice(offsets[t], offsets[t + 1])
            if offsets[t + 1] > offsets[t]:
                found.append((round(float(q.min_dihedral[sl].min()), 3), round(float(q.max_dihedral[sl].max()), 3)))
            else:
                found.append(None)
    return found


# ----------------------------------------------------------------------------- driver

def sgn(s):
    return "".join("+" if x > 0 else "-" if x < 0 else "0" for x in s)


def fmt_case(rec, res, which):
    idx, warps, cuts = res["argmin" if which == "min" else "argmax"]
    ex = rec.raw["example"]
    w = {i: (d, round(dist, 4)) for i, (d, dist) in warps.items()}
    c = {f"{i}{j}": round(f, 4) for (i, j), f in cuts.items()}
    rel = (rec.c - rec.c[0]).tolist()
    return (f"{rec.raw['cat']}, mask {ex[2]}, tet u={rel} at {rec.c[0].tolist()} (spacing {rec.raw['spacing']}), "
            f"signs {sgn(res['signs'])}, warps {w} (vertex: u-direction, distance in edge fractions), cuts {c}")


def run_variant(raws, reach_fn, args, label):
    t0 = time.time()
    recs = distinct_records(raws, reach_fn)
    worst = {c: dict(min=(1e9, None, None), max=(-1e9, None, None), n=0, points=0) for c in CATS}
    per_pattern = {}
    for rec in recs:
        w = worst[rec.raw["cat"]]
        w["n"] += 1
        for res in run_record(rec, args.budget, args.gw, args.gc):
            w["points"] += res["n"]
            if res["min"] < w["min"][0]:
                w["min"] = (res["min"], rec, res)
            if res["max"] > w["max"][0]:
                w["max"] = (res["max"], rec, res)
            key = (rec.raw["cat"], sgn(sorted(res["signs"], reverse=True)))
            pm = per_pattern.setdefault(key, [1e9, -1e9])
            pm[0] = min(pm[0], res["min"])
            pm[1] = max(pm[1], res["max"])
    # refine around the worst cases
    for c in CATS:
        w = worst[c]
        if w["n"] == 0:
            continue
        for which in ("min", "max"):
            val, rec, res = w[which]
            cur = res
            for _ in range(args.refine):
                new = refine(rec, cur, which)
                new["grid"] = cur["grid"]
                better = new["min"] < cur["min"] if which == "min" else new["max"] > cur["max"]
                if not better:
                    break
                # next round: finer steps around the new point
                new["grid"] = (2 * cur["grid"][0] - 1, 2 * cur["grid"][1] - 1)
                cur = new
            w[which + "_refined"] = (cur[which], rec, cur)
    out = dict(variant=label, records=len(recs), seconds=round(time.time() - t0, 1), cats={})
    print(f"\n=== {label}: {len(recs)} distinct tets, {time.time() - t0:.0f} s", flush=True)
    for c in CATS:
        w = worst[c]
        if w["n"] == 0:
            continue
        mn, rmn, smn = w["min_refined"]
        mx, rmx, smx = w["max_refined"]
        print(f"  {c:14s} tets {w['n']:5d}  grid points {w['points']:.3g}  worst min {w['min'][0]:7.3f} "
              f"(refined {mn:7.3f})  worst max {w['max'][0]:7.3f} (refined {mx:7.3f})")
        print(f"     min: {fmt_case(rmn, smn, 'min')}")
        print(f"     max: {fmt_case(rmx, smx, 'max')}")
        out["cats"][c] = dict(tets=w["n"], points=w["points"], min=w["min"][0], max=w["max"][0],
                              min_refined=mn, max_refined=mx, min_case=fmt_case(rmn, smn, "min"),
                              max_case=fmt_case(rmx, smx, "max"))
    if args.patterns:
        print("  per sign pattern (sorted signs) worst min / max:")
        for (c, p), (a, b) in sorted(per_pattern.items()):
            print(f"     {c:14s} {p}  {a:7.3f} {b:7.3f}")
    out["per_pattern"] = {f"{c} {p}": v for (c, p), v in sorted(per_pattern.items())}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["sanity", "measure"])
    ap.add_argument("--model", choices=["plane", "signs", "free"], default="plane",
                    help="plane: one plane cuts the tet's neighbourhood (L&S's setting); free: every cut fraction "
                         "and warp independent; signs: signs from a plane, cut fractions and warps free")
    ap.add_argument("--sign-normals", type=int, default=2000, help="signs: plane normals enumerating sign patterns")
    ap.add_argument("--sign-offsets", type=int, default=64, help="signs: offsets per normal")
    ap.add_argument("--random", type=int, default=100, help="random two-level trees (besides the structured ones)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--variants", default=",".join(list(VARIANTS)[:6]))
    # plane model
    ap.add_argument("--normals", type=int, default=500, help="stage 1: plane normals (Fibonacci sphere)")
    ap.add_argument("--offsets", type=int, default=24, help="stage 1: offsets per normal")
    ap.add_argument("--fine-normals", type=int, default=20000, help="stage 2")
    ap.add_argument("--fine-offsets", type=int, default=200, help="stage 2")
    ap.add_argument("--top", type=int, default=10, help="stage 2: worst tets per category, by min and by max")
    ap.add_argument("--keep", type=int, default=4, help="stage 2: best planes polished per tet")
    # free model
    ap.add_argument("--budget", type=float, default=2e5, help="free: grid points per tet and sign pattern")
    ap.add_argument("--gw", type=int, default=9, help="free: max points per warp edge over [0, reach]")
    ap.add_argument("--gc", type=int, default=17, help="free: max points per cut edge")
    ap.add_argument("--refine", type=int, default=3, help="free: refinement rounds around each worst case")
    ap.add_argument("--patterns", action="store_true", help="free: print the worst per sign pattern")
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    t0 = time.time()
    run = {"plane": run_plane_variant, "signs": run_signs_variant, "free": run_variant}[args.model]
    if args.mode == "sanity":
        raws = collect(uniform_config(), uniform=True)
        print(f"uniform lattice: {len(raws)} raw tets, reach check {check_production_reach(raws)} edges", flush=True)
        results = [run(raws, _production, args, "L&S (uniform fine lattice)")]
    else:
        raws = collect(configs(args.random, args.seed))
        print(f"{len(raws)} raw tets ({time.time() - t0:.0f} s), reach check {check_production_reach(raws)} edges",
              flush=True)
        results = [run(raws, VARIANTS[v], args, v) for v in args.variants.split(",")]
    print(f"\nid orders skipped as cyclic (distinct sign pattern / quad-rule tables): {CYCLIC_ORDERS[0]}")
    print(f"total {time.time() - t0:.0f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1, default=str)


if __name__ == "__main__":
    main()
