"""Read surface files: STL (binary and ASCII), OBJ, OFF and PLY (ASCII and binary).

Each reader returns vertices (V, 3) and triangles (F, 3) int64, polygons split into fans,
and the named groups the file puts its triangles in where it has two or more (the solids
of an ASCII STL, the ``g`` or ``o`` statements of an OBJ, the physical or CAD surfaces of a
Gmsh MSH: CAD programs export a part's faces or bodies so, and they are the patches
boundary conditions go on), or raises ParoctError saying what is wrong and where.  MSH is
read by paroct.msh.  paroct reads these formats itself:
meshio's readers refused valid files (OBJ with negative or ``v/vt`` indices, PLY with its
properties in another order or its list named ``vertex_index``, OFF with quads or colours,
STL with a byte-order mark), and walked a binary PLY whose header claimed 2e9 faces for
minutes.  Nothing here trusts a count in a header before checking it against the file's size.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any, Callable, NamedTuple

import numpy as np

from .errors import ParoctError

#: Surface formats paroct reads, by file extension.
SURFACE_EXTENSIONS = (".stl", ".obj", ".off", ".ply", ".msh")


class _Malformed(Exception):
    """A reader's complaint, turned into ParoctError with the file's name and format."""


class SurfaceFile(NamedTuple):
    """What a surface file holds.  vertices: (V, 3), float32 for binary STL (as stored), else
    float64; faces: (F, 3) int64, polygons split into fans; face_groups: (F,) int32, the group
    0 .. G - 1 of each triangle, or None when the file names fewer than two groups;
    group_names: the G names, in order of first appearance."""

    vertices: np.ndarray
    faces: np.ndarray
    face_groups: np.ndarray | None = None
    group_names: tuple[str, ...] = ()


def read_surface_file(path: str | os.PathLike) -> SurfaceFile:
    """The vertices, triangles and named groups (SurfaceFile) of a surface file (STL, OBJ,
    OFF, PLY, MSH).  Raises ParoctError for a missing or unreadable file, something that is not a
    regular file (a folder, a pipe), an unknown extension or a malformed file."""
    path = Path(path)
    regular_file(path, "a surface file")
    ext = path.suffix.lower()
    if ext not in SURFACE_EXTENSIONS:
        raise ParoctError(f"unknown surface format {ext or '(no extension)'!r} of {path}; use one of {', '.join(SURFACE_EXTENSIONS)}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ParoctError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        vertices, faces, face_groups, group_names = _READERS[ext](data)
    except _Malformed as exc:
        raise ParoctError(f"cannot read {path} as {ext[1:].upper()}: {exc}") from None
    if faces.size and (faces.min() < 0 or faces.max() >= vertices.shape[0]):
        bad = int(faces.min()) if faces.min() < 0 else int(faces.max())
        raise ParoctError(f"cannot read {path} as {ext[1:].upper()}: a face refers to vertex {bad + 1} "
                          f"(counting from 1), but there are {vertices.shape[0]} vertices")
    return SurfaceFile(vertices, faces, face_groups, group_names)


def regular_file(path: Path, what: str) -> None:
    """ParoctError unless path names a regular file: missing, unreadable, a directory, or a
    pipe, socket or device (whose open would block, or whose reading would never end)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise ParoctError(f"no such file: {path}") from None
    except OSError as exc:
        raise ParoctError(f"cannot read {path}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise ParoctError(f"{path} is a directory, not {what}")
    if not stat.S_ISREG(mode):
        raise ParoctError(f"{path} is not a regular file (a pipe, socket or device); save it to a file first")


def _text(data: bytes) -> str:
    """The file as text: UTF-8 (a byte-order mark dropped), as CAD programs write names
    today; a file that is not valid UTF-8 as Latin-1, every byte a character (names and
    comments of older files may hold any)."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _numbers(tokens, dtype, what: str) -> np.ndarray:
    """The tokens (strs) as an array of dtype, or _Malformed naming the first bad one.  Python's
    number syntax is wider than a file's: '1_0' would read as 10, so underscores are refused."""
    try:
        if "_" not in "".join(tokens):
            return np.array(tokens, dtype=dtype)
    except (ValueError, OverflowError):
        pass
    for token in tokens:  # name the first bad token (only on the error path)
        try:
            _number(token, dtype)
        except (ValueError, OverflowError):
            raise _Malformed(f"{what} {token!r} is not {'an integer' if dtype is np.int64 else 'a number'}") from None
    raise _Malformed(f"{what}s do not read as numbers")


def _number(word: str, kind):
    """word as kind (int, float or a numpy scalar type) in a file's syntax: Python's also takes
    '1_0' for 10, a ValueError here."""
    if "_" in word:
        raise ValueError(f"invalid literal: {word!r}")
    return kind(word)


def _named_groups(names: list, triangles: np.ndarray | None = None) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """(face_groups, group_names) of items named names[i], each standing for triangles[i]
    triangles (1 each if None): groups numbered in order of first appearance, same name same
    group; (None, ()) if fewer than two."""
    order = dict.fromkeys(names)
    if len(order) < 2:
        return None, ()
    index = {name: i for i, name in enumerate(order)}
    groups = np.array([index[name] for name in names], dtype=np.int32)
    return (groups if triangles is None else np.repeat(groups, triangles)), tuple(order)


def _fans(polygons: list) -> np.ndarray:
    """Triangles (F, 3) int64 of polygons (lists of vertex ids), each split as a fan."""
    tris = [(p[0], p[k], p[k + 1]) for p in polygons for k in range(1, len(p) - 1)]
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


# --- STL ---------------------------------------------------------------------------------

#: A binary STL facet: normal, three corners (float32) and an attribute word, 50 bytes.
_STL_FACET = np.dtype([("normal", "<f4", (3,)), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])


def _read_stl(data: bytes) -> SurfaceFile:
    """Binary STL (84-byte header with the facet count, then 50-byte facets; bytes past the
    last facet, which some exporters pad, ignored; a count of 0 before whole facets read as
    their number), or ASCII STL when the file is text that
    starts with ``solid`` and is not exactly a binary STL's size (UTF-16 text too, by its
    byte-order mark).  The corners are a soup, faces (F, 3) = 0 .. 3F - 1; binary corners
    stay float32 (_weld compares their bits)."""
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):
        try:
            return _read_ascii_stl(data.decode("utf-16"))
        except UnicodeDecodeError:
            pass
    n = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0]) if len(data) >= 84 else -1
    if len(data) != 84 + 50 * n and _looks_like_text(data[:512]):
        return _read_ascii_stl(_text(data))
    if n < 0 or len(data) < 84 + 50 * n:
        have = f"{len(data)} bytes" if n < 0 else f"{len(data)} bytes, its header says {n} triangles (84 + 50 x {n} = {84 + 50 * n} bytes)"
        raise _Malformed(f"neither ASCII STL (text starting with 'solid') nor a complete binary STL: {have}; "
                         "truncated or not an STL file")
    if n == 0 and len(data) > 84 and (len(data) - 84) % 50 == 0:
        n = (len(data) - 84) // 50  # a writer that streamed its facets and never wrote their count
    facets = np.frombuffer(data, dtype=_STL_FACET, count=n, offset=84)
    corners = np.ascontiguousarray(facets["corners"]).reshape(-1, 3)
    return SurfaceFile(corners, np.arange(3 * n, dtype=np.int64).reshape(n, 3))


def binary_stl_count_note(path: str | os.PathLike) -> str:
    """'' unless path is a binary STL whose header counts fewer facets than the whole 50-byte
    records after it: then a clause saying so, for the error of a surface that came out open
    or empty (the records past the count are read as padding, _read_stl)."""
    try:
        with open(path, "rb") as f:
            head = f.read(84)
            size = os.fstat(f.fileno()).st_size
    except OSError:
        return ""
    if len(head) < 84 or _looks_like_text(head) or (size - 84) % 50:
        return ""
    n, held = int(np.frombuffer(head, dtype="<u4", count=1, offset=80)[0]), (size - 84) // 50
    if held <= n:
        return ""
    return (f"; its header counts {n} triangles, but {held} whole 50-byte facet records follow the header "
            "(those past the count are read as padding): was the count written wrong?")


def _looks_like_text(start: bytes) -> bool:
    """Whether a file starting with these bytes may be ASCII STL: 'solid' after an optional
    byte-order mark and whitespace, and no NUL or other control bytes but whitespace."""
    start = start[3:] if start.startswith(b"\xef\xbb\xbf") else start
    if not start.lstrip().lower().startswith(b"solid"):
        return False
    return not any(b < 9 or 13 < b < 32 for b in start)


def _read_ascii_stl(text: str) -> SurfaceFile:
    """ASCII STL: ``solid [name]``, then facets ``facet normal ... outer loop vertex x y z
    (3 x) endloop endfacet``, ``endsolid``; several solids one after another (keywords in any
    case), each a group named by its ``solid`` line (``solid_<k>`` if it names none)."""
    lower = text.translate(_ASCII_LOWER)  # one character for one: positions stay those of text
    solids = _stl_solid_lines(text, lower)
    if len(solids) < 2:
        return SurfaceFile(*_ascii_stl_corners(lower.split()))
    parts = []
    for k, (body, name) in enumerate(solids):
        end = solids[k + 1][0] if k + 1 < len(solids) else len(lower)
        try:
            parts.append(_ascii_stl_corners(lower[body:end].split())[0])
        except _Malformed as exc:
            raise _Malformed(f"solid {k + 1} ({name or 'no name'}): {exc}") from None
    corners = np.concatenate(parts)
    counts = np.array([len(c) // 3 for c in parts])
    names = [name or f"solid_{k}" for k, (_, name) in enumerate(solids, start=1)]
    return SurfaceFile(corners, np.arange(corners.shape[0], dtype=np.int64).reshape(-1, 3), *_named_groups(names, counts))


_ASCII_LOWER = str.maketrans("ABCDEFGHIJKLMNOPQRSTUVWXYZ", "abcdefghijklmnopqrstuvwxyz")


def _stl_solid_lines(text: str, lower: str) -> list[tuple[int, str]]:
    """(where the solid's facets start, its name) of each ``solid`` line of an ASCII STL: the
    word first on its line, the rest of the line the name.  lower: text with ASCII letters in
    lower case (a regular expression over the text took 0.07 s of an 86 k-triangle file, these
    searches a few ms)."""
    opens = []
    at = lower.find("solid")
    while at >= 0:
        line_end = lower.find("\n", at)
        line_end = len(lower) if line_end < 0 else line_end
        rest = text[at + 5:line_end]
        if not lower[lower.rfind("\n", 0, at) + 1:at].strip() and (not rest or rest[0].isspace()):
            opens.append((line_end, rest.strip()))
        at = lower.find("solid", line_end)
    return opens


def _ascii_stl_corners(tokens: list) -> tuple[np.ndarray, np.ndarray]:
    """The corners (3F, 3) and triangles (F, 3) of an ASCII STL's lower-case words."""
    fast = _ascii_stl_facets(tokens)
    if fast is not None:
        return fast
    at = [i for i, word in enumerate(tokens) if word == "vertex"]  # a list: one long word made numpy's
    n_facets, n_ends = tokens.count("facet"), tokens.count("endfacet")  # fixed-width array 200 GiB
    if n_facets != n_ends or len(at) != 3 * n_facets:
        raise _Malformed(f"{n_facets} 'facet', {n_ends} 'endfacet' and {len(at)} 'vertex' keywords: expected 3 "
                         "vertices in every facet (truncated?)")
    if at and at[-1] + 3 >= len(tokens):
        raise _Malformed("the last vertex has fewer than 3 coordinates (truncated?)")
    coords = [tokens[i + k] for i in at for k in (1, 2, 3)]
    corners = _numbers(coords, np.float64, "a vertex coordinate").reshape(-1, 3)
    return corners, np.arange(corners.shape[0], dtype=np.int64).reshape(-1, 3)


#: A facet's 21 words: facet normal n n n outer loop (vertex x y z) x 3 endloop endfacet.
_FACET_WORDS = {0: "facet", 1: "normal", 5: "outer", 6: "loop", 7: "vertex", 11: "vertex", 15: "vertex",
                19: "endloop", 20: "endfacet"}


def _ascii_stl_facets(words: list) -> tuple[np.ndarray, np.ndarray] | None:
    """_read_ascii_stl's result for one solid of well-formed facets, by slicing the words 21
    at a time (a word-by-word search took 0.85 s of an 86 k-triangle file), or None."""
    try:
        first, last = words.index("facet"), len(words) - words[::-1].index("endfacet")
    except ValueError:
        return None
    block = words[first:last]
    if len(block) % 21 or "solid" in words[last:last + 1] or any(set(block[k::21]) != {w} for k, w in _FACET_WORDS.items()):
        return None
    columns = [block[k::21] for k in (8, 9, 10, 12, 13, 14, 16, 17, 18)]
    corners = np.stack([_numbers(c, np.float64, "a vertex coordinate") for c in columns], axis=1).reshape(-1, 3)
    return corners, np.arange(corners.shape[0], dtype=np.int64).reshape(-1, 3)


# --- OBJ ---------------------------------------------------------------------------------

def _read_obj(data: bytes) -> SurfaceFile:
    """Wavefront OBJ: ``v x y z [w]`` vertices, ``f`` faces of 3 or more corners ``i``,
    ``i/t``, ``i/t/n`` or ``i//n`` (the vertex index i from 1, or negative: counted back
    from the latest vertex); the groups of ``g name`` statements (of ``o name`` in a file
    with no ``g``; faces before the first are in ``default``), two or more named; every other
    statement (normals, texture coordinates, materials, lines) ignored.  A line ending in a
    backslash goes on on the next (Rhino writes long faces so)."""
    text = _text(data)
    lines = _joined_continuations(text.splitlines())
    fast = _obj_triangles(lines)
    if fast is not None:
        vertices, faces = fast
        triangles = None
    else:
        vertices, polygons = _obj_polygons(lines)
        faces = _fans(polygons)
        triangles = np.array([len(p) - 2 for p in polygons], dtype=np.int64)
    if _OBJ_GROUP.search(text) is None:
        return SurfaceFile(vertices, faces)
    return SurfaceFile(vertices, faces, *_named_groups(_obj_face_groups(lines), triangles))


_OBJ_GROUP = re.compile(r"^[ \t]*[go](?:[ \t]|$)", re.MULTILINE)


def _joined_continuations(lines: list) -> list:
    """OBJ's lines with each one ending in a backslash joined to the next, which is left
    blank so that later lines keep their numbers (a statement's errors name its first line)."""
    if not any(line.rstrip().endswith("\\") for line in lines):
        return lines
    out: list[str] = []
    start, carry = 0, None
    for i, line in enumerate(lines):
        if carry is None:
            start = i
            out.append(line)
        else:
            out[start] = carry + " " + line
            out.append("")
        statement = out[start].rstrip()
        carry = statement[:-1] if statement.endswith("\\") else None
    if carry is not None:  # a backslash on the last line continues nothing
        out[start] = carry
    return out


def _obj_face_groups(lines: list) -> list:
    """The group name of each ``f`` statement, in order: the latest ``g`` statement's names
    (joined by spaces) if the file has any, else the latest ``o`` statement's; ``default``
    before the first and for a statement with no name."""
    by_g, by_o, g, o, has_g = [], [], "default", "default", False
    for line in lines:
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if words[0] == "f":
            by_g.append(g)
            by_o.append(o)
        elif words[0] == "g":
            g, has_g = " ".join(words[1:]) or "default", True
        elif words[0] == "o":
            o = " ".join(words[1:]) or "default"
    return by_g if has_g else by_o


def _obj_polygons(lines: list) -> tuple[np.ndarray, list]:
    """Vertices (V, 3) and faces (lists of vertex ids from 0) of an OBJ's lines, statement by statement."""
    coords, polygons = [], []
    for number, line in enumerate(lines, start=1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if words[0] == "v":
            if len(words) < 4:
                raise _Malformed(f"line {number} reads {line.strip()!r}: a vertex needs 3 coordinates")
            coords.extend(words[1:4])
        elif words[0] == "f":
            if len(words) < 4:
                raise _Malformed(f"line {number} reads {line.strip()!r}: a face needs at least 3 corners")
            seen = len(coords) // 3
            try:
                ids = [_number(w.split("/", 1)[0], int) for w in words[1:]]
                if max(map(abs, ids)) > len(coords) // 3 + 2**31:  # nothing a file can index
                    raise ValueError
            except ValueError:
                raise _Malformed(f"line {number} reads {line.strip()!r}: a corner is not a vertex index") from None
            if 0 in ids:
                raise _Malformed(f"line {number} reads {line.strip()!r}: vertex indices count from 1 (or back from -1)")
            polygons.append([i - 1 if i > 0 else seen + i for i in ids])
    return _numbers(coords, np.float64, "a vertex coordinate").reshape(-1, 3), polygons


def _obj_triangles(lines: list) -> tuple[np.ndarray, np.ndarray] | None:
    """_read_obj's result for the common file, or None: every vertex ``v x y z`` and every face
    ``f a b c`` with plain positive indices, converted by numpy at once (the line-by-line
    parse took 0.25 s of an 86 k-triangle file)."""
    v_lines = [line for line in lines if line.startswith("v ")]
    f_lines = [line for line in lines if line.startswith("f ")]
    if not f_lines or any(line.lstrip().startswith(("v", "f")) and not line.startswith(("v ", "f ", "vt", "vn", "vp"))
                          for line in lines):
        return None
    faces_text, vertices_text = " ".join(f_lines), " ".join(v_lines)
    if "/" in faces_text or "-" in faces_text or "#" in faces_text or "_" in faces_text or "_" in vertices_text:
        return None
    try:
        coords = np.array(vertices_text.split()).reshape(len(v_lines), 4)[:, 1:].astype(np.float64)
        faces = np.array(faces_text.split()).reshape(len(f_lines), 4)[:, 1:].astype(np.int64) - 1
    except (ValueError, OverflowError):  # other counts than 3 on a line, or a word that is not a number
        return None
    return (coords, faces) if faces.size and faces.min() >= 0 else None  # index 0: the slow path says where


# --- OFF ---------------------------------------------------------------------------------

def _read_off(data: bytes) -> SurfaceFile:
    """ASCII OFF: an ``OFF`` header (``COFF``, ``NOFF``, ... too: extra numbers on a vertex
    line are ignored), the counts ``V F [E]`` (on the header line or the next), V vertex
    lines and F face lines ``n i_1 ... i_n [colour]``, indices from 0; ``#`` comments and
    blank lines anywhere."""
    if b"\0" in data[:4096]:
        raise _Malformed("not text (binary OFF is not read)")
    text = _text(data)
    fast = _off_triangles(text)
    if fast is not None:
        return SurfaceFile(*fast)
    lines = [words for words in (line.split("#", 1)[0].split() for line in text.splitlines()) if words]
    if not lines or not lines[0][0].upper().endswith("OFF"):
        raise _Malformed("the first line must be OFF (or COFF, NOFF, ...)")
    counts, start = (lines[0][1:], 1) if len(lines[0]) > 1 else ((lines[1] if len(lines) > 1 else []), 2)
    try:
        n_vertices, n_faces = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        raise _Malformed(f"expected the counts 'vertices faces [edges]', got {' '.join(counts)!r}") from None
    vertex_lines = lines[start:start + n_vertices]
    face_lines = lines[start + n_vertices:start + n_vertices + n_faces]
    if n_vertices < 0 or n_faces < 0 or len(vertex_lines) < n_vertices or len(face_lines) < n_faces:
        raise _Malformed(f"the header says {n_vertices} vertices and {n_faces} faces, the file holds "
                         f"{len(vertex_lines)} and {len(face_lines)} (truncated?)")
    if any(len(words) < 3 for words in vertex_lines):
        raise _Malformed("a vertex line has fewer than 3 coordinates")
    vertices = _numbers([w for words in vertex_lines for w in words[:3]], np.float64, "a vertex coordinate")
    polygons = []
    for words in face_lines:
        try:
            n = _number(words[0], int)
            ids = [_number(w, int) for w in words[1:n + 1]]
            if ids and max(map(abs, ids)) > n_vertices:
                raise _Malformed(f"a face line reads {' '.join(words)!r}: vertex {max(map(abs, ids))} of {n_vertices}")
        except ValueError:
            n, ids = -1, []
        if n < 3 or len(ids) < n:
            raise _Malformed(f"a face line reads {' '.join(words)!r}: expected n >= 3 and n indices")
        polygons.append(ids)
    return SurfaceFile(vertices.reshape(-1, 3), _fans(polygons))


def _off_triangles(text: str) -> tuple[np.ndarray, np.ndarray] | None:
    """_read_off's result for the common file, or None: the header ``OFF`` alone on its line,
    the counts on the next (comments and blank lines between), then no comment, 3
    coordinates a vertex and triangles ``3 a b c``.  The tokens are converted by numpy at
    once (a line-by-line parse took 0.33 s of armadillo's 86 k triangles)."""
    header: list[list[str]] = []
    pos = 0
    while len(header) < 2 and pos < len(text):
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end
        words = text[pos:end].split("#", 1)[0].split()
        pos = end + 1
        if words:
            header.append(words)
    if len(header) < 2 or header[0] != ["OFF"] or "#" in text[pos:]:
        return None
    counts = header[1]
    if len(counts) not in (2, 3) or not all(c.isdigit() for c in counts):
        return None
    n_vertices, n_faces = int(counts[0]), int(counts[1])
    tokens = text[pos:].split()
    if len(tokens) != 3 * n_vertices + 4 * n_faces:
        return None
    try:
        if "_" in "".join(tokens):  # Python's syntax, not a file's (read by the slow path, which says so)
            return None
        vertices = np.array(tokens[:3 * n_vertices], dtype=np.float64).reshape(n_vertices, 3)
        faces = np.array(tokens[3 * n_vertices:], dtype=np.int64).reshape(n_faces, 4)
    except (ValueError, OverflowError):
        return None
    if n_faces == 0 or not np.all(faces[:, 0] == 3):
        return None
    return vertices, np.ascontiguousarray(faces[:, 1:])


# --- PLY ---------------------------------------------------------------------------------

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _read_ply(data: bytes) -> SurfaceFile:
    """PLY, ASCII or binary (either byte order): the ``vertex`` element's x, y, z (in any
    order among other properties) and the ``face`` element's vertex list (``vertex_indices``
    or ``vertex_index``, or its only list), polygons split into fans; other elements skipped."""
    match = re.search(rb"^end_header[ \t\r]*$", data[:1 << 20], re.MULTILINE)  # a line of its own, not a comment's word
    if not data.startswith(b"ply") or match is None:
        raise _Malformed("expected a header from 'ply' to 'end_header'")
    end = match.start()
    body_start = data.find(b"\n", end) + 1 or len(data)
    elements: list[list[Any]] = []
    fmt = None  # elements: [name, count, [(name, dtype) or (name, count dtype, item dtype)]]
    for line in _text(data[:end]).splitlines()[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = {"ascii": "ascii", "binary_little_endian": "<", "binary_big_endian": ">"}[words[1]]
            elif words[0] == "element":
                elements.append([words[1], int(words[2]), []])
                if elements[-1][1] < 0:
                    raise ValueError
            elif words[0] == "property" and words[1] == "list":
                elements[-1][2].append((words[4], _PLY_TYPES[words[2]], _PLY_TYPES[words[3]]))
            elif words[0] == "property":
                elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
            else:
                raise ValueError
        except (KeyError, IndexError, ValueError):
            raise _Malformed(f"header line {line.strip()!r} is not PLY") from None
    if fmt is None:
        raise _Malformed("the header has no 'format' line")
    by_name = {e[0]: e for e in elements}
    if "vertex" not in by_name or "face" not in by_name:
        raise _Malformed(f"expected 'vertex' and 'face' elements, the header declares {', '.join(by_name) or 'none'}")
    axes = {p[0]: i for i, p in enumerate(by_name["vertex"][2]) if len(p) == 2}
    lists = [i for i, p in enumerate(by_name["face"][2]) if len(p) == 3]
    named = [i for i in lists if by_name["face"][2][i][0] in ("vertex_indices", "vertex_index")]
    if not all(a in axes for a in "xyz") or not (named or len(lists) == 1):
        raise _Malformed("expected vertex properties x, y, z and a face list 'vertex_indices'")
    face_list = (named or lists)[0]
    read = _ply_ascii if fmt == "ascii" else _ply_binary
    found = read(data[body_start:], elements, fmt)
    vertex_rows, face_rows = found["vertex"], found["face"]
    vertices = np.stack([vertex_rows[axes[a]] for a in "xyz"], axis=1).astype(np.float64)
    polygons = face_rows[face_list]
    if isinstance(polygons, np.ndarray):  # triangles only: (F, 3)
        if polygons.shape[1] < 3:
            raise _Malformed(f"faces of {polygons.shape[1]} vertices")
        return SurfaceFile(vertices, _fans_of_rows(polygons))
    if any(len(p) < 3 for p in polygons):
        raise _Malformed("a face has fewer than 3 vertices")
    return SurfaceFile(vertices, _fans([list(map(int, p)) for p in polygons]))


def _fans_of_rows(rows: np.ndarray) -> np.ndarray:
    """Fans of polygons of one size (F, n) int: (F (n - 2), 3) int64."""
    rows = rows.astype(np.int64)
    return np.stack([rows[:, [0, k, k + 1]] for k in range(1, rows.shape[1] - 1)], axis=1).reshape(-1, 3)


def _ply_ascii(body: bytes, elements: list, fmt: str) -> dict:
    """Per element name, its properties' values: a scalar property an array (count,), a list
    property an (count, n) array when every row has n items, else a list of arrays."""
    tokens = _text(body).split()
    pos, out = 0, dict[str, list]()
    for name, count, props in elements:
        if not props:  # an element of no properties holds no values
            out[name] = []
            continue
        if all(len(p) == 2 for p in props):
            width = len(props)
            if pos + count * width > len(tokens):
                raise _Malformed(f"the header says {count} {name} elements, the file ends before them (truncated?)")
            rows = _numbers(tokens[pos:pos + count * width], np.float64, f"a {name} value").reshape(count, width)
            out[name] = [rows[:, i] for i in range(width)]
            pos += count * width
            continue
        if len(props) == 1 and count:  # the common face element: try every row holding the same count
            n = _int_token(tokens, pos, name)
            if n >= 0 and pos + count * (n + 1) <= len(tokens):
                rows = _numbers(tokens[pos:pos + count * (n + 1)], np.float64, f"a {name} value").reshape(count, n + 1)
                if np.all(rows[:, 0] == n):
                    ids = rows[:, 1:]
                    bad = ~(np.isfinite(ids) & (ids == np.round(ids)) & (np.abs(ids) < 2.0**62))
                    if bad.any():  # '1.7', 'nan', '1e400' would be cast to some vertex
                        row, col = divmod(int(np.argmax(bad.ravel())), n)
                        raise _Malformed(f"a {name} index {tokens[pos + row * (n + 1) + 1 + col]!r} is not an integer")
                    out[name] = [ids.astype(np.int64)]
                    pos += count * (n + 1)
                    continue
        columns: list[list] = [[] for _ in props]
        for _ in range(count):
            for i, prop in enumerate(props):
                if len(prop) == 2:
                    columns[i].append(_float_token(tokens, pos, name))
                    pos += 1
                else:
                    n = _int_token(tokens, pos, name)
                    if n < 0 or pos + 1 + n > len(tokens):
                        raise _Malformed(f"a {name} list of {n} items runs past the end of the file (truncated?)")
                    columns[i].append(_numbers(tokens[pos + 1:pos + 1 + n], np.int64, f"a {name} index"))
                    pos += 1 + n
        out[name] = [np.array(c) if len(p) == 2 else c for c, p in zip(columns, props)]
    return out


def _int_token(tokens: list, pos: int, name: str) -> int:
    return int(_token(tokens, pos, name, int, "list count"))


def _float_token(tokens: list, pos: int, name: str) -> float:
    return _token(tokens, pos, name, float, "value")


def _token(tokens: list, pos: int, name: str, kind: type, what: str):
    """tokens[pos] as kind, or _Malformed naming the element and what the token should be."""
    if pos >= len(tokens):
        raise _Malformed(f"the file ends inside the {name} elements (truncated?)")
    try:
        return _number(tokens[pos], kind)
    except ValueError:
        raise _Malformed(f"a {name} {what} {tokens[pos]!r} is not {'an integer' if kind is int else 'a number'}") from None


def _ply_binary(body: bytes, elements: list, order: str) -> dict:
    """_ply_ascii's result for a binary body with byte order ``order`` ('<' or '>').  An element
    of scalars, or whose lists all hold the count its first row has, is read as one record
    array after its size is checked against the bytes left; others row by row."""
    pos, out = 0, dict[str, list]()
    for name, count, props in elements:
        if not props:  # an element of no properties holds no bytes
            out[name] = []
            continue
        first: list[tuple] = []  # the record layout if every list holds what the first row's does
        at = pos
        for prop in props:
            if len(prop) == 2:
                first.append((prop[0], order + prop[1]))
                at += np.dtype(prop[1]).itemsize
            else:
                size = np.dtype(prop[1]).itemsize
                n = 0
                if count and at + size <= len(body):
                    n = int(np.frombuffer(body, dtype=order + prop[1], count=1, offset=at)[0])
                    if n < 0 or at + size + n * np.dtype(prop[2]).itemsize > len(body):
                        n = 0  # no such row fits: the row-by-row path says where the file ends
                first += [(prop[0] + "#n", order + prop[1]), (prop[0], order + prop[2], (max(n, 0),))]
                at += size + max(n, 0) * np.dtype(prop[2]).itemsize
        record = np.dtype(first)
        if count and pos + count * record.itemsize > len(body):
            smallest = sum(np.dtype(p[1]).itemsize for p in props)
            if pos + count * smallest > len(body):
                raise _Malformed(f"the header says {count} {name} elements, at least {count * smallest} bytes, "
                                 f"but {len(body) - pos} are left (truncated?)")
        else:
            rows = np.frombuffer(body, dtype=record, count=count, offset=pos)
            if all(len(p) == 2 or np.all(rows[p[0] + "#n"] == record[p[0]].shape[0]) for p in props):
                out[name] = [rows[p[0]].astype(p[2] if len(p) == 3 else p[1]) for p in props]
                pos += count * record.itemsize
                continue
        columns: list[list] = [[] for _ in props]
        for _ in range(count):
            for i, prop in enumerate(props):
                size = np.dtype(prop[1]).itemsize
                if pos + size > len(body):
                    raise _Malformed(f"the file ends inside the {name} elements (truncated?)")
                value = np.frombuffer(body, dtype=order + prop[1], count=1, offset=pos)[0]
                pos += size
                if len(prop) == 3:
                    n, item = int(value), np.dtype(order + prop[2])
                    if n < 0 or pos + n * item.itemsize > len(body):
                        raise _Malformed(f"a {name} list of {n} items runs past the end of the file (truncated?)")
                    value = np.frombuffer(body, dtype=item, count=n, offset=pos).astype(np.int64)
                    pos += n * item.itemsize
                columns[i].append(value)
        out[name] = [np.array(c) if len(p) == 2 else c for c, p in zip(columns, props)]
    return out


# --- Gmsh MSH ----------------------------------------------------------------------------

def _read_msh(data: bytes) -> SurfaceFile:
    """A Gmsh surface mesh (MSH 4.1 or 2.2, ASCII or binary, read by paroct.msh): its
    triangles (quads split in two), grouped by physical surface (named as the file's
    $PhysicalNames name them, else ``physical_<tag>``; elements in none are ``default``), or,
    in a file with no physical groups, by geometrical surface (``surface_<tag>``: the CAD
    faces).  Second- and higher-order triangles and quads give their corners (the flat
    triangles between them).  Other elements (points, lines, a volume's tets) are ignored."""
    from .msh import QUAD_TYPES, TYPE_DIMENSION, MshError, read_msh, type_name

    try:
        msh = read_msh(data)
    except MshError as exc:
        raise _Malformed(str(exc)) from None
    surface = [msh.elements[kind]._replace(nodes=msh.elements[kind].nodes[:, :4 if kind in QUAD_TYPES else 3])
               for kind in sorted(msh.elements) if TYPE_DIMENSION.get(kind) == 2]
    if not surface:
        kinds = sorted(type_name(kind) for kind in msh.elements)
        raise _Malformed(f"no triangles or quads (it holds {', '.join(kinds) or 'no elements'}): give paroct the "
                         "part's surface mesh (in Gmsh, its 2D mesh)")
    by_physical = any(np.any(block.physical != 0) for block in surface)
    triangles, tags = [], []
    for block in surface:
        rows, block_tags = block.nodes, block.physical if by_physical else block.entity
        if rows.shape[1] == 4:
            rows, block_tags = _fans_of_rows(rows), np.repeat(block_tags, 2)
        triangles.append(rows)
        tags.append(block_tags)
    # Names per distinct tag, in order of first appearance, not per triangle.
    distinct, first, inverse = np.unique(np.concatenate(tags), return_index=True, return_inverse=True)
    order = np.argsort(first)
    names = [("default" if t == 0 else msh.names.get((2, t), f"physical_{t}")) if by_physical else f"surface_{t}"
             for t in distinct[order].tolist()]
    of_distinct, group_names = _named_groups(names)
    face_groups = None
    if of_distinct is not None:
        by_tag = np.empty(distinct.size, dtype=np.int32)
        by_tag[order] = of_distinct
        face_groups = by_tag[inverse.ravel()]
    return SurfaceFile(np.ascontiguousarray(msh.points, dtype=np.float64), np.concatenate(triangles),
                       face_groups, group_names)


_READERS: dict[str, Callable[[bytes], SurfaceFile]] = {".stl": _read_stl, ".obj": _read_obj, ".off": _read_off,
                                                       ".ply": _read_ply, ".msh": _read_msh}
