"""Load and validate the closed surface of the solid to mesh.

The triangles are welded and checked here: every edge in exactly two faces of opposite
orientation (sheets that welding joined along an edge taken apart again), positive enclosed
volume.  A surface of one shell (faces joined through
edges) is the solid as it is.  When a file holds several shells, manifold3d checks each
and unions the overlapping ones (shells of negative volume are cavities and are
subtracted), and everything downstream works on the manifold's triangles.  Either way
they are closed and consistently oriented (outward normals, positive volume).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Union

import manifold3d
import numba as nb
import numpy as np

from .errors import ParoctError
from .readers import binary_stl_count_note, read_surface_file
from .topology import link_fans, union, vertex_links

SurfaceSource = Union[str, os.PathLike, manifold3d.Manifold, tuple]


@dataclass(frozen=True)
class Surface:
    """A closed, oriented, manifold triangle surface bounding a solid.

    vertices: (V, 3) float64, model units.  faces: (F, 3) int32, counter-clockwise seen
    from outside.  volume, area: of the solid, model units.  genus: of the whole
    boundary (sum over components).  components: number of boundary shells.
    face_groups: (F,) int32, the named group 0 .. G - 1 of each triangle (the solids of an
    ASCII STL, the groups of an OBJ: readers.SurfaceFile), or None; group_names: the G
    names.  repairs: what surface_from_arrays mended (one shell's triangles turned).
    bbox_min, bbox_max: (3,) float64 corners of the vertices' bounding box (derived).
    """

    vertices: np.ndarray
    faces: np.ndarray
    volume: float
    area: float
    genus: int
    components: int
    face_groups: np.ndarray | None = field(default=None, repr=False, compare=False)
    group_names: tuple[str, ...] = field(default=(), compare=False)
    #: What loading mended in the input (triangles turned to face out), for the mesh's warnings.
    repairs: tuple[str, ...] = field(default=(), compare=False)
    bbox_min: np.ndarray = field(init=False, repr=False, compare=False)
    bbox_max: np.ndarray = field(init=False, repr=False, compare=False)
    #: Set by load_surface on the surfaces it built; one made by hand is validated when meshed.
    validated: bool = field(default=False, init=False, repr=False, compare=False)

    def __post_init__(self):
        _check_shapes(self.vertices, self.faces)
        # Stages ask for the box a dozen times per mesh; a reduction over the vertices each time
        # cost small parts several per cent.
        lo, hi, _ = bounding_box(np.ascontiguousarray(self.vertices, dtype=np.float64))
        for name, corner in (("bbox_min", lo), ("bbox_max", hi)):
            corner.setflags(write=False)
            object.__setattr__(self, name, corner)
        groups, names = _checked_groups(self.face_groups, self.group_names, np.shape(self.faces)[0], "Surface")
        object.__setattr__(self, "face_groups", groups)
        object.__setattr__(self, "group_names", names)

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bbox_max - self.bbox_min))

    def to_manifold(self) -> manifold3d.Manifold:
        """The solid as a manifold3d.Manifold (built anew on each call)."""
        return _to_manifold(self.vertices, self.faces)


def _check_shapes(vertices, faces) -> None:
    """ParoctError, stating the shapes and types, unless vertices are (V, 3) real numbers and
    faces (F, 3) integers, as arrays or what numpy reads as such (a Surface made by hand;
    load_surface checks what it reads)."""
    arrays: list[np.ndarray | None] = []
    for value in (vertices, faces):
        try:
            arrays.append(np.asarray(value))
        except (ValueError, TypeError):  # ragged lists
            arrays.append(None)
    v, f = arrays
    if v is None or f is None or v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 \
            or not (np.issubdtype(v.dtype, np.integer) or np.issubdtype(v.dtype, np.floating)) \
            or not (np.issubdtype(f.dtype, np.integer) or f.size == 0):
        raise ParoctError(f"Surface: vertices {_described(v, vertices)}, faces {_described(f, faces)}; expected "
                          "(V, 3) real numbers and (F, 3) integers (load_surface builds a Surface from arrays)")


def _described(array: np.ndarray | None, value) -> str:
    """What an error message says of a value: its shape and dtype as an array, else its type."""
    return f"shape {array.shape} {array.dtype}" if array is not None else f"of type {type(value).__name__}"


def _checked_groups(face_groups, group_names, n_faces: int, label: str) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """face_groups as a read-only (F,) int32 array with every value naming one of group_names
    (a tuple of str), or (None, ()); ParoctError, stating the numbers, otherwise."""
    if face_groups is None:
        if len(group_names):
            raise ParoctError(f"{label}: {len(group_names)} group names but no face_groups")
        return None, ()
    names = () if isinstance(group_names, str) else tuple(group_names)  # a str is no sequence of names
    if isinstance(group_names, str) or not all(isinstance(name, str) for name in names):
        raise ParoctError(f"{label}: group_names must be a sequence of strings (one a group)")
    groups = np.asarray(face_groups)
    if groups.shape != (n_faces,) or (groups.size and not np.issubdtype(groups.dtype, np.integer)):
        raise ParoctError(f"{label}: face_groups.shape = {groups.shape}, dtype {groups.dtype}; expected ({n_faces},) integers")
    if groups.size and (groups.min() < 0 or groups.max() >= len(names)):
        raise ParoctError(f"{label}: face_groups span {groups.min()} .. {groups.max()}, but len(group_names) = {len(names)}")
    groups = groups.astype(np.int32)
    groups.setflags(write=False)
    return groups, names


def _weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Merge exactly coincident vertices (-0.0 equals 0.0), drop faces with a repeated vertex
    and the vertices no face uses.  Vertices are numbered in the order the kept faces first
    use them, so the result depends only on the faces and their corner positions.  vertices:
    float32 (as binary STL stores them) or any type converted to float64.  Returns
    (vertices (V, 3) float64, faces (F, 3) int32, flag); the flag is False (and the arrays
    empty) if a corner has a NaN or infinite coordinate."""
    single = vertices.dtype == np.float32
    vertices = np.require(vertices, np.float32 if single else np.float64, ["C_CONTIGUOUS", "WRITEABLE"])
    return _weld_kernel(vertices, vertices.view(np.uint32 if single else np.uint64),
                        np.ascontiguousarray(faces, dtype=np.int64))


def _used_only(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """_weld without the merge: the vertices faces use, in index order, and the faces with no
    repeated vertex, renumbered; the flag is False if a used vertex is not finite."""
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])]
    used = np.zeros(vertices.shape[0], dtype=bool)
    used[faces] = True
    new_id = np.cumsum(used, dtype=np.int64) - 1
    vertices = np.ascontiguousarray(vertices[used], dtype=np.float64)
    return vertices, new_id[faces].astype(np.int32), bool(np.isfinite(vertices).all())


@nb.njit(cache=True, inline="always")
def _coordinate_bits(bits, v, i):
    """The bits (uint64) of coordinate i of vertex v, float32 or float64 (bits of that width),
    -0.0 read as +0.0 (equal values, equal bits: all bits but the sign bit are zero)."""
    b = np.uint64(bits[v, i])
    return np.uint64(0) if b << np.uint64(64 - 8 * bits.itemsize + 1) == 0 else b


@nb.njit(cache=True)
def _weld_kernel(vertices, bits, faces):
    """Open-addressing hash of the corners' bit patterns (one pass over the faces), then the
    compaction to the kept faces' vertices.

    The table has at least 4 slots a face: a closed surface has about F / 2 vertices, so it
    is an eighth full, and even a soup of unshared corners (3 F) leaves a quarter free.  It
    and the corner numbers are int32 (at most MAX_FACES faces, which surface_from_arrays
    checks): these pages are first touched here, at a cost per page."""
    nf = faces.shape[0]
    size = 16
    while size < 4 * nf:
        size *= 2
    table = np.full(size, -1, dtype=np.int32)
    first = np.empty(3 * nf, dtype=np.int32)  # the input vertex standing for each merged one
    # The merged vertices' bits, compared in place of the input's: merged ids come in the
    # faces' order, so those a face matches were mostly made by the faces just before it.
    first_bits = np.empty((3 * nf, 3), dtype=np.uint64)
    merged = np.empty((nf, 3), dtype=np.int32)
    m = 0
    for f in range(nf):
        for k in range(3):
            v = faces[f, k]
            b0 = _coordinate_bits(bits, v, 0)
            b1 = _coordinate_bits(bits, v, 1)
            b2 = _coordinate_bits(bits, v, 2)
            h = (b0 * np.uint64(0x9E3779B97F4A7C15)) ^ (b1 * np.uint64(0xC2B2AE3D27D4EB4F)) \
                ^ (b2 * np.uint64(0x165667B19E3779F9))
            slot = np.int64((h ^ (h >> np.uint64(29))) & np.uint64(size - 1))
            while True:
                j = table[slot]
                if j < 0:  # a new position: the only corners whose finiteness is not known yet
                    if not (np.isfinite(vertices[v, 0]) and np.isfinite(vertices[v, 1]) and np.isfinite(vertices[v, 2])):
                        return np.empty((0, 3), dtype=np.float64), np.empty((0, 3), dtype=np.int32), False
                    table[slot] = m
                    first[m] = v
                    first_bits[m, 0] = b0
                    first_bits[m, 1] = b1
                    first_bits[m, 2] = b2
                    merged[f, k] = m
                    m += 1
                    break
                if first_bits[j, 0] == b0 and first_bits[j, 1] == b1 and first_bits[j, 2] == b2:
                    merged[f, k] = j
                    break
                slot = (slot + 1) & (size - 1)
    new_id = np.full(m, -1, dtype=np.int32)
    out_faces = np.empty((nf, 3), dtype=np.int32)
    out_vertices = np.empty((m, 3), dtype=np.float64)
    n_faces = 0
    n_vertices = 0
    for f in range(nf):
        a = merged[f, 0]
        b = merged[f, 1]
        c = merged[f, 2]
        if a == b or b == c or c == a:
            continue
        for k in range(3):
            j = merged[f, k]
            if new_id[j] < 0:
                new_id[j] = n_vertices
                for i in range(3):  # not a row assignment: its shape check compiles numba's string formatting
                    out_vertices[n_vertices, i] = vertices[first[j], i] + 0.0  # -0.0 + 0.0 is +0.0
                n_vertices += 1
            out_faces[n_faces, k] = new_id[j]
        n_faces += 1
    return out_vertices[:n_vertices], out_faces[:n_faces], True


@nb.njit(cache=True)
def bounding_box(vertices):
    """Corners (3,) of the box of vertices (V >= 1, 3) and the largest coordinate magnitude:
    one pass (numpy's reductions along axis 0 of an (V, 3) array stride, 30 ns a vertex).
    The extremes are held in scalars and updated by selects, not by branches into (3,)
    arrays: 2 ms -> 1.2 ms on 600 k points, the same result (a NaN coordinate after the first
    vertex is never taken; the first vertex's stays)."""
    lo0 = hi0 = vertices[0, 0]
    lo1 = hi1 = vertices[0, 1]
    lo2 = hi2 = vertices[0, 2]
    for v in range(1, vertices.shape[0]):
        x, y, z = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        lo0 = x if x < lo0 else lo0
        hi0 = x if x > hi0 else hi0
        lo1 = y if y < lo1 else lo1
        hi1 = y if y > hi1 else hi1
        lo2 = z if z < lo2 else lo2
        hi2 = z if z > hi2 else hi2
    lo = np.array([lo0, lo1, lo2])
    hi = np.array([hi0, hi1, hi2])
    largest = 0.0
    for i in range(3):
        largest = max(largest, abs(lo[i]), abs(hi[i]))
    return lo, hi, largest


@nb.njit(cache=True)
def _edge_report(start, nxt):
    """Counts of (boundary edges, edges in more than two faces, edges whose two faces run
    them the same way) of the faces around every vertex (vertex_links' start, nxt).

    Edge {a, b} is run a -> b by the faces in a's list with nxt == b, b -> a by those in b's;
    it is counted once, at its first a -> b slot of its smaller end that runs it (or of the
    other end, if no face runs it from the smaller)."""
    boundary = 0
    nonmanifold = 0
    flipped = 0
    for v in range(start.shape[0] - 1):
        for s in range(start[v], start[v + 1]):
            w = nxt[s]
            seen_before = False
            for t in range(start[v], s):
                if nxt[t] == w:
                    seen_before = True
                    break
            if seen_before:
                continue
            back = 0
            for t in range(start[w], start[w + 1]):
                if nxt[t] == v:
                    back += 1
            if w < v and back > 0:
                continue  # counted from w
            ahead = 0
            for t in range(s, start[v + 1]):
                if nxt[t] == w:
                    ahead += 1
            count = ahead + back
            if count == 1:
                boundary += 1
            elif count > 2:
                nonmanifold += 1
            elif ahead != 1:
                flipped += 1
    return boundary, nonmanifold, flipped


def _shell_topology(faces: np.ndarray, n_vertices: int) -> tuple[int, int, int, int, np.ndarray]:
    """Edge report, fans and shells of a surface.

    Returns (boundary edges, edges in more than two faces, edges whose two faces run them the
    same way; fans (total over vertices), shell label (F,) of every face, 0..S-1 in order of
    first face).  The fans and shells are computed only if every edge joins two
    consistently oriented faces (else 0 and an empty label array).  A fan is a cycle of the
    faces around a vertex, joined through their edges at it (a vertex where sheets touch
    has several); a shell is a set of faces joined through edges.  With fans counted as
    vertices, V - E + F of each shell is 2 - 2 genus.

    Every face holding edge {v, w} is in v's list, running it v -> w (nxt == w) or w -> v
    (prv == w): the edges are all checked there.  Each edge of a good surface is run once
    each way, so for every slot s of v exactly one slot has nxt == nxt[s] (s itself) and
    exactly one, the face after s around v, has prv == nxt[s].  Any other count makes a
    bad edge, and _edge_report counts them.
    """
    start, face_of, nxt, prv = vertex_links(faces, n_vertices)
    following = np.empty(nxt.shape[0], dtype=np.int32)  # the slot of the face after s around its vertex
    fans = np.empty(n_vertices, dtype=np.int32)
    # A parallel kernel called from Python, not from another cached kernel: numba issue #8578
    # (such a call segfaults when loaded from the cache).
    link_fans(start, nxt, prv, following, fans)
    fewest = fans.min()
    if fewest < 0:
        return (*_edge_report(start, nxt), 0, np.empty(0, dtype=np.int64))
    if fewest == 1 and fans.max() == 1:
        return 0, 0, 0, n_vertices, _shells_of_one_fan_vertices(start, nxt, faces)
    return 0, 0, 0, int(fans.sum(dtype=np.int64)), _shells(start, face_of, nxt, following)


@nb.njit(cache=True)
def _shells_of_one_fan_vertices(start, nxt, faces):
    """_shells of a surface whose every vertex is used and has one fan: then the faces around
    a vertex are joined through their edges, so two faces are joined if and only if their
    vertices are linked through edges, and the shells are the components of the edge graph
    (nxt, by vertex).  A search over that graph reads each vertex's slots once; the union
    of faces through edges (_shells) reads parents at random, and took twice as long on
    armadillo."""
    n = start.shape[0] - 1
    component = np.full(n, -1, dtype=np.int32)
    stack = np.empty(n, dtype=np.int32)
    n_components = 0
    for root in range(n):
        if component[root] >= 0:
            continue
        component[root] = n_components
        stack[0] = root
        top = 1
        while top > 0:
            top -= 1
            v = stack[top]
            for s in range(start[v], start[v + 1]):
                w = nxt[s]
                if component[w] < 0:
                    component[w] = n_components
                    stack[top] = w
                    top += 1
        n_components += 1
    # Shells numbered in order of their first face, as _shells does.
    shell_of = np.full(n_components, -1, dtype=np.int64)
    label = np.empty(faces.shape[0], dtype=np.int64)
    n_shells = 0
    for f in range(faces.shape[0]):
        c = component[faces[f, 0]]
        if shell_of[c] < 0:
            shell_of[c] = n_shells
            n_shells += 1
        label[f] = shell_of[c]
    return label


@nb.njit(cache=True)
def _shells(start, face_of, nxt, following):
    """Shell label (F,) of every face of a surface whose every edge joins two consistently
    oriented faces, 0..S-1 in order of first face: the faces joined through edges, the two
    faces of edge {v, nxt[s]} being face_of[s] and face_of[following[s]] (link_fans)."""
    nf = face_of.shape[0] // 3
    parent = np.arange(nf)
    for v in range(start.shape[0] - 1):
        for s in range(start[v], start[v + 1]):
            if v < nxt[s]:  # the edge's two faces, joined once (at its smaller end)
                union(parent, face_of[s], face_of[following[s]])
    label = np.empty(nf, dtype=np.int64)
    root_label = np.full(nf, -1, dtype=np.int64)
    n_shells = 0
    for f in range(nf):
        r = f
        while parent[r] != r:
            r = parent[r]
        if root_label[r] < 0:
            root_label[r] = n_shells
            n_shells += 1
        label[f] = root_label[r]
    return label


@nb.njit(cache=True)
def _volume_area(vertices, faces, scale):
    """Enclosed volume (signed: positive for outward faces) and area of a closed surface,
    summed about its first vertex (small numbers where the surface lies far from the origin),
    over coordinates times ``scale``, a power of two (exact) that brings the part near unit
    size: a squared cross product underflowed for parts of 1e-90, overflowed at 1e80."""
    ox, oy, oz = vertices[0, 0], vertices[0, 1], vertices[0, 2]
    volume = 0.0
    area = 0.0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        ax, ay, az = (vertices[a, 0] - ox) * scale, (vertices[a, 1] - oy) * scale, (vertices[a, 2] - oz) * scale
        ux, uy, uz = (vertices[b, 0] - ox) * scale - ax, (vertices[b, 1] - oy) * scale - ay, (vertices[b, 2] - oz) * scale - az
        wx, wy, wz = (vertices[c, 0] - ox) * scale - ax, (vertices[c, 1] - oy) * scale - ay, (vertices[c, 2] - oz) * scale - az
        nx = uy * wz - uz * wy
        ny = uz * wx - ux * wz
        nz = ux * wy - uy * wx
        volume += ax * nx + ay * ny + az * nz
        area += np.sqrt(nx * nx + ny * ny + nz * nz)
    return volume / 6.0 / scale / scale / scale, area / 2.0 / scale / scale


def _split_touching_sheets(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The surface with sheets that touch along edges taken apart, or None if some edge
    cannot be: (vertices (V', 3) float64, faces (F, 3) int32, the same triangles).

    Welding coincident vertices joins solids that touch along an edge (two cubes sharing
    one, a strut lattice, a CAD assembly's bodies) into edges of 4, 6, ... faces.  Around
    such an edge the faces of a closed, consistently oriented surface alternate in
    direction, and each pair of neighbours bounds a wedge of solid or of space.  Pairing the
    two faces of every solid wedge (about the edge from its smaller vertex lo to its larger
    hi, a face running hi -> lo with the next face counter-clockwise) gives each edge two
    faces, and giving every fan of faces around a vertex its own copy of the vertex makes
    the surface a 2-manifold bounding the same solid: the touching sheets are kept apart, as
    manifold3d keeps them.

    Where no order about an edge pairs its faces (two neighbours run it the same way: solids
    that overlap there; or a face is flat, its third vertex on the edge's line), the k-th face
    running it one way is paired with the k-th running it the other.  Solids that overlap, or
    touch over an area with shared vertices (boxes stacked face to face, panels side by side),
    come apart into closed shells that may cross or touch there; the triangles are the same,
    and so is every point's winding number, so the union of the shells (surface_from_arrays)
    is the solid the surface bounds.  None if an edge's faces run it one way more often than
    the other.
    """
    new_vertices, new_faces, ok = _pair_and_split(np.ascontiguousarray(vertices, dtype=np.float64),
                                                  np.ascontiguousarray(faces, dtype=np.int32))
    return (new_vertices, new_faces) if ok else None


@nb.njit(cache=True)
def _half_edges_by_edge(faces, n_vertices):
    """Half-edge h = 3 f + k runs faces[f, k] -> faces[f, (k + 1) % 3]: its edge's key (3 F,),
    smaller end * n_vertices + larger, and the half-edges in order of keys (stable), so those
    of one edge are neighbours."""
    nf = faces.shape[0]
    keys = np.empty(3 * nf, dtype=np.int64)
    for f in range(nf):
        for k in range(3):
            p, q = np.int64(faces[f, k]), np.int64(faces[f, (k + 1) % 3])
            keys[3 * f + k] = min(p, q) * n_vertices + max(p, q)
    return keys, np.argsort(keys, kind="mergesort")


@nb.njit(cache=True)
def _pair_and_split(vertices, faces):
    """_split_touching_sheets' kernel: half-edge h = 3 f + k runs faces[f, k] -> faces[f, (k + 1) % 3]
    and starts at corner h; twins are paired by edge (about it, else in half-edge order), then
    corners joined through twins (union-find) become the new vertices, numbered in order of
    first corner."""
    nf = faces.shape[0]
    nv = np.int64(vertices.shape[0])
    keys, order = _half_edges_by_edge(faces, nv)
    twin = np.full(3 * nf, -1, dtype=np.int64)
    angle = np.empty(3 * nf)
    i = 0
    while i < 3 * nf:
        j = i + 1
        while j < 3 * nf and keys[order[j]] == keys[order[i]]:
            j += 1
        if (j - i) % 2:
            return np.empty((0, 3)), np.empty((0, 3), dtype=np.int32), False
        hi = keys[order[i]] % nv
        if not (_pair_by_angle(vertices, faces, order[i:j], keys[order[i]] // nv, hi, angle, twin)
                or _pair_in_order(faces, order[i:j], hi, twin)):
            return np.empty((0, 3)), np.empty((0, 3), dtype=np.int32), False
        i = j
    parent = np.arange(3 * nf)
    for h in range(3 * nf):
        t = twin[h]
        if h < t:  # h runs p -> q from corner h; t runs q -> p from corner t
            union(parent, h, 3 * (t // 3) + (t % 3 + 1) % 3)
            union(parent, 3 * (h // 3) + (h % 3 + 1) % 3, t)
    new_id = np.full(3 * nf, -1, dtype=np.int32)
    new_faces = np.empty((nf, 3), dtype=np.int32)
    new_vertices = np.empty((3 * nf, 3))
    m = 0
    for c in range(3 * nf):
        r = c
        while parent[r] != r:
            r = parent[r]
        if new_id[r] < 0:
            new_id[r] = m
            for i in range(3):  # not a row assignment: its shape check compiles numba's string formatting
                new_vertices[m, i] = vertices[faces[c // 3, c % 3], i]
            m += 1
        new_faces[c // 3, c % 3] = new_id[r]
    return new_vertices[:m], new_faces, True


@nb.njit(cache=True)
def _pair_by_angle(vertices, faces, around, lo, hi, angle, twin):
    """Pair the half-edges ``around`` (all on edge {lo, hi}) as twins, each face with the next
    about the edge on the solid's side (two faces: with each other); False, pairing nothing,
    if two faces run the edge the same way where they should alternate, or one is flat (its
    third vertex on the edge's line, where no angle orders it)."""
    n = around.shape[0]
    if n == 2:
        if (faces[around[0] // 3, around[0] % 3] == hi) == (faces[around[1] // 3, around[1] % 3] == hi):
            return False
        twin[around[0]], twin[around[1]] = around[1], around[0]
        return True
    d = vertices[hi] - vertices[lo]
    d = d / np.sqrt(np.sum(d * d))
    e1 = np.zeros(3)
    e2 = np.zeros(3)
    for s in range(n):
        h = around[s]
        w = vertices[faces[h // 3, (h % 3 + 2) % 3]] - vertices[lo]
        w = w - np.sum(w * d) * d
        length = np.sqrt(np.sum(w * w))
        if not length > 0:
            return False
        if s == 0:  # the first face's direction is angle 0
            e1 = w / length
            e2 = np.array([d[1] * e1[2] - d[2] * e1[1], d[2] * e1[0] - d[0] * e1[2],
                           d[0] * e1[1] - d[1] * e1[0]])
        angle[h] = np.arctan2(np.sum(w * e2), np.sum(w * e1))
    around = around[np.argsort(angle[around], kind="mergesort")]
    # A face running the edge hi -> lo has the solid just counter-clockwise of it (about
    # lo -> hi), one running lo -> hi just clockwise: they must alternate.
    down = faces[around[0] // 3, around[0] % 3] == hi
    for s in range(n):
        if (faces[around[s] // 3, around[s] % 3] == hi) != (down == (s % 2 == 0)):
            return False
    for s in range(0 if down else 1, n, 2):
        a, b = around[s], around[(s + 1) % n]
        twin[a], twin[b] = b, a
    return True


@nb.njit(cache=True)
def _pair_in_order(faces, around, hi, twin):
    """Pair the half-edges ``around`` of one edge in their order, the k-th running it one way
    with the k-th running it the other; False, pairing nothing, if the two counts differ."""
    n = around.shape[0]
    down = np.empty(n, dtype=np.int64)
    up = np.empty(n, dtype=np.int64)
    n_down = n_up = 0
    for s in range(n):
        if faces[around[s] // 3, around[s] % 3] == hi:
            down[n_down] = around[s]
            n_down += 1
        else:
            up[n_up] = around[s]
            n_up += 1
    if n_down != n_up:
        return False
    for k in range(n_down):
        twin[down[k]], twin[up[k]] = up[k], down[k]
    return True


def _turned_note(turned: np.ndarray, disagreed: int, label: str) -> tuple[str, ...]:
    """Surface.repairs for one shell whose faces the mask turned (F,) says were turned: () if none."""
    n = int(np.count_nonzero(turned))
    if n == 0:
        return ()
    if n == turned.shape[0]:
        return (f"{label}: the surface was inside out (its triangles faced in): all {n} turned",)
    return (f"{label}: {disagreed} edges whose two triangles disagreed: {n} of its {turned.shape[0]} triangles "
            "turned to face out with the rest",)


def _oriented_shell(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The faces (F, 3) of a closed surface (every edge in exactly two) with some turned so
    that each edge's two run it opposite ways, the first face as it is, and the mask (F,) of
    those turned; None if they are not one shell (joined through edges) or no turning agrees
    (a non-orientable surface)."""
    oriented, turned, ok = _orient_faces(np.ascontiguousarray(faces))
    return (oriented, turned) if ok else None


@nb.njit(cache=True)
def _orient_faces(faces):
    """_oriented_shell's kernel: half-edge h = 3 f + k runs faces[f, k] -> faces[f, (k + 1) % 3];
    the two of each edge are twins; a search from face 0 turns each face reached so that it
    runs its edge with the face it came from the other way."""
    nf = faces.shape[0]
    order = _half_edges_by_edge(faces, np.int64(faces.max()) + 1)[1]
    twin = np.empty(3 * nf, dtype=np.int64)
    for i in range(0, 3 * nf, 2):  # every edge in exactly two faces: sorted keys come in pairs
        twin[order[i]], twin[order[i + 1]] = order[i + 1], order[i]
    turned = np.zeros(nf, dtype=np.bool_)
    seen = np.zeros(nf, dtype=np.bool_)
    stack = np.empty(nf, dtype=np.int64)
    stack[0], seen[0], top, reached = 0, True, 1, 1
    while top > 0:
        top -= 1
        f = stack[top]
        for k in range(3):
            h = 3 * f + k
            t = twin[h]
            g = t // 3
            same = (faces[f, k] < faces[f, (k + 1) % 3]) == (faces[g, t % 3] < faces[g, (t % 3 + 1) % 3])
            want = turned[f] != same  # g turned iff f is and the two run the edge opposite ways, or the other case
            if not seen[g]:
                seen[g], turned[g] = True, want
                stack[top] = g
                top += 1
                reached += 1
            elif turned[g] != want:
                return faces, turned, False
    out = faces.copy()
    for f in range(nf):
        if turned[f]:
            out[f, 1], out[f, 2] = faces[f, 2], faces[f, 1]
    return out, turned, reached == nf


def _to_manifold(vertices: np.ndarray, faces: np.ndarray, face_id: np.ndarray | None = None) -> manifold3d.Manifold:
    mesh = manifold3d.Mesh64(
        vert_properties=np.ascontiguousarray(vertices, dtype=np.float64),
        tri_verts=np.ascontiguousarray(faces, dtype=np.uint64),
        face_id=None if face_id is None else np.ascontiguousarray(face_id, dtype=np.uint64),
    )
    return manifold3d.Manifold(mesh)


def _bad_edge_example(vertices: np.ndarray, faces: np.ndarray, kind: str) -> str:
    """', e.g. ...' naming one edge of a kind _edge_report counts ('boundary': in one
    triangle; 'nonmanifold': in more than two; 'flipped': in two that run it the same way)
    by its ends' coordinates, the one of smallest vertex ids; '' if there is none.  Only an
    error's text: sorting every edge of the surface is cheap beside a user's fix."""
    ends = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2), axis=1)
    forward = (faces < np.roll(faces, -1, axis=1)).reshape(-1)
    edges, first, inverse, count = np.unique(ends, axis=0, return_index=True, return_inverse=True, return_counts=True)
    if kind == "boundary":
        bad = count == 1
    elif kind == "nonmanifold":
        bad = count > 2
    else:  # two triangles that run the edge the same way
        bad = (count == 2) & (np.bincount(inverse.reshape(-1), weights=forward, minlength=edges.shape[0]) != 1)
    if not bad.any():
        return ""
    e = int(np.argmax(bad))
    a, b = sorted(", ".join(f"{x:.6g}" for x in vertices[v]) for v in edges[e])  # the same for any numbering
    return f", e.g. ({a}) - ({b})" + (f" in {count[e]} triangles" if kind == "nonmanifold" else "")


def _status_error(name: str, label: str, boundary: int = 0, nonmanifold: int = 0, flipped: int = 0,
                  where: str = "") -> ParoctError:
    """The error for a manifold3d status name, with edge counts where they are known and
    ``where`` (_bad_edge_example's text for the first kind counted) after them."""
    if name == "NonFiniteVertex":
        return ParoctError(f"{label}: a vertex coordinate is NaN or infinite")
    if name == "NotManifold":
        if boundary:
            return ParoctError(f"{label}: open surface, {boundary} boundary edges{where} (a solid needs a closed "
                               "surface)")
        if nonmanifold:
            return ParoctError(f"{label}: non-manifold surface, {nonmanifold} edges shared by more than two "
                               f"triangles{where} (solids overlapping or touching there, or a sheet inside or "
                               "outside the solid: paroct meshes what a closed 2-manifold surface bounds)")
        if flipped:
            return ParoctError(f"{label}: inconsistently oriented surface, {flipped} edges whose two triangles "
                               f"disagree{where}")
        return ParoctError(f"{label}: non-manifold surface (sheets touching at a vertex)")
    return ParoctError(f"{label}: manifold3d rejected the surface ({name})")


#: Largest coordinate magnitude and smallest longest bounding-box side meshed: volumes
#: (length cubed) and tet estimates overflow or underflow float64 beyond them.  Meshing is
#: scale-invariant in between (tets of edge 1e-99 and 1e99 give the same mesh, scaled).
MAX_COORDINATE = 1e100
MIN_EXTENT = 1e-100
#: Most triangles a surface may have: the weld numbers its corners in int32 (an STL that
#: large would be 36 GB).
MAX_FACES = (2**31 - 1) // 3


def _check_scale(vertices: np.ndarray, label: str) -> None:
    """Refuse coordinates beyond MAX_COORDINATE and parts smaller than MIN_EXTENT."""
    lo, hi, largest = bounding_box(vertices)
    if largest > MAX_COORDINATE:
        raise ParoctError(f"{label}: a vertex coordinate reaches {largest:.3g}; paroct meshes coordinates up to "
                          f"{MAX_COORDINATE:.0e} in magnitude (volumes overflow beyond): scale the part")
    extent = float((hi - lo).max())
    if extent < MIN_EXTENT:
        raise ParoctError(f"{label}: the part spans only {extent:.3g} (longest side of its bounding box); paroct meshes "
                          f"parts of {MIN_EXTENT:.0e} or more (volumes underflow below): scale the part")


def surface_from_arrays(vertices: np.ndarray, faces: np.ndarray, label: str = "surface", *,
                        weld: bool = True, face_groups: np.ndarray | None = None,
                        group_names: tuple[str, ...] = ()) -> Surface:
    """Validate a triangle surface and build its solid; see load_surface.  weld: merge exactly
    coincident vertices (a triangle soup, as files hold them); False keeps the vertices as
    numbered, dropping only those no face uses (a manifold3d mesh, whose sheets touching
    along an edge or at a vertex have vertices of their own).  face_groups (F,) and
    group_names: named groups of the faces (see Surface), kept with the triangles through
    welding and the union of overlapping shells."""
    try:
        vertices, faces = np.asarray(vertices), np.asarray(faces)
    except (ValueError, TypeError) as exc:  # ragged nested lists
        raise ParoctError(f"{label}: vertices and faces must be (V, 3) and (F, 3) arrays ({exc})") from None
    if vertices.dtype.kind not in "iuf":
        raise ParoctError(f"{label}: vertices.dtype = {vertices.dtype}, expected real numbers")
    if vertices.dtype != np.float32:  # float32 (binary STL) is welded as it is, exactly
        vertices = vertices.astype(np.float64, copy=False)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ParoctError(f"{label}: vertices.shape = {vertices.shape}, expected (V, 3)")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ParoctError(f"{label}: faces.shape = {faces.shape}, expected (F, 3)")
    if faces.shape[0] == 0 or vertices.shape[0] == 0:
        raise ParoctError(f"{label}: empty surface (len(vertices) = {vertices.shape[0]}, len(faces) = {faces.shape[0]})")
    if not np.issubdtype(faces.dtype, np.integer):
        raise ParoctError(f"{label}: faces.dtype = {faces.dtype}, expected integers")
    if faces.shape[0] > MAX_FACES:
        raise ParoctError(f"{label}: len(faces) = {faces.shape[0]}; paroct reads surfaces of at most {MAX_FACES} triangles")
    if faces.min() < 0 or faces.max() >= vertices.shape[0]:  # in the given type: uint64 ids wrap in int64
        raise ParoctError(
            f"{label}: face indices span {faces.min()}..{faces.max()} but len(vertices) = {vertices.shape[0]}"
        )
    faces = faces.astype(np.int64, copy=False)
    groups, names = _checked_groups(face_groups, group_names, faces.shape[0], label)
    if groups is not None:  # the faces welding keeps: no two corners at one position (or one vertex)
        c = vertices[faces] if weld else faces
        same = [(c[:, i] == c[:, (i + 1) % 3]).reshape(c.shape[0], -1).all(axis=1) for i in range(3)]
        groups = groups[~(same[0] | same[1] | same[2])]
    vertices, faces, finite = _weld(vertices, faces) if weld else _used_only(vertices, faces)
    if not finite:
        raise ParoctError(f"{label}: a vertex coordinate is NaN or infinite")
    if faces.shape[0] == 0:
        raise ParoctError(f"{label}: every triangle is degenerate (repeated vertex)")
    _check_scale(vertices, label)
    boundary, nonmanifold, flipped, fans, shell = _shell_topology(faces, vertices.shape[0])
    if nonmanifold and not boundary:  # solids touching along edges, overlapping or touching over an area
        split = _split_touching_sheets(vertices, faces)
        if split is not None:
            topology = _shell_topology(split[1], split[0].shape[0])
            if not any(topology[:3]):  # pairs that cross sheets may leave edges joined
                (vertices, faces), (boundary, nonmanifold, flipped, fans, shell) = split, topology
    turned, disagreed = np.zeros(faces.shape[0], dtype=bool), flipped
    if flipped and not boundary and not nonmanifold:  # one shell with some triangles turned the wrong way
        oriented = _oriented_shell(faces)
        if oriented is not None:
            faces, turned = oriented
            boundary, nonmanifold, flipped, fans, shell = _shell_topology(faces, vertices.shape[0])
    if boundary or nonmanifold or flipped:
        where = _bad_edge_example(vertices, faces, "boundary" if boundary else "nonmanifold" if nonmanifold else "flipped")
        raise _status_error("NotManifold", label, boundary, nonmanifold, flipped, where)
    n_shells = int(shell.max()) + 1
    if n_shells == 1:
        lo, hi, _ = bounding_box(vertices)
        volume, area = _volume_area(vertices, faces, math.ldexp(1.0, -math.frexp(float((hi - lo).max()))[1]))
        if volume < 0:  # one closed shell bounds one solid: its triangles face in
            faces, volume, turned = np.ascontiguousarray(faces[:, ::-1]), -volume, ~turned
        if not volume > 0:
            raise ParoctError(f"{label}: the surface encloses zero volume (volume = {volume:.6g})")
        return _validated(Surface(vertices, faces, float(volume), float(area), _genus(fans, faces, 1), 1, groups, names,
                                  _turned_note(turned, disagreed, label)))

    # Several shells: manifold3d checks each, unions the solids and subtracts the cavities.
    solids, cavities, lost, signed_sum, area_sum = [], [], [], 0.0, 0.0
    by_shell = np.argsort(shell, kind="stable")  # faces[shell == c] for each c would be O(F) a shell
    bounds = np.searchsorted(shell[by_shell], np.arange(n_shells + 1))
    for c in range(n_shells):
        # The shell's own vertices only: a manifold of all of them (mostly unused) cost each
        # shell O(V), 2 ms a shell for 3000 small spheres.
        used, shell_faces = np.unique(faces[by_shell[bounds[c]:bounds[c + 1]]], return_inverse=True)
        shell_vertices, shell_faces = vertices[used], shell_faces.reshape(-1, 3)
        # manifold3d carries each triangle's face id through the union: the group it came from.
        face_id = None if groups is None else groups[by_shell[bounds[c]:bounds[c + 1]]]
        part = _to_manifold(shell_vertices, shell_faces, face_id)
        status = part.status()
        if status.name != "NoError":
            raise _status_error(status.name, label)
        vol = part.volume()
        signed_sum += vol
        area_sum += part.surface_area()
        if vol > 0:
            solids.append(part)
        elif vol < 0:
            cavities.append(_to_manifold(shell_vertices, shell_faces[:, ::-1], face_id))
            lost.append((shell_faces.shape[0], (shell_vertices.min(axis=0) + shell_vertices.max(axis=0)) / 2, vol))
    if not solids:
        raise ParoctError(f"{label}: the surface encloses zero or negative volume (inside out?)")
    if cavities:  # a cavity is a hole in a solid: one in none bounds nothing (an inside-out part?)
        everything = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add)
        for cavity, (n, centre, vol) in zip(cavities, lost):
            if (cavity - everything).volume() > 1e-9 * cavity.volume():
                x, y, z = centre
                raise ParoctError(f"{label}: a shell of {n} triangles around ({x:.6g}, {y:.6g}, {z:.6g}) encloses negative "
                                  f"volume ({vol:.6g}) and does not lie wholly inside the other shells: inside out, or "
                                  "crossing their surface? (a cavity must lie inside a solid; reverse its triangles if it "
                                  "is a solid)")
    solid = _nested_union(solids, cavities)
    volume = solid.volume()
    if not volume > 0:
        raise ParoctError(f"{label}: the surface encloses zero or negative volume (volume = {volume:.6g})")
    area = solid.surface_area()
    if (len(solids) + len(cavities) == n_shells and abs(volume - signed_sum) <= DISJOINT_SHELLS * volume
            and abs(area - area_sum) <= DISJOINT_SHELLS * area):
        # No shell overlaps another or touches it over an area (the union lost no volume and no
        # surface): the shells bound the solid as they are, and shells that touch along edges or
        # at corners stay apart, as they do in the mesh.  manifold3d's union would join some of
        # them through zero-width necks (a 6 x 6 x 6 checkerboard of 108 cubes came back as 36
        # shells), a topology no mesh keeps.
        return _validated(Surface(vertices, faces, float(volume), float(area), _genus(fans, faces, n_shells), n_shells,
                                  groups, names))
    out = solid.to_mesh64()
    out_vertices = np.array(out.vert_properties, dtype=np.float64)[:, :3]
    out_faces = np.array(out.tri_verts, dtype=np.int32)
    out_groups = None if groups is None else np.asarray(out.face_id, dtype=np.int64)
    *_, fans, shell = _shell_topology(out_faces, out_vertices.shape[0])
    n_shells = int(shell.max()) + 1
    return _validated(Surface(out_vertices, out_faces, float(volume), float(area), _genus(fans, out_faces, n_shells), n_shells,
                              out_groups, names))


def _validated(surface: Surface) -> Surface:
    object.__setattr__(surface, "validated", True)
    return surface


#: Shells whose union's volume and area are their signed volumes' and areas' sums to this
#: relative difference are taken as overlapping nowhere and touching over no area (along
#: edges or at corners at most): float sums of the same solid differed by up to 1.2e-15
#: relative (200 apart spheres), while two cubes overlapping by 1e-12 of their side differ
#: in volume by 1.5e-12, and cubes sharing part of a face in area by 13 %.
DISJOINT_SHELLS = 1e-13


def _nested_union(solids: list, cavities: list) -> manifold3d.Manifold:
    """The solid of shells given as manifolds of positive volume: solids, and cavities (shells
    of negative volume, turned outward): the points of positive winding number.  The solids
    are united and the cavities subtracted, except solids that lie inside a cavity (islands,
    as a ball in a hollow sphere), which are added back after, with the cavities inside them
    handled the same way, level by level (subtracting every cavity from every solid dropped
    the islands).  Containment is tested only where one bounding box holds the other."""
    islands, inner = _inside_any(solids, cavities), set[int]()
    if islands:
        inner = _inside_any(cavities, [solids[i] for i in islands])
    outer_solids = [m for i, m in enumerate(solids) if i not in islands]
    outer_cavities = [m for i, m in enumerate(cavities) if i not in inner]
    solid = manifold3d.Manifold.batch_boolean(outer_solids, manifold3d.OpType.Add)
    if outer_cavities:
        solid = solid - manifold3d.Manifold.batch_boolean(outer_cavities, manifold3d.OpType.Add)
    if islands:
        solid = solid + _nested_union([solids[i] for i in islands], [cavities[i] for i in inner])
    return solid


def _inside_any(parts: list, containers: list) -> set[int]:
    """Indices of parts (manifolds) that lie inside one of containers (manifolds): a bounding
    box within the container's, and no volume left when the container is subtracted."""
    inside: set[int] = set()
    if not parts or not containers:
        return inside
    boxes = np.array([c.bounding_box() for c in containers]).reshape(-1, 2, 3)
    for i, part in enumerate(parts):
        lo, hi = np.asarray(part.bounding_box()).reshape(2, 3)
        holding = np.flatnonzero(np.all(boxes[:, 0] <= lo, axis=1) & np.all(boxes[:, 1] >= hi, axis=1))
        volume = part.volume()
        if any((part - containers[c]).volume() <= 1e-9 * volume for c in holding):
            inside.add(i)
    return inside


def _genus(fans: int, faces: np.ndarray, n_shells: int) -> int:
    """Genus summed over the shells: each has V - E + F = 2 - 2 genus, with every fan
    counted as a vertex (sheets touching at a vertex are apart there) and E = 3 F / 2."""
    return (2 * n_shells - (fans - faces.shape[0] // 2)) // 2


def load_surface(source: SurfaceSource) -> Surface:
    """The validated closed surface of a solid.

    source: a path to an STL, OBJ, OFF, PLY or Gmsh MSH file; a ``manifold3d.Manifold``; or a
    ``(vertices (V, 3), faces (F, 3))`` pair.  Exactly coincident vertices are merged,
    degenerate triangles dropped, solids touching along an edge or at a corner kept apart
    (as the mesh keeps them), overlapping shells unioned.  Raises ParoctError with
    the reason (open surface with its number of boundary edges, non-manifold edges,
    NaN coordinates, empty, zero or negative volume).
    """
    if isinstance(source, manifold3d.Manifold):
        status = source.status()
        if status.name != "NoError":
            raise _status_error(status.name, "manifold")
        if source.is_empty():
            raise ParoctError("manifold: empty solid")
        mesh = source.to_mesh64()
        faces = np.asarray(mesh.tri_verts, dtype=np.int64)
        merge_from = np.asarray(mesh.merge_from_vert, dtype=np.int64)
        if merge_from.size:  # vertices split only where their properties (normals, UVs) differ
            to = np.arange(len(mesh.vert_properties))
            to[merge_from] = np.asarray(mesh.merge_to_vert, dtype=np.int64)
            faces = to[faces]
        positions = np.asarray(mesh.vert_properties)[:, :3]
        try:
            # Welded like a file, then taken apart at touching edges: touching sheets apart
            # everywhere, as in the mesh (manifold3d joins some through zero-width necks).
            return surface_from_arrays(positions, faces, "manifold")
        except ParoctError:
            # A touching edge no pairing undoes (flat faces around it): the manifold's own vertices.
            return surface_from_arrays(positions, faces, "manifold", weld=False)
    if isinstance(source, Surface):  # one of ours as it is; one made by hand checked like arrays
        return source if source.validated else surface_from_arrays(
            source.vertices, source.faces, face_groups=source.face_groups, group_names=source.group_names)
    if isinstance(source, tuple):
        if len(source) != 2:
            raise ParoctError(f"expected a (vertices, faces) pair, got a tuple of {len(source)}")
        return surface_from_arrays(source[0], source[1])
    if isinstance(source, (str, os.PathLike)):
        read = read_surface_file(source)
        try:
            return surface_from_arrays(read.vertices, read.faces, str(source), face_groups=read.face_groups,
                                       group_names=read.group_names)
        except ParoctError as exc:
            if os.fspath(source).lower().endswith(".stl") and ("open surface" in str(exc) or "empty" in str(exc)):
                note = binary_stl_count_note(source)
                if note:
                    raise ParoctError(f"{exc}{note}") from None
            if os.fspath(source).lower().endswith(".msh") and "open surface" in str(exc):
                raise ParoctError(f"{exc}; a Gmsh file holds only the elements of its physical groups when it has "
                                  "any: put every surface of the part in one (or set Mesh.SaveAll = 1)") from None
            raise
    raise ParoctError(f"cannot mesh a {type(source).__name__}: pass a file path, a manifold3d.Manifold or (vertices, faces)")
