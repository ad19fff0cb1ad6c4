"""For comparison: plain coning of the leaf boundary triangulation to the leaf centre
(no closure, either 2-split face rule), worst over all leaf patterns."""
import numpy as np
from collections import Counter
import transitions as tr
from leaf import boundary, CUBE_EDGES as LE, S
from geom import to_space, quality

G = tr.symmetries()
reps = {}
for F, E in tr.patterns():
    reps.setdefault(tr.canon(F, E, G), (F, E))
for rule in (0, 1):
    worst = (180, 0, 1); h = Counter()
    for F, E in reps.values():
        Eidx = {LE.index(e) for e in E}
        pts, tris = boundary(set(F), Eidx, lambda p, q, r: rule)
        c = np.array([S / 2] * 3)
        lo = 180
        for t in tris:
            X = to_space(np.array([pts[t[0]], pts[t[1]], pts[t[2]], c], float))
            a, b, rr, v = quality(X)
            lo = min(lo, a); worst = (min(worst[0], a), max(worst[1], b), min(worst[2], rr))
        h[round(lo, 2)] += 1
    print('2-split rule', rule, 'coning worst', [round(float(x), 3) for x in worst], 'orbits by min dihedral', sorted(h.items()))
