"""Load and validate the closed surface of the solid to mesh.

manifold3d owns the solid: it checks that the triangles bound a 2-manifold and, when a
file holds several shells, unions the overlapping ones (shells of negative volume are
cavities and are subtracted).  Everything downstream works on the manifold's own
triangles, which are closed and consistently oriented (outward normals, positive volume).
"""

from __future__ import annotations

import contextlib
import io
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import manifold3d
import numba as nb
import numpy as np

from .errors import ParoctError
from .topology import edge_multiplicities

#: Surface formats read through meshio, by file extension.
SURFACE_EXTENSIONS = (".stl", ".obj", ".off", ".ply")

SurfaceSource = Union[str, os.PathLike, manifold3d.Manifold, tuple]


@dataclass(frozen=True)
class Surface:
    """A closed, oriented, manifold triangle surface bounding a solid.

    vertices: (V, 3) float64, model units.  faces: (F, 3) int32, counter-clockwise seen
    from outside.  volume, area: of the solid, model units.  genus: of the whole
    boundary (sum over components).  components: number of boundary shells.
    """

    vertices: np.ndarray
    faces: np.ndarray
    volume: float
    area: float
    genus: int
    components: int
    manifold: Any = field(default=None, repr=False, compare=False)

    @property
    def bbox_min(self) -> np.ndarray:
        return self.vertices.min(axis=0)

    @property
    def bbox_max(self) -> np.ndarray:
        return self.vertices.max(axis=0)

    @property
    def diagonal(self) -> float:
        return float(np.linalg.norm(self.bbox_max - self.bbox_min))


def read_surface_file(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 and triangles (F, 3) int64 of a surface file (STL, OBJ, OFF, PLY).

    Quadrilaterals and polygons are split into triangles.  Raises ParoctError for a
    missing file, an unknown extension or a file meshio cannot parse.
    """
    import meshio  # only at the edge of the package

    path = Path(path)
    if not path.exists():
        raise ParoctError(f"no such file: {path}")
    if path.is_dir():
        raise ParoctError(f"{path} is a directory, not a surface file")
    ext = path.suffix.lower()
    if ext not in SURFACE_EXTENSIONS:
        raise ParoctError(f"unknown surface format {ext or '(no extension)'!r} of {path}; use one of {', '.join(SURFACE_EXTENSIONS)}")
    try:
        soup = _read_binary_stl(path) if ext == ".stl" else None
        if soup is not None:
            return soup
        # meshio's ASCII STL reader trips numpy overflow warnings and prints its own error
        # line before raising; ours below is the one the user gets.
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()):
            warnings.simplefilter("ignore", RuntimeWarning)
            raw = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types, even SystemExit, for malformed files
        text = str(exc).strip()
        msg = text.splitlines()[0] if text and not isinstance(exc, SystemExit) else "malformed file"
        raise ParoctError(f"cannot read {path} as {ext[1:].upper()}: {msg}") from None
    tris = []
    for block in raw.cells:
        data = np.asarray(block.data, dtype=np.int64)
        if block.type == "triangle":
            tris.append(data)
        elif block.type in ("quad", "polygon") or (data.ndim == 2 and data.shape[1] > 3 and block.type.startswith("polygon")):
            for k in range(1, data.shape[1] - 1):  # fan split
                tris.append(data[:, [0, k, k + 1]])
    if not tris:
        raise ParoctError(f"{path} holds no triangles")
    return np.asarray(raw.points, dtype=np.float64)[:, :3], np.concatenate(tris)


#: A binary STL facet: normal, three corners (float32) and an attribute word, 50 bytes.
_STL_FACET = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def _read_binary_stl(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """Triangle soup (3F corners (3F, 3) float64, faces (F, 3) int64) of a binary STL, or None
    if the file is not one (its size is not 84 + 50 F for the F in its header: ASCII STL).

    Read straight into numpy: meshio's STL reader merges the corners with a row-wise
    np.unique that took half a second on an 86 k-triangle part; _weld merges them later anyway.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(84)
        if len(head) < 84:
            return None
        n = int(np.frombuffer(head, dtype="<u4", count=1, offset=80)[0])
        if size != 84 + 50 * n:
            return None
        facets = np.fromfile(fh, dtype=_STL_FACET, count=n)
    corners = facets["corners"].reshape(-1, 3).astype(np.float64)
    return corners, np.arange(3 * n, dtype=np.int64).reshape(n, 3)


@nb.njit(cache=True)
def _face_components(faces, n_vertices):
    """Component label (F,) int64 of every face, faces joined through shared vertices."""
    parent = np.arange(n_vertices)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for f in range(faces.shape[0]):
        r0 = find(faces[f, 0])
        for k in range(1, 3):
            r = find(faces[f, k])
            if r != r0:
                parent[max(r, r0)] = min(r, r0)
                r0 = min(r, r0)
    labels = np.empty(faces.shape[0], dtype=np.int64)
    for f in range(faces.shape[0]):
        labels[f] = find(faces[f, 0])
    return labels


def _edge_report(faces: np.ndarray, n_vertices: int) -> tuple[int, int, int]:
    """Counts of (boundary edges, edges with more than two faces, edges whose two faces disagree in orientation)."""
    count, forward, _ = edge_multiplicities(np.ascontiguousarray(faces, dtype=np.int64), n_vertices)
    return int(np.sum(count == 1)), int(np.sum(count > 2)), int(np.sum((count == 2) & (forward != 1)))


def _weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge exactly coincident vertices, drop faces with a repeated vertex.  The merged
    vertices are sorted by (x, y, z), as np.unique(axis=0) would give them, by a three-key
    lexsort (np.unique's row sort was 10x slower)."""
    if vertices.shape[0] == 0:
        return vertices, faces
    order = np.lexsort((vertices[:, 2], vertices[:, 1], vertices[:, 0]))
    ordered = vertices[order]
    first = np.empty(ordered.shape[0], dtype=bool)
    first[0] = True
    np.any(ordered[1:] != ordered[:-1], axis=1, out=first[1:])
    inverse = np.empty(ordered.shape[0], dtype=np.int64)
    inverse[order] = np.cumsum(first) - 1
    uniq = ordered[first]
    faces = inverse[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    return uniq, faces[keep]


def _to_manifold(vertices: np.ndarray, faces: np.ndarray) -> manifold3d.Manifold:
    mesh = manifold3d.Mesh64(
        vert_properties=np.ascontiguousarray(vertices, dtype=np.float64),
        tri_verts=np.ascontiguousarray(faces, dtype=np.uint64),
    )
    return manifold3d.Manifold(mesh)


def _status_error(name: str, label: str, boundary: int = 0, nonmanifold: int = 0, flipped: int = 0) -> ParoctError:
    """The error for a manifold3d status name, with edge counts where they are known."""
    if name == "NonFiniteVertex":
        return ParoctError(f"{label}: a vertex coordinate is NaN or infinite")
    if name == "NotManifold":
        if boundary:
            return ParoctError(f"{label}: open surface, {boundary} boundary edges (a solid needs a closed surface)")
        if nonmanifold:
            return ParoctError(f"{label}: non-manifold surface, {nonmanifold} edges shared by more than two triangles")
        if flipped:
            return ParoctError(f"{label}: inconsistently oriented surface, {flipped} edges whose two triangles disagree")
        return ParoctError(f"{label}: non-manifold surface (sheets touching at a vertex)")
    return ParoctError(f"{label}: manifold3d rejected the surface ({name})")


def surface_from_arrays(vertices: np.ndarray, faces: np.ndarray, label: str = "surface") -> Surface:
    """Validate a triangle surface and build its solid; see load_surface."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ParoctError(f"{label}: vertices.shape = {vertices.shape}, expected (V, 3)")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise ParoctError(f"{label}: faces.shape = {faces.shape}, expected (F, 3)")
    if faces.shape[0] == 0 or vertices.shape[0] == 0:
        raise ParoctError(f"{label}: empty surface (len(vertices) = {vertices.shape[0]}, len(faces) = {faces.shape[0]})")
    if not np.issubdtype(faces.dtype, np.integer):
        raise ParoctError(f"{label}: faces.dtype = {faces.dtype}, expected integers")
    faces = faces.astype(np.int64)
    if faces.min() < 0 or faces.max() >= vertices.shape[0]:
        raise ParoctError(
            f"{label}: face indices span {faces.min()}..{faces.max()} but len(vertices) = {vertices.shape[0]}"
        )
    used = np.zeros(vertices.shape[0], dtype=bool)
    used[faces.ravel()] = True
    if not np.all(np.isfinite(vertices[used])):
        raise ParoctError(f"{label}: a vertex coordinate is NaN or infinite")
    vertices, faces = _weld(vertices, faces)
    if faces.shape[0] == 0:
        raise ParoctError(f"{label}: every triangle is degenerate (repeated vertex)")
    boundary, nonmanifold, flipped = _edge_report(faces, vertices.shape[0])
    if boundary or nonmanifold or flipped:
        raise _status_error("NotManifold", label, boundary, nonmanifold, flipped)

    labels = _face_components(faces, vertices.shape[0])
    shells = [faces[labels == c] for c in np.unique(labels)]
    solids, cavities = [], []
    for shell in shells:
        part = _to_manifold(vertices, shell)
        status = part.status()
        if status.name != "NoError":
            raise _status_error(status.name, label)
        vol = part.volume()
        if vol > 0:
            solids.append(part)
        elif vol < 0:
            cavities.append(_to_manifold(vertices, shell[:, ::-1]))
    if not solids:
        raise ParoctError(f"{label}: the surface encloses zero or negative volume (inside out?)")
    if len(shells) == 1:
        solid = solids[0]
    else:
        solid = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add)
        if cavities:
            solid = solid - manifold3d.Manifold.batch_boolean(cavities, manifold3d.OpType.Add)
    volume = solid.volume()
    if not volume > 0:
        raise ParoctError(f"{label}: the surface encloses zero or negative volume (volume = {volume:.6g})")
    out = solid.to_mesh64()
    out_vertices = np.array(out.vert_properties, dtype=np.float64)[:, :3]
    out_faces = np.array(out.tri_verts, dtype=np.int32)
    return Surface(
        vertices=out_vertices,
        faces=out_faces,
        volume=float(volume),
        area=float(solid.surface_area()),
        genus=int(solid.genus()),
        components=len(solid.decompose()) if len(shells) > 1 else 1,
        manifold=solid,
    )


def load_surface(source: SurfaceSource) -> Surface:
    """The validated closed surface of a solid.

    source: a path to an STL, OBJ, OFF or PLY file; a ``manifold3d.Manifold``; or a
    ``(vertices (V, 3), faces (F, 3))`` pair.  Exactly coincident vertices are merged,
    degenerate triangles dropped, overlapping shells unioned.  Raises ParoctError with
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
        return surface_from_arrays(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts), "manifold")
    if isinstance(source, tuple):
        if len(source) != 2:
            raise ParoctError(f"expected a (vertices, faces) pair, got a tuple of {len(source)}")
        return surface_from_arrays(source[0], source[1])
    if isinstance(source, (str, os.PathLike)):
        vertices, faces = read_surface_file(source)
        return surface_from_arrays(vertices, faces, str(source))
    raise ParoctError(f"cannot mesh a {type(source).__name__}: pass a file path, a manifold3d.Manifold or (vertices, faces)")
