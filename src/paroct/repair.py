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


def band_boundary(tets: np.ndarray, core: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boundary faces of a stuffed mesh from its band alone.

    core: (V,) True for vertices all of whose faces are interior (unwarped inside lattice
    vertices: every lattice face through three of them is kept by the stencils on both
    sides).  Only tets with a non-core vertex, the band, can then have boundary faces.
    Returns (band (M,) mask, band face neighbours (B, 4) indexing tets[band], boundary faces (F, 3)).
    """
    band = ~core[tets].all(axis=1)
    band_tets = np.ascontiguousarray(tets[band])
    neighbour, _, _ = match_faces(band_tets)
    faces = boundary_faces(band_tets, neighbour)
    faces = faces[~core[faces].all(axis=1)]
    return band, neighbour, np.ascontiguousarray(faces)


def remove_pinches(tets: np.ndarray, core: np.ndarray) -> tuple[np.ndarray, int]:
    """Tets (M', 4) whose boundary is a closed 2-manifold, and the number of tets removed.

    core: see band_boundary; vertices of removed tets leave the core (their faces may now
    be boundary), so pass a copy if the caller's mask must not change.
    """
    removed = 0
    for _ in range(MAX_ROUNDS):
        band, neighbour, faces = band_boundary(tets, core)
        bad = nonmanifold_vertices(faces, core.shape[0])
        if not bad.any():
            return tets, removed
        band_tets = np.ascontiguousarray(tets[band])
        drop_band = _split_stars(band_tets, neighbour, bad)
        drop = np.zeros(tets.shape[0], dtype=bool)
        drop[np.nonzero(band)[0][drop_band]] = True
        core[tets[drop].ravel()] = False
        removed += int(drop.sum())
        tets = tets[~drop]
    raise AssertionError(f"boundary still non-manifold after {MAX_ROUNDS} rounds of pinch removal")
