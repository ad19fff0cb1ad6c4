"""Boundary patches: the solid's surface split at its sharp edges, and the mesh's boundary
triangles tagged with the patch they lie on, so that boundary conditions can be put on them
(Gmsh physical groups, Abaqus surfaces and node sets, Medit references: see io.write_mesh).

Where the input names groups of its triangles (the solids of an ASCII STL, the ``g``
statements of an OBJ, the physical surfaces of a Gmsh mesh: CAD programs export faces or
bodies so), the groups are the patches, with their names.  Otherwise, or when a feature
angle is asked for, a patch is a set of surface triangles joined across edges where the
surface turns by less than the feature angle (the angle between the two triangles'
normals), the usual rule of CAD and of Gmsh's ``ClassifySurfaces``: a box has 6 patches, a
cylinder 3 at 40 degrees.  Each boundary triangle of a mesh paroct made whose three vertices
lie on input triangles of one patch (MeshResult.point_faces: stuffing knows the triangle each
cut point lies on) takes that patch; the others, and every triangle of a mesh given as
arrays, take the patch of the input triangle nearest their centroid (exact point-to-triangle
distances, check.nearest_triangles).
Stuffing cuts sharp edges (by less than one size), so the tagged faces along a sharp edge
split between its two patches where the cut falls, not on the edge itself, unless the
boundary is moved onto the edges after (MeshResult.with_sharp_edges, sharp.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from .check import nearest_triangles, validated_mesh
from .errors import ParoctError
from .features import face_normals
from .sizing import is_number
from .surface import Surface, SurfaceSource, load_surface
from .topology import face_owners, half_edge_twins, match_faces, tet_faces_of, union, used_vertices, vertex_stars

#: Default feature angle, degrees: edges where the surface turns by more bound patches.
DEFAULT_FEATURE_ANGLE = 40.0


@dataclass(frozen=True)
class BoundaryPatches:
    """The boundary triangles of a tet mesh, tagged by surface patch.

    faces: (B, 3) int32 vertex ids into the mesh's points, counter-clockwise seen from
    outside; tets: (B,) int64 the tet each triangle bounds; tet_faces: (B,) int8 which face
    of that tet it is (k: the face opposite the tet's vertex k); patches: (B,) int32 the
    patch of each triangle, 1 .. n_patches (from 1, as files number them: Gmsh's physical
    tags must be positive); n_patches: the surface's patch count (a patch too small for the
    lattice may have no triangle); feature_angle: degrees, or None where the patches are the
    input's named groups; names: the patches' names, names[p - 1] of patch p (``patch_<p>``
    if not given).
    """

    faces: np.ndarray
    tets: np.ndarray
    tet_faces: np.ndarray
    patches: np.ndarray
    n_patches: int
    feature_angle: float | None
    names: tuple[str, ...] = ()

    def __post_init__(self):
        for name, dtype in (("faces", np.int32), ("tets", np.int64), ("tet_faces", np.int8), ("patches", np.int32)):
            try:
                object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=dtype))
            except (TypeError, ValueError, OverflowError) as exc:
                raise ParoctError(f"BoundaryPatches.{name}: not an array of integers ({exc})") from None
        b = self.faces.shape[0] if self.faces.ndim else -1
        if self.faces.shape != (b, 3) or any(a.shape != (b,) for a in (self.tets, self.tet_faces, self.patches)):
            raise ParoctError(f"faces.shape = {self.faces.shape}, tets.shape = {self.tets.shape}, tet_faces.shape = "
                              f"{self.tet_faces.shape}, patches.shape = {self.patches.shape}; want (B, 3) and (B,)")
        if b and (self.patches.min() < 1 or self.patches.max() > self.n_patches):
            raise ParoctError(f"patches span {self.patches.min()} .. {self.patches.max()}, n_patches = {self.n_patches}")
        names = tuple(self.names) or tuple(f"patch_{p}" for p in range(1, self.n_patches + 1))
        if len(names) != self.n_patches or not all(isinstance(name, str) for name in names):
            raise ParoctError(f"len(names) = {len(names)}, n_patches = {self.n_patches}; want a name (str) a patch")
        object.__setattr__(self, "names", names)

    def by_patch(self) -> list[np.ndarray]:
        """The triangles of each patch: ids (into faces) of patch p at [p - 1], in array order;
        one stable sort for all (a mask a patch is B x n_patches)."""
        order = np.argsort(self.patches, kind="stable")
        return np.split(order, np.searchsorted(self.patches[order], np.arange(2, self.n_patches + 1)))


def checked_feature_angle(feature_angle: float) -> float:
    """feature_angle, or ParoctError unless it is a number of degrees in (0, 180]."""
    if not (is_number(feature_angle) and 0 < feature_angle <= 180):
        raise ParoctError(f"feature angle = {feature_angle}: must be a number of degrees in (0, 180]")
    return feature_angle


def surface_patches(surface: Surface | SurfaceSource, feature_angle: float = DEFAULT_FEATURE_ANGLE) -> np.ndarray:
    """Patch id (F,) int32 of each of the surface's triangles (a Surface, or what
    load_surface reads): triangles joined across every edge where their unit normals differ
    by less than ``feature_angle`` degrees (0 < angle <= 180), numbered 1, 2, ... in the order
    of each patch's first triangle.  A triangle of zero area has no normal: it joins the
    patch across its longest edge."""
    checked_feature_angle(feature_angle)
    surface = surface if isinstance(surface, Surface) else load_surface(surface)
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    vertices = np.ascontiguousarray(surface.vertices, dtype=np.float64)
    return _patches(vertices, faces, face_normals(vertices, faces), math.cos(math.radians(feature_angle)))


@nb.njit(cache=True)
def _patches(vertices, faces, normals, min_cos):
    """surface_patches' kernel over unit normals (F, 3) (zero for zero-area faces): every edge
    a -> b of a face matched with its twin b -> a (topology.half_edge_twins), union-find over
    the smooth ones, then labels by first face."""
    nf = faces.shape[0]
    nv = vertices.shape[0]
    longest = np.zeros(nf, dtype=np.int64)  # the face's longest edge j, from corner j to j + 1
    for f in range(nf):
        best = -1.0
        for j in range(3):
            p, q = faces[f, j], faces[f, (j + 1) % 3]
            d = 0.0
            for k in range(3):
                d += (vertices[q, k] - vertices[p, k]) ** 2
            if d > best:
                best, longest[f] = d, j
    twin = half_edge_twins(faces, nv)
    parent = np.arange(nf)
    for h in range(3 * nf):
        t = twin[h]
        if t <= h:  # each edge once, from its half-edge of smaller index
            continue
        f, j, g, i = h // 3, h % 3, t // 3, t % 3
        dot = normals[f, 0] * normals[g, 0] + normals[f, 1] * normals[g, 1] + normals[f, 2] * normals[g, 2]
        flat_f = normals[f, 0] == 0 and normals[f, 1] == 0 and normals[f, 2] == 0
        flat_g = normals[g, 0] == 0 and normals[g, 1] == 0 and normals[g, 2] == 0
        if (not flat_f and not flat_g and dot > min_cos) or (flat_f and longest[f] == j) or (flat_g and longest[g] == i):
            union(parent, f, g)
    labels = np.zeros(nf, dtype=np.int32)
    n_patches = 0
    for f in range(nf):
        # union keeps parent[x] <= x, so parent[f] was flattened to its root already.
        r = parent[parent[f]]
        parent[f] = r
        if labels[r] == 0:
            n_patches += 1
            labels[r] = n_patches
        labels[f] = labels[r]
    return labels


def boundary_patches(points: np.ndarray, tets: np.ndarray, surface: Surface | SurfaceSource,
                     feature_angle: float | None = None) -> BoundaryPatches:
    """The boundary triangles of the tet mesh (points (N, 3) float64, tets (M, 4) positively
    oriented) tagged with the patches of the surface it fills (a Surface or anything
    load_surface takes): each takes the patch of the surface triangle nearest its centroid.
    The patches are the surface's named groups (Surface.face_groups) when it has them and
    feature_angle is None, else surface_patches at feature_angle (default
    DEFAULT_FEATURE_ANGLE).  ParoctError for malformed arrays (check.check_mesh's rules) or
    surface."""
    points, tets = validated_mesh(points, tets)
    return _tagged_boundary(points, tets, load_surface(surface), feature_angle)


def surface_labels(surface: Surface, feature_angle: float | None) -> tuple[np.ndarray, tuple[str, ...], float | None]:
    """(patch of each surface triangle (F,) int32 from 1, the patches' names or (), the feature
    angle used or None): the named groups when the surface has them and feature_angle is None,
    else surface_patches at feature_angle (default DEFAULT_FEATURE_ANGLE)."""
    if feature_angle is None and surface.face_groups is not None:
        return surface.face_groups + 1, surface.group_names, None
    feature_angle = DEFAULT_FEATURE_ANGLE if feature_angle is None else feature_angle
    return surface_patches(surface, feature_angle), (), feature_angle


def _tagged_boundary(points: np.ndarray, tets: np.ndarray, surface: Surface, feature_angle: float | None,
                     known: np.ndarray | None = None, point_faces: np.ndarray | None = None) -> BoundaryPatches:
    """boundary_patches over arrays known good (a mesh paroct made: points float64, tets int).
    known: the boundary triangles (B, 3) if known (MeshResult.boundary_faces): their tets are
    then found in the stars of their vertices, one pass over the tets instead of matching
    every face (fea_part at diag/40: 141 ms).  point_faces: the surface triangle (N,) each
    point lies on, -1 if not known (MeshResult.point_faces): a boundary triangle whose three
    vertices lie on triangles of one patch takes that patch without a search."""
    return tag_boundary(points, tets, surface, *surface_labels(surface, feature_angle), known, point_faces)


def _vertex_patches(faces: np.ndarray, labels: np.ndarray, point_faces: np.ndarray | None) -> np.ndarray:
    """Patch (B,) int32 of each triangle (faces (B, 3)) whose three vertices lie on surface
    triangles (point_faces) of one patch (labels, from 1); 0 for the others, and for all
    without point_faces.  Such a triangle is a chord of its patch: stuffing puts a boundary
    vertex on the triangle its lattice edge crosses, and a triangle with its corners on two
    patches straddles their seam, where the nearest triangle to its centroid decides."""
    if point_faces is None:
        return np.zeros(faces.shape[0], dtype=np.int32)
    if point_faces.size and point_faces.max() >= labels.shape[0]:
        raise ParoctError(f"point_faces name triangles up to {point_faces.max()}, but the surface has {labels.shape[0]}: "
                          "they belong to another surface (a MeshResult's surface replaced?)")
    return _agreed_patches(faces, np.ascontiguousarray(labels, dtype=np.int32),
                           np.ascontiguousarray(point_faces, dtype=np.int32))


@nb.njit(cache=True, parallel=True)
def _agreed_patches(faces, labels, point_faces):
    """_vertex_patches' kernel (numpy's gathers and masks of (B, 3) took 15 ms of round_rod's
    0.8 M boundary triangles at diag/80)."""
    patches = np.zeros(faces.shape[0], dtype=np.int32)
    for b in nb.prange(faces.shape[0]):
        first = point_faces[faces[b, 0]]
        if first < 0:
            continue
        patch = labels[first]
        agree = True
        for k in range(1, 3):
            on = point_faces[faces[b, k]]
            agree &= on >= 0 and labels[on] == patch
        if agree:
            patches[b] = patch
    return patches


def tag_boundary(points: np.ndarray, tets: np.ndarray, surface: Surface, labels: np.ndarray, names: tuple[str, ...],
                 feature_angle: float | None, known: np.ndarray | None = None,
                 point_faces: np.ndarray | None = None) -> BoundaryPatches:
    """_tagged_boundary with the surface's labels given (surface_labels' three results)."""
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    if known is None:
        owner, face = np.nonzero(match_faces(tets)[0] < 0)
    else:
        known = np.ascontiguousarray(known, dtype=np.int64)
        # The distinct first vertices by a mask: np.unique hashed round_rod's 0.8 M at diag/80 in 140 ms.
        firsts = np.flatnonzero(used_vertices(known[:, :1], points.shape[0]))
        owner, face = face_owners(tets, known, *vertex_stars(tets, firsts, points.shape[0]))
        if known.shape[0] and owner.min() < 0:
            raise ParoctError("boundary faces given that are no tet's faces")
        order = np.lexsort((face, owner))  # as matching lists them: by tet, then face
        owner, face = owner[order], face[order].astype(np.int64)
    faces = tet_faces_of(tets, owner, face)
    patches = _vertex_patches(faces, labels, point_faces)
    search = np.flatnonzero(patches == 0)
    if search.size:
        corners = faces[search]
        centroids = (points[corners[:, 0]] + points[corners[:, 1]] + points[corners[:, 2]]) / 3
        patches[search] = labels[nearest_triangles(centroids, surface.vertices, surface.faces)[1]]
    return BoundaryPatches(faces.astype(np.int32), owner.astype(np.int64), face.astype(np.int8), patches.astype(np.int32),
                           len(names) or int(labels.max(initial=0)), None if feature_angle is None else float(feature_angle),
                           names)
