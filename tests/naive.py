"""Slow, obvious references for the bit tricks and exact kernels, compared in the tests."""

from __future__ import annotations

import math

import numpy as np

from paroct.octant import MAX_LEVEL


def morton_key(x: int, y: int, z: int) -> int:
    """Interleave bits one by one: bit i of x, y, z goes to bits 3i, 3i + 1, 3i + 2."""
    key = 0
    for i in range(21):
        key |= ((x >> i) & 1) << (3 * i)
        key |= ((y >> i) & 1) << (3 * i + 1)
        key |= ((z >> i) & 1) << (3 * i + 2)
    return key


def octant_contains(anchor_a, level_a, anchor_b, level_b) -> bool:
    """Octant a contains octant b (as closed sets of integer points) by comparing boxes."""
    side_a = 1 << (MAX_LEVEL - level_a)
    side_b = 1 << (MAX_LEVEL - level_b)
    return all(anchor_a[i] <= anchor_b[i] and anchor_b[i] + side_b <= anchor_a[i] + side_a for i in range(3))


def winding_number(point, vertices, faces, direction) -> int:
    """Signed crossings of the ray from -infinity to point along direction, with Python fractions.

    The point is moved to point - eps * direction (and a generic transverse eps**2, eps**3 offset
    in the row coordinates used by paroct.rays is NOT reproduced here: only use points off the surface).
    """
    from fractions import Fraction

    d = [Fraction(int(c)) for c in direction]
    p = [Fraction(int(c)) for c in point]
    total = 0
    for f in faces:
        a, b, c = ([Fraction(int(v)) for v in vertices[i]] for i in f)
        # Solve p - s d = a + beta (b - a) + gamma (c - a), s > 0 means crossing before the point.
        m = [[b[i] - a[i], c[i] - a[i], d[i]] for i in range(3)]
        rhs = [p[i] - a[i] for i in range(3)]
        det = _det3(m)
        if det == 0:
            continue
        beta = _det3([[rhs[i], m[i][1], m[i][2]] for i in range(3)]) / det
        gamma = _det3([[m[i][0], rhs[i], m[i][2]] for i in range(3)]) / det
        s = _det3([[m[i][0], m[i][1], rhs[i]] for i in range(3)]) / det
        if beta > 0 and gamma > 0 and beta + gamma < 1 and s > 0:
            normal = _cross([b[i] - a[i] for i in range(3)], [c[i] - a[i] for i in range(3)])
            total += 1 if sum(normal[i] * d[i] for i in range(3)) < 0 else -1
    return total


def _det3(m):
    return (
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    )


def _cross(u, v):
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def unit_normal(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> list[float]:
    """Unit normal of triangle abc by the right-hand rule; zeros if it is degenerate."""
    n = _cross([b[i] - a[i] for i in range(3)], [c[i] - a[i] for i in range(3)])
    length = math.sqrt(sum(x * x for x in n))
    return [x / length for x in n] if length > 0 else [0.0, 0.0, 0.0]


def tet_radius_ratio(p: np.ndarray) -> float:
    """3 r / R of one tet (4, 3) from the circumcentre solved as a linear system."""
    a = 2.0 * (p[1:] - p[0])
    b = np.sum(p[1:] ** 2 - p[0] ** 2, axis=1)
    centre = np.linalg.solve(a, b)
    circum = np.linalg.norm(centre - p[0])
    vol = abs(np.linalg.det(p[1:] - p[0])) / 6.0
    area = 0.0
    for skip in range(4):
        q = np.delete(p, skip, axis=0)
        area += 0.5 * np.linalg.norm(np.cross(q[1] - q[0], q[2] - q[0]))
    return 3.0 * (3.0 * vol / area) / circum


def tet_dihedral_angles(p: np.ndarray) -> list[float]:
    """The six dihedral angles (degrees) from the angle between the two faces' in-plane normals."""
    out = []
    for i in range(4):
        for j in range(i + 1, 4):
            k, m = [x for x in range(4) if x not in (i, j)]
            e = p[j] - p[i]
            e = e / np.linalg.norm(e)
            u = p[k] - p[i]
            u = u - e * np.dot(u, e)
            w = p[m] - p[i]
            w = w - e * np.dot(w, e)
            out.append(np.degrees(np.arccos(np.clip(np.dot(u, w) / np.linalg.norm(u) / np.linalg.norm(w), -1, 1))))
    return out


def point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Distance from p to the closed triangle abc by enumerating the closest-point candidates.

    The closest point is a corner, the foot of p on an edge line (if within the edge), or the
    foot on the plane (if its least-squares barycentrics are in the triangle); every candidate
    is a point of the triangle, so the smallest candidate distance is the distance, even for
    degenerate triangles.
    """
    p, a, b, c = (np.asarray(x, dtype=np.float64) for x in (p, a, b, c))
    candidates = [a, b, c]
    for s, e in ((a, b), (b, c), (c, a)):
        d = e - s
        dd = float(np.dot(d, d))
        if dd > 0:
            t = float(np.dot(p - s, d)) / dd
            if 0.0 <= t <= 1.0:
                candidates.append(s + t * d)
    m = np.column_stack([b - a, c - a])
    (u, v), *_ = np.linalg.lstsq(m, p - a, rcond=None)
    if u >= 0 and v >= 0 and u + v <= 1:
        candidates.append(a + u * (b - a) + v * (c - a))
    return min(float(np.linalg.norm(p - q)) for q in candidates)


def triangle_meets_cube(tri: np.ndarray, lo: np.ndarray, side: float) -> bool:
    """Clip the triangle by the cube's six half-spaces (Sutherland-Hodgman); it meets the closed
    cube iff something is left."""
    poly = [np.asarray(p, dtype=float) for p in tri]
    for axis in range(3):
        for bound, keep_below in ((lo[axis], False), (lo[axis] + side, True)):
            out = []
            for i in range(len(poly)):
                p, q = poly[i], poly[(i + 1) % len(poly)]
                p_in = p[axis] <= bound if keep_below else p[axis] >= bound
                q_in = q[axis] <= bound if keep_below else q[axis] >= bound
                if p_in:
                    out.append(p)
                if p_in != q_in:
                    t = (bound - p[axis]) / (q[axis] - p[axis])
                    out.append(p + t * (q - p))
            poly = out
            if not poly:
                return False
    return True


def cells_meeting_triangles(tris: np.ndarray, side: float, n_cells: int) -> set[tuple[int, int, int]]:
    """All cells (i, j, k) of the grid of ``side`` in [0, n_cells)^3 that meet a triangle, by clipping."""
    out = set()
    for tri in tris:
        lo = np.maximum(np.floor(tri.min(axis=0) / side).astype(int) - 1, 0)
        hi = np.minimum(np.floor(tri.max(axis=0) / side).astype(int) + 1, n_cells - 1)
        for i in range(lo[0], hi[0] + 1):
            for j in range(lo[1], hi[1] + 1):
                for k in range(lo[2], hi[2] + 1):
                    if triangle_meets_cube(tri, np.array([i, j, k]) * side, side):
                        out.add((i, j, k))
    return out


def face_centres(anchors: np.ndarray, sides: np.ndarray, eager: np.ndarray) -> set[tuple[int, int, int]]:
    """Face centres of the coarse leaves that are vertices, face by face from sets of points.

    A cube edge is split when its midpoint is some leaf's corner.  A face's centre is a vertex
    when it is some leaf's corner (a finer face); or when both face edges at a corner off the
    face's Freudenthal diagonal (the diagonal joins its corners of least and greatest
    coordinate sum) are split (the minimal rule); or when one of its four edges is split and a
    leaf sharing the face (this one or the same-size leaf across) is marked in eager (L,).
    """
    corners = set()
    for a, s in zip(anchors.tolist(), sides.tolist()):
        for dx in (0, s):
            for dy in (0, s):
                for dz in (0, s):
                    corners.add((a[0] + dx, a[1] + dy, a[2] + dz))
    marked = {(tuple(a), s): bool(e) for a, s, e in zip(anchors.tolist(), sides.tolist(), eager.tolist())}
    out = set()
    for a, s in zip(anchors.tolist(), sides.tolist()):
        if s < 2:
            continue
        for k in range(3):
            for b in (0, s):
                i, j = [x for x in range(3) if x != k]
                quad = []
                for di in (0, s):
                    for dj in (0, s):
                        p = list(a)
                        p[k] += b
                        p[i] += di
                        p[j] += dj
                        quad.append(tuple(p))
                centre = tuple(sum(p[x] for p in quad) // 4 for x in range(3))
                quad.sort(key=sum)
                off_diagonal = quad[1:3]

                def split(p, q):
                    return tuple((p[x] + q[x]) // 2 for x in range(3)) in corners

                def adjacent(q):
                    return [p for p in (quad[0], quad[3]) if sum(abs(p[x] - q[x]) for x in range(3)) == s]

                across = list(a)
                across[k] += s if b else -s
                any_marked = marked[(tuple(a), s)] or marked.get((tuple(across), s), False)
                minimal = any(all(split(q, p) for p in adjacent(q)) for q in off_diagonal)
                one_edge = any(split(q, p) for q in off_diagonal for p in adjacent(q))
                if centre in corners or minimal or (one_edge and any_marked):
                    out.add(centre)
    return out


def vertex_order(anchors: np.ndarray, sides: np.ndarray, eager: np.ndarray, prefix: np.ndarray) -> np.ndarray:
    """Lattice points (V, 3) of number_vertices' vertices in id order, by its definition: the
    prefix points, then each leaf's corners (corner c at anchor + side * CUBE_CORNERS[c]) leaf
    by leaf, then the face centres that are vertices (face_centres), first those of the leaves
    marked eager, then of the others, each leaf's in SPLIT_POINT_OFFSETS order; a point at its
    first place only."""
    from paroct.frame import CUBE_CORNERS
    from paroct.transitions import SPLIT_POINT_OFFSETS

    centres = face_centres(anchors, sides, eager)
    order = {}
    for p in prefix.tolist():
        order.setdefault(tuple(p), len(order))
    for a, s in zip(anchors.tolist(), sides.tolist()):
        for c in CUBE_CORNERS.tolist():
            order.setdefault(tuple(a[k] + s * c[k] for k in range(3)), len(order))
    for phase in (True, False):
        for a, s, e in zip(anchors.tolist(), sides.tolist(), eager.tolist()):
            if s < 2 or bool(e) != phase:
                continue
            for offset in SPLIT_POINT_OFFSETS[12:].tolist():
                point = tuple(a[k] + s // 2 * offset[k] for k in range(3))
                if point in centres:
                    order.setdefault(point, len(order))
    return np.array(list(order), dtype=np.int64).reshape(-1, 3)


def match_faces(tets: np.ndarray) -> tuple[np.ndarray, int, int]:
    """Face neighbours by a dict of sorted vertex triples (see topology.match_faces)."""
    faces_of = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]
    seen: dict = {}
    neighbour = -np.ones((len(tets), 4), dtype=np.int64)
    overloaded = same_side = 0
    for t, tet in enumerate(tets):
        for k, f in enumerate(faces_of):
            face = [int(tet[i]) for i in f]
            key = tuple(sorted(face))
            if key not in seen:
                seen[key] = (t, k, face)
                continue
            ot, ok, other = seen[key]
            if ot < 0 or neighbour[ot, ok] != -1:
                overloaded += 1
                seen[key] = (-1, -1, other)
                continue
            neighbour[ot, ok], neighbour[t, k] = t, ot
            rotations = [other, other[1:] + other[:1], other[2:] + other[:2]]
            same_side += face in rotations
    return neighbour, overloaded, same_side


def surface_edges(faces: np.ndarray) -> tuple[int, int, int]:
    """(edges, vertices used, edges not in exactly two faces of opposite orientation) by a dict."""
    seen: dict = {}
    for f in faces:
        for j in range(3):
            p, q = int(f[j]), int(f[(j + 1) % 3])
            count, forward = seen.get((min(p, q), max(p, q)), (0, 0))
            seen[(min(p, q), max(p, q))] = (count + 1, forward + (p < q))
    bad = sum(1 for count, forward in seen.values() if count != 2 or forward != 1)
    return len(seen), len({int(v) for v in np.ravel(faces)}), bad


def face_components(faces: np.ndarray) -> int:
    """Connected components of triangles joined through shared vertices, by merging vertex
    sets."""
    group: dict = {}
    for f in np.asarray(faces).tolist():
        merged = {v for v in f}
        for v in f:
            merged |= group.get(v, set())
        for v in merged:
            group[v] = merged
    return len({id(g) for g in group.values()})


def nonmanifold_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Mask (V,) of the vertices whose link (faces (v, p, q) as edges p -> q) is not one
    cycle through distinct vertices, by dictionaries (see topology.nonmanifold_vertices)."""
    links: dict = {}
    for f in np.asarray(faces).tolist():
        for j in range(3):
            links.setdefault(f[j], []).append((f[(j + 1) % 3], f[(j + 2) % 3]))
    bad = np.zeros(n_vertices, dtype=bool)
    for v, edges in links.items():
        after = dict(edges)
        if len(after) != len(edges) or sorted(after) != sorted(q for _, q in edges):
            bad[v] = True
            continue
        cur, steps = edges[0][0], 0
        while True:
            cur, steps = after[cur], steps + 1
            if cur == edges[0][0]:
                break
        bad[v] = steps != len(edges)
    return bad


def stuffed_boundary(tets: np.ndarray, core: np.ndarray) -> np.ndarray:
    """Faces (F, 3) without a face neighbour (match_faces) and without a core vertex, in order
    of tet and face (see repair.stuffed_boundary)."""
    faces_of = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]
    neighbour, _, _ = match_faces(tets)
    out = [[int(tets[t, i]) for i in faces_of[k]] for t in range(len(tets)) for k in range(4)
           if neighbour[t, k] < 0 and not core[tets[t, faces_of[k]]].any()]
    return np.array(out, dtype=np.int64).reshape(-1, 3)


def star_partners(tets: np.ndarray, star: list[int], v: int) -> dict[tuple[int, int], int]:
    """{(i, k): j} for tet star[i] and each vertex k of it other than v: the smallest index
    j != i of a tet of star holding the face through v opposite k (the other two vertices
    and v), -1 if none; every pair of tets compared vertex by vertex."""
    out = {}
    for i, t in enumerate(star):
        for k in range(4):
            if tets[t, k] == v:
                continue
            face = set(tets[t].tolist()) - {int(tets[t, k])}
            out[(i, k)] = next((j for j, o in enumerate(star) if j != i and face <= set(tets[o].tolist())), -1)
    return out


def repair_pinches(tets: np.ndarray, bad, rank=None, checked: set | None = None) -> np.ndarray:
    """Alive mask (M,) of paroct.repair's worklist repair, by dictionaries; checked, if given,
    gets every vertex the worklist checks.

    rank (V,): the order of the vertices (default: their ids).  A stack of vertices starts
    with ``bad`` in ascending rank (the last popped first).  A vertex's live star splits into
    pieces joined through faces containing it; the live faces through it without a live
    partner give link edges p -> q (faces oriented outward, rotated to start at the vertex).
    If the link edges do not form one closed cycle, every piece but the largest goes (ties:
    the piece holding the tet whose other three vertices' sorted ranks come first), or the
    whole star if it is one piece; the vertices of removed tets not on the stack are pushed,
    in ascending rank.
    """
    rank = list(range(int(tets.max()) + 1)) if rank is None else [int(r) for r in rank]
    faces_of = [(1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1)]
    star: dict = {}
    holders: dict = {}
    for t, tet in enumerate(tets.tolist()):
        for v in tet:
            star.setdefault(v, []).append(t)
        for f in faces_of:
            holders.setdefault(frozenset(tet[i] for i in f), []).append(t)
    alive = np.ones(len(tets), dtype=bool)
    work = sorted((int(v) for v in bad), key=lambda v: rank[v])
    queued = set(work)
    while work:
        v = work.pop()
        queued.discard(v)
        if checked is not None:
            checked.add(v)
        live = [t for t in star.get(v, []) if alive[t]]
        piece = {t: t for t in live}

        def root(t):
            while piece[t] != t:
                t = piece[t]
            return t

        link = []
        for t in live:
            tet = tets[t].tolist()
            for f in faces_of:
                face = [tet[i] for i in f]
                if v not in face:
                    continue
                partners = [o for o in holders[frozenset(face)] if o != t and alive[o]]
                if partners:
                    a, b = root(t), root(partners[0])
                    piece[max(a, b)] = min(a, b)
                    continue
                i = face.index(v)
                link.append((face[(i + 1) % 3], face[(i + 2) % 3]))
        if not link:
            continue
        nxt = dict(link)
        if len(nxt) == len(link):
            cur, steps = link[0][0], 0
            while cur in nxt and steps <= len(link):
                cur, steps = nxt[cur], steps + 1
                if cur == link[0][0]:
                    break
            if steps == len(link) and cur == link[0][0]:
                continue
        roots = [root(t) for t in live]
        sizes = {r: roots.count(r) for r in roots}

        def tet_key(t, v=v):
            return sorted(rank[w] for w in tets[t].tolist() if w != v)

        largest = [t for t, r in zip(live, roots) if sizes[r] == max(sizes.values())]
        keep = roots[live.index(min(largest, key=tet_key))]
        pushed = []
        for t, r in zip(live, roots):
            if len(sizes) == 1 or r != keep:
                if alive[t]:
                    alive[t] = False
                    for w in tets[t].tolist():
                        if w not in queued:
                            pushed.append(w)
                            queued.add(w)
        work.extend(sorted(pushed, key=lambda w: rank[w]))
    return alive


def star_violation(lattice_points, coords, tets, inside, cuts, targets, star, bound, first_centre=None) -> float:
    """Worst violation of bound (degrees) over the tets stuffing gives the lattice tets star
    (indices into tets) with these warps, by stuffing just them and measuring every tet; 180
    if one is folded or flat (an angle of 0 or 180 degrees).  The twin of stuffing._star_score."""
    from paroct.quality import tet_quality
    from paroct.stuffing import stuff

    points, out, _ = stuff(lattice_points, coords, tets[star], inside, cuts, targets, flat_ok=True,
                           first_centre=first_centre)
    q = tet_quality(points, out)
    if np.any(q.volume <= 0) or np.any(q.min_dihedral <= 0) or np.any(q.max_dihedral >= 180):
        return 180.0
    if out.shape[0] == 0:
        return 0.0
    return float(max(0.0, (bound[0] - q.min_dihedral).max(), (q.max_dihedral - bound[1]).max()))


def chord_volumes(points, faces, point_faces, surface_vertices, surface_faces) -> np.ndarray:
    """Twin of check.chord_volumes, face by face: -area / 24 x the sum over the edges p -> q of
    (n_q - n_p) . (q - p), n the unit normal of the surface triangle each vertex lies on; 0
    for a face with a vertex on none (-1)."""
    out = np.zeros(len(faces))
    for f, face in enumerate(faces):
        if min(point_faces[v] for v in face) < 0:
            continue
        normals = [np.array(unit_normal(*surface_vertices[surface_faces[point_faces[v]]])) for v in face]
        turn = sum(float(np.dot(normals[(j + 1) % 3] - normals[j], points[face[(j + 1) % 3]] - points[face[j]]))
                   for j in range(3))
        a, b, c = (points[v] for v in face)
        out[f] = -0.5 * float(np.linalg.norm(np.cross(b - a, c - a))) * turn / 24.0
    return out


def far_from_points(queries: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """Mask of the queries with no point within radius: every pair measured."""
    if points.shape[0] == 0:
        return np.ones(queries.shape[0], dtype=bool)
    d = np.sqrt(((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2))
    return d.min(axis=1) > radius


def cut_edges(tets: np.ndarray, inside: np.ndarray, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(starts, ends, directions) of the distinct tet edges whose ends differ in class, numbered
    in order of first occurrence (tet by tet, edges (0,1) (0,2) (0,3) (1,2) (1,3) (2,3)), each
    from its end whose coordinates come first as tuples (x, y, z), then by id; direction: index in
    EDGE_DIRECTIONS of a unit lattice edge, -1 otherwise.  A dict on the sorted pair."""
    from paroct.frame import EDGE_DIRECTIONS

    seen: dict[tuple[int, int], int] = {}
    starts, ends, dirs = [], [], []
    for tet in tets.tolist():
        for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
            p, q = tet[i], tet[j]
            if inside[p] == inside[q] or (min(p, q), max(p, q)) in seen:
                continue
            seen[min(p, q), max(p, q)] = len(starts)
            if (tuple(coords[q]), q) < (tuple(coords[p]), p):
                p, q = q, p
            d = coords[q] - coords[p]
            hits = np.flatnonzero((EDGE_DIRECTIONS == d).all(axis=1))
            starts.append(p)
            ends.append(q)
            dirs.append(int(hits[0]) if hits.size else -1)
    return np.array(starts, dtype=np.int64), np.array(ends, dtype=np.int64), np.array(dirs, dtype=np.int64)


def warp_targets(coords: np.ndarray, starts, ends, fracs, spacing, h: float) -> np.ndarray:
    """Labelle & Shewchuk's warps as stuffing.warp_targets states them, edge by edge: alpha
    0.24999 for long lattice edges (two nonzero components), 0.41189 for short ones, 0.24999
    for edges off the lattices (a leaf of side 2 gcd(|d|)); each end's reach is alpha times
    min(1, its spacing / the edge's spacing); a vertex warps to its closest violating cut
    point, on ties the one whose edge's other end has the smaller coordinates as a tuple
    (then id)."""
    from math import gcd

    from paroct.frame import LATTICE_TO_SPACE

    best = np.full(coords.shape[0], np.inf)
    target = np.full(coords.shape[0], -1, dtype=np.int64)
    other = {}  # vertex -> its target edge's other end, as a tuple
    for e, (a, b, f) in enumerate(zip(starts.tolist(), ends.tolist(), fracs.tolist())):
        d = coords[b] - coords[a]
        s = int(np.abs(d).max())
        on_lattice = s > 0 and set(np.abs(d).tolist()) <= {0, s} and (np.all(d >= 0) or np.all(d <= 0))
        if on_lattice:
            alpha = 0.24999 if np.count_nonzero(d) == 2 else 0.41189
        else:
            alpha, s = 0.24999, 2 * gcd(*np.abs(d).tolist())
        length = float(np.linalg.norm(LATTICE_TO_SPACE @ d)) * h
        for v, w, t in ((a, b, f), (b, a, 1.0 - f)):
            if t < alpha * min(1.0, spacing[v] / s) and (t * length, tuple(coords[w]), w) < (best[v], *other.get(v, ((), 0))):
                best[v], target[v], other[v] = t * length, e, (tuple(coords[w]), w)
    return target


def group_by_vertex(vertices: np.ndarray, owners: np.ndarray) -> list[list[int]]:
    """For each vertex, the rows of owners (N, K) holding it: column by column, each
    column's rows in order."""
    return [[r for c in range(owners.shape[1]) for r in range(owners.shape[0]) if owners[r, c] == v]
            for v in vertices]


def retarget(vertices, visit, star_first, stars, option_first, options, tets, signs, targets, points, lattice_points,
             inside, coords, first_centre, table, prism, lo, hi, min_ratio, sweeps):
    """stuffing._retarget without skipping any vertex: each sweep scores every vertex's star,
    in the order visit, and, where it is bad, tries every option (in place, as _retarget)."""
    from paroct.stuffing import _set_warp, _star_score

    for _ in range(sweeps):
        moved = 0
        for i in visit:
            v = vertices[i]
            star = stars[star_first[i]:star_first[i + 1]]
            score = _star_score(star, tets, signs, points, lattice_points, coords, first_centre, table, prism, lo, hi)
            if score[0] <= 0 and score[1] >= min_ratio:
                continue
            current = best_target = targets[v]
            best = score
            for e in [*options[option_first[i]:option_first[i + 1]], -1]:
                if e == current:
                    continue
                _set_warp(v, e, signs, targets, points, lattice_points, inside)
                w, r = _star_score(star, tets, signs, points, lattice_points, coords, first_centre, table, prism, lo, hi)
                if w < best[0] or (w == best[0] and r > best[1]):
                    best, best_target = (w, r), e
            _set_warp(v, best_target, signs, targets, points, lattice_points, inside)
            moved += best_target != current
        if moved == 0:
            break


def first_winding_outside(keys: np.ndarray, fracs: np.ndarray, signs: np.ndarray, tie: float, key_bits: int) -> int:
    """rays.first_winding_outside on plain lists: split the crossings into rows (key >> key_bits),
    each row into runs of crossings less than tie cells after the one before, and sum the
    runs' signs along the row; the index of the first run that ends outside {0, 1}, or -1."""
    rows: dict[int, list[int]] = {}
    for i, key in enumerate(keys.tolist()):
        rows.setdefault(key >> key_bits, []).append(i)
    found = []
    for members in rows.values():
        runs = [[members[0]]]
        for a, b in zip(members, members[1:]):
            gap = float(int(keys[b]) - int(keys[a])) + (float(fracs[b]) - float(fracs[a]))
            if gap <= tie:
                runs[-1].append(b)
            else:
                runs.append([b])
        winding = 0
        for run in runs:
            winding += sum(int(signs[i]) for i in run)
            if winding not in (0, 1):
                found.append(run[0])
                break
    return min(found, default=-1)


def surface_patches(vertices: np.ndarray, faces: np.ndarray, feature_angle: float) -> np.ndarray:
    """Patch id (F,) from 1 of each triangle by a breadth-first search over an edge dict: across
    an edge when both unit normals exist and turn by less than feature_angle degrees, or when
    one triangle has zero area and the edge is its longest; numbered by first triangle."""
    normals, longest = [], []
    for f in np.asarray(faces).tolist():
        a, b, c = (np.asarray(vertices[i], dtype=float) for i in f)
        n = np.cross(b - a, c - a)
        length = float(np.linalg.norm(n))
        normals.append(n / length if length > 0 else None)
        lengths = [float(np.sum((np.asarray(vertices[f[(j + 1) % 3]]) - np.asarray(vertices[f[j]])) ** 2)) for j in range(3)]
        longest.append(int(np.argmax(lengths)))
    by_edge: dict = {}
    for i, f in enumerate(np.asarray(faces).tolist()):
        for j in range(3):
            by_edge.setdefault(frozenset((f[j], f[(j + 1) % 3])), []).append((i, j))
    neighbours: list = [[] for _ in range(len(faces))]
    for pair in by_edge.values():
        (f, j), (g, i) = pair
        smooth = (normals[f] is not None and normals[g] is not None
                  and math.degrees(math.acos(max(-1.0, min(1.0, float(normals[f] @ normals[g]))))) < feature_angle)
        if smooth or (normals[f] is None and longest[f] == j) or (normals[g] is None and longest[g] == i):
            neighbours[f].append(g)
            neighbours[g].append(f)
    labels = np.zeros(len(faces), dtype=np.int32)
    count = 0
    for start in range(len(faces)):
        if labels[start]:
            continue
        count += 1
        labels[start] = count
        todo = [start]
        while todo:
            for g in neighbours[todo.pop()]:
                if not labels[g]:
                    labels[g] = count
                    todo.append(g)
    return labels


def triangles_cross(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether triangles a and b (3, 3) cross: an edge of one passes through the other's
    interior with its ends strictly on both sides of that plane and the line strictly inside
    the three edges, with exact rational arithmetic."""
    from fractions import Fraction

    def orient(p, q, r, s):
        (bx, by, bz), (cx, cy, cz), (dx, dy, dz) = ([Fraction(u) - Fraction(v) for u, v in zip(w, p)] for w in (q, r, s))
        det = bx * (cy * dz - cz * dy) - by * (cx * dz - cz * dx) + bz * (cx * dy - cy * dx)
        return (det > 0) - (det < 0)

    def edge_through(p, q, t):
        sp, sq = orient(*t, p), orient(*t, q)
        if sp == 0 or sq == 0 or sp == sq:
            return False
        signs = {orient(p, q, t[i], t[(i + 1) % 3]) for i in range(3)}
        return len(signs) == 1 and 0 not in signs

    return any(edge_through(x[i], x[(i + 1) % 3], y) for x, y in ((a, b), (b, a)) for i in range(3))


def nearest_on_segments(point: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, float]:
    """The nearest point of any segment (starts[i], ends[i]) to point, and its distance:
    each segment sampled finely enough, then the best refined by the exact projection."""
    best, best_d = None, math.inf
    for a, b in zip(starts, ends):
        d = b - a
        dd = float(d @ d)
        t = 0.0 if dd == 0 else min(1.0, max(0.0, float((point - a) @ d) / dd))
        for s in (0.0, 1.0, t):
            q = a + s * d
            dist = float(np.linalg.norm(point - q))
            if dist < best_d:
                best, best_d = q, dist
    return best, best_d


def feature_curves(faces: np.ndarray, labels: np.ndarray) -> tuple[set, set]:
    """({(sorted edge, sorted label pair)} of the edges between two labels, {vertices with
    three or more labels}), by dictionaries of edges and vertices."""
    edge_faces: dict = {}
    for f, tri in enumerate(faces.tolist()):
        for j in range(3):
            edge_faces.setdefault(tuple(sorted((tri[j], tri[(j + 1) % 3]))), []).append(f)
    curves = {(e, tuple(sorted((int(labels[f]), int(labels[g]))))) for e, (f, g) in edge_faces.items()
              if labels[f] != labels[g]}
    around: dict = {}
    for f, tri in enumerate(faces.tolist()):
        for v in tri:
            around.setdefault(v, set()).add(int(labels[f]))
    return curves, {v for v, s in around.items() if len(s) >= 3}


def triangle_pieces(corners: np.ndarray, spacing: float) -> tuple[list[np.ndarray], list[int]]:
    """Strips by recursion: a triangle with an edge over spacing is cut by the lines parallel
    to its shortest edge (the first of equal ones, opposite corner a) at k = ceil(longest /
    spacing) (at least 2) equal steps along the other two, and each strip's triangles cut
    again.  Returns
    the pieces and the triangle of each, in order of triangle."""
    pieces, owner = [], []

    def cut(tri, t):
        opposite = [float(np.sum((tri[(j + 2) % 3] - tri[(j + 1) % 3]) ** 2)) for j in range(3)]
        if max(opposite) <= spacing * spacing:
            pieces.append(tri)
            owner.append(t)
            return
        a = int(np.argmin(opposite))
        k = max(2, math.ceil(math.sqrt(max(opposite)) / spacing))  # 1 when the root rounds to spacing
        pa, pb, pc = tri[a], tri[(a + 1) % 3], tri[(a + 2) % 3]
        p = [pa + (pb - pa) * i / k for i in range(k + 1)]
        q = [pa + (pc - pa) * i / k for i in range(k + 1)]
        for i in range(k):
            cut(np.array([p[i], p[i + 1], q[i + 1]]), t)
            if i > 0:
                cut(np.array([p[i], q[i + 1], q[i]]), t)

    for t, tri in enumerate(corners):
        cut(np.asarray(tri, dtype=float), t)
    return pieces, owner


def largest_principal_curvature(points: np.ndarray, normals: np.ndarray, weights: np.ndarray) -> float:
    """J's largest singular value for the normals fitted as n(x) = n0 + J (x - x0) over the
    points' two directions of largest spread, by weighted least squares spelled out: the
    tangent frame from the points' covariance, then J's 3 x 2 block from the normal equations."""
    w = weights / weights.sum()
    x0 = (w[:, None] * points).sum(axis=0)
    n0 = (w[:, None] * normals).sum(axis=0)
    dp, dn = points - x0, normals - n0
    cov = sum(wi * np.outer(d, d) for wi, d in zip(w, dp))
    lam, vec = np.linalg.eigh(cov)
    tangent = vec[:, 1:]  # the two directions of largest spread
    q = dp @ tangent  # (K, 2) tangent coordinates
    a = sum(wi * np.outer(qi, qi) for wi, qi in zip(w, q))
    b = sum(wi * np.outer(ni, qi) for wi, ni, qi in zip(w, dn, q))
    return float(np.linalg.svd(b @ np.linalg.inv(a), compute_uv=False)[0])


def touching_leaves(keys: np.ndarray, levels: np.ndarray, first: int, end: int) -> list[int]:
    """Leaves outside keys[first:end] whose closed boxes meet the closed box of one in it:
    every pair of boxes compared, anchors decoded bit by bit."""
    def box(i):
        key = int(keys[i])
        anchor = [sum(((key >> (3 * b + a)) & 1) << b for b in range(MAX_LEVEL)) for a in range(3)]
        return anchor, 1 << (MAX_LEVEL - int(levels[i]))

    own = [box(i) for i in range(first, end)]
    out = []
    for j in range(len(keys)):
        if first <= j < end:
            continue
        b, s = box(j)
        if any(all(b[k] <= a[k] + t and a[k] <= b[k] + s for k in range(3)) for a, t in own):
            out.append(j)
    return out


def faces_near_interval(snapped: np.ndarray, faces: np.ndarray, bits: int, levels: int, margin: int, first: int,
                        end: int) -> list[int]:
    """The triangles whose box of closed finest cells, grown by margin cells, holds a cell of
    Morton key in [first, end): every cell of the box keyed and compared."""
    out, top = [], (1 << levels) - 1
    for f, tri in enumerate(faces):
        pts = snapped[tri]
        lo = [max(int(pts[:, k].min()) // (1 << bits) - 1 - margin, 0) for k in range(3)]
        hi = [min(int(pts[:, k].max()) // (1 << bits) + margin, top) for k in range(3)]
        cells = [(x, y, z) for x in range(lo[0], hi[0] + 1) for y in range(lo[1], hi[1] + 1)
                 for z in range(lo[2], hi[2] + 1)]
        shift = MAX_LEVEL - levels
        if any(first <= morton_key(x << shift, y << shift, z << shift) < end for x, y, z in cells):
            out.append(f)
    return out


def cells_near_interval(cells: np.ndarray, levels: int, first: int, end: int) -> list[bool]:
    """For each finest cell (K, 3) (cell coordinates of a frame of ``levels`` levels): whether
    a cell of key in [first, end) is at Chebyshev distance at most 1 from it."""
    shift, n = MAX_LEVEL - levels, 1 << levels
    owned = [(x, y, z) for x in range(n) for y in range(n) for z in range(n)
             if first <= morton_key(x << shift, y << shift, z << shift) < end]
    return [any(max(abs(int(c[0]) - x), abs(int(c[1]) - y), abs(int(c[2]) - z)) <= 1 for x, y, z in owned)
            for c in cells]


def faces_over_rows(snapped: np.ndarray, faces: np.ndarray, bits: int, basis: np.ndarray,
                    points: np.ndarray) -> list[int]:
    """The triangles whose row coordinates (basis rows 1 and 2 of the snapped vertices, over
    2**bits) span a box holding the row of one of the lattice points."""
    rows = {(int(r[0]), int(r[1])) for r in points @ basis[1:].T}
    out = []
    for f, tri in enumerate(faces):
        proj = snapped[tri] @ basis[1:].T / float(1 << bits)
        lo, hi = proj.min(axis=0), proj.max(axis=0)
        if any(lo[0] <= a <= hi[0] and lo[1] <= b <= hi[1] for a, b in rows):
            out.append(f)
    return out


def owned_ids(keys, owners):
    """owners.owned_ids by a dict: every distinct (owner, key) pair, sorted, numbered in
    that order; returns (the ids of each piece's keys, the count)."""
    pairs = sorted({(int(o), int(k)) for piece_keys, piece_owners in zip(keys, owners)
                    for k, o in zip(piece_keys, piece_owners)})
    index = {pair: i for i, pair in enumerate(pairs)}
    return [[index[(int(o), int(k))] for k, o in zip(piece_keys, piece_owners)]
            for piece_keys, piece_owners in zip(keys, owners)], len(pairs)


def pinch_clusters(tets, bad, rings: int) -> list[list[int]]:
    """The bad vertices grouped as repair.local_repair groups them, by sets: the tets touching
    the vertices within ``rings`` edges of a bad one, joined through shared vertices; each
    group ascending, the groups by their first vertex."""
    rows = [set(map(int, t)) for t in np.asarray(tets).tolist()]
    region = set(int(v) for v in bad)
    for _ in range(rings):
        region = set().union(*[r for r in rows if r & region])
    sub = [r for r in rows if r & region]
    groups: list[set] = []
    for r in sub:  # merge every group sharing a vertex with this tet
        touching_groups = [g for g in groups if g & r]
        merged = set(r).union(*touching_groups)
        groups = [g for g in groups if not g & r] + [merged]
    clusters = [sorted(int(v) for v in bad if v in g) for g in groups]
    return sorted((c for c in clusters if c), key=lambda c: c[0])


def unshared_faces(faces: np.ndarray) -> np.ndarray:
    """The faces (F, 3) whose vertex set no other face has, by a dict of sorted triples (see
    range_pinches: the mesh boundary from the ranges' boundaries joined)."""
    count: dict = {}
    for f in np.asarray(faces).tolist():
        key = tuple(sorted(f))
        count[key] = count.get(key, 0) + 1
    return np.array([f for f in np.asarray(faces).tolist() if count[tuple(sorted(f))] == 1]).reshape(-1, 3)


def prism_triangulations() -> np.ndarray:
    """stuffing.PRISM_TETS by brute force: for each choice of quad diagonals (bit i of the index:
    0 joins bottom i to top i+1, 1 joins bottom i+1 to top i; bottom 0, 1, 2, top 3, 4, 5, 3 + i
    above i), the first triple of tets (in itertools' order) with no tet holding a whole quad,
    every face shared by at most two tets and those held once exactly the prism's boundary
    split along the diagonals; -1 rows where none does (the two cyclic choices)."""
    import itertools

    bottom, top = [0, 1, 2], [3, 4, 5]
    quads = [(bottom[i], bottom[(i + 1) % 3], top[(i + 1) % 3], top[i]) for i in range(3)]
    table = np.full((8, 3, 4), -1, dtype=np.int64)
    for bits in range(8):
        diagonals = [(q[0], q[2]) if not (bits >> i) & 1 else (q[1], q[3]) for i, q in enumerate(quads)]
        boundary = {frozenset(bottom), frozenset(top)}
        for q, d in zip(quads, diagonals):
            for other in (x for x in q if x not in d):
                boundary.add(frozenset(d + (other,)))
        for triple in itertools.combinations(itertools.combinations(range(6), 4), 3):
            if any(set(q) <= set(t) for t in triple for q in quads):
                continue  # a tet holding a whole (planar) quad is flat
            count: dict = {}
            for t in triple:
                for f in itertools.combinations(t, 3):
                    count[frozenset(f)] = count.get(frozenset(f), 0) + 1
            if {f for f, c in count.items() if c == 1} == boundary and max(count.values()) <= 2:
                table[bits] = triple
                break
    return table
