"""Measurement study: isosurface stuffing across a one-level change of the band.

What it measures
----------------
paroct stuffs (Labelle & Shewchuk 2007) only finest-level BCC tets.  This script stuffs
two-level 2:1 octrees (coarse leaves of side 2 next to fine leaves of side 1, fine lattice
units; closure templates of paroct.transitions on the coarse transition leaves) cut by random
planes and spheres passing near the coarse/fine interface, with ONE generic stencil:

* cut points exact on every sign-changing edge of the emitted (conforming) tets;
* warp: a cut point on edge (v, w) violates v if |cut - v| < alpha(kind) * |w - v|; every
  vertex moves to its closest violating cut point, all decided from unwarped positions;
* edge kinds: lattice short (u-difference s*e_i or s*(1,1,1)), lattice long (s*(e_i+e_j)),
  any power-of-two scale s; non-lattice template edges (e.g. (1,-1,0), (2,1,1));
  warp variants differ in alpha for non-lattice edges and in an optional cap for vertices
  shared with fine leaves (see VARIANTS);
* stencils as stuffing._stencil_tet; quad diagonals by the L&S rule on faces of the BCC lattice
  at some level (coordinates divided by the level's side), by a face-local rule elsewhere
  (diagonal at the smallest vertex id); cyclic +++- prisms are counted and coned to their centroid.

It reports, per warp variant, the worst min/max dihedral angles of output tets by origin
(template tets, BCC tets sharing a vertex with a template tet, other BCC tets), the fraction of
cut coarse transition leaves with an output tet outside [10.7, 164.8] degrees, the worst cases
and their causes, and cyclic-prism counts.  A sanity mode checks the generic implementation
against the L&S bound on a uniform fine lattice, plus conformity and volume.

Run from the repository root with paroct installed (results: docs/thin_study/README.md):
    python docs/thin_study/study.py sanity --n 3000 --n-conform 300      # about 6 minutes
    python docs/thin_study/study.py measure --n 1000 --n-conform 100     # about 7 minutes
    python docs/thin_study/study.py measure --variants extra --n 400 --n-conform 20
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import sys
import time

import numpy as np

from paroct import lattice
from paroct.frame import LATTICE_TO_SPACE
from paroct.stuffing import PRISM_TETS
from paroct.transitions import CHAIN_IS_ODD, CHAINS, TEMPLATE_COUNTS, TEMPLATE_TETS

ALPHA_LONG = 0.24999
ALPHA_SHORT = 0.41189
LO, HI = 10.7, 164.8
SHORT_LEN = math.sqrt(3) / 2

# Edge kinds.
FS, FL, CS, CL, NL = range(5)
KIND_NAMES = ["fine-short", "fine-long", "coarse-short", "coarse-long", "non-lattice"]

#: Warp variants: name -> (alpha per kind, cap).  cap: a vertex that is a corner of a fine leaf
#: is violated only by cut points closer than alpha * (fine length): for coarse lattice edges the
#: same-direction fine edge (len / scale), for non-lattice edges len / 2.
VARIANTS = {
    "NL=short": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT], False),
    "NL=long": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_LONG], False),
    "NL=never": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, 0.0], False),
    "NL=short+cap": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT], True),
    "NL=long+cap": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_LONG], True),
    "NL=never+cap": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, 0.0], True),
}
#: Extra variants (--variants extra): every alpha scaled by the factor for edges of template tets
#: (an edge is a template edge if some template tet has it), non-lattice as NL=long.
EXTRA_VARIANTS = {
    "NL=long,tmpl*0.75": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_LONG], False, 0.75),
    "NL=long,tmpl*0.5": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_LONG], False, 0.5),
    "NL=never,tmpl*0.75": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, 0.0], False, 0.75),
    "all*0.75": ([ALPHA_SHORT, ALPHA_LONG, ALPHA_SHORT, ALPHA_LONG, ALPHA_LONG], False, "all0.75"),
}


# ----------------------------------------------------------------------------- configurations

def two_level_tree(n_coarse: int, refined: np.ndarray):
    """Leaves of a two-level tree over [0, 2 n_coarse)^3: coarse cell (i, j, k) (side 2) is split
    into 8 fine leaves where refined[i, j, k].  Any such tree is 2:1 balanced.  Returns
    (anchors (L, 3), sides (L,)) sorted by Morton key, as lattice.number_vertices wants."""
    anchors, sides = [], []
    for i, j, k in np.ndindex(refined.shape):
        a = 2 * np.array([i, j, k])
        if refined[i, j, k]:
            for c in range(8):
                anchors.append(a + [(c >> 0) & 1, (c >> 1) & 1, (c >> 2) & 1])
                sides.append(1)
        else:
            anchors.append(a)
            sides.append(2)
    anchors = np.array(anchors, dtype=np.int64)
    sides = np.array(sides, dtype=np.int64)
    from paroct.octant import morton_keys
    order = np.argsort(morton_keys(anchors), kind="stable")
    return anchors[order], sides[order]


def make_config(kind: str, rng, n_coarse=4):
    """Structured (slab / edge / corner / checker) or random two-level trees."""
    idx = np.indices((n_coarse,) * 3)
    h = n_coarse // 2
    if kind == "uniform":
        refined = np.ones((n_coarse,) * 3, dtype=bool)
    elif kind == "slab":
        axis = rng.integers(3)
        refined = idx[axis] >= h if rng.random() < 0.5 else idx[axis] < h
    elif kind == "edge":
        a, b = rng.choice(3, 2, replace=False)
        refined = (idx[a] >= h) & (idx[b] >= h)
    elif kind == "corner":
        refined = (idx[0] >= h) & (idx[1] >= h) & (idx[2] >= h)
        if rng.random() < 0.5:
            refined = ~refined
    elif kind == "random":
        refined = rng.random((n_coarse,) * 3) < rng.uniform(0.2, 0.6)
    else:
        raise ValueError(kind)
    return two_level_tree(n_coarse, refined)


# ----------------------------------------------------------------------------- emission

def emit(anchors, sides):
    """Tets of the leaves with provenance: (coords, tets (M, 4), leaf (M,), mask (M,), chain (M,),
    vertices).  Same tets as lattice.graded_tets (checked)."""
    V = lattice.number_vertices(anchors, sides)
    tets, leaf, mask, chain = [], [], [], []
    for i in range(len(sides)):
        r = V.split_row[i]
        for c in range(6):
            labels = [int(V.corner_ids[i, CHAINS[c, k]]) for k in range(4)]
            m = 0
            for k in range(5):
                from paroct.transitions import CHAIN_SPLITS
                lab = -1 if r < 0 else int(V.split_ids[r, CHAIN_SPLITS[c, k]])
                labels.append(lab)
                if lab >= 0:
                    m |= 1 << k
            for t in range(TEMPLATE_COUNTS[m]):
                tm = TEMPLATE_TETS[m, t]
                if CHAIN_IS_ODD[c]:
                    tm = tm[[0, 2, 1, 3]]
                tets.append([labels[x] for x in tm])
                leaf.append(i)
                mask.append(m)
                chain.append(c)
    tets = np.array(tets, dtype=np.int64)
    return V.coords, tets, np.array(leaf), np.array(mask), np.array(chain), V


def edge_kind(d):
    """(kind, scale) of a u-difference vector."""
    nz = d[d != 0]
    if len(nz) and np.all(nz == nz[0]):
        s = abs(int(nz[0]))
        if len(nz) == 2:
            return (FL if s == 1 else CL), s
        return (FS if s == 1 else CS), s
    return NL, 0


# ----------------------------------------------------------------------------- surfaces

class Plane:
    def __init__(self, n, p):
        self.n = n / np.linalg.norm(n)
        self.d = float(self.n @ p)

    def f(self, x):
        return x @ self.n - self.d

    def cut(self, x0, x1):
        f0, f1 = self.f(x0), self.f(x1)
        t = f0 / (f0 - f1)
        return t


class Sphere:
    def __init__(self, c, r):
        self.c, self.r = c, r

    def f(self, x):
        return np.sum((x - self.c) ** 2, axis=-1) - self.r ** 2

    def cut(self, x0, x1):
        # |x0 + t (x1 - x0) - c|^2 = r^2, exactly one root in (0, 1).
        d = x1 - x0
        e = x0 - self.c
        a = d @ d
        b = 2 * d @ e
        cc = e @ e - self.r ** 2
        disc = math.sqrt(max(b * b - 4 * a * cc, 0.0))
        best = None
        for t in ((-b - disc) / (2 * a), (-b + disc) / (2 * a)):
            if -1e-12 <= t <= 1 + 1e-12 and (best is None or abs(t - 0.5) < abs(best - 0.5)):
                best = t
        # one sign change: the root is unique in [0, 1]; refine by bisection-safe Newton guard
        return min(max(best, 0.0), 1.0)


def random_surface(kind, rng, points, center_pts):
    p = center_pts[rng.integers(len(center_pts))] + rng.uniform(-0.5, 0.5, 3)
    if kind == "plane":
        return Plane(rng.normal(size=3), p)
    r = float(np.exp(rng.uniform(np.log(2), np.log(20))))
    v = rng.normal(size=3)
    return Sphere(p + r * v / np.linalg.norm(v), r)


# ----------------------------------------------------------------------------- geometry

def tet_volumes(P):
    return np.einsum("ij,ij->i", P[:, 1] - P[:, 0], np.cross(P[:, 2] - P[:, 0], P[:, 3] - P[:, 0])) / 6.0


def dihedral_extremes(P):
    """(min, max) dihedral angle in degrees of tets P (M, 4, 3), any orientation; 0/180 if flat."""
    a, b, c, d = P[:, 0], P[:, 1], P[:, 2], P[:, 3]
    # normals of faces opposite each vertex, outward for positive volume; sign-fixed below
    n = np.stack([np.cross(c - b, d - b), np.cross(d - a, c - a), np.cross(b - a, d - a), np.cross(c - a, b - a)], 1)
    vol = tet_volumes(P)
    n = n * np.sign(vol)[:, None, None]
    ln = np.linalg.norm(n, axis=2)
    cos = []
    for k, m in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
        cos.append(-np.einsum("ij,ij->i", n[:, k], n[:, m]) / np.maximum(ln[:, k] * ln[:, m], 1e-300))
    cos = np.clip(np.stack(cos, 1), -1, 1)
    ang = np.degrees(np.arccos(cos))
    flat = np.abs(vol) < 1e-12
    mn = np.where(flat, 0.0, ang.min(1))
    mx = np.where(flat, 180.0, ang.max(1))
    return mn, mx


# ----------------------------------------------------------------------------- stuffing

class Mesh:
    """A configuration: coords, tets with provenance, edge kinds, face rules."""

    def __init__(self, anchors, sides):
        self.anchors, self.sides = anchors, sides
        self.coords, self.tets, self.leaf, self.mask, self.chain, self.V = emit(anchors, sides)
        self.points = self.coords @ LATTICE_TO_SPACE.T
        nv = len(self.coords)
        self.fine_vertex = np.zeros(nv, dtype=bool)
        self.fine_vertex[self.V.corner_ids[sides == 1].ravel()] = True
        self.coarse_vertex = np.zeros(nv, dtype=bool)
        self.coarse_vertex[self.V.corner_ids[sides == 2].ravel()] = True
        # tet origin: 0 fine BCC, 1 coarse BCC, 2 template
        self.origin = np.where(self.mask != 0, 2, np.where(self.sides[self.leaf] == 1, 0, 1))
        tmpl_vertex = np.zeros(nv, dtype=bool)
        tmpl_vertex[self.tets[self.origin == 2].ravel()] = True
        self.template_edges = {(int(min(t[i], t[j])), int(max(t[i], t[j])))
                               for t in self.tets[self.origin == 2] for i in range(4) for j in range(i + 1, 4)}
        self.near_template = tmpl_vertex[self.tets].any(1) & (self.origin != 2)
        # Tets with a vertex on the block boundary: that vertex's star is incomplete (its warp sees
        # fewer edges than in the unbounded lattice), so L&S need not hold there; excluded from stats.
        n_root = int((anchors + sides[:, None]).max())
        on_root = ((self.coords == 0) | (self.coords == n_root)).any(1)
        self.root_tet = on_root[self.tets].any(1)
        # transition leaves: coarse leaves with a nonzero mask chain
        self.transition_leaf = np.zeros(len(sides), dtype=bool)
        self.transition_leaf[self.leaf[self.mask != 0]] = True
        # edges
        self.edge_kind = {}
        self.edge_scale = {}
        for t in self.tets:
            for i in range(4):
                for j in range(i + 1, 4):
                    a, b = int(min(t[i], t[j])), int(max(t[i], t[j]))
                    if (a, b) not in self.edge_kind:
                        k, s = edge_kind(self.coords[b] - self.coords[a])
                        self.edge_kind[(a, b)] = k
                        self.edge_scale[(a, b)] = s
        self.root = 2 * anchors.max() + 0  # not used
        self.n_root = int((anchors + sides[:, None]).max())
        self.interface = np.nonzero(self.fine_vertex & self.coarse_vertex)[0]
        self.force_local = False  # mutation test: the local rule on every face

    # --- quad diagonal rules
    def quad_first_diagonal(self, a, b, e, local_rule="minid", P=None, cut_be=None, cut_ae=None):
        """Diagonal of quad (a, b, cut(b,e), cut(a,e)) on face (a, b, e): True joins a-cut(b,e).
        L&S rule on BCC faces of some level, local rule elsewhere.  Returns (choice, lattice_face)."""
        ka = self.edge_kind[(min(a, b), max(a, b))]
        kb = self.edge_kind[(min(a, e), max(a, e))]
        kc = self.edge_kind[(min(b, e), max(b, e))]
        s1 = self.edge_scale[(min(a, b), max(a, b))]
        s2 = self.edge_scale[(min(a, e), max(a, e))]
        s3 = self.edge_scale[(min(b, e), max(b, e))]
        if not self.force_local and NL not in (ka, kb, kc) and s1 == s2 == s3 and np.all(self.coords[[a, b, e]] % s1 == 0):
            c = self.coords // s1
            return _ls_rule(c, a, b, e), True
        if local_rule == "minid":
            return a < b, False
        raise ValueError(local_rule)


def _bcc(c, v):
    u0, u1, u2 = c[v]
    return (u0 + u1 - u2, -u0 + u1 + u2, u0 - u1 + u2)


def _is_long(c, a, b):
    return (int(c[a].sum() - c[b].sum()) & 1) == 0


def _ls_rule(c, a, b, e):
    """stuffing._quad_first_diagonal on integer coordinates c of one BCC level."""
    if not _is_long(c, a, b):
        return not _is_long(c, a, e)
    A, B, E = _bcc(c, a), _bcc(c, b), _bcc(c, e)
    k = sum(1 for i in range(3) if 2 * A[i] > B[i] + E[i])
    corners = (int(c[a].sum()) & 1) == 0
    return (k & 1) == (1 if corners else 0)


def stuff(mesh: Mesh, surf, alphas, cap, local_rule="minid", pin_root=False, tscale=1.0):
    """Generic stuffing of every tet of the mesh.  Returns a dict of arrays:
    points, out (K, 4), src (K,) source tet, coned (K,) bool, plus per-vertex warp info."""
    pts = mesh.points
    f = surf.f(pts)
    inside = f < 0
    nv = len(pts)
    # cut edges
    cut_index = {}
    cut_t = []
    cut_edges = []
    for (a, b), k in mesh.edge_kind.items():
        if inside[a] != inside[b]:
            t = surf.cut(pts[a], pts[b])
            cut_index[(a, b)] = len(cut_t)
            cut_t.append(t)
            cut_edges.append((a, b))
    cut_t = np.array(cut_t)
    cut_pts = np.array([pts[a] + t * (pts[b] - pts[a]) for (a, b), t in zip(cut_edges, cut_t)]).reshape(-1, 3)
    # warps
    best = np.full(nv, np.inf)
    target = np.full(nv, -1)
    for e, ((a, b), t) in enumerate(zip(cut_edges, cut_t)):
        k = mesh.edge_kind[(a, b)]
        length = float(np.linalg.norm(pts[b] - pts[a]))
        alpha = alphas[k]
        if tscale == "all0.75":
            alpha *= 0.75
        elif tscale != 1.0 and (a, b) in mesh.template_edges:
            alpha *= tscale
        for v, dist in ((a, t * length), (b, (1 - t) * length)):
            lim = alpha * length
            if cap and mesh.fine_vertex[v] and k != FS and k != FL:
                lim = alpha * (length / mesh.edge_scale[(a, b)] if k in (CS, CL) else length / 2)
            if pin_root:  # checks only: a root-boundary vertex warps only within its root faces
                cv, cw = mesh.coords[v], mesh.coords[b if v == a else a]
                on = (cv == 0) | (cv == mesh.n_root)
                if (on & (cw != cv)).any():
                    continue
            if dist < lim and dist < best[v]:
                best[v] = dist
                target[v] = e
    warped = target >= 0
    points = np.concatenate([pts, cut_pts])
    points[:nv][warped] = cut_pts[target[warped]]
    signs = np.where(inside, 1, -1)
    signs[warped] = 0

    def cid(p, q):
        return nv + cut_index[(min(p, q), max(p, q))]

    out, src, coned, cyclic_src = [], [], [], []
    extra = []
    n_cyclic = 0
    for ti, t in enumerate(mesh.tets):
        s = signs[t]
        if (s > 0).all():
            out.append(t.tolist())
            src.append(ti)
            coned.append(False)
            continue
        plus = [int(v) for v in t if signs[v] > 0]
        zero = [int(v) for v in t if signs[v] == 0]
        minus = [int(v) for v in t if signs[v] < 0]
        n_p, n_z, n_m = len(plus), len(zero), len(minus)
        tl = []
        if n_p == 0:
            continue
        if n_m == 0:
            tl.append(t.tolist())
        elif n_p == 1:
            a = plus[0]
            tl.append([cid(a, int(v)) if signs[v] < 0 else int(v) for v in t])
        elif n_p == 2 and n_z == 1:
            a, b = plus
            z, e = zero[0], minus[0]
            cae, cbe = cid(a, e), cid(b, e)
            first, _ = mesh.quad_first_diagonal(a, b, e, local_rule)
            if first:
                tl += [[z, a, b, cbe], [z, a, cbe, cae]]
            else:
                tl += [[z, a, b, cae], [z, b, cbe, cae]]
        else:
            if n_p == 2:
                a, b = plus
                c, d = minus
                pv = [a, cid(a, c), cid(a, d), b, cid(b, c), cid(b, d)]
                choice = 0
                if not mesh.quad_first_diagonal(a, b, c, local_rule)[0]:
                    choice |= 1
                if mesh.quad_first_diagonal(a, b, d, local_rule)[0]:
                    choice |= 4
                if PRISM_TETS[choice, 0, 0] < 0:
                    choice |= 2
            else:
                pv = plus + [cid(p, minus[0]) for p in plus]
                choice = 0
                for i in range(3):
                    j = (i + 1) % 3
                    if not mesh.quad_first_diagonal(pv[i], pv[j], minus[0], local_rule)[0]:
                        choice |= 1 << i
            if PRISM_TETS[choice, 0, 0] < 0:
                n_cyclic += 1
                cyclic_src.append(ti)
                # cone to the centroid
                centre = len(points) + len(extra)
                extra.append(np.mean([points[v] for v in pv], axis=0))
                tris = [(0, 1, 2), (3, 4, 5)]
                for i in range(3):
                    j = (i + 1) % 3
                    if (choice >> i) & 1 == 0:  # bottom i - top j
                        tris += [(i, j, 3 + j), (i, 3 + j, 3 + i)]
                    else:
                        tris += [(i, j, 3 + i), (j, 3 + j, 3 + i)]
                for tri in tris:
                    out.append([centre] + [pv[x] for x in tri])
                    src.append(ti)
                    coned.append(True)
                continue
            for i in range(3):
                tl.append([pv[x] for x in PRISM_TETS[choice, i]])
        for tt in tl:
            out.append(tt)
            src.append(ti)
            coned.append(False)
    if extra:
        points = np.concatenate([points, np.array(extra)])
    out = np.array(out, dtype=np.int64).reshape(-1, 4)
    vol = tet_volumes(points[out])
    neg = vol < 0
    out[neg] = out[neg][:, [0, 1, 3, 2]]
    return dict(points=points, out=out, src=np.array(src, dtype=np.int64), coned=np.array(coned, dtype=bool),
                signs=signs, inside=inside, warped=warped, target=target, cut_edges=cut_edges, n_cyclic=n_cyclic,
                cyclic_src=cyclic_src, f=f, n_lattice=nv)


def check_conformity(mesh, res, surf):
    """(#faces used > 2 times or twice with one orientation, #boundary faces neither on the surface nor
    on the root boundary).  Faces are keyed by vertex ids (cut points and the Steiner centres included)."""
    out = res["out"]
    faces = collections.defaultdict(list)
    for t in out:
        for k in range(4):
            f = [int(x) for j, x in enumerate(t) if j != k]
            # orientation as seen from outside of the tet: parity of the permutation
            key = tuple(sorted(f))
            perm = [f.index(x) for x in key]
            parity = (perm[0] < perm[1]) + (perm[0] < perm[2]) + (perm[1] < perm[2])
            faces[key].append((parity + k) % 2)
    nv = res["n_lattice"]
    pts = res["points"]
    uinv = np.linalg.inv(LATTICE_TO_SPACE)
    bad_multi = 0
    bad_boundary = 0
    for key, ori in faces.items():
        if len(ori) > 2 or (len(ori) == 2 and ori[0] == ori[1]):
            bad_multi += 1
        elif len(ori) == 1:
            on_surface = all(v >= nv or res["signs"][v] == 0 for v in key)
            if on_surface:
                continue
            u = pts[list(key)] @ uinv.T
            on_root = any(np.allclose(u[:, i], 0, atol=1e-9) or np.allclose(u[:, i], mesh.n_root, atol=1e-9) for i in range(3))
            if not on_root:
                bad_boundary += 1
    return bad_multi, bad_boundary


def exact_plane_volume(mesh, surf):
    """Volume of the block (union of the unwarped tets) on the inside of a plane: the B-spline
    formula per tet, sum_{f_i < 0} (-f_i)^3 / prod_{j != i} (f_j - f_i)."""
    P = mesh.points[mesh.tets]
    vol = np.abs(tet_volumes(P))
    F = surf.f(P.reshape(-1, 3)).reshape(-1, 4)
    frac = np.zeros(len(F))
    for i in range(4):
        num = np.where(F[:, i] < 0, (-F[:, i]) ** 3, 0.0)
        den = np.ones(len(F))
        for j in range(4):
            if j != i:
                den = den * (F[:, j] - F[:, i])
        frac += num / den
    return float((vol * frac).sum())


# ----------------------------------------------------------------------------- modes

def sample_pairs(config_kinds, n, rng, n_coarse=4):
    """Yield (config kind, mesh, surface kind, surface) with no vertex on the surface."""
    cache = {}
    for s in range(n):
        ck = config_kinds[s % len(config_kinds)]
        anchors, sides = make_config(ck, rng, n_coarse)
        key = (ck, anchors.tobytes(), sides.tobytes())
        if key not in cache:
            if len(cache) > 200:
                cache.clear()
            cache[key] = Mesh(anchors, sides)
        mesh = cache[key]
        centres = mesh.interface if len(mesh.interface) else np.arange(len(mesh.points))
        centres_pts = mesh.points[centres]
        sk = "plane" if s % 2 == 0 else "sphere"
        while True:
            surf = random_surface(sk, rng, mesh.points, centres_pts)
            if np.min(np.abs(surf.f(mesh.points))) > 1e-9:
                break
        yield s, ck, mesh, sk, surf


def sanity(args):
    rng = np.random.default_rng(args.seed)
    anchors, sides = make_config("uniform", rng, args.n_coarse)
    mesh = Mesh(anchors, sides)
    mesh.force_local = args.mutate
    # emission check
    ref = lattice.graded_tets(mesh.V)
    assert sorted(map(tuple, np.sort(ref, 1))) == sorted(map(tuple, np.sort(mesh.tets, 1)))
    worst_min, worst_max = 180.0, 0.0
    n_bad = n_cyc = n_conf = n_bnd = n_root_bad = 0
    vol_err, vol_checked = 0.0, 0
    kinds = collections.Counter()
    t0 = time.time()
    for s in range(args.n):
        sk = "plane" if s % 2 == 0 else "sphere"
        centre = rng.uniform(1, mesh.n_root - 1, 3) @ LATTICE_TO_SPACE.T
        while True:
            surf = random_surface(sk, rng, mesh.points, centre[None])
            if np.min(np.abs(surf.f(mesh.points))) > 1e-9:
                break
        res = stuff(mesh, surf, VARIANTS["NL=short"][0], False)
        touched = mesh.tets[res["src"]]
        sel = ~(res["signs"][touched] > 0).all(1)
        mn, mx = dihedral_extremes(res["points"][res["out"]])
        rootbad = sel & mesh.root_tet[res["src"]] & ((mn < LO) | (mx > HI))
        n_root_bad += int(rootbad.sum())
        sel &= ~mesh.root_tet[res["src"]]
        mn, mx = mn[sel], mx[sel]
        if len(mn):
            worst_min = min(worst_min, mn.min())
            worst_max = max(worst_max, mx.max())
            n_bad += int(((mn < LO) | (mx > HI)).sum())
        n_cyc += res["n_cyclic"]
        if s < args.n_conform or sk == "plane":
            res = stuff(mesh, surf, VARIANTS["NL=short"][0], False, pin_root=True)
        if s < args.n_conform:
            m, b = check_conformity(mesh, res, surf)
            n_conf += m
            # boundary faces off the root: allowed only at root-boundary vertices that warped off it
            n_bnd += b
            kinds["checked"] += 1
            if b:
                kinds["samples with open faces off root/surface"] += 1
        if sk == "plane":
            if True:  # pinned root-boundary warps: the mesh is the block clipped by the plane
                got = float(np.abs(tet_volumes(res["points"][res["out"]])).sum())
                want = exact_plane_volume(mesh, surf)
                vol_err = max(vol_err, abs(got - want) / max(want, 1e-9))
                vol_checked += 1
    print(json.dumps(dict(samples=args.n, lattice_tets=len(mesh.tets), worst_min=worst_min, worst_max=worst_max,
                          tets_outside=n_bad, tets_outside_at_block_boundary_excluded=n_root_bad, cyclic=n_cyc, conformity_checked=kinds["checked"], nonmanifold_faces=n_conf,
                          open_faces_off_root_or_surface=n_bnd, samples_open=kinds["samples with open faces off root/surface"],
                          plane_volume_checked=vol_checked, max_rel_volume_error=vol_err,
                          seconds=round(time.time() - t0, 1)), indent=1))


def cause_of(mesh, res, ti, out_rows):
    """Short description of why source tet ti's output went bad: kinds of the edges along which its
    vertices warped, kinds of its cut edges, coned or not."""
    t = mesh.tets[ti]
    warps = []
    for v in t:
        e = res["target"][v]
        if e >= 0:
            a, b = res["cut_edges"][e]
            k = mesh.edge_kind[(a, b)]
            own = (a in t) and (b in t)
            warps.append(KIND_NAMES[k] + ("(own edge)" if own else "(outside edge)"))
    cuts = []
    for i in range(4):
        for j in range(i + 1, 4):
            a, b = int(min(t[i], t[j])), int(max(t[i], t[j]))
            if res["signs"][a] * res["signs"][b] < 0:
                cuts.append(KIND_NAMES[mesh.edge_kind[(a, b)]])
    return warps, cuts


def measure(args):
    rng = np.random.default_rng(args.seed)
    kinds = args.configs.split(",")
    variants = {k: (a, c, 1.0) for k, (a, c) in VARIANTS.items()} if args.variants == "main" else EXTRA_VARIANTS
    stats = {v: dict(worst=collections.defaultdict(list), leaves=0, bad_leaves=0, cyclic=0, cyclic_tets=0,
                     bad_by_origin=collections.Counter(), worst_cases=[], cause=collections.Counter(),
                     bad_fine_only=0, out_by_origin=collections.Counter(), conform=0, open_faces=0,
                     bad_tets_cyclic=0, root_excluded_bad=0, coarse_bcc_leaves=0, coarse_bcc_bad=0)
             for v in variants}
    t0 = time.time()
    for s, ck, mesh, sk, surf in sample_pairs(kinds, args.n, rng, args.n_coarse):
        for vname, (alphas, cap, tscale) in variants.items():
            st = stats[vname]
            res = stuff(mesh, surf, alphas, cap, tscale=tscale)
            src = res["src"]
            touched_src = ~(res["signs"][mesh.tets] > 0).all(1)  # per source tet
            sel = touched_src[src] & ~mesh.root_tet[src]
            st["root_excluded_bad"] += int((touched_src[src] & mesh.root_tet[src]).sum())
            mn, mx = dihedral_extremes(res["points"][res["out"]])
            bad = sel & ((mn < LO) | (mx > HI))
            org = mesh.origin[src]
            near = mesh.near_template[src]
            cat = np.where(org == 2, "template", np.where(near, "BCC-near-template", np.where(org == 1, "coarse-BCC-far", "fine-BCC-far")))
            for c in ("template", "BCC-near-template", "coarse-BCC-far", "fine-BCC-far"):
                m = sel & (cat == c)
                if m.any():
                    st["worst"][c].append((float(mn[m].min()), float(mx[m].max())))
                    st["out_by_origin"][c] += int(m.sum())
                    st["bad_by_origin"][c] += int((bad & m).sum())
            st["cyclic"] += res["n_cyclic"]
            if res["n_cyclic"]:
                st["cyclic_tets"] += int(res["coned"].sum())
                st["bad_tets_cyclic"] += int((bad & res["coned"]).sum())
            # leaves
            leaf_of_out = mesh.leaf[src]
            touched_leaves = np.unique(mesh.leaf[touched_src & ~mesh.root_tet])
            bad_leaves = set(np.unique(leaf_of_out[bad]).tolist())
            for L in touched_leaves:
                if mesh.sides[L] == 2 and mesh.transition_leaf[L]:
                    st["leaves"] += 1
                    st["bad_leaves"] += L in bad_leaves
                elif mesh.sides[L] == 2:
                    st["coarse_bcc_leaves"] += 1
                    st["coarse_bcc_bad"] += L in bad_leaves
            # bad tets only in fine leaves (not refinable in place)
            if bad.any() and all(mesh.sides[L] == 1 for L in bad_leaves):
                st["bad_fine_only"] += 1
            for k in np.nonzero(bad)[0]:
                ti = int(src[k])
                warps, cuts = cause_of(mesh, res, ti, None)
                key = ("coned" if res["coned"][k] else "") + " warps:" + ",".join(sorted(set(warps))) + " cuts:" + ",".join(sorted(set(cuts)))
                st["cause"][(cat[k], key)] += 1
                sig = "".join(sorted("+" if x > 0 else "-" if x < 0 else "0" for x in res["signs"][mesh.tets[ti]]))
                st["worst_cases"].append((float(mn[k]), float(mx[k]), int(s), ck, sk, str(cat[k]), int(mesh.mask[ti]),
                                          int(mesh.chain[ti]), sig, warps, cuts, bool(res["coned"][k])))
            if s < args.n_conform:
                m_, b_ = check_conformity(mesh, stuff(mesh, surf, alphas, cap, pin_root=True, tscale=tscale), surf)
                st["conform"] += m_
                st["open_faces"] += b_
        if (s + 1) % 100 == 0:
            print(f"# {s + 1} samples, {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
    report(stats, args)


def q(xs, p):
    return float(np.quantile(xs, p)) if len(xs) else float("nan")


def report(stats, args):
    summary = {}
    for vname, st in stats.items():
        print(f"\n=== variant {vname} ===")
        print(f"cut coarse transition leaves: {st['leaves']}, with a tet outside [{LO}, {HI}]: {st['bad_leaves']} "
              f"({100 * st['bad_leaves'] / max(st['leaves'], 1):.2f} %)")
        print(f"cut plain coarse leaves (coarse BCC only): {st['coarse_bcc_leaves']}, bad: {st['coarse_bcc_bad']}")
        print(f"samples whose bad tets are all in fine leaves: {st['bad_fine_only']}")
        print(f"touched output tets excluded (a vertex on the block boundary): {st['root_excluded_bad']}")
        print(f"cyclic +++- prisms: {st['cyclic']} (coned tets {st['cyclic_tets']}, of them bad {st['bad_tets_cyclic']})")
        print(f"conformity (first {args.n_conform} samples): non-manifold/misoriented faces {st['conform']}, open faces {st['open_faces']}")
        print("per-sample worst by origin: [min of worst-min, 1%, 5%, median] / [max of worst-max, 99%, 95%, median]; "
              "samples with worst outside; output tets; bad tets")
        for c, w in st["worst"].items():
            a = np.array(w)
            outside = int(((a[:, 0] < LO) | (a[:, 1] > HI)).sum())
            print(f"  {c:20s} n={len(a):5d} min {a[:, 0].min():6.2f} {q(a[:, 0], .01):6.2f} {q(a[:, 0], .05):6.2f} {q(a[:, 0], .5):6.2f}"
                  f" | max {a[:, 1].max():6.2f} {q(a[:, 1], .99):6.2f} {q(a[:, 1], .95):6.2f} {q(a[:, 1], .5):6.2f}"
                  f" | outside {outside:4d} | tets {st['out_by_origin'][c]:7d} bad {st['bad_by_origin'][c]:5d}")
        print("top causes of bad tets (category, warps along / cut edges):")
        for (c, k), n in st["cause"].most_common(8):
            print(f"  {n:5d}  {c}: {k}")
        wc = sorted(st["worst_cases"], key=lambda r: min(r[0], 180 - r[1]))[: args.show]
        print("worst cases: (min, max, sample, config, surface, origin, mask, chain, signs, warps, cuts, coned)")
        for r in wc:
            print("  ", r)
        summary[vname] = dict(leaves=st["leaves"], bad_leaves=st["bad_leaves"], cyclic=st["cyclic"])
    print(json.dumps(summary))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mode", choices=["sanity", "measure"])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--n-coarse", type=int, default=4, help="coarse cells per axis (block side 2 n in fine units)")
    ap.add_argument("--n-conform", type=int, default=100, help="samples checked for conformity")
    ap.add_argument("--configs", default="slab,edge,corner,random")
    ap.add_argument("--show", type=int, default=8)
    ap.add_argument("--variants", choices=["main", "extra"], default="main")
    ap.add_argument("--mutate", action="store_true", help="sanity: min-id diagonals on every face (must fail)")
    args = ap.parse_args()
    if args.mode == "sanity":
        sanity(args)
    else:
        measure(args)


if __name__ == "__main__":
    main()
