"""Make the boundary of a stuffed mesh a closed 2-manifold by removing tets at pinches.

Where the solid is thinner than the lattice resolves, stuffing can leave two parts of
the mesh touching at a single vertex or edge.  Such a vertex's star (the tets around it)
splits into pieces joined only through it; we keep the largest piece.  A vertex whose
star is one piece but whose boundary link is not one fan (an annulus: the surface passes
through it twice) loses its whole star.  Repeat until no such vertex is left.  Every
removal is counted and reported; the caller warns when volume or topology changed.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .topology import boundary_faces, match_faces, nonmanifold_vertices

#: Give up after this many rounds (each round removes tets, so it always terminates).
MAX_ROUNDS = 64


@nb.njit(cache=True)
def _split_stars(tets, neighbour, bad):
    """Mask (M,) of tets to remove around the bad vertices."""
    m = tets.shape[0]
    n_vertices = bad.shape[0]
    deg = np.zeros(n_vertices + 1, dtype=np.int64)
    for t in range(m):
        for i in range(4):
            if bad[tets[t, i]]:
                deg[tets[t, i] + 1] += 1
    for v in range(n_vertices):
        deg[v + 1] += deg[v]
    star = np.empty(deg[n_vertices], dtype=np.int64)
    fill = deg[:-1].copy()
    for t in range(m):
        for i in range(4):
            v = tets[t, i]
            if bad[v]:
                star[fill[v]] = t
                fill[v] += 1
    remove = np.zeros(m, dtype=np.bool_)
    for v in range(n_vertices):
        lo = deg[v]
        hi = deg[v + 1]
        if hi == lo:
            continue
        n = hi - lo
        label = np.arange(n)
        # Union the star's tets across their faces through v (the face opposite v excluded).
        changed = True
        while changed:
            changed = False
            for i in range(n):
                t = star[lo + i]
                for k in range(4):
                    if tets[t, k] == v:
                        continue
                    o = neighbour[t, k]
                    if o < 0:
                        continue
                    for j in range(n):
                        if star[lo + j] == o and label[j] != label[i]:
                            lab = min(label[i], label[j])
                            label[i] = lab
                            label[j] = lab
                            changed = True
        sizes = np.zeros(n, dtype=np.int64)
        for i in range(n):
            sizes[label[i]] += 1
        keep = np.argmax(sizes)
        if sizes[keep] == n:
            for i in range(n):
                remove[star[lo + i]] = True
        else:
            for i in range(n):
                if label[i] != keep:
                    remove[star[lo + i]] = True
    return remove


def remove_pinches(n_points: int, tets: np.ndarray) -> tuple[np.ndarray, int]:
    """Tets (M', 4) whose boundary is a closed 2-manifold, and the number of tets removed."""
    removed = 0
    for _ in range(MAX_ROUNDS):
        neighbour, _, _ = match_faces(tets)
        bad = nonmanifold_vertices(np.ascontiguousarray(boundary_faces(tets, neighbour)), n_points)
        if not bad.any():
            return tets, removed
        drop = _split_stars(tets, neighbour, bad)
        removed += int(drop.sum())
        tets = tets[~drop]
    raise AssertionError(f"boundary still non-manifold after {MAX_ROUNDS} rounds of pinch removal")
