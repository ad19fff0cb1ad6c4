"""Sanity: the block verifier must reject a wrong face rule (face with e01+e02 split
triangulated m01-v2 instead of v1-m02 in one tet template) and a dropped hanging vertex."""
import numpy as np
import transitions as tr

T = tr.build_table()
G = tr.symmetries()
orbits = {}
for F, E in tr.patterns():
    k = tr.canon(F, E, G)
    orbits.setdefault(k, (F, E))

def n_fail(table, limit=60):
    bad = 0
    for F, E in list(orbits.values())[:limit]:
        tets, _ = tr.mesh(tr.block_leaves(F, E), table)
        err, _ = tr.check(tets, (0, 0, 0), (12, 12, 12), with_quality=False)
        bad += err is not None
    return bad

print('correct table failures:', n_fail(T))
# mutation 1: ignore the hanging vertex of e01
T1 = dict(T); T1[1] = ([(0, 1, 2, 3)],) + T[1][1:]
print('dropped hanging vertex failures:', n_fail(T1))
# mutation 2: mask 9 = e01+e02 with the other diagonal of the 2-split boundary face
P = tr.local_problem(9)
split = tr.split_edges(9)
bd = [(0, 4, 5), (4, 3 - 3 + 2, 5)]  # placeholder, rebuilt below
m01, m02 = tr.mid(0, 1), tr.mid(0, 2)
bd = [(0, m01, m02), (m01, 1, 2), (m01, 2, m02)]  # m01-v2 instead of v1-m02
for f in tr.TET_FACES[1:]:
    bd += tr.face_triangulation(f, split)
res = P.triangulations(bd)
best = res[0]
tets = []
for q in best:
    X = np.array([P.X[i] for i in q])
    tets.append(tuple(q) if tr.quality(X)[3] > 0 else (q[1], q[0], q[2], q[3]))
T2 = dict(T); T2[9] = (tets,) + T[9][1:]
print('wrong face rule failures:', n_fail(T2, limit=len(orbits)))
