"""Write and read tet meshes: meshio for every format, except .vtu (the default output), Abaqus
.inp, Medit .mesh and Gmsh .msh, which paroct writes itself (4 M tets: 0.9, 3.1 and 2.3 s
against meshio's 5.8, 20 and 31 s for the first three), with the boundary's patches where
asked (boundary.BoundaryPatches); the package's only meshio edge besides surface input."""

from __future__ import annotations

import base64
import contextlib
import io
import os
import re
import warnings
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numba as nb
import numpy as np

from .errors import ParoctError
from .readers import regular_file
from .surface import bounding_box

if TYPE_CHECKING:
    from .boundary import BoundaryPatches

#: meshio format to use for an extension where meshio's own default is wrong or ambiguous
#: (.msh maps to ANSYS first), with the options that make the output binary where allowed.
_FORMAT_OVERRIDES = {
    ".msh": ("gmsh", {"binary": True}),
    ".vtk": ("vtk", {"binary": True}),
    ".vtu": ("vtu", {"binary": True}),
}
#: Surface-only formats, which cannot hold tets.
_SURFACE_ONLY = {".stl", ".obj", ".off", ".ply", ".wrl", ".svg", ".wkt"}
#: Extensions whose meshio writer (5.3) gives no file of the tets: Nastran's asserts, Medit's
#: binary .meshb and AFLR's .ugrid write files meshio cannot read back.
_BROKEN_WRITERS = {".bdf": "Nastran", ".fem": "Nastran", ".nas": "Nastran", ".meshb": "binary Medit",
                   ".ugrid": "UGRID"}


def output_format(path: str | os.PathLike) -> tuple[str, dict]:
    """The meshio format name and writer options for an output path; ParoctError if it cannot hold tets."""
    import meshio

    path = Path(path)
    ext = path.suffix.lower()
    double = "".join(path.suffixes[-2:]).lower()  # .vol.gz, .dato.gz, .post.gz
    if len(path.suffixes) > 1 and double in meshio.extension_to_filetypes:
        ext = double
    if ext in _FORMAT_OVERRIDES:
        return _FORMAT_OVERRIDES[ext]
    if ext in _SURFACE_ONLY:
        raise ParoctError(f"{path}: {ext} holds surfaces only; write tets to .vtu, .msh, .mesh, .inp, .vtk or .xdmf")
    if ext in _BROKEN_WRITERS:
        raise ParoctError(f"{path}: meshio's {_BROKEN_WRITERS[ext]} writer does not give a file of these tets that "
                          "reads back; write .vtu, .msh, .mesh, .inp or .vtk instead")
    formats = meshio.extension_to_filetypes.get(ext)
    if not formats:
        raise ParoctError(f"{path}: unknown mesh format {ext or '(no extension)'!r}; use e.g. .vtu, .msh, .mesh, .inp, .vtk")
    return formats[0], {}


#: Python packages meshio's writer of a format imports, asked for before any work.
_WRITER_PACKAGES = {"xdmf": "h5py", "med": "h5py", "h5m": "h5py", "hmf": "h5py", "cgns": "h5py", "exodus": "netCDF4"}


def checked_output(path: str | os.PathLike, boundary: bool = False) -> tuple[str, dict]:
    """output_format's (format, options) once everything about the output that can be known
    before meshing is right: ParoctError if the format holds no tets (or no boundary patches,
    when boundary), needs a package that is not installed, or the path is a folder or in a
    folder that does not exist."""
    import importlib.util

    path = Path(path)
    fmt, options = output_format(path)
    if boundary and fmt not in _BOUNDARY_FORMATS:
        raise ParoctError(f"{path}: {fmt} files hold no boundary patches here; write .msh, .inp, .mesh, .vtu or .vtk")
    package = _WRITER_PACKAGES.get(fmt)
    if package and importlib.util.find_spec(package) is None:
        raise ParoctError(f"{path}: writing {fmt} needs the package {package}, not installed; install it or write .vtu")
    if path.is_dir():
        raise ParoctError(f"{path}: is a folder; give a file name")
    if path.parent and not path.parent.is_dir():
        raise ParoctError(f"{path}: folder {path.parent} does not exist")
    return fmt, options


def write_mesh(path: str | os.PathLike, points: np.ndarray, tets: np.ndarray, cell_data: dict | None = None,
               boundary: BoundaryPatches | None = None) -> None:
    """Write a tet mesh; the format follows the extension (binary where the format allows).

    points: (N, 3) finite float64; tets: (M, 4) integer ids into points; cell_data: name ->
    (M,) or (M, K) array of integers or floats (bools are written as 0 and 1), in .vtu, .vtk,
    .msh and .xdmf.  boundary: the boundary triangles of these tets tagged by patch
    (paroct.boundary_patches), written after the tets: in Gmsh .msh as physical groups
    named as the patches (``patch_<p>`` for patches by feature angle; dimension 2, tag p)
    beside ``solid`` (3, 1); in Abaqus .inp as element-face surfaces and node sets of those
    names in upper case (``PATCH_<p>``); in Medit .mesh as triangles with
    reference p; in .vtu and .vtk as triangle cells with the cell data ``boundary_patch``
    (p, and 0 on the tets), cell_data arrays padded with zeros there.  ParoctError, stating
    the shapes or the kinds, for anything else.  The same arrays always give the same bytes.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ParoctError(f"path = {path!r}: give a file name (str or pathlib.Path)")
    path = Path(path)
    fmt, options = checked_output(path, boundary is not None)
    points, tets, cell_data = _checked(points, tets, cell_data)
    if cell_data and fmt not in _CELL_DATA_FORMATS:
        raise ParoctError(f"{path}: {fmt} files hold no cell data here; write .vtu, .vtk, .msh or .xdmf")
    if boundary is not None:
        _check_boundary(boundary, points, tets, cell_data)
    try:
        if fmt == "vtu":
            _write_vtu(path, points, tets, *_with_triangles(tets, cell_data, boundary))
        elif fmt == "gmsh":
            _write_gmsh(path, points, tets, boundary, cell_data)
        elif fmt in _TEXT_WRITERS:
            _TEXT_WRITERS[fmt](path, points, tets, boundary)
        else:
            _write_with_meshio(path, fmt, options, points, tets, *_with_triangles(tets, cell_data, boundary))
    except OSError as exc:
        raise ParoctError(f"{path}: cannot write ({exc.strerror or exc})") from None


#: Formats whose files keep cell data and boundary patches as write_mesh writes them (each
#: read back by a test; meshio's Tecplot, FLAC3D, SU2, DOLFIN and TetGen writers drop the
#: triangles or write files that do not read back).
_CELL_DATA_FORMATS = {"vtu", "vtk", "gmsh", "xdmf"}
_BOUNDARY_FORMATS = {"vtu", "vtk", "gmsh", "abaqus", "medit"}


def _check_boundary(boundary, points: np.ndarray, tets: np.ndarray, cell_data: dict) -> None:
    """ParoctError unless boundary is a BoundaryPatches of these tets: each triangle is face
    tet_faces of tet tets (so its ids are points')."""
    from .boundary import BoundaryPatches
    from .topology import TET_FACES

    if not isinstance(boundary, BoundaryPatches):
        raise ParoctError(f"boundary = {type(boundary).__name__}: give the BoundaryPatches of these tets "
                          "(result.boundary_patches())")
    if "boundary_patch" in cell_data:
        raise ParoctError("cell_data['boundary_patch'] is the name the boundary's patches are written under; rename it")
    owner, face = boundary.tets, boundary.tet_faces
    if len(owner) and (owner.min() < 0 or owner.max() >= len(tets) or face.min() < 0 or face.max() > 3):
        raise ParoctError(f"boundary: its triangles name tets {owner.min()} .. {owner.max()} and faces {face.min()} .. "
                          f"{face.max()}, but len(tets) = {len(tets)}: the patches of another mesh?")
    if not np.array_equal(tets[owner[:, None], TET_FACES[face]], boundary.faces):
        raise ParoctError("boundary: its triangles are not the faces of these tets it names: the patches of another mesh?")


def _with_triangles(tets: np.ndarray, cell_data: dict, boundary: BoundaryPatches | None) -> tuple[np.ndarray | None, dict]:
    """The boundary triangles (B, 3) (None without a boundary) and the cell data over the tets
    then the triangles: ``boundary_patch`` added (0 on the tets), the others padded with 0."""
    if boundary is None:
        return None, cell_data
    padded = {name: np.concatenate([values, np.zeros((len(boundary.faces), *values.shape[1:]), dtype=values.dtype)])
              for name, values in cell_data.items()}
    padded["boundary_patch"] = np.concatenate([np.zeros(len(tets), dtype=np.int32), boundary.patches])
    return boundary.faces, padded


def _write_with_meshio(path: Path, fmt: str, options: dict, points: np.ndarray, tets: np.ndarray,
                       triangles: np.ndarray | None, cell_data: dict) -> None:
    import meshio

    blocks = [("tetra", tets.astype(np.int64))]
    data = {name: [values] for name, values in cell_data.items()}
    if triangles is not None and len(triangles):  # meshio's VTK writer fails on an empty block
        blocks.append(("triangle", triangles.astype(np.int64)))
        data = {name: [values[:len(tets)], values[len(tets):]] for name, values in cell_data.items()}
    elif triangles is not None:
        data = {name: [values[:len(tets)]] for name, values in cell_data.items()}
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):  # some writers print their warnings
            meshio.write(path, meshio.Mesh(points, blocks, cell_data=data), file_format=fmt, **options)
    except ImportError as exc:
        raise ParoctError(f"{path}: writing {fmt} needs an extra package ({exc.name or exc}); install it or pick .vtu") from None
    for line in printed.getvalue().splitlines():
        if line.strip():
            warnings.warn(f"meshio: {line.strip()}", stacklevel=3)


def _checked(points, tets, cell_data: dict | None) -> tuple[np.ndarray, np.ndarray, dict]:
    """points as (N, 3) finite float64, tets (M, 4) integer ids into them and cell_data name ->
    (M,) or (M, K) arrays of integers or floats (bools as uint8, float16 as float32), or
    ParoctError stating the shapes or kinds."""
    try:
        points = np.asarray(points, dtype=np.float64)
        tets = np.asarray(tets)
    except (TypeError, ValueError) as exc:
        raise ParoctError(f"points and tets must be (N, 3) and (M, 4) arrays ({exc})") from None
    if points.ndim != 2 or points.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 or tets.dtype.kind not in "iu":
        raise ParoctError(f"points.shape = {points.shape}, tets.shape = {tets.shape} ({tets.dtype}); "
                          "want (N, 3) and (M, 4) integer")
    if tets.size and (tets.min() < 0 or tets.max() >= len(points)):
        raise ParoctError(f"tets hold vertex ids {tets.min()} .. {tets.max()}, len(points) = {len(points)}")
    if not np.all(np.isfinite(points)):
        raise ParoctError("a point coordinate is NaN or infinite")
    if cell_data is not None and not isinstance(cell_data, dict):
        raise ParoctError(f"cell_data = {type(cell_data).__name__}: give a dict of name -> (M,) array")
    checked = {}
    for name, values in (cell_data or {}).items():
        values = np.asarray(values)
        if values.dtype == np.bool_:
            values = values.astype(np.uint8)
        elif values.dtype == np.float16:
            values = values.astype(np.float32)
        if not isinstance(name, str) or values.dtype.kind not in "iuf" or values.ndim not in (1, 2) \
                or values.shape[0] != len(tets):
            raise ParoctError(f"cell_data[{name!r}]: shape {values.shape}, {values.dtype}; want (M,) or (M, K) "
                              f"integers or floats, M = len(tets) = {len(tets)}")
        checked[name] = values
    return points, tets, checked


#: VTK cell types of a linear tetrahedron and triangle.
_VTK_TETRA = 10
_VTK_TRIANGLE = 5
#: Uncompressed bytes per zlib block of a .vtu array (VTK's own writers use 32-64 KiB).
VTU_BLOCK_BYTES = 1 << 16
#: zlib level of .vtu arrays: level 1 compresses tet meshes within 5 % of level 6's size
#: in a quarter of the time.
VTU_ZLIB_LEVEL = 1


def _write_vtu(path: Path, points: np.ndarray, tets: np.ndarray, triangles: np.ndarray | None, cell_data: dict) -> None:
    """VTK XML unstructured grid of tets, then the triangles if any (arrays as _checked and
    _with_triangles return them).

    Every array is inline base64 of zlib-compressed blocks with a UInt64 header
    (``compressor="vtkZLibDataCompressor"``, the layout VTK, ParaView and meshio read).
    Connectivity and offsets are Int32 while they fit (half the bytes of meshio's Int64);
    the blocks are compressed on all cores (zlib releases the GIL).
    """
    n_tets = len(tets)
    n_triangles = 0 if triangles is None else len(triangles)
    n_cells = n_tets + n_triangles
    n_ids = 4 * n_tets + 3 * n_triangles
    index_type = "<i4" if max(len(points), n_ids) < 2**31 else "<i8"
    connectivity = tets.astype(index_type, copy=False).reshape(-1)
    offsets = np.arange(4, 4 * n_tets + 1, 4, dtype=index_type)
    types = np.full(n_cells, _VTK_TETRA, dtype="u1")
    if triangles is not None and n_triangles:
        connectivity = np.concatenate([connectivity, triangles.astype(index_type, copy=False).reshape(-1)])
        offsets = np.concatenate([offsets, np.arange(4 * n_tets + 3, n_ids + 1, 3, dtype=index_type)])
        types[n_tets:] = _VTK_TRIANGLE
    sections = [
        ("Points", [("Points", points.astype("<f8", copy=False))]),
        ("Cells", [("connectivity", connectivity), ("offsets", offsets), ("types", types)]),
        ("CellData", [(name, values.astype(values.dtype.newbyteorder("<"), copy=False))
                      for name, values in cell_data.items()]),
    ]
    # Every array's VTK type before the file is opened: an array it cannot hold leaves no file.
    vtk_types = {(section, name): _vtu_type(values.dtype) for section, arrays in sections for name, values in arrays}
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    with open(path, "wb") as out, ThreadPoolExecutor(min(8, cores)) as pool:
        out.write(b'<?xml version="1.0"?>\n<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" '
                  b'header_type="UInt64" compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
                  + f'<Piece NumberOfPoints="{len(points)}" NumberOfCells="{n_cells}">\n'.encode())
        for section, arrays in sections:
            if not arrays:
                continue
            out.write(f"<{section}>\n".encode())
            for name, values in arrays:
                components = f'NumberOfComponents="{values.shape[1]}" ' if values.ndim == 2 else ""
                out.write(f'<DataArray type="{vtk_types[section, name]}" Name="{name}" {components}format="binary">\n'.encode())
                out.write(_vtu_zlib_base64(values, pool))
                out.write(b"\n</DataArray>\n")
            out.write(f"</{section}>\n".encode())
        out.write(b"</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")


def _vtu_type(dtype: np.dtype) -> str:
    kind = {"f": "Float", "i": "Int", "u": "UInt"}.get(dtype.kind)
    if kind is None:
        raise ValueError(f"cannot write {dtype} arrays to .vtu")
    return f"{kind}{8 * dtype.itemsize}"


def _vtu_zlib_base64(values: np.ndarray, pool: ThreadPoolExecutor) -> bytes:
    """One .vtu binary array: base64 of the UInt64 header (blocks, block size, last block
    size, compressed sizes), then base64 of the compressed blocks (VTK encodes them apart)."""
    raw = np.ascontiguousarray(values).reshape(-1).view(np.uint8).data
    starts = range(0, len(raw), VTU_BLOCK_BYTES)
    blocks = list(pool.map(lambda i: zlib.compress(raw[i:i + VTU_BLOCK_BYTES], VTU_ZLIB_LEVEL), starts))
    last = len(raw) - VTU_BLOCK_BYTES * (len(blocks) - 1) if blocks else 0
    header = np.array([len(blocks), VTU_BLOCK_BYTES, last, *map(len, blocks)], dtype="<u8")
    return base64.b64encode(header.tobytes()) + base64.b64encode(b"".join(blocks))


#: Rows formatted per chunk by the text writers (bounds their memory to about 100 MB).
_TEXT_CHUNK_ROWS = 1 << 20


#: Abaqus's face number (S1 .. S4) of a C3D4 tet's face k, the face opposite its vertex k
#: (topology.TET_FACES): S1 = nodes 1-2-3, S2 = 1-4-2, S3 = 2-4-3, S4 = 3-4-1.
_ABAQUS_FACE = np.array([3, 4, 2, 1])
#: Ids per data line of an Abaqus *ELSET or *NSET (its limit is 16).
_ABAQUS_IDS_PER_LINE = 16


def _write_abaqus(path: Path, points: np.ndarray, tets: np.ndarray, boundary: BoundaryPatches | None = None) -> None:
    """Abaqus / CalculiX input of linear tets (C3D4): *NODE and *ELEMENT blocks, ids from 1,
    coordinates with 17 significant digits (they read back bit for bit).  With a boundary,
    each patch is an element-based *SURFACE named as the patch (_abaqus_names: ``PATCH_<p>``
    for patches by feature angle) over element sets ``<name>_S1`` .. ``_S4`` of the tets whose
    face S1 .. S4 lies on it, and a node set of that name of its triangles' nodes."""
    with open(path, "wb") as out:
        out.write(b"*HEADING\nparoct tet mesh\n*NODE\n")
        _write_points(out, points, "%d, %.17g, %.17g, %.17g\n", with_ids=True)
        out.write(b"*ELEMENT, TYPE=C3D4, ELSET=SOLID\n")
        _write_int_rows(out, tets, b", ", with_ids=True)
        if boundary is None:
            return
        side = _ABAQUS_FACE[boundary.tet_faces]
        for name, on in zip(_abaqus_names(boundary.names), boundary.by_patch()):
            if not on.size:
                continue
            sides = []
            for s in range(1, 5):
                ids = np.sort(boundary.tets[on[side[on] == s]])
                if ids.size:
                    out.write(f"*ELSET, ELSET={name}_S{s}\n".encode())
                    _write_id_lines(out, ids)
                    sides.append(s)
            out.write(f"*SURFACE, NAME={name}, TYPE=ELEMENT\n".encode())
            out.write("".join(f"{name}_S{s}, S{s}\n" for s in sides).encode())
            out.write(f"*NSET, NSET={name}\n".encode())
            _write_id_lines(out, np.unique(boundary.faces[on]))


#: Abaqus names: at most 80 characters, a letter first, then letters, digits and underscores;
#: a patch's element sets add ``_S<k>``.
_ABAQUS_NAME_LENGTH = 80 - 3


def _abaqus_names(names: tuple[str, ...]) -> list[str]:
    """The patches' names as Abaqus takes them, upper case and distinct (Abaqus ignores case):
    other characters become ``_``, a name not starting with a letter gets ``P_`` before it, a
    long one is cut, and one already taken gets ``_<p>`` (its patch) after it."""
    out, taken = [], set()
    for p, name in enumerate(names, start=1):
        name = re.sub(r"[^A-Z0-9_]", "_", name.upper())
        name = name if name[:1].isalpha() else "P_" + name
        name = name[:_ABAQUS_NAME_LENGTH]
        base, k = name, 1
        while name in taken:  # "a", "A", "A_2" -> A, A_2, A_2_3
            tail = f"_{p}" if k == 1 else f"_{p}_{k}"
            name, k = base[:_ABAQUS_NAME_LENGTH - len(tail)] + tail, k + 1
        taken.add(name)
        out.append(name)
    return out


#: Bytes (UTF-8) of a physical name in the .msh files paroct writes: Gmsh 4.15 failed to
#: open a file with a name of 253 characters and dropped every physical group at 254 or more.
_GMSH_NAME_BYTES = 128


def _gmsh_names(names: tuple[str, ...]) -> list[str]:
    """The patches' names as Gmsh and meshio read them back: a quoted string on one line, so
    quotes, backslashes (meshio splits the line as a shell would) and control characters
    become ``_``; cut to _GMSH_NAME_BYTES bytes of UTF-8 (whole characters), and one
    already taken (or "solid", the volume's) gets ``_<p>`` (its patch) after it."""
    out, taken = [], {"solid"}
    for p, name in enumerate(names, start=1):
        name = _utf8_prefix(re.sub(r'["\\\x00-\x1f\x7f]', "_", name), _GMSH_NAME_BYTES)
        base, k = name, 1
        while name in taken:
            tail = f"_{p}" if k == 1 else f"_{p}_{k}"
            name, k = _utf8_prefix(base, _GMSH_NAME_BYTES - len(tail)) + tail, k + 1
        taken.add(name)
        out.append(name)
    return out


def _utf8_prefix(text: str, n_bytes: int) -> str:
    """The longest prefix of text whose UTF-8 takes at most n_bytes bytes."""
    return text.encode("utf-8")[:n_bytes].decode("utf-8", errors="ignore")


def _write_id_lines(out, ids: np.ndarray) -> None:
    """0-based ids (K,) as 1-based Abaqus data lines of _ABAQUS_IDS_PER_LINE ids each."""
    full = len(ids) - len(ids) % _ABAQUS_IDS_PER_LINE
    _write_int_rows(out, ids[:full].reshape(-1, _ABAQUS_IDS_PER_LINE), b", ", with_ids=False)
    if full < len(ids):
        _write_int_rows(out, ids[full:].reshape(1, -1), b", ", with_ids=False)


def _write_medit(path: Path, points: np.ndarray, tets: np.ndarray, boundary: BoundaryPatches | None = None) -> None:
    """Medit .mesh (MMG, FreeFem) of tets, ASCII, double precision: every vertex and tet with
    reference 1, the boundary's triangles (if given) with their patch as reference;
    coordinates with 17 significant digits (they read back bit for bit)."""
    with open(path, "wb") as out:
        out.write(f"MeshVersionFormatted 2\nDimension 3\nVertices\n{len(points)}\n".encode())
        _write_points(out, points, "%.17g %.17g %.17g 1\n", with_ids=False)
        out.write(f"Tetrahedra\n{len(tets)}\n".encode())
        _write_int_rows(out, tets, b" ", with_ids=False, reference=1)
        if boundary is not None:
            out.write(f"Triangles\n{len(boundary.faces)}\n".encode())
            # _write_int_rows writes every value + 1: the patch - 1 column comes out as the patch.
            rows = np.column_stack([boundary.faces, boundary.patches - 1])
            _write_int_rows(out, rows, b" ", with_ids=False)
        out.write(b"End\n")


def _write_gmsh(path: Path, points: np.ndarray, tets: np.ndarray, boundary: BoundaryPatches | None = None,
                cell_data: dict | None = None) -> None:
    """Gmsh MSH 4.1, binary: the tets as volume entity 1 in the physical group ``solid`` (3, 1);
    with a boundary, each patch p as surface entity p in the physical group (2, p) named as the
    patch (``patch_<p>`` for patches by feature angle), its triangles after the tets, patch by patch.  Node and element tags from 1, in
    array order; the nodes are one block of the volume (Gmsh finds a group's nodes through its
    elements, and readers that number points by block, as meshio does, keep the order).  Each
    cell_data array is an $ElementData block over every element (0 on the triangles), as doubles."""
    n_patches = 0 if boundary is None else boundary.n_patches
    size_t, c_int = np.dtype("<u8"), np.dtype("<i4")

    def ints(values, dtype=c_int) -> bytes:
        return np.asarray(values, dtype=dtype).tobytes()

    def box(corners: np.ndarray) -> bytes:  # a kernel: numpy's min along axis 0 took 1.5 s of 4 M tets
        return np.concatenate(bounding_box(corners)[:2] if len(corners) else [np.zeros(6)]).astype("<f8").tobytes()

    patch_faces = [] if boundary is None else [boundary.faces[on] for on in boundary.by_patch()]
    with open(path, "wb") as out:
        out.write(b"$MeshFormat\n4.1 1 8\n" + ints([1]) + b"\n$EndMeshFormat\n")
        names = [(3, 1, "solid")] + [(2, p, name) for p, name in
                                     enumerate(_gmsh_names(() if boundary is None else boundary.names), start=1)]
        out.write(f"$PhysicalNames\n{len(names)}\n".encode())
        out.write("".join(f'{dim} {tag} "{name}"\n' for dim, tag, name in names).encode() + b"$EndPhysicalNames\n")
        # Entities: surfaces (tag, box, physical tags, bounding curves), then the volume
        # (tag, box, physical tags, bounding surfaces).
        out.write(b"$Entities\n" + ints([0, 0, n_patches, 1], size_t))
        for p, faces in enumerate(patch_faces, start=1):
            out.write(ints([p]) + box(points[np.unique(faces)]) + ints([1], size_t) + ints([p]) + ints([0], size_t))
        out.write(ints([1]) + box(points) + ints([1], size_t) + ints([1]) + ints([n_patches], size_t)
                  + ints(np.arange(1, n_patches + 1)) + b"\n$EndEntities\n")
        out.write(b"$Nodes\n" + ints([1, len(points), 1, len(points)], size_t) + ints([3, 1, 0]) + ints([len(points)], size_t))
        # Arrays are written through their buffers, uncopied.
        out.write(np.arange(1, len(points) + 1, dtype=size_t).data)
        out.write(np.ascontiguousarray(points, dtype="<f8").data)
        out.write(b"\n$EndNodes\n")
        blocks = [(3, 1, _GMSH_TETRA, tets)] + [(2, p, _GMSH_TRIANGLE, f) for p, f in enumerate(patch_faces, start=1)
                                                if len(f)]  # an empty block is legal, but meshio cannot read it
        n_elements = sum(len(rows) for *_, rows in blocks)
        out.write(b"$Elements\n" + ints([len(blocks), n_elements, 1, n_elements], size_t))
        tag = 1
        for dim, entity, kind, rows in blocks:
            table = np.empty((len(rows), rows.shape[1] + 1), dtype=size_t)
            table[:, 0] = np.arange(tag, tag + len(rows))
            table[:, 1:] = rows + 1
            out.write(ints([dim, entity, kind]) + ints([len(rows)], size_t))
            out.write(table.data)
            tag += len(rows)
        out.write(b"\n$EndElements\n")
        for name, values in (cell_data or {}).items():
            columns = values.reshape(len(tets), -1)
            rows = np.zeros(n_elements, dtype=[("tag", c_int), ("values", "<f8", (columns.shape[1],))])
            rows["tag"] = np.arange(1, n_elements + 1)
            rows["values"][:len(tets)] = columns
            out.write(f'$ElementData\n1\n"{name}"\n1\n0.0\n3\n0\n{columns.shape[1]}\n{n_elements}\n'.encode())
            out.write(rows.data)
            out.write(b"\n$EndElementData\n")


#: Gmsh element types of a 4-node tetrahedron and a 3-node triangle.
_GMSH_TETRA = 4
_GMSH_TRIANGLE = 2


#: meshio format name -> paroct's own writer (no cell data).
_TEXT_WRITERS = {"abaqus": _write_abaqus, "medit": _write_medit}


def _write_points(out, points: np.ndarray, line: str, with_ids: bool) -> None:
    """points (N, 3) as text lines of the %-format line (ids from 1 first if with_ids)."""
    for lo in range(0, len(points), _TEXT_CHUNK_ROWS):
        chunk = points[lo:lo + _TEXT_CHUNK_ROWS]
        if with_ids:
            rows = np.empty((len(chunk), 4), dtype=object)
            rows[:, 0] = range(lo + 1, lo + 1 + len(chunk))
            rows[:, 1:] = chunk
            values = tuple(rows.ravel().tolist())
        else:
            values = tuple(chunk.ravel().tolist())
        out.write(((line * len(chunk)) % values).encode())


def _write_int_rows(out, tets: np.ndarray, sep: bytes, with_ids: bool, reference: int = -1) -> None:
    """tets (M, 4) as text lines of 1-based ids joined by sep, after the element id (from 1)
    if with_ids, before reference if it is not negative."""
    sep_bytes = np.frombuffer(sep, dtype=np.uint8)
    for lo in range(0, len(tets), _TEXT_CHUNK_ROWS):
        chunk = np.ascontiguousarray(tets[lo:lo + _TEXT_CHUNK_ROWS], dtype=np.int64)
        out.write(_int_lines(chunk, lo + 1 if with_ids else -1, reference, sep_bytes).tobytes())


@nb.njit(cache=True)
def _decimal_digits(v):
    """Digits of v >= 0 in decimal."""
    n = 1
    while v >= 10000:
        v //= 10000
        n += 4
    return n + (v >= 10) + (v >= 100) + (v >= 1000)


@nb.njit(cache=True)
def _int_lines(rows, first_id, reference, sep):
    """ASCII lines, one per row of rows (M, K) int64 >= 0: [id,] row + 1 [, reference], the
    values in decimal joined by sep (uint8); the id (first_id + row index) only if first_id
    >= 0, the reference only if it is >= 0.  Two passes: line lengths, then the bytes."""
    m, k = rows.shape
    n_values = k + (first_id >= 0) + (reference >= 0)
    fixed = (n_values - 1) * len(sep) + 1 + (_decimal_digits(reference) if reference >= 0 else 0)
    ends = np.empty(m + 1, dtype=np.int64)
    ends[0] = 0
    for i in range(m):
        n = fixed
        for j in range(k):
            n += _decimal_digits(rows[i, j] + 1)
        if first_id >= 0:
            n += _decimal_digits(first_id + i)
        ends[i + 1] = ends[i] + n
    out = np.empty(ends[m], dtype=np.uint8)
    values = np.empty(k + 2, dtype=np.int64)
    for i in range(m):
        n = 0
        if first_id >= 0:
            values[n] = first_id + i
            n += 1
        for j in range(k):
            values[n] = rows[i, j] + 1
            n += 1
        if reference >= 0:
            values[n] = reference
        p = ends[i]
        for j in range(n_values):
            if j:
                for c in range(len(sep)):
                    out[p] = sep[c]
                    p += 1
            q = p + _decimal_digits(values[j])
            p = q
            v = np.uint64(values[j])  # unsigned: division by 10 without floor-division fix-ups
            while True:
                q -= 1
                d = v // np.uint64(10)
                out[q] = np.uint8(np.uint64(48) + v - d * np.uint64(10))
                v = d
                if v == 0:
                    break
        out[p] = 10
    return out


def _read_gmsh_tets(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """Points and tets of a Gmsh MSH file (paroct.msh), None if the file is no Gmsh MSH
    (an ANSYS .msh); ParoctError for a damaged one or one without tets."""
    from .msh import TETRA, MshError, is_msh, read_msh, type_name

    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ParoctError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not is_msh(data):
        return None
    try:
        msh = read_msh(data)
    except MshError as exc:
        raise ParoctError(f"cannot read {path} as Gmsh MSH: {exc}") from None
    if TETRA not in msh.elements or not len(msh.elements[TETRA].nodes):
        kinds = sorted(type_name(kind) for kind in msh.elements) or ["none"]
        raise ParoctError(f"{path} holds no tetrahedra (cells: {', '.join(kinds)})")
    return msh.points, msh.elements[TETRA].nodes


def read_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) float64 and tets (M, 4) int64 of a volume mesh file."""
    import meshio

    path = Path(path)
    regular_file(path, "a mesh file")
    ext = path.suffix.lower()
    formats: list[str | None] = [None]  # meshio's choice by extension
    if ext in _FORMAT_OVERRIDES:  # ours first, then any other format of the extension (.msh: Gmsh, ANSYS)
        ours = _FORMAT_OVERRIDES[ext][0]
        formats = [ours] + [f for f in meshio.extension_to_filetypes.get(ext, []) if f != ours]
    if ext == ".msh":
        gmsh = _read_gmsh_tets(path)
        if gmsh is not None:
            return gmsh
        formats.remove("gmsh")
    raw, first_error, said = None, None, ""
    for fmt in formats:
        # meshio prints a reader's complaint (stdout) and its own (stderr), then exits: the
        # reader's complaint, if it has one, is the reason.
        printed = io.StringIO()
        try:
            with contextlib.redirect_stdout(printed), contextlib.redirect_stderr(io.StringIO()):
                raw = meshio.read(path, file_format=fmt)
            break
        except (Exception, SystemExit) as exc:
            text = printed.getvalue() if isinstance(exc, SystemExit) else str(exc)
            lines = [line.strip() for line in text.splitlines() if line.strip()]
            if isinstance(exc, KeyError) and exc.args:  # a cell naming a node the file lacks
                lines = [f"a cell refers to node {exc.args[0]}, "
                         "which the file does not define"]
            elif "need at least one array to concatenate" in text:  # meshio's .vtu reader on no cells
                lines = ["it holds no cells"]
            said = said or (lines[0] if lines else "")
            first_error = first_error or said or f"not a {fmt or ext} file, or a damaged one"
    if raw is None:
        if ext == ".msh":
            raise ParoctError(f"cannot read {path}: not a Gmsh MSH file (it does not start with $MeshFormat), "
                              f"nor an ANSYS one" + (f" (meshio: {said})" if said else ""))
        tried = f" (read as {' and as '.join(str(f) for f in formats)})" if len(formats) > 1 else ""
        raise ParoctError(f"cannot read {path}{tried}: {first_error}")
    blocks = [np.asarray(b.data, dtype=np.int64).reshape(-1, 4) for b in raw.cells if b.type == "tetra"]
    if not sum(len(b) for b in blocks):
        kinds = sorted({b.type for b in raw.cells}) or ["none"]
        raise ParoctError(f"{path} holds no tetrahedra (cells: {', '.join(kinds)})")
    return np.asarray(raw.points, dtype=np.float64)[:, :3], np.concatenate(blocks)
