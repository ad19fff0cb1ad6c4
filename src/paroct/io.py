"""Write and read tet meshes through meshio: the package's only meshio edge besides surface input."""

from __future__ import annotations

import os
from pathlib import Path

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
    import meshio

    path = Path(path)

    ext = path.suffix.lower()
    if ext in _FORMAT_OVERRIDES:
        return _FORMAT_OVERRIDES[ext]
    if ext in _SURFACE_ONLY:
        raise ParoctError(f"{path}: {ext} holds surfaces only; write tets to .vtu, .msh, .mesh, .inp, .vtk or .xdmf")
    formats = meshio.extension_to_filetypes.get(ext)
    if not formats:
        raise ParoctError(f"{path}: unknown mesh format {ext or '(no extension)'!r}; use e.g. .vtu, .msh, .mesh, .inp, .vtk")
    return formats[0], {}


def write_mesh(path: str | os.PathLike, points: np.ndarray, tets: np.ndarray, cell_data: dict | None = None) -> None:
    """Write a tet mesh; the format follows the extension (binary where the format allows).

    points: (N, 3) float64; tets: (M, 4) integer; cell_data: name -> (M,) array.
    The same arrays always give the same bytes.
    """
    import meshio

    path = Path(path)
    fmt, options = output_format(path)
    mesh = meshio.Mesh(
        np.asarray(points, dtype=np.float64),
        [("tetra", np.asarray(tets, dtype=np.int64))],
        cell_data={k: [np.asarray(v)] for k, v in (cell_data or {}).items()},
    )
    if path.parent and not path.parent.exists():
        raise ParoctError(f"{path}: folder {path.parent} does not exist")
    try:
        meshio.write(path, mesh, file_format=fmt, **options)
    except ImportError as exc:
        raise ParoctError(f"{path}: writing {fmt} needs an extra package ({exc.name or exc}); install it or pick .vtu") from None
    except OSError as exc:
        raise ParoctError(f"{path}: cannot write ({exc.strerror or exc})") from None


def read_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) float64 and tets (M, 4) int64 of a volume mesh file."""
    import meshio

    path = Path(path)
    if not path.exists():
        raise ParoctError(f"no such file: {path}")
    ext = path.suffix.lower()
    fmt = _FORMAT_OVERRIDES[ext][0] if ext in _FORMAT_OVERRIDES else None
    try:
        raw = meshio.read(path, file_format=fmt)
    except (Exception, SystemExit) as exc:
        text = str(exc).strip()
        msg = text.splitlines()[0] if text and not isinstance(exc, SystemExit) else "malformed file"
        raise ParoctError(f"cannot read {path}: {msg}") from None
    blocks = [np.asarray(b.data, dtype=np.int64) for b in raw.cells if b.type == "tetra"]
    if not blocks:
        kinds = sorted({b.type for b in raw.cells}) or ["none"]
        raise ParoctError(f"{path} holds no tetrahedra (cells: {', '.join(kinds)})")
    return np.asarray(raw.points, dtype=np.float64)[:, :3], np.concatenate(blocks)
