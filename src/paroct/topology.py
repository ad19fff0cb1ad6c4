"""Derived topology of tet meshes: face matching, boundary surface, manifoldness, genus.

Pure functions over (tets (M, 4) int) arrays.  Faces and edges are matched by bucketing
them on their smallest vertex (a counting sort), so there is no limit on the vertex count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

#: Face k of a positively oriented tet is opposite vertex k, ordered to face outward.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]], dtype=np.int64)


def int32_ids(ids: np.ndarray) -> np.ndarray:
    """Vertex ids (tets (M, 4), faces, ...) as the C-contiguous int32 array the kernels are
    compiled for (the mesher's tets are int32; no copy then): one specialization of each kernel,
    whatever integers a caller passes (int64 tets from tests and from np.unique's inverse
    compiled stuffing's and the pinch repair's kernels a second time, about 36 s of a cold test
    suite).  ValueError if an id does not fit in int32."""
    if ids.dtype != np.int32 and ids.size and not (-2**31 <= ids.min() and ids.max() < 2**31):
        raise ValueError(f"ids {ids.min()}..{ids.max()} do not fit in int32")
    return np.ascontiguousarray(ids, dtype=np.int32)


@nb.njit(cache=True, inline="always")
def _sort3(a, b, c):
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return a, b, c


@nb.njit(cache=True)
def match_faces(tets):
    """Neighbour across every tet face.

    Returns (neighbour (M, 4) int64: the tet sharing face k of tet t, or -1 on the boundary;
    overloaded: number of faces found in more than two tets; same_side: number of faces
    whose two tets order them the same way, i.e. lie on the same side, inverted).
    """
    m = tets.shape[0]
    n_vertices = 1
    for t in range(m):
        for k in range(4):
            n_vertices = max(n_vertices, tets[t, k] + 1)
    if n_vertices > (np.int64(1) << 32):
        raise ValueError("match_faces packs two vertex ids in 64 bits: at most 2**32 vertices")
    # Bucket the face occurrences by their smallest vertex (a counting sort): each bucket holds
    # every face that could match, a few dozen at most, and vertex ids are spatially coherent,
    # so the buckets of nearby tets are near each other in memory.  No hashing, no probing.
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for t in range(m):
        for k in range(4):
            start[min(tets[t, TET_FACES[k, 0]], tets[t, TET_FACES[k, 1]], tets[t, TET_FACES[k, 2]]) + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    # Per stored face: its two larger vertices packed in one key (a bucket is scanned over keys
    # alone, 8 bytes a face) and tet * 4 + face of the first tet holding it.
    pairs = np.empty(4 * m, dtype=np.int64)
    owner = np.empty(4 * m, dtype=np.int64)
    neighbour = np.full((m, 4), -1, dtype=np.int64)
    overloaded = 0
    same_side = 0
    for t in range(m):
        for k in range(4):
            v0 = tets[t, TET_FACES[k, 0]]
            v1 = tets[t, TET_FACES[k, 1]]
            v2 = tets[t, TET_FACES[k, 2]]
            a, b, c = _sort3(v0, v1, v2)
            pair = (np.int64(b) << 32) | np.int64(c)
            found = -1
            for s in range(start[a], fill[a]):
                if pairs[s] == pair:
                    found = s
                    break
            if found < 0:
                s = fill[a]
                fill[a] += 1
                pairs[s] = pair
                owner[s] = t * 4 + k
                continue
            o = owner[found]
            if o < 0:
                overloaded += 1
                continue
            ot = o // 4
            ok = o % 4
            if neighbour[ot, ok] != -1:
                overloaded += 1
                owner[found] = -1
                continue
            neighbour[ot, ok] = t
            neighbour[t, k] = ot
            # Opposite orientation means the cyclic order of the two faces is reversed.
            w0 = tets[ot, TET_FACES[ok, 0]]
            w1 = tets[ot, TET_FACES[ok, 1]]
            w2 = tets[ot, TET_FACES[ok, 2]]
            if (w0 == v0 and w1 == v1) or (w1 == v0 and w2 == v1) or (w2 == v0 and w0 == v1):
                same_side += 1
    return neighbour, overloaded, same_side


@nb.njit(cache=True, parallel=True)
def touching(tets, marked):
    """Mask (M,) of the rows of tets (M, K) (tets, faces) with a marked vertex
    (marked[tets].any(axis=1) without its (M, K) temporary)."""
    out = np.empty(tets.shape[0], dtype=np.bool_)
    for t in nb.prange(tets.shape[0]):
        hit = False
        for k in range(tets.shape[1]):
            hit |= marked[tets[t, k]]
        out[t] = hit
    return out


@nb.njit(cache=True)
def vertex_stars(tets, vertices, n_points):
    """The tets around each of the given vertices (K,), by a counting sort over one pass of
    the tets: star_tets[star_start[i]:star_start[i + 1]] around vertices[i], in tet order;
    local (n_points,) maps a point to its i (-1 for the others)."""
    local = np.full(n_points, -1, dtype=np.int64)
    for i in range(vertices.shape[0]):
        local[vertices[i]] = i
    star_start = np.zeros(vertices.shape[0] + 1, dtype=np.int64)
    for t in range(tets.shape[0]):
        for j in range(4):
            i = local[tets[t, j]]
            if i >= 0:
                star_start[i + 1] += 1
    for i in range(vertices.shape[0]):
        star_start[i + 1] += star_start[i]
    fill = star_start[:-1].copy()
    star_tets = np.empty(star_start[-1], dtype=np.int64)
    for t in range(tets.shape[0]):
        for j in range(4):
            i = local[tets[t, j]]
            if i >= 0:
                star_tets[fill[i]] = t
                fill[i] += 1
    return star_start, star_tets, local


@nb.njit(cache=True, parallel=True)
def face_owners(tets, faces, star_start, star_tets, local):
    """For each triangle of faces (B, 3): the first tet (in the star of its first vertex, from
    vertex_stars) holding all three vertices, and which of its faces it is (k: the face
    opposite the tet's vertex k); (-1, -1) if none.  Parallel over the triangles: the scans
    of the stars are random reads of tets (round_rod's 0.8 M boundary triangles at diag/80:
    66 ms serial)."""
    owner = np.full(faces.shape[0], -1, dtype=np.int64)
    which = np.full(faces.shape[0], -1, dtype=np.int8)
    for f in nb.prange(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        i = local[a]
        for s in range(star_start[i], star_start[i + 1]):
            t = star_tets[s]
            held = 0
            other = -1
            for j in range(4):
                w = tets[t, j]
                if w == a or w == b or w == c:
                    held += 1
                else:
                    other = j
            if held == 3:
                owner[f], which[f] = t, other
                break
    return owner, which


@nb.njit(cache=True, parallel=True)
def tet_faces_of(tets, owner, face):
    """Triangles (B, 3) of tets' type: face face[b] of tet owner[b], as TET_FACES orders it
    (tets[owner[:, None], TET_FACES[face]] without numpy's broadcast gather, 4x slower)."""
    out = np.empty((owner.shape[0], 3), dtype=tets.dtype)
    for b in nb.prange(owner.shape[0]):
        for k in range(3):
            out[b, k] = tets[owner[b], TET_FACES[face[b], k]]
    return out


def boundary_faces(tets: np.ndarray, neighbour: np.ndarray) -> np.ndarray:
    """Boundary triangles (B, 3), oriented outward, of tets with the given face neighbours."""
    t, k = np.nonzero(neighbour < 0)
    return tets[t[:, None], TET_FACES[k]]


@nb.njit(cache=True)
def edge_bucket_starts(faces, n_vertices):
    """Bucket starts (V + 1,) of a counting sort of the edge occurrences of triangles (F, 3) by
    their smaller vertex: those with smaller vertex a take slots start[a] .. start[a + 1] - 1."""
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for f in range(faces.shape[0]):
        for j in range(3):
            start[min(faces[f, j], faces[f, (j + 1) % 3]) + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    return start


@nb.njit(cache=True)
def half_edge_twins(faces, n_vertices):
    """The twin (F * 3,) of each half-edge h = 3 f + j (from faces[f, j] to faces[f, (j + 1) % 3]):
    the half-edge running the other way along the same edge, or -1 if none (a closed,
    consistently oriented surface has exactly one).  A counting sort of the half-edges by
    smaller vertex, each slot holding its larger vertex and direction, then a search of each
    bucket (through the faces, the search took 9 of armadillo's 15 ms of surface_patches)."""
    nf = faces.shape[0]
    start = edge_bucket_starts(faces, n_vertices)
    fill = start[:-1].copy()
    slot = np.empty(3 * nf, dtype=np.int64)
    larger = np.empty(3 * nf, dtype=np.int64)
    upward = np.empty(3 * nf, dtype=np.bool_)  # from the smaller vertex to the larger
    for f in range(nf):
        for j in range(3):
            p, q = faces[f, j], faces[f, (j + 1) % 3]
            a = min(p, q)
            slot[fill[a]] = 3 * f + j
            larger[fill[a]] = max(p, q)
            upward[fill[a]] = p < q
            fill[a] += 1
    twin = np.full(3 * nf, -1, dtype=np.int64)
    for a in range(n_vertices):
        for s in range(start[a], start[a + 1]):
            for t in range(start[a], start[a + 1]):
                if larger[t] == larger[s] and upward[t] != upward[s]:
                    twin[slot[s]] = slot[t]
                    break
    return twin


@nb.njit(cache=True)
def edge_multiplicities(faces, n_vertices):
    """Per distinct edge of triangles (F, 3): how many faces hold it (E,) and how many of
    them run it from its smaller to its larger vertex (E,); and the number of vertices used.
    A closed oriented 2-manifold has every edge at (2, 1).  Edges are bucketed by their
    smaller vertex (a counting sort, as in match_faces)."""
    nf = faces.shape[0]
    start = edge_bucket_starts(faces, n_vertices)
    fill = start[:-1].copy()
    other = np.empty(3 * nf, dtype=np.int64)
    count = np.zeros(3 * nf, dtype=np.int64)
    forward = np.zeros(3 * nf, dtype=np.int64)
    used = np.zeros(n_vertices, dtype=np.bool_)
    for f in range(nf):
        for j in range(3):
            p = faces[f, j]
            q = faces[f, (j + 1) % 3]
            used[p] = True
            a = min(p, q)
            b = max(p, q)
            s = start[a]
            while s < fill[a] and other[s] != b:
                s += 1
            if s == fill[a]:
                other[s] = b
                fill[a] += 1
            count[s] += 1
            if p < q:
                forward[s] += 1
    n_edges = 0
    for a in range(n_vertices):
        for s in range(start[a], fill[a]):
            count[n_edges] = count[s]
            forward[n_edges] = forward[s]
            n_edges += 1
    return count[:n_edges], forward[:n_edges], int(used.sum())


@nb.njit(cache=True)
def vertex_links(faces, n_vertices):
    """The faces around every vertex, as the edges of its link: for s in start[v]..start[v+1]-1,
    face face_of[s] is (v, nxt[s], prv[s]) in its own orientation.  Returns (start (V+1,) int64,
    face_of, nxt, prv (3F,) of the faces' integer type), a counting sort of the corners by vertex."""
    nf = faces.shape[0]
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for f in range(nf):
        for j in range(3):
            start[faces[f, j] + 1] += 1
    for v in range(n_vertices):
        start[v + 1] += start[v]
    face_of = np.empty(3 * nf, dtype=faces.dtype)
    nxt = np.empty(3 * nf, dtype=faces.dtype)
    prv = np.empty(3 * nf, dtype=faces.dtype)
    fill = start[:-1].copy()
    for f in range(nf):
        for j in range(3):
            v = faces[f, j]
            face_of[fill[v]] = f
            nxt[fill[v]] = faces[f, (j + 1) % 3]
            prv[fill[v]] = faces[f, (j + 2) % 3]
            fill[v] += 1
    return start, face_of, nxt, prv


#: Vertex degree up to which link_fans compares every pair of slots (about 6 on a mesh).
_SCAN_DEGREE = 64


@nb.njit(cache=True, parallel=True)
def link_fans(start, nxt, prv, following, fans):
    """Fans around every vertex from the faces around it (vertex_links' start, nxt, prv).

    following[s]: the slot of v whose prv is nxt[s], the face after s around v.  fans[v]:
    the number of fans at v, the cycles of following; 0 if no face has v; -1 if nxt[s] is
    the prv of other than exactly one slot of v for some slot s, or following is not a
    permutation of v's slots (two slots with one nxt).  So v passes if and only if every
    nxt of its slots is the nxt of exactly one and the prv of exactly one: every edge {v, w}
    in exactly two faces that run it opposite ways passes at both ends, and any other edge
    fails at one.  Vertices run in parallel chunks, each writing only its own slots."""
    n = start.shape[0] - 1
    n_chunks = max(1, min(n // 1024, 64))
    for c in nb.prange(n_chunks):
        for v in range(c * n // n_chunks, (c + 1) * n // n_chunks):
            lo = start[v]
            hi = start[v + 1]
            bad = False
            if hi - lo <= _SCAN_DEGREE:
                for s in range(lo, hi):
                    w = nxt[s]
                    back = 0
                    after = -1
                    for t in range(lo, hi):
                        if prv[t] == w:
                            back += 1
                            after = t
                    bad |= back != 1
                    following[s] = after
            else:  # a sort, not d^2 comparisons: a vertex of 2 M faces (a fuzzed polygon) took minutes
                order = np.argsort(prv[lo:hi])
                sorted_prv = prv[lo:hi][order]
                for s in range(lo, hi):
                    first = np.searchsorted(sorted_prv, nxt[s], side="left")
                    last = np.searchsorted(sorted_prv, nxt[s], side="right")
                    bad |= last - first != 1
                    following[s] = lo + order[first] if last - first == 1 else -1
            if bad:
                fans[v] = -1
                continue
            count = 0
            for s in range(lo, hi):  # walk the cycles, marking visited slots by -2 - following
                if following[s] < 0:
                    continue
                count += 1
                cur = s
                while following[cur] >= 0:
                    after = following[cur]
                    following[cur] = -2 - after
                    cur = after
                bad |= cur != s  # a walk that ends elsewhere met a slot with two predecessors
            for s in range(lo, hi):
                following[s] = -2 - following[s]
            fans[v] = -1 if bad else count


def vertex_fans(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Fans (V,) int32 around every vertex of triangles (F, 3): see link_fans."""
    start, _, nxt, prv = vertex_links(faces, n_vertices)
    fans = np.empty(n_vertices, dtype=np.int32)
    link_fans(start, nxt, prv, np.empty(nxt.shape[0], dtype=np.int32), fans)
    return fans


def nonmanifold_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Mask (V,) of surface vertices whose incident faces do not form exactly one closed fan,
    vertices on an edge in other than two faces, or two run the same way, included.  (The
    link of v, its faces (v, p, q) as edges p -> q, is then not a single cycle.)"""
    return nonmanifold_of_fans(vertex_fans(faces, n_vertices))


def nonmanifold_of_fans(fans: np.ndarray) -> np.ndarray:
    """nonmanifold_vertices from vertex_fans' result."""
    return (fans != 1) & (fans != 0)


@nb.njit(cache=True)
def union(parent, a, b):
    """Joins the sets of a and b in the union-find forest ``parent`` (path halving; the
    smaller root becomes the root of both)."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    while parent[b] != b:
        parent[b] = parent[parent[b]]
        b = parent[b]
    if a != b:
        parent[max(a, b)] = min(a, b)


@nb.njit(cache=True)
def used_vertices(ids, n_vertices):
    """Mask (n_vertices,) of the vertices that rows of ids (N, K) (faces, tets) use."""
    used = np.zeros(n_vertices, dtype=np.bool_)
    for r in range(ids.shape[0]):
        for k in range(ids.shape[1]):
            used[ids[r, k]] = True
    return used


@nb.njit(cache=True)
def keep_rows(rows, keep):
    """Move the rows (N, K) whose keep (N,) bool is set to the front, in order, in place;
    returns how many: rows[:count] is np.compress(keep, rows, axis=0).  Half compress's
    time and no second array (14 M tets: 51 against 102 ms, and 224 MB not allocated)."""
    count = 0
    for r in range(rows.shape[0]):
        if keep[r]:
            if count != r:
                for k in range(rows.shape[1]):
                    rows[count, k] = rows[r, k]
            count += 1
    return count


def local_vertex_ids(ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of ids (N, K) with their vertices numbered 0..B-1 in order of first use, and
    vertex_of (B,) int64, the original id of each: (local (N, K) of ids' type, vertex_of).
    Kernels sized by the vertex count then size by B: a stuffed mesh's boundary uses a
    sixth of its points (round_rod at diag/80: 418 k of 2.4 M), and its counting sorts and
    union-find over 2.4 M slots took twice as long.  Ids spread far wider than the rows (a
    range's boundary faces in a whole mesh's ids, range_pinches) are numbered through a hash
    table sized by the rows instead of an array over every id up to the largest."""
    largest = int(ids.max()) if ids.size else -1
    if largest + 1 > SPARSE_IDS * ids.size:
        bits = max(4, int(2 * ids.size).bit_length())  # at least twice the entries
        return _number_by_first_use(ids, np.full(1 << bits, -1, dtype=np.int64), bits)
    return _number_by_first_use(ids, np.full(largest + 1, -1, dtype=np.int64), 0)


#: local_vertex_ids hashes ids whose largest exceeds this many times the number of entries.
SPARSE_IDS = 8


@nb.njit(cache=True)
def _number_by_first_use(ids, table, bits):
    """local_vertex_ids' kernel.  table: the local id of each id, -1 where none yet: indexed by
    the id (bits 0: an array over 0..largest), or 2**bits slots of open addressing (Fibonacci
    hash, linear probing)."""
    mask = (np.int64(1) << bits) - 1
    vertex_of = np.empty(ids.size, dtype=np.int64)
    local = np.empty_like(ids)
    b = 0
    for r in range(ids.shape[0]):
        for k in range(ids.shape[1]):
            v = np.int64(ids[r, k])
            s = v
            if bits:
                s = np.int64((np.uint64(v) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(64 - bits))
                while table[s] >= 0 and vertex_of[table[s]] != v:
                    s = (s + 1) & mask
            if table[s] < 0:
                table[s] = b
                vertex_of[b] = v
                b += 1
            local[r, k] = table[s]
    return local, vertex_of[:b]


@nb.njit(cache=True)
def _components(faces, n_vertices):
    parent = component_roots(faces, n_vertices)
    used = used_vertices(faces, n_vertices)
    count = 0
    for v in range(n_vertices):
        if used[v] and parent[v] == v:
            count += 1
    return count


@nb.njit(cache=True)
def component_roots(faces, n_vertices):
    """The root (n_vertices,) int64 of each vertex's component, the triangles (F, 3) joining
    their vertices: the smallest vertex of the component (each vertex its own if no face
    uses it)."""
    parent = np.arange(n_vertices)
    for f in range(faces.shape[0]):
        for j in range(1, 3):
            union(parent, faces[f, 0], faces[f, j])
    for v in range(n_vertices):  # ascending: a parent is smaller, so its root is final
        parent[v] = parent[parent[v]]
    return parent


@dataclass(frozen=True)
class SurfaceTopology:
    """Topology of a closed triangle surface.  manifold: every edge in two faces of opposite
    orientation and every vertex's faces one closed fan; genus summed over components."""

    n_faces: int
    n_vertices: int
    n_edges: int
    bad_edges: int
    bad_vertices: int
    components: int
    euler: int

    @property
    def manifold(self) -> bool:
        return self.bad_edges == 0 and self.bad_vertices == 0

    @property
    def genus(self) -> int:
        return (2 * self.components - self.euler) // 2


def surface_topology(faces: np.ndarray, n_vertices: int, *, fans: np.ndarray | None = None) -> SurfaceTopology:
    """Edges, manifoldness, components and Euler characteristic of triangles (F, 3).
    fans: vertex_fans(faces, n_vertices), when the caller has it (remove_pinches).  Where
    every vertex passes link_fans' slot test every edge is in two faces run opposite ways,
    3 F / 2 edges; only otherwise are the edges counted (edge_multiplicities)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if faces.shape[0] == 0:
        return SurfaceTopology(0, 0, 0, 0, 0, 0, 0)
    if fans is None:
        fans = vertex_fans(faces, n_vertices)
    n_used = int(np.count_nonzero(fans))
    bad_vertices = int(np.count_nonzero(nonmanifold_of_fans(fans)))
    if fans.min() >= 0:
        n_edges, bad_edges = 3 * faces.shape[0] // 2, 0
    else:
        count, forward, _ = edge_multiplicities(faces, n_vertices)
        n_edges = count.shape[0]
        bad_edges = int(np.sum((count != 2) | (forward != 1)))
    components = _components(faces, n_vertices)
    euler = n_used - n_edges + faces.shape[0]
    return SurfaceTopology(faces.shape[0], n_used, n_edges, bad_edges, bad_vertices, components, euler)
