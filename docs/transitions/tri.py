"""Enumerate triangulations of a tet (points on its boundary + optional extra points)."""
import itertools
import numpy as np
from geom import to_space, quality, interiors_overlap

EDGES = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]  # local edge k -> midpoint label 4+k
FACES = [(0, 1, 2), (1, 2, 3), (0, 1, 3), (0, 2, 3)]


def orient(a, b, c, d):
    return int(np.sign(np.dot(np.cross(b - a, c - a), d - a)))


def triangle_triangulations(tri, split):
    """tri: 3 corner labels (local); split: set of local edge indices (into EDGES) split.
    Returns list of triangulations, each a frozenset of frozenset triangles (labels)."""
    a, b, c = tri
    poly = []
    for x, y in ((a, b), (b, c), (c, a)):
        poly.append(x)
        e = EDGES.index(tuple(sorted((x, y))))
        if e in split:
            poly.append(4 + e)
    # straight vertices (midpoints) cannot be ear tips of a degenerate triangle
    n = len(poly)
    mids = {p for p in poly if p >= 4}
    out = set()

    def rec(P):
        if len(P) == 3:
            return [[tuple(P)]]
        res = []
        # triangulations of convex polygon: edge P[0]-P[1] lies in a triangle with apex P[k]
        for k in range(2, len(P)):
            t = (P[0], P[1], P[k])
            if degenerate(t):
                continue
            left = P[1:k + 1]
            right = [P[0]] + P[k:]
            L = rec(left) if len(left) >= 3 else [[]]
            R = rec(right) if len(right) >= 3 else [[]]
            for l in L:
                for r in R:
                    res.append([t] + l + r)
        return res

    def degenerate(t):
        # midpoint with both its edge ends
        for m in t:
            if m >= 4:
                i, j = EDGES[m - 4]
                if i in t and j in t:
                    return True
        return False

    for tr in rec(poly):
        if any(degenerate(t) for t in tr):
            continue
        out.add(frozenset(frozenset(t) for t in tr))
    return sorted(out, key=lambda s: sorted(sorted(t) for t in s))


class TetProblem:
    """Points: dict label -> integer u coordinate (np array). Corners 0..3 are the tet."""

    def __init__(self, U):
        self.U = U
        self.labels = sorted(U)
        self.X = {k: to_space(v) for k, v in U.items()}
        self._cands = None

    def face_plane_of(self, tri):
        """index of tet face containing all 3 labels, or None."""
        for fi, f in enumerate(FACES):
            if all(self.on_face(l, fi) for l in tri):
                return fi
        return None

    def on_face(self, l, fi):
        f = FACES[fi]
        U = self.U
        return orient(U[f[0]], U[f[1]], U[f[2]], U[l]) == 0

    def candidates(self):
        if self._cands is not None:
            return self._cands
        U = self.U
        labs = self.labels
        c = []
        for q in itertools.combinations(labs, 4):
            P = [U[i] for i in q]
            if orient(*P) == 0:
                continue
            # empty: no other point in closed tet
            ok = True
            for l in labs:
                if l in q:
                    continue
                s = [orient(*(P[:i] + [U[l]] + P[i + 1:])) for i in range(4)]
                s0 = orient(*P)
                if all(x * s0 >= 0 for x in s):
                    ok = False
                    break
            if ok:
                c.append(q)
        self._cands = c
        return c

    def triangulations(self, boundary, limit=None, accept=None):
        """boundary: list of triangles (label triples) covering the tet boundary.
        accept(tet)->bool prunes tets. Yields lists of tets (label 4-tuples)."""
        U = self.U
        inner = np.mean([U[i] for i in range(4)], axis=0)
        bset = {frozenset(t) for t in boundary}
        cands = [q for q in self.candidates() if accept is None or accept(q)]
        # faces -> candidate tets
        by_face = {}
        for q in cands:
            for f in itertools.combinations(q, 3):
                by_face.setdefault(frozenset(f), []).append(q)
        # reject tets with a face in a tet face plane that's not a boundary triangle
        good = set()
        for q in cands:
            ok = True
            for f in itertools.combinations(q, 3):
                if self.face_plane_of(f) is not None and frozenset(f) not in bset:
                    ok = False
            if ok:
                good.add(q)
        # open faces: frozenset -> label of the side already filled (None for outside)
        # we track for each open face the "forbidden" apex side via a placed point
        openf = {}
        for t in boundary:
            openf[frozenset(t)] = 'out'
        placed = []
        results = []
        Uarr = {k: np.asarray(v, float) for k, v in U.items()}

        def side(face, p):
            a, b, c = [U[i] for i in face]
            return orient(a, b, c, U[p])

        def rec():
            if limit is not None and len(results) >= limit:
                return
            if not openf:
                results.append(list(placed))
                return
            # choose the open face with fewest candidates
            best = None
            for f, filled in openf.items():
                fl = tuple(f)
                if filled == 'out':
                    bad = -side(fl, 'c') if False else None
                opts = []
                for q in by_face.get(f, []):
                    if q not in good or q in placed_set:
                        continue
                    apex = [x for x in q if x not in f][0]
                    if filled == 'out':
                        # apex must be on the inner side of boundary face
                        s = orient(*[U[i] for i in fl], inner)
                        if orient(*[U[i] for i in fl], U[apex]) != s or s == 0:
                            continue
                    else:
                        if side(fl, apex) == side(fl, filled):
                            continue
                    opts.append(q)
                if best is None or len(opts) < len(best[1]):
                    best = (f, opts)
                    if not opts:
                        break
            f, opts = best
            for q in opts:
                A = np.array([Uarr[i] for i in q])
                if any(interiors_overlap(A, np.array([Uarr[i] for i in p])) for p in placed):
                    continue
                # apply
                changes = []
                ok = True
                for g in itertools.combinations(q, 3):
                    g = frozenset(g)
                    other = [x for x in q if x not in g][0]
                    if g in openf:
                        changes.append((g, openf[g]))
                        del openf[g]
                    else:
                        if self.face_plane_of(tuple(g)) is not None:
                            ok = False  # boundary face already closed
                        changes.append((g, None))
                        openf[g] = other
                placed.append(q)
                placed_set.add(q)
                if ok:
                    rec()
                placed.pop()
                placed_set.discard(q)
                for g, old in reversed(changes):
                    if old is None:
                        del openf[g]
                    else:
                        openf[g] = old
        placed_set = set()
        rec()
        return results
