"""Make the boundary of a stuffed mesh a closed 2-manifold by removing tets at pinches.

Where the solid is thinner than the lattice resolves, stuffing can leave two parts of
the mesh touching at a single vertex or edge.  Such a vertex's star (the tets around it)
splits into pieces joined only through it; we keep the largest piece.  A vertex whose
star is one piece but whose boundary link is not one fan (an annulus: the surface passes
through it twice) loses its whole star.  The vertices of removed tets are checked again,
until no bad vertex is left (each step removes tets, so it ends).  Every
removal is counted and reported; the caller warns when volume or topology changed.
"""

from __future__ import annotations

from typing import Iterator

import numba as nb
import numpy as np

from .rays import _orient3d
from .topology import TET_FACES as _FACES
from .topology import (SurfaceTopology, _sort3, int32_ids, keep_rows, local_vertex_ids, match_faces, nonmanifold_of_fans,
                       surface_topology, touching, union, used_vertices, vertex_fans)


@nb.njit(cache=True)
def _vertex_tets(tets, n_vertices):
    """CSR of the tets around each vertex: (offsets (V+1,), tet ids)."""
    deg = np.zeros(n_vertices + 1, dtype=np.int64)
    for t in range(tets.shape[0]):
        for i in range(4):
            deg[tets[t, i] + 1] += 1
    for v in range(n_vertices):
        deg[v + 1] += deg[v]
    ids = np.empty(deg[n_vertices], dtype=np.int64)
    fill = deg[:-1].copy()
    for t in range(tets.shape[0]):
        for i in range(4):
            v = tets[t, i]
            ids[fill[v]] = t
            fill[v] += 1
    return deg, ids


@nb.njit(cache=True)
def _star_partners(tets, star, n, v, partner, keys, slots):
    """partner[4 i + k] = the index j != i in star[:n] of the tet sharing with tet star[i] its
    face through v opposite its vertex k (the smallest such j), -1 if none, for the k whose
    vertex is not v: a face through v has both its tets in v's star.  keys, slots: scratch
    of at least 3 n.

    The faces are keyed by their two vertices other than v and sorted (insertion sort: 3 n
    keys, n about 24), so equal keys are neighbours; testing every pair of the star's tets
    vertex by vertex cost 3 n^2 x 16 comparisons, 17 us a vertex (a plate whose 0.01 slots
    the lattice bridged at size / 8 had 83 k pinched vertices: 1.4 -> 0.66 s a repair)."""
    m = 0
    for i in range(n):
        t = star[i]
        for k in range(4):
            if tets[t, k] == v:
                continue
            a = -1
            b = -1
            for c in range(4):
                w = np.int64(tets[t, c])
                if c != k and w != v:
                    if a < 0:
                        a = w
                    else:
                        b = w
            key = (min(a, b) << 32) | max(a, b)
            j = m
            while j > 0 and keys[j - 1] > key:  # stable: equal keys keep slot order
                keys[j] = keys[j - 1]
                slots[j] = slots[j - 1]
                j -= 1
            keys[j] = key
            slots[j] = 4 * i + k
            m += 1
    r = 0
    while r < m:
        e = r + 1
        while e < m and keys[e] == keys[r]:
            e += 1
        # slots[r:e] ascend, and a tet holds no key twice: the smallest other tet is the
        # first of the run, or the second for the first itself.
        for q in range(r, e):
            if e - r == 1:
                partner[slots[q]] = -1
            else:
                partner[slots[q]] = slots[r + 1 if q == r else r] // 4
        r = e


@nb.njit(cache=True)
def _tet_before(tets, s, t, v, rank):
    """Whether tet s comes before tet t, both around vertex v: their other three vertices,
    each sorted by rank, compared in turn (distinct tets differ in one)."""
    a = _ranks_without(tets, s, v, rank)
    b = _ranks_without(tets, t, v, rank)
    for i in range(3):
        if a[i] != b[i]:
            return a[i] < b[i]
    return s < t


@nb.njit(cache=True, inline="always")
def _ranks_without(tets, t, v, rank):
    """The ranks (3,) of tet t's vertices other than v, ascending."""
    out = np.empty(3, dtype=np.int64)
    m = 0
    for k in range(4):
        w = tets[t, k]
        if w != v:
            r = rank[w]
            j = m
            while j > 0 and out[j - 1] > r:
                out[j] = out[j - 1]
                j -= 1
            out[j] = r
            m += 1
    return out


#: Rows of _repair_star's scratch: the live star, the link's sources and targets, the
#: pieces' labels, the face partners, _star_partners' keys and slots, the pieces' sizes.
STAR_SCRATCH_ROWS = 8


@nb.njit(cache=True)
def _repair_star(v, tets, alive, offsets, ids, remove_out, rank, scratch):
    """Check vertex v; if its live boundary is not one fan, mark tets to remove in remove_out
    (the star's pieces but the largest, of equal largest the one holding the first tet by
    _tet_before; the whole star if it is one piece).  Face neighbours come from the live star
    itself.  Returns the count.  scratch: (STAR_SCRATCH_ROWS, 4 x the largest star) int64,
    reused from vertex to vertex (fresh arrays a check cost a tenth of the repair of
    round_rod's pass at diag/160, 19 k checks an order)."""
    lo = offsets[v]
    hi = offsets[v + 1]
    star = scratch[0]
    n = 0
    for i in range(lo, hi):
        if alive[ids[i]]:
            star[n] = ids[i]
            n += 1
    if n == 0:
        return 0
    # Boundary link edges p -> q from live boundary faces (v, p, q) of the star.
    src = scratch[1]
    dst = scratch[2]
    m = 0
    label = scratch[3]
    for i in range(n):
        label[i] = i
    partner = scratch[4]
    _star_partners(tets, star, n, v, partner, scratch[5], scratch[6])
    for i in range(n):
        t = star[i]
        for k in range(4):
            if tets[t, k] == v:
                continue
            j = partner[4 * i + k]
            if j >= 0:
                if label[j] != label[i]:
                    old = max(label[i], label[j])
                    new = min(label[i], label[j])
                    for r in range(n):
                        if label[r] == old:
                            label[r] = new
                continue
            # Face k (opposite vertex k) is on the boundary; orient it outward, rotate v first.
            f0 = tets[t, _FACES[k, 0]]
            f1 = tets[t, _FACES[k, 1]]
            f2 = tets[t, _FACES[k, 2]]
            if f0 == v:
                src[m] = f1
                dst[m] = f2
            elif f1 == v:
                src[m] = f2
                dst[m] = f0
            else:
                src[m] = f0
                dst[m] = f1
            m += 1
    if m == 0:
        return 0
    ok = True
    for i in range(m):
        for j in range(i + 1, m):
            if src[i] == src[j]:
                ok = False
    if ok:
        cur = src[0]
        steps = 0
        while True:
            found = -1
            for i in range(m):
                if src[i] == cur:
                    found = i
            if found < 0:
                ok = False
                break
            cur = dst[found]
            steps += 1
            if cur == src[0] or steps > m:
                break
        ok = ok and steps == m and cur == src[0]
    if ok:
        return 0
    sizes = scratch[7]
    sizes[:n] = 0
    for i in range(n):
        sizes[label[i]] += 1
    largest = np.max(sizes[:n])
    keep = -1
    for i in range(n):  # the piece of the first tet, by the vertices' ranks, among the largest
        if sizes[label[i]] == largest and (keep < 0 or _tet_before(tets, star[i], star[keep], v, rank)):
            keep = i
    keep = label[keep]
    count = 0
    for i in range(n):
        if sizes[keep] == n or label[i] != keep:
            remove_out[count] = star[i]
            count += 1
    return count


@nb.njit(cache=True)
def _repair(tets, bad_vertices, n_vertices, complete, rank):
    """Worklist repair: check the bad vertices, remove tets, re-check the vertices they had.

    A stack: bad_vertices pushed in their order (the caller's: ascending rank), the last one
    checked first; the vertices of the tets a check removes pushed in ascending rank, the
    ones not yet on the stack.  rank (V,): an order of the vertices by their places (their
    coordinates), so that the repair, ties included, does not depend on how the mesh is
    numbered.  complete: (V,) True where the vertex's whole star is among tets.  Returns
    (alive (M,) mask, ok): ok is False if the work reached a vertex with an incomplete star
    (nothing is trusted then).
    """
    offsets, ids = _vertex_tets(tets, n_vertices)
    alive = np.ones(tets.shape[0], dtype=np.bool_)
    queued = np.zeros(n_vertices, dtype=np.bool_)
    work = np.empty(bad_vertices.shape[0] + 16, dtype=np.int64)
    top = 0
    for v in bad_vertices:
        work[top] = v
        top += 1
        queued[v] = True
    largest_star = np.int64(np.max(offsets[1:] - offsets[:-1])) + 1
    buf = np.empty(largest_star, dtype=np.int64)
    scratch = np.empty((STAR_SCRATCH_ROWS, 4 * largest_star), dtype=np.int64)
    while top > 0:
        top -= 1
        v = work[top]
        queued[v] = False
        if not complete[v]:
            return alive, False
        count = _repair_star(v, tets, alive, offsets, ids, buf, rank, scratch)
        first_new = top
        for i in range(count):
            t = buf[i]
            if not alive[t]:
                continue
            alive[t] = False
            for j in range(4):
                w = tets[t, j]
                if not queued[w]:
                    if top == work.shape[0]:
                        work = np.concatenate((work, np.empty(top, dtype=np.int64)))
                    # Insertion into the new run, ascending rank: pushed in that order.
                    k = top
                    while k > first_new and rank[work[k - 1]] > rank[w]:
                        work[k] = work[k - 1]
                        k -= 1
                    work[k] = w
                    top += 1
                    queued[w] = True
    return alive, True


#: Chunks of tets the parallel count-and-fill of surface_faces hands to the threads.
TET_CHUNKS = 64


@nb.njit(cache=True, inline="always")
def _surface_face_count(tets, core, t):
    """Faces of tet t without a core vertex: 1 if it has one core vertex, 4 if none, else 0."""
    n_core = core[tets[t, 0]] + core[tets[t, 1]] + core[tets[t, 2]] + core[tets[t, 3]]
    return 4 if n_core == 0 else (1 if n_core == 1 else 0)


@nb.njit(cache=True, parallel=True)
def surface_faces(tets, core):
    """The faces (C, 3) of tets without a core vertex, oriented outward, in order of tet and
    face (TET_FACES): the only faces that can lie on the boundary of a stuffed mesh (its
    vertices are cut points and warped vertices, on the surface).  Count per chunk, prefix
    sum, fill: each thread writes only its chunks' rows.  (A skeleton shared with other
    count-and-fill kernels, taking the per-tet count as a function argument, is compiled
    again in every process: numba caches no function-typed signature, 2.2 s a process.)"""
    m = tets.shape[0]
    n_chunks = max(min(m, TET_CHUNKS), 1)
    starts = np.zeros(n_chunks + 1, dtype=np.int64)
    for c in nb.prange(n_chunks):
        n = 0
        for t in range(c * m // n_chunks, (c + 1) * m // n_chunks):
            n += _surface_face_count(tets, core, t)
        starts[c + 1] = n
    for c in range(n_chunks):
        starts[c + 1] += starts[c]
    out = np.empty((starts[n_chunks], 3), dtype=tets.dtype)
    for c in nb.prange(n_chunks):
        n = starts[c]
        for t in range(c * m // n_chunks, (c + 1) * m // n_chunks):
            if _surface_face_count(tets, core, t) == 0:
                continue
            for k in range(4):
                a = tets[t, _FACES[k, 0]]
                b = tets[t, _FACES[k, 1]]
                d = tets[t, _FACES[k, 2]]
                if core[a] or core[b] or core[d]:
                    continue
                out[n, 0] = a
                out[n, 1] = b
                out[n, 2] = d
                n += 1
    return out


@nb.njit(cache=True)
def unmatched_faces(faces, n_vertices):
    """Mask (F,) of the faces whose vertex set no other face has; of three or more with one
    vertex set, all but the first two (the faces match_faces leaves without a neighbour).
    Faces are bucketed by their smallest vertex (a counting sort, as in match_faces)."""
    nf = faces.shape[0]
    if n_vertices > (np.int64(1) << 32):
        raise ValueError("unmatched_faces packs two vertex ids in 64 bits: at most 2**32 vertices")
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for f in range(nf):
        start[min(faces[f, 0], faces[f, 1], faces[f, 2]) + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    pairs = np.empty(nf, dtype=np.int64)
    first = np.empty(nf, dtype=np.int64)
    seen = np.empty(nf, dtype=np.int64)
    out = np.ones(nf, dtype=np.bool_)
    for f in range(nf):
        a, b, c = _sort3(faces[f, 0], faces[f, 1], faces[f, 2])
        pair = (np.int64(b) << 32) | np.int64(c)
        s = start[a]
        while s < fill[a] and pairs[s] != pair:
            s += 1
        if s == fill[a]:
            pairs[s] = pair
            first[s] = f
            seen[s] = 1
            fill[a] += 1
            continue
        seen[s] += 1
        if seen[s] == 2:
            out[first[s]] = False
            out[f] = False
    return out


def stuffed_boundary(tets: np.ndarray, core: np.ndarray) -> np.ndarray:
    """Boundary faces (F, 3) of a stuffed mesh, oriented outward.  core: (V,) True for
    vertices all of whose faces are interior (unwarped inside lattice vertices: every
    lattice face through three of them is kept by the stencils on both sides), so only
    faces without one can be boundary faces (surface_faces), and they are matched among
    themselves (a sixth of matching every face of the tets with three vertices not core)."""
    faces, vertex_of = _local_boundary(tets, core)
    return renumbered(faces, vertex_of)


def _local_boundary(tets: np.ndarray, core: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """stuffed_boundary's faces (F, 3) in local vertex ids, and vertex_of (B,): the mesh's id
    of each (local_vertex_ids of the faces without a core vertex)."""
    candidates, vertex_of = local_vertex_ids(surface_faces(tets, core))
    return np.compress(unmatched_faces(candidates, vertex_of.shape[0]), candidates, axis=0), vertex_of


@nb.njit(cache=True, parallel=True)
def renumbered(rows, new_id):
    """new_id[rows] for rows (N, K) of ids (faces in local ids to the mesh's, tets to new ids),
    of rows' type, in one parallel pass."""
    out = np.empty_like(rows)
    for f in nb.prange(rows.shape[0]):
        for k in range(rows.shape[1]):
            out[f, k] = new_id[rows[f, k]]
    return out


def remove_pinches(tets: np.ndarray, core: np.ndarray,
                   points: np.ndarray | None = None) -> tuple[np.ndarray, int, np.ndarray, SurfaceTopology]:
    """Tets (M', 4) whose boundary is a closed 2-manifold, the number of tets removed, the
    boundary faces (F, 3) of the result and their topology.

    The fans around the boundary's vertices find the bad vertices cheaply; only if there are
    any is the repair run (local_repair, in the order of the points (V, 3), by default the
    ids) and the boundary updated around the removed tets.
    Both inputs are updated in place: the tets kept move to the front of tets (the result is
    a view of it, no second (M, 4) array in the peak), and core (see stuffed_boundary) loses
    the vertices of removed tets.
    """
    tets = np.ascontiguousarray(tets)
    # The boundary's topology is found over its own vertices, numbered 0..B-1.
    faces, vertex_of = _local_boundary(tets, core)
    local_fans = vertex_fans(faces, vertex_of.shape[0])
    bad = np.flatnonzero(nonmanifold_of_fans(local_fans))
    if bad.size == 0:
        return tets, 0, renumbered(faces, vertex_of), surface_topology(faces, vertex_of.shape[0], fans=local_fans)
    # Back to mesh ids for the repair, the bad vertices in ascending order as before.
    faces, bad = renumbered(faces, vertex_of), np.sort(vertex_of[bad])
    fans = np.zeros(core.shape[0], dtype=local_fans.dtype)
    fans[vertex_of] = local_fans
    alive = local_repair(tets, bad, core.shape[0], points=points)
    removed = np.nonzero(~alive)[0]
    lost = np.zeros(core.shape[0], dtype=bool)
    lost[tets[removed].ravel()] = True
    core &= ~lost
    around = np.nonzero(touching(tets, lost))[0]  # every face neighbour of a removed tet
    faces = _faces_after_removal(faces, tets[around], alive[around])
    tets = tets[:keep_rows(tets, alive)]
    # Every face gone or new has its vertices in removed tets: only their fans change, and
    # the faces through them give them (featuretype at diag/80: 2.0 -> 0.4 ms).
    changed = np.flatnonzero(lost)
    fans[changed] = vertex_fans(np.compress(touching(faces, lost), faces, axis=0), core.shape[0])[changed]
    topology = surface_topology(faces, core.shape[0], fans=fans)
    if topology.bad_vertices:
        raise AssertionError("pinch repair left a non-manifold boundary vertex")
    return tets, int(removed.size), faces, topology


#: Rings of vertices around the bad ones whose stars local_repair works on first.  A
#: repair reaches past one ring only where a removal pinches a neighbour in turn; the
#: mesher's meshes never did (corpus at diag/40, /80 and /160).  The band of tets with a
#: vertex that is not core, which it worked on before, cost 4-5x more: featuretype at
#: diag/80, 9 bad vertices in 285 k tets, 6.8 -> 1.3 ms.
PINCH_RINGS = 1


#: The orders of the vertices the repair runs in (local_repair), as (axes, sign): points
#: ranked lexicographically by their coordinates in ``axes`` order, times ``sign``.  Each is
#: a place-only order, so no numbering of the mesh changes the result; the repair in the one
#: that removes the least volume is kept (ties: the first).  On 31 pinched passes of corpus
#: and generated parts (session 45), the four removed 12 157 tets where the vertex ids'
#: order removed 12 387 and the first order alone 12 389.
PINCH_ORDERS = (((0, 1, 2), 1), ((0, 1, 2), -1), ((2, 1, 0), 1), ((2, 1, 0), -1))


def local_repair(tets: np.ndarray, bad: np.ndarray, n_vertices: int, rings: int = PINCH_RINGS,
                 points: np.ndarray | None = None) -> np.ndarray:
    """Mask (M,) of the tets kept by the worklist repair (_repair) started at the bad vertices.

    The repair of a vertex reads only its star, so it runs on the stars of the vertices at
    most ``rings`` edges from a bad one (pinch_neighbourhood: the tets touching them, each of
    those stars complete there); only if the worklist leaves them does it run on the whole
    mesh.  With points (V, 3), those tets are repaired cluster by cluster
    (repair_near_pinches), so no numbering of the mesh changes the result and a cluster needs
    nothing from the others (a partition can repair its own); should no order stay within a
    cluster's stars, every cluster is repaired on the whole mesh, in the one order of
    PINCH_ORDERS that removes the least volume in all.  Without points, in the order of the
    ids.  A run on part of the mesh and on the whole give the same.
    """
    tets = int32_ids(tets)
    sub_ids, region = pinch_neighbourhood(tets, bad, n_vertices, rings)
    sub = np.take(tets, sub_ids, axis=0)
    if points is None:
        return _repaired_by_ids(tets, sub_ids, sub, bad, region)
    vertex_of, local = np.unique(sub, return_inverse=True)  # ascending ids: ties by id, as on the whole mesh
    kept = repair_near_pinches(local.reshape(sub.shape), np.searchsorted(vertex_of, bad), region[vertex_of],
                               points[vertex_of])
    if kept is None:  # a cluster's worklist left its stars in every order
        whole = np.ones(n_vertices, dtype=bool)
        used = np.flatnonzero(used_vertices(tets, n_vertices))
        kept = _least_volume_repair(tets, bad, whole, _ranks_in_orders(points, used), points, tets)
        assert kept is not None  # on the whole mesh every star is complete
        return kept
    alive = np.ones(tets.shape[0], dtype=bool)
    alive[sub_ids[~kept]] = False
    return alive


def pinch_neighbourhood(tets: np.ndarray, bad: np.ndarray, n_vertices: int,
                        rings: int = PINCH_RINGS) -> tuple[np.ndarray, np.ndarray]:
    """The tets local_repair works on first: (their rows (ascending) in tets (M, 4), region
    (n_vertices,) bool, the vertices at most ``rings`` edges from a bad one, whose stars are
    all among those tets: the tets touching them)."""
    region = np.zeros(n_vertices, dtype=bool)
    region[bad] = True
    near = touching(tets, region)
    for _ in range(rings):
        region = used_vertices(np.compress(near, tets, axis=0), n_vertices)
        near = touching(tets, region)
    return np.flatnonzero(near), region


def repair_near_pinches(tets: np.ndarray, bad: np.ndarray, complete: np.ndarray,
                        points: np.ndarray) -> np.ndarray | None:
    """Kept mask (S,) of the tets (S, 4) around the bad vertices (pinch_neighbourhood's, in
    their own ids 0..K-1, numbered in the order of the mesh's ids), or None if a cluster's
    worklist leaves the stars in every order (then the whole mesh must be repaired).

    The tets fall into clusters (joined through shared vertices) that no removal in another
    touches; each is repaired in each of PINCH_ORDERS of the coordinates of its vertices
    (points (K, 3)), and of the orders whose worklist stays within the vertices whose star is
    complete there (complete (K,) bool: pinch_neighbourhood's region) the one that removes
    the least volume is kept (ties: the first)."""
    tets = int32_ids(tets)  # local ids from np.unique's inverse come as int64
    ranks = _ranks_in_orders(points)
    kept_all = np.ones(tets.shape[0], dtype=bool)
    for rows, vertices, cluster_tets, members in _clusters(tets, bad):
        kept = _least_volume_repair(cluster_tets, members, complete[vertices], ranks[:, vertices], points, tets[rows])
        if kept is None:
            return None
        kept_all[rows[~kept]] = False
    return kept_all


def _least_volume_repair(tets: np.ndarray, bad: np.ndarray, complete: np.ndarray, ranks: np.ndarray,
                         points: np.ndarray, mesh_tets: np.ndarray) -> np.ndarray | None:
    """_repair of tets (T, 4) from the bad vertices in each of the orders ranks (O, K) (their
    vertices' ranks, PINCH_ORDERS'): the kept mask (T,) of the run that removes the least
    volume (ties: the first) among those that stay where stars are complete, or None if none
    does.  mesh_tets: the same tets by mesh ids, points (V, 3) theirs (for the volumes)."""
    best, best_volume = None, np.inf
    in_orders = np.stack([bad[np.argsort(rank[bad], kind="stable")] for rank in ranks])
    # A cluster's ranks come as a column gather (F order), its tets as int64 (_clusters): one
    # layout, one type, one compile of the kernel for clusters and the whole mesh (int32).
    alive, ok = _repairs_in_orders(int32_ids(tets), in_orders, complete.shape[0], complete,
                                   np.ascontiguousarray(ranks))
    volumes = _removed_volumes(points, np.ascontiguousarray(mesh_tets), alive)
    for kept, stayed, volume in zip(alive, ok, volumes):
        if stayed and volume < best_volume:
            best, best_volume = kept, volume
    return best


@nb.njit(cache=True, parallel=True)
def _repairs_in_orders(tets, bad_in_orders, n_vertices, complete, ranks):
    """_repair in each order at once, one order to a thread (each owns its row of the
    output): the kept masks (O, M) and ok (O,) of the bad vertices bad_in_orders[o] (O, B)
    by ranks[o] (O, V).  (In turn, the four orders took 50 ms of round_rod's pass at
    diag/160, 67 k tets and 2.7 k bad vertices.)"""
    n_orders = ranks.shape[0]
    alive = np.empty((n_orders, tets.shape[0]), dtype=np.bool_)
    ok = np.empty(n_orders, dtype=np.bool_)
    for o in nb.prange(n_orders):
        kept, stayed = _repair(tets, bad_in_orders[o], n_vertices, complete, ranks[o])
        alive[o] = kept
        ok[o] = stayed
    return alive, ok


def _clusters(sub: np.ndarray, bad: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """The clusters of tets sub (S, 4) (joined through shared vertices) holding bad vertices,
    each numbered on its own, so that repairing one costs its size: (rows (ascending) of sub,
    its vertices (K,) as mesh ids, its tets (R, 4) numbered 0..K-1 in that order, its bad
    vertices in those numbers)."""
    local, vertex_of = local_vertex_ids(sub)
    roots = _vertex_roots(local, vertex_of.shape[0])
    by_root = np.argsort(roots, kind="stable")  # each cluster's vertices together
    vertex_roots = roots[by_root]
    place = np.empty(vertex_of.shape[0], dtype=np.int64)  # each vertex's number in its cluster
    place[by_root] = np.arange(vertex_of.shape[0]) - np.searchsorted(vertex_roots, vertex_roots)
    tet_rows = np.argsort(roots[local[:, 0]], kind="stable")
    tet_roots = roots[local[tet_rows, 0]]
    sorted_ids = np.argsort(vertex_of)
    bad_local = sorted_ids[np.searchsorted(vertex_of, bad, sorter=sorted_ids)]
    bad_local = bad_local[np.argsort(roots[bad_local], kind="stable")]
    bad_roots = roots[bad_local]
    for root in np.unique(bad_roots):
        lo, hi = np.searchsorted(vertex_roots, [root, root + 1])
        rows = tet_rows[slice(*np.searchsorted(tet_roots, [root, root + 1]))]
        members = bad_local[slice(*np.searchsorted(bad_roots, [root, root + 1]))]
        yield rows, vertex_of[by_root[lo:hi]], place[local[rows]], place[members]


def _repaired_by_ids(tets: np.ndarray, sub_ids: np.ndarray, sub: np.ndarray, bad: np.ndarray,
                     region: np.ndarray) -> np.ndarray:
    """local_repair without points: in the order of the ids, all clusters at once, on sub
    (tets[sub_ids], holding every star of region), or on the whole mesh should the worklist
    leave it."""
    n_vertices = region.shape[0]
    ids = np.arange(n_vertices)  # a vertex's rank is its id
    sub_alive, ok = _repair(sub, np.sort(bad), n_vertices, region, ids)
    if not ok:
        return _repair(tets, np.sort(bad), n_vertices, np.ones(n_vertices, dtype=bool), ids)[0]
    alive = np.ones(tets.shape[0], dtype=bool)
    alive[sub_ids[~sub_alive]] = False
    return alive


@nb.njit(cache=True)
def _vertex_roots(tets, n_vertices):
    """The root (V,) of each vertex's cluster: vertices joined through the tets (T, 4) that
    hold them (union-find; a vertex in no tet is its own root)."""
    parent = np.arange(n_vertices)
    for t in range(tets.shape[0]):
        for k in range(1, 4):
            union(parent, tets[t, 0], tets[t, k])
    for v in range(n_vertices):
        r = v
        while parent[r] != r:
            r = parent[r]
        parent[v] = r
    return parent


@nb.njit(cache=True)
def _removed_volumes(points, tets, alive):
    """Total unsigned volume (O,) of the tets (T, 4) over points (V, 3) that each row of
    alive (O, T) removes.  (numpy's gather, cross product and sum over each order's removed
    tets took 21 ms of round_rod's pass at diag/80, 16 k of 68 k tets removed.)"""
    volumes = np.zeros(alive.shape[0])
    for o in range(alive.shape[0]):
        total = 0.0
        for t in range(tets.shape[0]):
            if alive[o, t]:
                continue
            a, b, c, d = tets[t, 0], tets[t, 1], tets[t, 2], tets[t, 3]
            total += abs(_orient3d(points[a, 0], points[a, 1], points[a, 2], points[b, 0], points[b, 1], points[b, 2],
                                   points[c, 0], points[c, 1], points[c, 2], points[d, 0], points[d, 1], points[d, 2]))
        volumes[o] = total / 6.0
    return volumes


def _ranks_in_orders(points: np.ndarray, used: np.ndarray | None = None) -> np.ndarray:
    """Ranks (O, V) int64 of each point (points (V, 3)) in each of PINCH_ORDERS of the
    coordinates: order (axes, sign) is lexicographic over sign * the coordinates in axes
    order, equal points by id.  used: the ids (ascending) of the only points the caller
    compares (the others rank 0): the stuffed mesh's points include every lattice vertex,
    most in no tet (round_rod's pass at diag/160: 25 k of 124 k, 41 -> 11 ms for four).

    One sort an axes order: the descending order is the ascending one's runs of equal points
    in reverse, each run still by id (lexsort took 6 ms a call on 25 k points)."""
    chosen = points if used is None else points[used]
    ranks = np.zeros((len(PINCH_ORDERS), points.shape[0]), dtype=np.int64)
    ascending = {}
    for o, (axes, sign) in enumerate(PINCH_ORDERS):
        if axes not in ascending:
            keys = chosen[:, list(axes)]
            order = np.lexsort(keys.T[::-1])
            ordered = keys[order]
            starts = np.flatnonzero(np.concatenate([[True], np.any(ordered[1:] != ordered[:-1], axis=1)]))
            ascending[axes] = order, starts
        order, starts = ascending[axes]
        n = order.shape[0]
        position = np.arange(n)
        if sign < 0:  # run r at [starts[r], ends[r]) moves to n - ends[r], its members in turn
            ends = np.append(starts[1:], n)
            run = np.repeat(np.arange(starts.shape[0]), ends - starts)
            position = n - ends[run] + (position - starts[run])
        ranked = np.empty(n, dtype=np.int64)
        ranked[order] = position
        if used is None:
            ranks[o] = ranked
        else:
            ranks[o, used] = ranked
    return ranks


def _faces_after_removal(faces: np.ndarray, near: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """The boundary faces once the dead tets are gone: the old boundary faces (F, 3) except
    the dead tets' own, and the faces of dead tets whose live neighbour they expose, turned to
    face out of it.  near (S, 4): the tets with a vertex of a dead tet (so every face
    neighbour of a dead tet), alive (S,) their mask."""
    neighbour, _, _ = match_faces(near)
    dead = np.nonzero(~alive)[0]
    dead_faces = near[dead[:, None, None], _FACES[None, :, :]].reshape(-1, 3)  # face k of each dead tet
    across = neighbour[dead].ravel()
    gone = np.sort(dead_faces[across < 0], axis=1)
    gone = np.ascontiguousarray(gone[np.lexsort(gone.T[::-1])])
    exposed = (across >= 0) & alive[np.maximum(across, 0)]
    return np.concatenate([np.compress(_faces_not_in(faces, gone), faces, axis=0), dead_faces[exposed][:, ::-1]])


@nb.njit(cache=True)
def _faces_not_in(faces, sorted_triples):
    """Mask (F,) of the faces whose vertex set is not a row of sorted_triples (rows ascending,
    sorted lexicographically)."""
    kept = np.ones(faces.shape[0], dtype=np.bool_)
    n = sorted_triples.shape[0]
    for f in range(faces.shape[0]):
        a, b, c = _sort3(faces[f, 0], faces[f, 1], faces[f, 2])
        lo = 0
        hi = n
        while lo < hi:
            mid = (lo + hi) // 2
            x, y, z = sorted_triples[mid, 0], sorted_triples[mid, 1], sorted_triples[mid, 2]
            if x < a or (x == a and (y < b or (y == b and z < c))):
                lo = mid + 1
            else:
                hi = mid
        if lo < n and sorted_triples[lo, 0] == a and sorted_triples[lo, 1] == b and sorted_triples[lo, 2] == c:
            kept[f] = False
    return kept
