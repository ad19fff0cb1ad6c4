"""Write and read tet meshes: meshio for every format, except .vtu (the default output), Abaqus
.inp and Medit .mesh, which paroct writes itself (4 M tets: 0.9, 3.1 and 2.3 s against
meshio's 5.8, 20 and 31 s); the package's only meshio edge besides surface input."""

from __future__ import annotations

import base64
import contextlib
import io
import os
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numba as nb
import numpy as np

from .errors import ParoctError

#: meshio format to use for an extension where meshio's own default is wrong or ambiguous
#: (.msh maps to ANSYS first), with the options that make the output binary where allowed.
_FORMAT_OVERRIDES = {
    ".msh": ("gmsh", {"binary": True}),
    ".vtk": ("vtk", {"binary": True}),
    ".vtu": ("vtu", {"binary": True}),
}
#: Surface-only formats, which cannot hold tets.
_SURFACE_ONLY = {".stl", ".obj", ".off", ".ply", ".wrl", ".svg"}


def output_format(path: str | os.PathLike) -> tuple[str, dict]:
    """The meshio format name and writer options for an output path; ParoctError if it cannot hold tets."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext in _FORMAT_OVERRIDES:
        return _FORMAT_OVERRIDES[ext]
    if ext in _SURFACE_ONLY:
        raise ParoctError(f"{path}: {ext} holds surfaces only; write tets to .vtu, .msh, .mesh, .inp, .vtk or .xdmf")
    import meshio

    formats = meshio.extension_to_filetypes.get(ext)
    if not formats:
        raise ParoctError(f"{path}: unknown mesh format {ext or '(no extension)'!r}; use e.g. .vtu, .msh, .mesh, .inp, .vtk")
    return formats[0], {}


def write_mesh(path: str | os.PathLike, points: np.ndarray, tets: np.ndarray, cell_data: dict | None = None) -> None:
    """Write a tet mesh; the format follows the extension (binary where the format allows).

    points: (N, 3) float64; tets: (M, 4) integer ids into points; cell_data: name -> (M,)
    array (ValueError, with the shapes, for anything else).  The same arrays always give the
    same bytes.
    """
    path = Path(path)
    fmt, options = output_format(path)
    if path.parent and not path.parent.exists():
        raise ParoctError(f"{path}: folder {path.parent} does not exist")
    points, tets, cell_data = _checked(points, tets, cell_data)
    try:
        if fmt == "vtu":
            _write_vtu(path, points, tets, cell_data)
        elif fmt in _TEXT_WRITERS and not cell_data:  # with cell data, meshio's writer keeps what the format can
            _TEXT_WRITERS[fmt](path, points, tets)
        else:
            _write_with_meshio(path, fmt, options, points, tets, cell_data)
    except OSError as exc:
        raise ParoctError(f"{path}: cannot write ({exc.strerror or exc})") from None


def _write_with_meshio(path: Path, fmt: str, options: dict, points: np.ndarray, tets: np.ndarray, cell_data: dict) -> None:
    import meshio

    mesh = meshio.Mesh(points, [("tetra", tets.astype(np.int64))], cell_data={k: [v] for k, v in cell_data.items()})
    try:
        meshio.write(path, mesh, file_format=fmt, **options)
    except ImportError as exc:
        raise ParoctError(f"{path}: writing {fmt} needs an extra package ({exc.name or exc}); install it or pick .vtu") from None


def _checked(points, tets, cell_data: dict | None) -> tuple[np.ndarray, np.ndarray, dict]:
    """points as (N, 3) float64, tets (M, 4) integer ids into them and cell_data name -> (M, ...)
    arrays, or ValueError stating the shapes."""
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets)
    if points.ndim != 2 or points.shape[1] != 3 or tets.ndim != 2 or tets.shape[1] != 4 or tets.dtype.kind not in "iu":
        raise ValueError(f"points.shape = {points.shape}, tets.shape = {tets.shape} ({tets.dtype}); "
                         "want (N, 3) and (M, 4) integer")
    if tets.size and (tets.min() < 0 or tets.max() >= len(points)):
        raise ValueError(f"tets hold vertex ids {tets.min()} .. {tets.max()}, len(points) = {len(points)}")
    cell_data = {name: np.asarray(values) for name, values in (cell_data or {}).items()}
    for name, values in cell_data.items():
        if values.shape[:1] != (len(tets),):
            raise ValueError(f"cell_data[{name!r}].shape = {values.shape}, len(tets) = {len(tets)}")
    return points, tets, cell_data


#: VTK cell type of a linear tetrahedron.
_VTK_TETRA = 10
#: Uncompressed bytes per zlib block of a .vtu array (VTK's own writers use 32-64 KiB).
VTU_BLOCK_BYTES = 1 << 16
#: zlib level of .vtu arrays: level 1 compresses tet meshes within 5 % of level 6's size
#: in a quarter of the time.
VTU_ZLIB_LEVEL = 1


def _write_vtu(path: Path, points: np.ndarray, tets: np.ndarray, cell_data: dict) -> None:
    """VTK XML unstructured grid of tets (arrays as _checked returns them).

    Every array is inline base64 of zlib-compressed blocks with a UInt64 header
    (``compressor="vtkZLibDataCompressor"``, the layout VTK, ParaView and meshio read).
    Connectivity and offsets are Int32 while they fit (half the bytes of meshio's Int64);
    the blocks are compressed on all cores (zlib releases the GIL).
    """
    n_cells = len(tets)
    index_type = "<i4" if max(len(points), 4 * n_cells) < 2**31 else "<i8"
    sections = [
        ("Points", [("Points", points.astype("<f8", copy=False))]),
        ("Cells", [("connectivity", tets.astype(index_type, copy=False).reshape(-1)),
                   ("offsets", np.arange(4, 4 * n_cells + 1, 4, dtype=index_type)),
                   ("types", np.full(n_cells, _VTK_TETRA, dtype="u1"))]),
        ("CellData", [(name, values.astype(values.dtype.newbyteorder("<"), copy=False))
                      for name, values in cell_data.items()]),
    ]
    # Every array's VTK type before the file is opened: an array it cannot hold leaves no file.
    types = {(section, name): _vtu_type(values.dtype) for section, arrays in sections for name, values in arrays}
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
                out.write(f'<DataArray type="{types[section, name]}" Name="{name}" {components}format="binary">\n'.encode())
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
    raw = memoryview(np.ascontiguousarray(values).reshape(-1).view(np.uint8))
    starts = range(0, len(raw), VTU_BLOCK_BYTES)
    blocks = list(pool.map(lambda i: zlib.compress(raw[i:i + VTU_BLOCK_BYTES], VTU_ZLIB_LEVEL), starts))
    last = len(raw) - VTU_BLOCK_BYTES * (len(blocks) - 1) if blocks else 0
    header = np.array([len(blocks), VTU_BLOCK_BYTES, last, *map(len, blocks)], dtype="<u8")
    return base64.b64encode(header.tobytes()) + base64.b64encode(b"".join(blocks))


#: Rows formatted per chunk by the text writers (bounds their memory to about 100 MB).
_TEXT_CHUNK_ROWS = 1 << 20


def _write_abaqus(path: Path, points: np.ndarray, tets: np.ndarray) -> None:
    """Abaqus / CalculiX input of linear tets (C3D4): *NODE and *ELEMENT blocks, ids from 1,
    coordinates with 17 significant digits (they read back bit for bit)."""
    with open(path, "wb") as out:
        out.write(b"*HEADING\nparoct tet mesh\n*NODE\n")
        _write_points(out, points, "%d, %.17g, %.17g, %.17g\n", with_ids=True)
        out.write(b"*ELEMENT, TYPE=C3D4\n")
        _write_int_rows(out, tets, b", ", with_ids=True)


def _write_medit(path: Path, points: np.ndarray, tets: np.ndarray) -> None:
    """Medit .mesh (MMG, FreeFem) of tets, ASCII, double precision: every vertex and tet with
    reference 1; coordinates with 17 significant digits (they read back bit for bit)."""
    with open(path, "wb") as out:
        out.write(f"MeshVersionFormatted 2\nDimension 3\nVertices\n{len(points)}\n".encode())
        _write_points(out, points, "%.17g %.17g %.17g 1\n", with_ids=False)
        out.write(f"Tetrahedra\n{len(tets)}\n".encode())
        _write_int_rows(out, tets, b" ", with_ids=False, reference=1)
        out.write(b"End\n")


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
    sep = np.frombuffer(sep, dtype=np.uint8)
    for lo in range(0, len(tets), _TEXT_CHUNK_ROWS):
        chunk = np.ascontiguousarray(tets[lo:lo + _TEXT_CHUNK_ROWS], dtype=np.int64)
        out.write(_int_lines(chunk, lo + 1 if with_ids else -1, reference, sep).tobytes())


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


def read_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) float64 and tets (M, 4) int64 of a volume mesh file."""
    import meshio

    path = Path(path)
    if not path.exists():
        raise ParoctError(f"no such file: {path}")
    ext = path.suffix.lower()
    formats = [None]  # meshio's choice by extension
    if ext in _FORMAT_OVERRIDES:  # ours first, then any other format of the extension (.msh: Gmsh, ANSYS)
        ours = _FORMAT_OVERRIDES[ext][0]
        formats = [ours] + [f for f in meshio.extension_to_filetypes.get(ext, []) if f != ours]
    raw, first_error = None, None
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
            first_error = first_error or (lines[0] if lines else f"not a {fmt or ext} file, or a damaged one")
    if raw is None:
        tried = f" (read as {' and as '.join(formats)})" if len(formats) > 1 else ""
        raise ParoctError(f"cannot read {path}{tried}: {first_error}")
    blocks = [np.asarray(b.data, dtype=np.int64) for b in raw.cells if b.type == "tetra"]
    if not blocks:
        kinds = sorted({b.type for b in raw.cells}) or ["none"]
        raise ParoctError(f"{path} holds no tetrahedra (cells: {', '.join(kinds)})")
    return np.asarray(raw.points, dtype=np.float64)[:, :3], np.concatenate(blocks)
