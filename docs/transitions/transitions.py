"""Transition templates for a coarse paroct leaf next to finer leaves (2:1 balance).

    python transitions.py table      # build the 25-entry template table, print it, write template_table.json
    python transitions.py enumerate  # leaf patterns, orbits under the 12 symmetries, masks, worst quality
    python transitions.py verify     # exhaustive 3x3x3 block check of all leaf-pattern orbits + random octrees
    python transitions.py explore    # lattice-only feasibility of all 64 split masks (why the closure is needed)

Rule (see docs/transitions.md):
  * a cube edge of a leaf is split iff its midpoint is a corner of a finer leaf;
  * a face diagonal is split (face centre inserted) iff the face neighbour is finer OR at one of
    the two face corners off the diagonal both face edges are split  (face-local "closure");
  * the main diagonal is never split (no leaf-centre vertex);
  * each Freudenthal tet, with chain v0=0 -> v1 -> v2 -> v3=7, is replaced by TABLE[mask].
Single-threaded, numpy only (plus geom.py / tri.py from this folder).
"""
import itertools
import json
import sys
from collections import Counter

import numpy as np

from geom import CORNERS, FREUD, quality, to_space
from tri import EDGES, TetProblem, triangle_triangulations

TOL = 1e-9
# local labels: 0..3 chain corners, 4 + k midpoint of tri.EDGES[k]
# tri.EDGES = [(0,1),(0,2),(0,3),(1,2),(1,3),(2,3)]
NAME = {0: 'v0', 1: 'v1', 2: 'v2', 3: 'v3', 4: 'm01', 5: 'm02', 6: 'm03', 7: 'm12', 8: 'm13', 9: 'm23'}
# mask bits as documented: bit0 e01, bit1 e12, bit2 e23 (cube edges), bit3 e02, bit4 e13 (face diagonals)
BIT_EDGE = [(0, 1), (1, 2), (2, 3), (0, 2), (1, 3)]
LONG = {(0, 2), (1, 3)}
CHAIN_U = {0: np.array([0, 0, 0]), 1: np.array([2, 0, 0]), 2: np.array([2, 2, 0]), 3: np.array([2, 2, 2])}
TET_FACES = [(0, 1, 2), (1, 2, 3), (0, 1, 3), (0, 2, 3)]  # first two on the leaf boundary


def mid(i, j):
    return 4 + EDGES.index(tuple(sorted((i, j))))


def split_edges(mask):
    return {BIT_EDGE[b] for b in range(5) if mask >> b & 1}


def admissible(mask):
    """masks produced by the closure: two split cube edges of a boundary face imply its diagonal."""
    s = split_edges(mask)
    return not ({(0, 1), (1, 2)} <= s and (0, 2) not in s) and not ({(1, 2), (2, 3)} <= s and (1, 3) not in s)


def face_triangulation(face, split):
    """The face rule: 1 split -> midpoint to opposite corner; 2 splits (always incl. the long edge)
    -> long-edge midpoint to opposite corner, then halve the half holding the other split edge;
    3 splits -> red (the finer neighbour's triangulation)."""
    p, q, r = face
    es = [e for e in itertools.combinations(face, 2) if e in split]
    if not es:
        return [face]
    if len(es) == 3:
        a, b, c = mid(p, q), mid(q, r), mid(p, r)
        return [(p, a, c), (a, q, b), (c, b, r), (a, b, c)]
    if len(es) == 2:
        lg = [e for e in es if e in LONG]
        assert len(lg) == 1, (face, es)
        lg = lg[0]
        other = [e for e in es if e != lg][0]
        apex = [x for x in face if x not in lg][0]
        m = mid(*lg)
        out = []
        for end in lg:  # the two halves (end, apex, m)
            if end in other:
                mo = mid(*other)
                out += [(end, mo, m), (mo, apex, m)]
            else:
                out.append((end, apex, m))
        return out
    i, j = es[0]
    k = [x for x in face if x not in (i, j)][0]
    return [(i, mid(i, j), k), (mid(i, j), j, k)]


def tet_quality(P):
    lo, hi, rr, v = quality(P)
    return lo, hi, rr


def ok(P):
    lo, hi, rr = tet_quality(P)
    return lo >= 30 - TOL and hi <= 135 + TOL and rr >= 0.4 - TOL


def local_problem(mask):
    U = dict(CHAIN_U)
    for (i, j) in split_edges(mask):
        U[mid(i, j)] = (CHAIN_U[i] + CHAIN_U[j]) // 2
    return TetProblem(U)


def build_table():
    """mask -> (tets as local-label 4-tuples with positive orientation, min dih, max dih, min 3r/R)."""
    table = {}
    for mask in range(32):
        if not admissible(mask):
            continue
        P = local_problem(mask)
        split = split_edges(mask)
        bd = [t for f in TET_FACES for t in face_triangulation(f, split)]
        res = P.triangulations(bd, accept=lambda q: ok(np.array([P.X[i] for i in q])))
        assert res, f'no valid template for mask {mask:05b}'

        def key(r):
            Q = [tet_quality(np.array([P.X[i] for i in q])) for q in r]
            return (round(min(x[0] for x in Q), 6), round(min(x[2] for x in Q), 6),
                    -round(max(x[1] for x in Q), 6), -len(r))
        best = max(res, key=key)
        tets = []
        for q in best:  # orient positively in space
            X = np.array([P.X[i] for i in q])
            tets.append(tuple(q) if quality(X)[3] > 0 else (q[1], q[0], q[2], q[3]))
        Q = [tet_quality(np.array([P.X[i] for i in q])) for q in tets]
        table[mask] = (sorted(tets), min(x[0] for x in Q), max(x[1] for x in Q), min(x[2] for x in Q))
    return table


def mask_name(m):
    return '+'.join('e%d%d' % BIT_EDGE[b] for b in range(5) if m >> b & 1) or '-'


# ---------------------------------------------------------------- global assembly
CHAINS = [tuple(sorted(t, key=lambda c: bin(c).count('1'))) for t in FREUD]
# +1 if the chain (0, v1, v2, 7) is positively oriented (even axis permutation), else -1:
# templates are stored positive for the chain (0, 1, 3, 7); odd chains swap two vertices per tet.
CHAIN_SIGN = [int(np.sign(np.linalg.det(np.array([CORNERS[c] for c in ch[1:]]) - CORNERS[ch[0]]))) for ch in CHAINS]


CLOSURE = 'eager'  # or 'minimal'; set from the command line (--minimal)


def leaf_masks(esplit, finer_face):
    """esplit(c, d) -> bool for cube edges; finer_face(p, r) -> bool for the face with diagonal p-r.
    Face-centre closure: 'eager' = insert the centre of every face with any split edge;
    'minimal' = only if both edges at an off-diagonal corner q of the face are split."""
    def dsplit(p, r):
        bits = [1 << i for i in range(3) if (p ^ r) >> i & 1]
        if CLOSURE == 'eager':
            return finer_face(p, r) or any(esplit(p, p ^ b) or esplit(p ^ b, r) for b in bits)
        return finer_face(p, r) or any(esplit(p, p ^ b) and esplit(p ^ b, r) for b in bits)
    out = []
    for v0, v1, v2, v3 in CHAINS:
        m = (esplit(v0, v1) << 0) | (esplit(v1, v2) << 1) | (esplit(v2, v3) << 2)
        m |= (dsplit(v0, v2) << 3) | (dsplit(v1, v3) << 4)
        out.append(m)
    return out


def mesh(leaves, table):
    """leaves: list of (anchor tuple, size) over the integer u grid. Returns tets in doubled u."""
    V = set()
    for a, s in leaves:
        for c in CORNERS:
            V.add(tuple(np.array(a) + s * c))
    tets, masks = [], []
    for a, s in leaves:
        a = np.array(a)
        P = [a + s * CORNERS[c] for c in range(8)]

        def esplit(c, d):
            return s > 1 and tuple((P[c] + P[d]) // 2) in V
        ms = leaf_masks(esplit, esplit)  # face finer iff its centre is a corner of a finer leaf
        masks += ms
        for ch, m in zip(CHAINS, ms):
            lab = {i: 2 * P[ch[i]] for i in range(4)}
            for k, (i, j) in enumerate(EDGES):
                lab[4 + k] = (lab[i] + lab[j]) // 2
            for t in table[m][0]:
                if CHAIN_SIGN[CHAINS.index(ch)] < 0:
                    t = (t[1], t[0], t[2], t[3])
                tets.append(tuple(tuple(int(x) for x in lab[i]) for i in t))
    return tets, masks


def check(tets, lo_box, hi_box, with_quality=True):
    """every face shared by exactly 2 tets on opposite sides or on the box boundary; volumes positive
    and summing to the box volume. lo_box/hi_box in doubled u."""
    faces = {}
    vol = 0.0
    worst = [180.0, 0.0, 1.0]
    for t in tets:
        X = to_space(np.array(t, float))
        lo, hi, rr, v = quality(X)
        if v <= 1e-12:
            return f'non-positive volume {t}', worst
        vol += v
        if with_quality:
            worst = [min(worst[0], lo), max(worst[1], hi), min(worst[2], rr)]
        for k in range(4):
            f = tuple(sorted(t[:k] + t[k + 1:]))
            F = np.array(f)
            side = np.sign(np.dot(np.cross(F[1] - F[0], F[2] - F[0]), np.array(t[k]) - F[0]))
            faces.setdefault(f, []).append(side)
    n = np.array(hi_box) - np.array(lo_box)
    box_vol = abs(np.linalg.det(0.5 * np.array([[1.0, 1, -1], [-1, 1, 1], [1, -1, 1]]))) * np.prod(n.astype(float))
    if abs(vol - box_vol) > 1e-9 * box_vol:
        return f'volume {vol} != {box_vol}', worst
    for f, sides in faces.items():
        F = np.array(f)
        onb = any(np.all(F[:, a] == lo_box[a]) or np.all(F[:, a] == hi_box[a]) for a in range(3))
        if onb and len(sides) != 1:
            return f'boundary face {f} in {len(sides)} tets', worst
        if not onb and (len(sides) != 2 or sides[0] == sides[1]):
            return f'face {f} in {len(sides)} tets / same side', worst
    return None, worst


# ---------------------------------------------------------------- leaf patterns and symmetry
CUBE_EDGES = sorted({tuple(sorted((c, c ^ (1 << a)))) for c in range(8) for a in range(3)})
FACES6 = [(a, s) for a in range(3) for s in (0, 1)]


def face_corners(fi):
    a, s = FACES6[fi]
    return frozenset(c for c in range(8) if (c >> a & 1) == s)


def face_edges(fi):
    fc = face_corners(fi)
    return {e for e in CUBE_EDGES if set(e) <= fc}


def symmetries():
    G = []
    for perm in itertools.permutations(range(3)):
        for inv in (0, 7):
            G.append(lambda c, perm=perm, inv=inv: sum(1 << perm[i] for i in range(3) if c >> i & 1) ^ inv)
    fs = {frozenset(t) for t in FREUD}
    assert all({frozenset(g(c) for c in t) for t in FREUD} == fs for g in G)
    return G


def patterns():
    """all (F, E): finer faces F, split cube edges E containing the edges of F."""
    for fm in range(64):
        F = frozenset(fi for fi in range(6) if fm >> fi & 1)
        forced = set().union(*[face_edges(fi) for fi in F])
        free = [e for e in CUBE_EDGES if e not in forced]
        for em in range(1 << len(free)):
            yield F, frozenset(forced | {free[i] for i in range(len(free)) if em >> i & 1})


def pattern_masks(F, E):
    es = lambda c, d: tuple(sorted((c, d))) in E
    ff = lambda p, r: any({p, r} <= face_corners(fi) for fi in F)
    return leaf_masks(es, ff)


def canon(F, E, G):
    best = None
    for g in G:
        Fg = tuple(sorted(j for fi in F for j in range(6) if face_corners(j) == frozenset(g(c) for c in face_corners(fi))))
        Eg = tuple(sorted(tuple(sorted((g(c), g(d)))) for c, d in E))
        if best is None or (Fg, Eg) < best:
            best = (Fg, Eg)
    return best


def block_leaves(F, E):
    """3x3x3 block of cells of side 2 realising pattern (F, E) at the centre cell: refine the face
    cells of F and the edge-diagonal cells of the edges in E not on a face of F."""
    refine = set()
    for fi in F:
        a, s = FACES6[fi]
        c = [1, 1, 1]; c[a] = 2 if s else 0
        refine.add(tuple(c))
    onF = set().union(*[face_edges(fi) for fi in F])
    for (c, d) in E:
        if (c, d) in onF:
            continue
        axis = (c ^ d).bit_length() - 1
        cell = [1, 1, 1]
        for b in range(3):
            if b != axis:
                cell[b] = 2 if c >> b & 1 else 0
        refine.add(tuple(cell))
    leaves = []
    for cell in itertools.product(range(3), repeat=3):
        a = 2 * np.array(cell)
        if cell in refine:
            leaves += [(tuple(a + c), 1) for c in CORNERS]
        else:
            leaves.append((tuple(a), 2))
    return leaves


def random_balanced_octree(L, rng, p):
    leaves = {((0, 0, 0), 2 ** L)}
    for _ in range(L):
        new = set()
        for a, s in leaves:
            if s > 1 and rng.random() < p:
                new |= {(tuple(np.array(a) + s // 2 * c), s // 2) for c in CORNERS}
            else:
                new.add((a, s))
        leaves = new
    changed = True
    while changed:  # naive ripple: split any leaf touching (face/edge/corner) a leaf < half its size
        changed = False
        lst = sorted(leaves)
        for a, s in lst:
            lo = np.array(a)
            if s >= 4 and any(2 * t < s and np.all(np.array(b) <= lo + s) and np.all(np.array(b) + t >= lo)
                              for b, t in lst):
                leaves.discard((a, s))
                leaves |= {(tuple(lo + s // 2 * c), s // 2) for c in CORNERS}
                changed = True
                break
    return sorted(leaves)


# ---------------------------------------------------------------- commands
def cmd_table():
    T = build_table()
    print(f'{len(T)} admissible masks (of 32)')
    for m, (tets, lo, hi, rr) in T.items():
        print(f'{m:2d} {m:05b} {mask_name(m):22s} n={len(tets)} dih [{lo:6.2f}, {hi:6.2f}] 3r/R {rr:.4f} : ' +
              ' '.join('(' + ','.join(NAME[i] for i in t) + ')' for t in tets))
    worst = (min(v[1] for v in T.values()), max(v[2] for v in T.values()), min(v[3] for v in T.values()))
    print('worst over table: min dih %.4f max dih %.4f min 3r/R %.4f' % worst)
    json.dump({str(m): {'name': mask_name(m), 'tets': [[NAME[i] for i in t] for t in v[0]],
                        'min_dihedral': v[1], 'max_dihedral': v[2], 'min_radius_ratio': v[3]}
               for m, v in T.items()}, open('template_table.json', 'w'), indent=1)
    return T


def cmd_enumerate(T):
    G = symmetries()
    orbits, seen, n = {}, Counter(), 0
    for F, E in patterns():
        n += 1
        ms = pattern_masks(F, E)
        seen.update(ms)
        k = canon(F, E, G)
        q = [T[m] for m in ms]
        w = (min(x[1] for x in q), max(x[2] for x in q), min(x[3] for x in q))
        if k in orbits:
            assert np.allclose(orbits[k][0], w), 'symmetric patterns differ in quality'
        else:
            orbits[k] = (w, (F, E))
    print(f'{n} leaf patterns (F, E), {len(orbits)} orbits under the 12 symmetries; '
          f'{len(seen)} distinct tet masks occur: {sorted(seen)}')
    h = Counter(tuple(round(float(x), 2) for x in w) for w, _ in orbits.values())
    print('worst (min dih, max dih, 3r/R) over the leaf -> number of orbits:')
    for k, v in sorted(h.items()):
        print('  ', k, v)
    return orbits


def cmd_verify(T, orbits, trials=12):
    bad = 0
    for i, (w, (F, E)) in enumerate(orbits.values()):
        leaves = block_leaves(F, E)
        tets, masks = mesh(leaves, T)
        centre = [k for k, (a, s) in enumerate(leaves) if a == (2, 2, 2) and s == 2][0]
        assert masks[6 * centre:6 * centre + 6] == pattern_masks(F, E)
        err, _ = check(tets, (0, 0, 0), (12, 12, 12), with_quality=False)
        if err:
            bad += 1
            print('FAIL', F, sorted(E), err)
    print(f'3x3x3 block: {len(orbits)} orbit representatives, {bad} failures')
    rng = np.random.default_rng(2024)
    W = [180.0, 0.0, 1.0]
    seen = set()
    for t in range(trials):
        L = 3 + t % 2
        leaves = random_balanced_octree(L, rng, rng.uniform(0.3, 0.7))
        tets, masks = mesh(leaves, T)
        err, w = check(tets, (0, 0, 0), (2 ** (L + 1),) * 3)
        assert err is None, err
        seen |= set(masks)
        W = [min(W[0], w[0]), max(W[1], w[1]), min(W[2], w[2])]
        print(f'  random octree L={L}: {len(leaves)} leaves, {len(tets)} tets, conforming, '
              f'dih [{w[0]:.4f}, {w[1]:.4f}] 3r/R {w[2]:.4f}', flush=True)
    print('random octrees: worst in space', W, 'masks seen', len(seen))
    rng = np.random.default_rng(7)
    nl = nt = 0
    for t in range(6):
        leaves = random_balanced_octree(4, rng, rng.uniform(0.3, 0.7))
        tets, _ = mesh(leaves, T)
        nl += len(leaves); nt += len(tets)
    print(f'cost: {nt} tets for {nl} leaves ({nt / nl:.3f} per leaf; 6.000 without transitions)')
    return bad == 0


def cmd_explore():
    """lattice-only templates for every 6-bit mask (incl. the main diagonal), any face rule"""
    bad = []
    for m6 in range(64):
        U = dict(CHAIN_U)
        split = {EDGES[k] for k in range(6) if m6 >> k & 1}
        for (i, j) in split:
            U[mid(i, j)] = (CHAIN_U[i] + CHAIN_U[j]) // 2
        P = TetProblem(U)
        opts = [triangle_triangulations(f, {EDGES.index(e) for e in split}) for f in TET_FACES]
        feas = False
        for combo in itertools.product(*opts):
            bd = [tuple(t) for ft in combo for t in ft]
            if P.triangulations(bd, limit=1, accept=lambda q: ok(np.array([P.X[i] for i in q]))):
                feas = True
                break
        if not feas:
            bad.append('+'.join('e%d%d' % e for e in sorted(split)))
    print('6-bit masks with NO lattice-only template under any face triangulation:', bad)


if __name__ == '__main__':
    if '--minimal' in sys.argv:
        sys.argv.remove('--minimal')
        CLOSURE = 'minimal'
    print('closure:', CLOSURE)
    what = sys.argv[1] if len(sys.argv) > 1 else 'all'
    if what == 'explore':
        cmd_explore()
        sys.exit()
    T = cmd_table()
    if what in ('enumerate', 'verify', 'all'):
        orbits = cmd_enumerate(T)
    if what in ('verify', 'all'):
        sys.exit(0 if cmd_verify(T, orbits) else 1)
