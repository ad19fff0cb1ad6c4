"""Read Gmsh MSH files: versions 4.1 and 2.2 (also 2.0, 2.1), ASCII and binary.

Returns the nodes, the elements of each Gmsh element type with their node indices,
elementary (CAD entity) and physical tags, and the physical groups' names: what paroct
reads as a surface (triangles, quads) or checks as a volume mesh (tets).  The layout is the
Gmsh reference manual's, section "MSH file format" (4.1) and its legacy 2.2 section.

paroct reads MSH itself because meshio 5.3 maps an element's node tag that the file does
not define, but that lies below its largest node tag, to the last node, silently: a damaged
file read as a different mesh.  Here every count in the file is checked against the bytes
that remain before anything is allocated from it, and every node tag an element names must
be defined once.
"""

from __future__ import annotations

import re
import shlex
import warnings
from typing import NamedTuple

import numpy as np

#: Nodes of each Gmsh element type (the manual's table; 15 is a point).
NODES_PER_TYPE = {1: 2, 2: 3, 3: 4, 4: 4, 5: 8, 6: 6, 7: 5, 8: 3, 9: 6, 10: 9, 11: 10, 12: 27, 13: 18, 14: 14,
                  15: 1, 16: 8, 17: 20, 18: 15, 19: 13, 20: 9, 21: 10, 22: 12, 23: 15, 24: 15, 25: 21, 26: 4,
                  27: 5, 28: 6, 29: 20, 30: 35, 31: 56, 92: 64, 93: 125}
#: Names of the types a message may mention.
TYPE_NAMES = {1: "line", 2: "triangle", 3: "quad", 4: "tetra", 5: "hexahedron", 6: "wedge", 7: "pyramid",
              8: "line3", 9: "triangle6", 10: "quad9", 11: "tetra10", 15: "vertex"}
#: Dimension of each type's element (points 0, lines 1, surfaces 2, volumes 3).
TYPE_DIMENSION = {kind: 0 if kind == 15 else 1 if kind in (1, 8, 26, 27, 28) else
                  2 if kind in (2, 3, 9, 10, 16, 20, 21, 22, 23, 24, 25) else 3 for kind in NODES_PER_TYPE}
TRIANGLE, QUAD, TETRA = 2, 3, 4
#: The quads among the surface types, of any order (4, 9 and 8 nodes); the others are triangles.
#: An element lists its corners first.
QUAD_TYPES = (QUAD, 10, 16)
_SPACE = re.compile(rb"\s*")
_COUNT = re.compile(r"[0-9]{1,18}")
_TAG = re.compile(r"-?[0-9]{1,18}")
_BOM = b"\xef\xbb\xbf"


def _shown(text: str) -> str:
    """File text quoted for a message: repr (control bytes escaped), cut to 40 characters."""
    return repr(text[:40] + ("..." if len(text) > 40 else ""))


class MshError(Exception):
    """What is wrong with a file, in words (the caller adds its name)."""


class MshElements(NamedTuple):
    """The elements of one type, in file order.  nodes: (K, n) int64 indices into the
    file's points; entity: (K,) int64 elementary tag (the CAD entity); physical: (K,) int64
    the first physical group's tag, 0 where the element is in none."""

    nodes: np.ndarray
    entity: np.ndarray
    physical: np.ndarray


class MshFile(NamedTuple):
    """points: (N, 3) float64 in the file's node order; elements: Gmsh type -> MshElements;
    names: (dimension, physical tag) -> the group's name."""

    points: np.ndarray
    elements: dict
    names: dict


def is_msh(data: bytes) -> bool:
    """Whether data starts (after white space) as a Gmsh MSH 2 or 4 file does."""
    return data.startswith(b"$MeshFormat", _after_space(data, _text_start(data)))


def _after_space(data: bytes, pos: int) -> int:
    """Where the white space from pos on ends."""
    match = _SPACE.match(data, pos)  # never None: _SPACE matches the empty string too
    return pos if match is None else match.end()


def _no_entities() -> tuple[dict, dict, dict, dict]:
    """Entities per dimension 0..3, none yet: tag -> (physical tags, (parent dimension, parent tag))."""
    return {}, {}, {}, {}


def _text_start(data: bytes) -> int:
    """Where a file's text starts: after a UTF-8 byte-order mark, if it has one."""
    return len(_BOM) if data.startswith(_BOM) else 0


def type_name(kind: int) -> str:
    return TYPE_NAMES.get(kind, f"type {kind}")


def read_msh(data: bytes) -> MshFile:
    """The nodes, elements and group names (MshFile) of a Gmsh MSH file's bytes; MshError
    saying what is wrong and where."""
    reader = _Reader(data)
    version, binary, size_t = reader.format()
    names: dict[tuple[int, int], str] = {}
    nodes, elements, entities = None, None, _no_entities()
    seen = set()
    read_once = {"PhysicalNames", "Entities", "PartitionedEntities", "Nodes", "ParametricNodes", "Elements"}
    while (section := reader.next_section()) is not None:
        if section in read_once:
            if section in seen or (section.endswith("Nodes") and nodes is not None):
                raise MshError(f"it has two ${section} sections")
            seen.add(section)
        if section == "PhysicalNames":
            names = reader.physical_names()
        elif section in ("Entities", "PartitionedEntities") and version == 4:
            if elements is not None:
                raise MshError(f"its ${section} section comes after $Elements")
            for dim, listed in enumerate(reader.entities(binary, size_t, partitioned=section != "Entities")):
                entities[dim].update(listed)
        elif section == "Nodes" or (section == "ParametricNodes" and version == 2):
            nodes = (reader.nodes4(binary, size_t) if version == 4
                     else reader.nodes2(binary, parametric=section == "ParametricNodes"))
        elif section == "Elements":
            elements = reader.elements4(binary, size_t, entities) if version == 4 else reader.elements2(binary)
        else:  # $Comments, $NodeData, $Periodic, ...: the manual says to skip what one does not read
            reader.skip(section)
    if nodes is None or elements is None:
        raise MshError(f"it has no ${'Nodes' if nodes is None else 'Elements'} section")
    tags, points = nodes
    index = _node_index(tags)
    return MshFile(points, {kind: MshElements(index(node_tags), entity, physical)
                            for kind, (node_tags, entity, physical) in elements.items()}, names)


def _node_index(tags: np.ndarray):
    """A function from node tags (any shape, int64) to indices into the nodes; MshError for a
    tag no node has.  tags (N,): the nodes' tags in file order, each defined once.  Tags up
    to 4 N + 1024 (Gmsh numbers from 1 with few gaps) go through a dense table, others
    through a sorted search."""
    if tags.size and tags.min() < 1:
        raise MshError(f"a node has tag {int(tags.min())} (tags start at 1)")
    largest = int(tags.max()) if tags.size else 0
    if largest <= 4 * tags.size + 1024:
        table = np.full(largest + 2, -1, dtype=np.int64)  # table[largest + 1]: every tag past the last
        table[tags] = np.arange(tags.size)
        if np.count_nonzero(table >= 0) != tags.size:
            seen = np.zeros(largest + 1, dtype=np.int64)
            np.add.at(seen, tags, 1)
            raise MshError(f"node tag {int(np.flatnonzero(seen > 1)[0])} is defined twice")

        def index(element_tags: np.ndarray) -> np.ndarray:
            out = table[np.clip(element_tags, 0, largest + 1)]
            if out.size and out.min() < 0:
                raise MshError(f"an element names node {int(element_tags[out < 0][0])}, which the file does not define")
            return out
        return index
    order = np.argsort(tags, kind="stable")
    sorted_tags = tags[order]
    if np.any(same := sorted_tags[1:] == sorted_tags[:-1]):
        raise MshError(f"node tag {int(sorted_tags[1:][same][0])} is defined twice")

    def index_sparse(element_tags: np.ndarray) -> np.ndarray:
        at = np.minimum(np.searchsorted(sorted_tags, element_tags), sorted_tags.size - 1)
        found = sorted_tags[at] == element_tags
        if not found.all():
            raise MshError(f"an element names node {int(element_tags[~found][0])}, which the file does not define")
        return order[at]
    return index_sparse


class _Reader:
    """A cursor over the file's bytes, section by section."""

    def __init__(self, data: bytes):
        self.data, self.pos = data, _text_start(data)

    def _skip_space(self) -> bool:
        """Move the cursor past white space; whether anything follows."""
        self.pos = _after_space(self.data, self.pos)
        return self.pos < len(self.data)

    def format(self) -> tuple[int, bool, np.dtype]:
        """(major version, binary, size_t dtype) from $MeshFormat; MshError for another version."""
        if not is_msh(self.data):
            raise MshError("not a Gmsh MSH file: it does not start with $MeshFormat (MSH 1 files are not read)")
        self.next_section()
        line = self._line()
        words = line.split()
        if len(words) < 3:
            raise MshError(f"its $MeshFormat line {_shown(line)} is not 'version file-type data-size'")
        version, file_type, data_size = words[:3]
        if version not in ("2", "2.0", "2.1", "2.2", "4.1"):
            raise MshError(f"MSH version {_shown(version)} is not read: save the mesh as MSH 4.1 or 2.2 "
                           "(Gmsh: Mesh.MshFileVersion)")
        if file_type not in ("0", "1") or data_size not in ("4", "8"):
            raise MshError(f"its $MeshFormat line {_shown(line)} has file type {_shown(file_type)} (0 or 1) "
                           f"and data size {_shown(data_size)} (4 or 8)")
        binary = file_type == "1"
        if binary:
            one = self._binary(np.dtype("<i4"), 1, "the byte-order mark")[0]
            if one != 1:
                raise MshError("its byte-order mark is not 1 in little-endian order (big-endian files are not read)")
        self._end("MeshFormat")
        return int(version[0]), binary, np.dtype("<u8" if data_size == "8" else "<u4")

    # --- sections -----------------------------------------------------------------------

    def next_section(self) -> str | None:
        """The name of the next $Section (the cursor after its line), None at the end."""
        if not self._skip_space():
            return None
        line = self._line()
        if not line.startswith("$") or line.startswith("$End"):
            raise MshError(f"expected a section ($Name), found {_shown(line)}")
        name = line[1:].strip()
        if not re.fullmatch(r"[A-Za-z0-9_]{1,40}", name):
            raise MshError(f"expected a section ($Name), found {_shown(line)}")
        return name

    def skip(self, name: str) -> None:
        end = self.data.find(b"$End" + name.encode(), self.pos)
        if end < 0:
            raise MshError(f"section ${name} has no $End{name}")
        self.pos = end
        self._end(name)

    def _end(self, name: str) -> None:
        self._skip_space()
        marker = b"$End" + name.encode()
        if not self.data.startswith(marker, self.pos):
            raise MshError(f"section ${name} does not end where its counts say (no $End{name} there)")
        self.pos += len(marker)

    def _line(self) -> str:
        end = self.data.find(b"\n", self.pos)
        end = len(self.data) if end < 0 else end
        line = self.data[self.pos:end].decode("utf-8", errors="replace").strip()
        self.pos = end + 1
        return line

    def _binary(self, dtype: np.dtype, count: int, what: str) -> np.ndarray:
        """count values of dtype at the cursor; MshError if the file ends first."""
        need = int(count) * dtype.itemsize
        if count < 0 or self.pos + need > len(self.data):
            raise MshError(f"the file ends inside {what}: {count} values of {dtype.itemsize} bytes need {need} "
                           f"bytes, {max(len(self.data) - self.pos, 0)} remain")
        out = np.frombuffer(self.data, dtype=dtype, count=int(count), offset=self.pos)
        self.pos += need
        return out

    def _ascii_numbers(self, name: str) -> np.ndarray:
        """Every number of section name up to its $End line, as float64 (exact for integers
        below 2**53), the cursor on the $End line."""
        end = self.data.find(b"$End" + name.encode(), self.pos)
        if end < 0:
            raise MshError(f"section ${name} has no $End{name}")
        body = self.data[self.pos:end]
        self.pos = end
        bad = re.search(rb"[^0-9eE+\-.\s]", body)
        if bad is None:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("error")
                    values = np.fromstring(body.decode("ascii"), sep=" ")
            except (ValueError, DeprecationWarning):
                values = None
            if values is not None and np.isfinite(values).all():
                return values
        for token in body.split():
            word = token.decode("utf-8", errors="replace")
            try:
                finite = re.fullmatch(r"[-+0-9.eE]+", word) and np.isfinite(float(word))
            except ValueError:
                finite = False
            if not finite:
                raise MshError(f"${name} holds {_shown(word)}, which is not a finite number")
        raise MshError(f"${name} holds numbers that do not read")

    def physical_names(self) -> dict:
        """(dim, tag) -> name; a name is quoted, with the quotes of Gmsh's writer."""
        count = self._line()
        if not _COUNT.fullmatch(count):
            raise MshError(f"$PhysicalNames starts with {_shown(count)}, not a count")
        names = {}
        for _ in range(int(count)):
            line = self._line()
            words = line.split(maxsplit=2)
            if len(words) < 3 or not all(_TAG.fullmatch(w) for w in words[:2]):
                raise MshError(f"$PhysicalNames line {_shown(line)} is not 'dimension tag \"name\"'")
            name = words[2]
            if len(name) >= 2 and name[0] == name[-1] == '"':
                name = name[1:-1]
            else:
                try:
                    name = " ".join(shlex.split(name))
                except ValueError:
                    pass
            names[(int(words[0]), int(words[1]))] = name
        self._end("PhysicalNames")
        return names

    # --- MSH 4.1 ------------------------------------------------------------------------

    def entities(self, binary: bool, size_t: np.dtype, partitioned: bool = False) -> tuple:
        """Per dimension 0..3: entity tag -> (its physical tags, (parent dimension, parent
        tag)) of $Entities (an entity is its own parent) or, partitioned, of
        $PartitionedEntities, whose entities are the pieces of the model's entities
        (partition interfaces: pieces of an entity of another dimension)."""
        section = "PartitionedEntities" if partitioned else "Entities"
        out = _no_entities()
        read = self._numbers(section, binary, size_t)
        if partitioned:
            read("size_t", 1)  # partitions
            read("int", 2 * int(read("size_t", 1)[0]))  # ghost entities: (tag, partition) pairs
        counts = read("size_t", 4)
        for dim in range(4):
            for _ in range(int(counts[dim])):
                tag = int(read("int", 1)[0])
                parent = (dim, tag)
                if partitioned:
                    parent_dim, parent_tag = (int(v) for v in read("int", 2))
                    parent = (parent_dim, parent_tag)
                    read("int", int(read("size_t", 1)[0]))  # the partitions it is in
                read("double", 3 if dim == 0 else 6)
                n_physical = int(read("size_t", 1)[0])
                out[dim][tag] = ([int(t) for t in read("int", n_physical)], parent)
                if dim > 0:
                    read("int", int(read("size_t", 1)[0]))
        read.done()
        self._end(section)
        return out

    def _numbers(self, section: str, binary: bool, size_t: np.dtype):
        """A reader of a 4.1 section's numbers in order, read(kind, count) with kind 'int',
        'size_t' or 'double', and done() at its end: binary values at the cursor, or the
        section's text (_Numbers)."""
        if not binary:
            return _Numbers(self._ascii_numbers(section), f"${section}")
        return _BinaryNumbers(self, {"int": np.dtype("<i4"), "size_t": size_t, "double": np.dtype("<f8")},
                              f"${section}")

    def nodes4(self, binary: bool, size_t: np.dtype) -> tuple[np.ndarray, np.ndarray]:
        """(tags (N,) int64, points (N, 3) float64) of a 4.1 $Nodes section."""
        read = self._numbers("Nodes", binary, size_t)
        header = read("size_t", 4)
        n_blocks, n_nodes = int(header[0]), int(header[1])
        tag_blocks, point_blocks = [], []
        for _ in range(n_blocks):
            dim, _, parametric = (int(v) for v in read("int", 3))
            if parametric not in (0, 1) or not 0 <= dim <= 3:
                raise MshError(f"a $Nodes block has entity dimension {dim} and parametric flag {parametric}")
            count = int(read("size_t", 1)[0])
            block_tags = read("size_t", count)
            per_node = 3 + (dim if parametric else 0)  # x y z, then u (curves), u v (surfaces), u v w
            tag_blocks.append(_tags(block_tags, "$Nodes"))
            point_blocks.append(read("double", count * per_node).reshape(count, per_node)[:, :3])
        read.done()
        self._end("Nodes")
        tags = np.concatenate(tag_blocks) if tag_blocks else np.zeros(0, dtype=np.int64)
        if tags.size != n_nodes:
            raise MshError(f"$Nodes says it holds {n_nodes} nodes, its blocks hold {tags.size}")
        points = np.concatenate(point_blocks).astype(np.float64) if point_blocks else np.zeros((0, 3))
        return tags, points

    def elements4(self, binary: bool, size_t: np.dtype, entities: tuple) -> dict:
        """Gmsh type -> (node tags (K, n) int64, entity tags (K,), physical tags (K,)) of a 4.1
        $Elements section (blocks of one type and entity, merged per type); an element is in
        its entity's first physical group, 0 for none (entities: Reader.entities' per
        dimension; empty where the file has no $Entities).  A partitioned file's elements
        take their parent entity's tag, and those on partition interfaces are left out."""
        listed = any(entities)
        read = self._numbers("Elements", binary, size_t)
        header = read("size_t", 4)
        n_blocks, n_elements = int(header[0]), int(header[1])
        blocks: dict[int, list] = {}
        total = 0
        for _ in range(n_blocks):
            dim, entity, kind = (int(v) for v in read("int", 3))
            count = int(read("size_t", 1)[0])
            if kind not in NODES_PER_TYPE:
                raise MshError(f"$Elements holds elements of Gmsh type {kind}, which paroct does not know")
            if dim != TYPE_DIMENSION[kind]:
                raise MshError(f"an $Elements block puts {type_name(kind)} elements on an entity of dimension {dim}")
            width = 1 + NODES_PER_TYPE[kind]
            rows = read("size_t", count * width).reshape(count, width)
            total += count
            physicals, parent = [], (dim, entity)
            if listed:
                if entity not in entities[dim]:
                    raise MshError(f"an $Elements block names entity {entity} of dimension {dim}, which "
                                   "$Entities does not list")
                physicals, parent = entities[dim][entity]
                if parent[0] != dim:  # a partition interface, no part of the model
                    continue
            group = physicals[0] if physicals else 0
            blocks.setdefault(kind, []).append((_tags(rows[:, 1:], "$Elements"),
                                                np.full(count, parent[1], dtype=np.int64),
                                                np.full(count, group, dtype=np.int64)))
        read.done()
        self._end("Elements")
        if total != n_elements:
            raise MshError(f"$Elements says it holds {n_elements} elements, its blocks hold {total}")
        return {kind: _merged(parts) for kind, parts in blocks.items()}

    # --- MSH 2.2 ------------------------------------------------------------------------

    def nodes2(self, binary: bool, parametric: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(tags (N,) int64, points (N, 3) float64) of a 2.2 $Nodes section, or of a
        $ParametricNodes one (Gmsh's Mesh.SaveParametric): 'tag x y z dim entity' and dim
        parametric coordinates on a curve (1) or surface (2)."""
        if parametric:
            return self._parametric_nodes2(binary)
        count = self._count("Nodes")
        if binary:
            record = np.dtype([("tag", "<i4"), ("xyz", "<f8", (3,))])
            rows = self._binary(record, count, "$Nodes")
            tags, points = rows["tag"].astype(np.int64), rows["xyz"].astype(np.float64)
        else:
            read = _Numbers(self._ascii_numbers("Nodes"), "$Nodes")
            rows = read("double", count * 4).reshape(count, 4)
            read.done()
            tags, points = _integers(rows[:, 0], "$Nodes"), np.ascontiguousarray(rows[:, 1:])
        self._end("Nodes")
        return tags, points

    def _parametric_nodes2(self, binary: bool) -> tuple[np.ndarray, np.ndarray]:
        count = self._count("ParametricNodes")
        tags, points = [], []
        if binary:
            done = 0
            while done < count:  # runs of nodes on entities of one dimension: records of one size
                if self.pos + 36 > len(self.data):
                    raise MshError("the file ends inside $ParametricNodes")
                dim = int(np.frombuffer(self.data, "<i4", 1, self.pos + 28)[0])
                if not 0 <= dim <= 3:
                    raise MshError(f"a $ParametricNodes node is on an entity of dimension {dim}")
                record = np.dtype([("tag", "<i4"), ("xyz", "<f8", (3,)), ("dim", "<i4"), ("entity", "<i4"),
                                   ("uv", "<f8", (dim if dim in (1, 2) else 0,))])
                available = min(count - done, (len(self.data) - self.pos) // record.itemsize)
                if available == 0:
                    raise MshError("the file ends inside $ParametricNodes")
                rows = np.frombuffer(self.data, record, available, self.pos)
                n = _run_length(rows["dim"] != dim)
                tags.append(rows["tag"][:n].astype(np.int64))
                points.append(rows["xyz"][:n])
                self.pos += n * record.itemsize
                done += n
        else:
            values = self._ascii_numbers("ParametricNodes")
            start = 0
            while start < values.size:
                if start + 6 > values.size:
                    raise MshError("$ParametricNodes ends inside a node")
                dim = values[start + 4]
                if dim not in (0, 1, 2, 3):
                    raise MshError(f"a $ParametricNodes node is on an entity of dimension {dim:g}")
                width = 6 + (int(dim) if dim in (1, 2) else 0)
                rows = values[start:start + (values.size - start) // width * width].reshape(-1, width)
                n = _run_length(rows[:, 4] != dim)
                tags.append(_integers(rows[:n, 0], "$ParametricNodes"))
                points.append(rows[:n, 1:4])
                start += n * width
            if sum(t.size for t in tags) != count:
                raise MshError(f"$ParametricNodes says it holds {count} nodes, it holds {sum(t.size for t in tags)}")
        self._end("ParametricNodes")
        return (np.concatenate(tags) if tags else np.zeros(0, dtype=np.int64),
                np.concatenate(points).astype(np.float64) if points else np.zeros((0, 3)))

    def elements2(self, binary: bool) -> dict:
        """Gmsh type -> (node tags (K, n), elementary tags (K,), physical tags (K,)) of a 2.2
        $Elements section; the first tag of an element is its physical group, the second
        its elementary entity."""
        count = self._count("Elements")
        parts: dict[int, list] = {}
        if binary:
            done = 0
            while done < count:
                kind, n, n_tags = (int(v) for v in self._binary(np.dtype("<i4"), 3, "$Elements"))
                if kind not in NODES_PER_TYPE:
                    raise MshError(f"$Elements holds elements of Gmsh type {kind}, which paroct does not know")
                if n < 1 or done + n > count or n_tags < 0:
                    raise MshError(f"an $Elements block header counts {n} elements with {n_tags} tags, "
                                   f"{count - done} of the section's {count} remain")
                width = 1 + n_tags + NODES_PER_TYPE[kind]
                rows = self._binary(np.dtype("<i4"), n * width, "$Elements").reshape(n, width).astype(np.int64)
                parts.setdefault(kind, []).append(_tagged2(rows, 1, n_tags))
                done += n
        else:
            values = self._ascii_numbers("Elements")
            start = 0
            while start < values.size:  # runs of lines of one layout
                kind, n_tags, width, n = _run2(values, start)
                rows = _integers(values[start:start + n * width], "$Elements").reshape(n, width)
                parts.setdefault(kind, []).append(_tagged2(rows, 3, n_tags))
                start += n * width
            listed = sum(p[0].shape[0] for runs in parts.values() for p in runs)
            if listed != count:
                raise MshError(f"$Elements says it holds {count} elements, it holds {listed}")
        self._end("Elements")
        return {kind: _without_group_copies(*_merged(runs)) for kind, runs in parts.items()}

    def _count(self, name: str) -> int:
        line = self._line()
        if not _COUNT.fullmatch(line):
            raise MshError(f"${name} starts with {_shown(line)}, not a count")
        return int(line)


class _BinaryNumbers:
    """_Reader._numbers of a binary file: values of the kind's type at the reader's cursor."""

    def __init__(self, reader: _Reader, types: dict, section: str):
        self.reader, self.types, self.section = reader, types, section

    def __call__(self, kind: str, count: int) -> np.ndarray:
        return self.reader._binary(self.types[kind], count, self.section)

    def done(self) -> None:
        pass


class _Numbers:
    """The numbers of an ASCII section read in order; kind 'double' as they are, 'int' and
    'size_t' checked to be integers."""

    def __init__(self, values: np.ndarray, section: str):
        self.values, self.at, self.section = values, 0, section

    def __call__(self, kind: str, count: int) -> np.ndarray:
        if count < 0 or self.at + count > self.values.size:
            raise MshError(f"{self.section} ends early: its counts ask for {count} more numbers, "
                           f"{self.values.size - self.at} remain")
        out = self.values[self.at:self.at + count]
        self.at += count
        return out if kind == "double" else _integers(out, self.section)

    def done(self) -> None:
        if self.at != self.values.size:
            raise MshError(f"{self.section} holds {self.values.size - self.at} numbers more than its counts say")


def _integers(values: np.ndarray, section: str) -> np.ndarray:
    """float64 values (read from text) as int64; MshError for one that is not a whole number,
    or whose magnitude reaches 2**53 (from there float64 rounds whole numbers)."""
    large = np.abs(values) >= 2.0 ** 53
    if large.any():
        raise MshError(f"{section} holds {float(values[large][0]):.17g}, beyond the 2**53 paroct reads in a text file")
    ints = values.astype(np.int64)
    bad = ints != values
    if bad.any():
        raise MshError(f"{section} holds {float(values[bad][0]):g} where a whole number belongs")
    return ints


def _tags(values: np.ndarray, section: str) -> np.ndarray:
    """Unsigned binary tags as int64; MshError for one of 2**63 or more."""
    if values.dtype.kind == "u" and values.size and int(values.max()) >= 2 ** 63:
        raise MshError(f"{section} holds tag {int(values.max())}, beyond 2**63")
    return values.astype(np.int64)


def _run_length(differs: np.ndarray) -> int:
    """Rows before the first True of differs (all of them if none; at least 1: row 0 starts
    the run)."""
    first = np.flatnonzero(differs[1:])
    return int(first[0]) + 1 if first.size else max(int(differs.size), 1)


def _run2(values: np.ndarray, start: int) -> tuple[int, int, int, int]:
    """(type, tags, numbers per element, elements) of the run of 2.2 ASCII element lines of
    one layout from values[start] ('tag type n_tags tags... nodes...'): the run is found by
    doubling the rows compared, so a file of one layout costs O(elements)."""
    if start + 3 > values.size:
        raise MshError("$Elements ends inside an element")
    kind, n_tags = int(values[start + 1]), int(values[start + 2])
    if kind not in NODES_PER_TYPE or n_tags < 0 or n_tags != values[start + 2]:
        raise MshError(f"$Elements holds an element of Gmsh type {values[start + 1]:g} with "
                       f"{values[start + 2]:g} tags, which paroct does not know")
    width = 3 + n_tags + NODES_PER_TYPE[kind]
    available = (values.size - start) // width
    if available == 0:
        raise MshError("$Elements ends inside an element")
    n, step = 1, 1
    while n < available:
        upto = min(n + step, available)
        rows = values[start + n * width:start + upto * width].reshape(-1, width)
        differ = np.flatnonzero((rows[:, 1] != kind) | (rows[:, 2] != n_tags))
        if differ.size:
            return kind, n_tags, width, n + int(differ[0])
        n, step = upto, step * 2
    return kind, n_tags, width, n


def _tagged2(rows: np.ndarray, first: int, n_tags: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(node tags, elementary tags, physical tags) of 2.2 element rows whose tags start at
    column first: binary rows are 'tag tags... nodes...' (first 1), ASCII ones 'tag type n_tags
    tags... nodes...' (first 3)."""
    zero = np.zeros(rows.shape[0], dtype=np.int64)
    physical = rows[:, first] if n_tags >= 1 else zero
    entity = rows[:, first + 1] if n_tags >= 2 else zero
    return np.ascontiguousarray(rows[:, first + n_tags:]), entity.copy(), physical.copy()


def _without_group_copies(nodes: np.ndarray, entity: np.ndarray, physical: np.ndarray) -> tuple:
    """MSH 2 lists an element once per physical group it is in (Gmsh's writer): the copies,
    rows of the same nodes and entity in another group, are dropped, the first kept (its
    group is the element's, as MSH 4.1 gives the entity's first).  Rows repeated in one
    group stay: a file's duplicate elements are the file's."""
    if nodes.shape[0] < 2:
        return nodes, entity, physical
    key = np.column_stack([nodes, entity])
    order = np.lexsort(key.T[::-1])
    same = np.all(key[order[1:]] == key[order[:-1]], axis=1)
    if not same.any():
        return nodes, entity, physical
    run_start = np.maximum.accumulate(np.where(np.concatenate([[False], same]), 0, np.arange(order.size)))
    first = order[run_start]  # per sorted row, the first row (lowest index: lexsort is stable) of its run
    copy = np.zeros(nodes.shape[0], dtype=bool)
    copy[order] = physical[order] != physical[first]
    keep = ~copy
    return nodes[keep], entity[keep], physical[keep]


def _merged(parts: list) -> tuple:
    """One (nodes, entity, physical) of a type's blocks."""
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))
