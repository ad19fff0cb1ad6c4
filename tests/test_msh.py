"""paroct's Gmsh MSH reader (paroct.msh): the same mesh as meshio reads from valid files of
both versions and encodings, and a clear MshError, never a wrong mesh or another exception,
from damaged ones."""

import meshio
import numpy as np
import pytest

from paroct.cli import main
from paroct.io import read_mesh, write_mesh
from paroct.msh import QUAD, TETRA, TRIANGLE, MshError, read_msh

RNG = np.random.default_rng(7)
POINTS = RNG.random((40, 3))
TETS = RNG.integers(0, 40, (25, 4))
TRIANGLES = RNG.integers(0, 40, (12, 3))
QUADS = RNG.integers(0, 40, (3, 4))


def _meshio_file(tmp_path, binary: bool):
    mesh = meshio.Mesh(POINTS, [("tetra", TETS), ("triangle", TRIANGLES), ("quad", QUADS)],
                       cell_data={"gmsh:physical": [np.full(25, 9), np.arange(12) % 3 + 1, np.full(3, 4)],
                                  "gmsh:geometrical": [np.full(25, 1), np.arange(12) % 3 + 10, np.full(3, 20)]},
                       field_data={"solid": np.array([9, 3]), "inlet": np.array([1, 2]), "wall 2": np.array([2, 2])})
    path = tmp_path / f"m22_{int(binary)}.msh"
    meshio.write(path, mesh, file_format="gmsh22", binary=binary)
    return path


def _ascii41(tags: np.ndarray, elements_tets: np.ndarray, parametric: bool = True) -> bytes:
    """A 4.1 ASCII file as Gmsh writes one: $Entities with physical tags, the nodes in two
    blocks (the second parametric on a surface: u v after x y z), node tags ``tags`` (N,),
    tets in volume 1 (physical 9) and triangles in surface 3 (physical 5, named)."""
    n = len(POINTS)
    half = n // 2
    lines = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat",
             "$PhysicalNames", "2", '2 5 "top face"', '3 9 "solid"', "$EndPhysicalNames",
             "$Entities", "0 0 1 1",
             "3 0 0 0 1 1 1 1 5 0", "1 0 0 0 1 1 1 1 9 1 3", "$EndEntities",
             "$Nodes", f"2 {n} {tags.min()} {tags.max()}", f"3 1 0 {half}"]
    lines += [str(t) for t in tags[:half]] + [" ".join(repr(float(v)) for v in p) for p in POINTS[:half]]
    lines += [f"2 3 {int(parametric)} {n - half}"] + [str(t) for t in tags[half:]]
    lines += [" ".join(repr(float(v)) for v in p) + (" 0.5 0.25" if parametric else "") for p in POINTS[half:]]
    lines += ["$EndNodes", "$Elements", f"2 {len(elements_tets) + len(TRIANGLES)} 1 {len(elements_tets) + len(TRIANGLES)}",
              f"3 1 4 {len(elements_tets)}"]
    lines += [f"{k + 1} " + " ".join(str(tags[v]) for v in row) for k, row in enumerate(elements_tets)]
    lines += [f"2 3 2 {len(TRIANGLES)}"]
    lines += [f"{k + 100} " + " ".join(str(tags[v]) for v in row) for k, row in enumerate(TRIANGLES)]
    lines += ["$EndElements", "$Comments", "anything $Nodes", "$EndComments", ""]
    return "\n".join(lines).encode()


@pytest.mark.parametrize("binary", [False, True])
def test_msh_22_reads_as_meshio_reads_it(tmp_path, binary):
    path = _meshio_file(tmp_path, binary)
    msh = read_msh(path.read_bytes())
    assert np.array_equal(msh.points, POINTS)
    for kind, cells in ((TETRA, TETS), (TRIANGLE, TRIANGLES), (QUAD, QUADS)):
        assert np.array_equal(msh.elements[kind].nodes, cells)
    assert np.array_equal(msh.elements[TRIANGLE].physical, np.arange(12) % 3 + 1)
    assert np.array_equal(msh.elements[TRIANGLE].entity, np.arange(12) % 3 + 10)
    assert np.array_equal(msh.elements[TETRA].physical, np.full(25, 9))
    assert msh.names == {(3, 9): "solid", (2, 1): "inlet", (2, 2): "wall 2"}


def test_msh_41_ascii_with_node_blocks_parametric_nodes_and_sparse_tags():
    tags = RNG.permutation(np.arange(1, 400))[:len(POINTS)] * 3  # sparse, unordered, never 0
    msh = read_msh(_ascii41(tags, TETS))
    assert np.array_equal(msh.points, POINTS)
    assert np.array_equal(msh.elements[TETRA].nodes, TETS) and np.array_equal(msh.elements[TRIANGLE].nodes, TRIANGLES)
    assert set(msh.elements[TETRA].physical) == {9} and set(msh.elements[TRIANGLE].physical) == {5}
    assert set(msh.elements[TRIANGLE].entity) == {3}
    assert msh.names == {(2, 5): "top face", (3, 9): "solid"}


def test_paroct_msh_reads_back_exactly(tmp_path):
    path = tmp_path / "m.msh"
    write_mesh(path, POINTS, TETS)
    points, tets = read_mesh(path)
    assert np.array_equal(points, POINTS) and np.array_equal(tets, TETS)


def test_an_element_naming_an_undefined_node_is_refused(tmp_path, capsys):
    """The file meshio 5.3 reads silently as another mesh: node tags 1..40 but 17, and a tet
    naming 17 (meshio reads it as node -1, the last)."""
    tags = np.arange(1, len(POINTS) + 2)
    tags = np.delete(tags, 16)  # 1..16, 18..41
    text = _ascii41(tags, TETS, parametric=False).decode()
    lines = text.splitlines()
    at = lines.index(f"3 1 4 {len(TETS)}") + 1
    lines[at] = "1 17 " + " ".join(lines[at].split()[2:])
    path = tmp_path / "gap.msh"
    path.write_text("\n".join(lines))
    with pytest.raises(MshError, match=r"^an element names node 17, which the file does not define$"):
        read_msh(path.read_bytes())
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("as Gmsh MSH: an element names node 17, which the file does not define")
    assert len(err.splitlines()) == 1


def test_node_tags_defined_twice_or_below_one_are_refused():
    tags = np.arange(1, len(POINTS) + 1)
    with pytest.raises(MshError, match=r"node tag 5 is defined twice"):
        read_msh(_ascii41(np.where(tags == 6, 5, tags), TETS))
    with pytest.raises(MshError, match=r"a node has tag 0"):
        read_msh(_ascii41(tags - 1, TETS))


@pytest.mark.parametrize("header, match", [
    (b"$MeshFormat\n4.0 0 8\n$EndMeshFormat\n", r"MSH version '4.0' is not read: save the mesh as MSH 4.1 or 2.2"),
    (b"$MeshFormat\n2.2 1 8\n\x00\x00\x00\x01\n$EndMeshFormat\n", r"big-endian files are not read"),
    (b"$NOD\n1\n1 0 0 0\n$ENDNOD\n", r"not a Gmsh MSH file: it does not start with \$MeshFormat"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 1_0\n$EndNodes\n", r"\$Nodes holds '1_0', which is not a finite number"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n", r"it has no \$Elements section"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n2\n1 0 0 0\n$EndNodes\n", r"\$Nodes ends early"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 0\n$EndNodes\n$Elements\n1\n1 4 0 1 1 1 1.5\n$EndElements\n",
     r"\$Elements holds 1.5 where a whole number belongs"),
    (b"$MeshFormat\n4.1 1 8\n\x01\x00\x00\x00\n$EndMeshFormat\n$Nodes\n" + np.array([1, 10**12, 1, 10**12], "<u8").tobytes(),
     r"the file ends inside \$Nodes"),
])
def test_malformed_files_say_what_is_wrong(header, match):
    with pytest.raises(MshError, match=match):
        read_msh(header)


@pytest.mark.parametrize("version", ["22_binary", "41_binary", "41_ascii"])
def test_damaged_files_raise_msh_error_or_read_what_they_hold(tmp_path, version):
    """Every prefix of a file, and 300 files with random bytes changed (fixed seed): MshError,
    or a mesh whose elements name only its nodes; never another exception."""
    if version == "22_binary":
        data = _meshio_file(tmp_path, True).read_bytes()
    elif version == "41_binary":
        write_mesh(tmp_path / "m.msh", POINTS, TETS)
        data = (tmp_path / "m.msh").read_bytes()
    else:
        data = _ascii41(np.arange(1, len(POINTS) + 1), TETS)
    rng = np.random.default_rng(3)
    damaged = [data[:n] for n in range(0, len(data), 7)]
    for _ in range(300):
        raw = bytearray(data)
        for at in rng.integers(0, len(raw), rng.integers(1, 4)):
            raw[at] = int(rng.integers(0, 256)) if rng.random() < 0.5 else raw[at] ^ 0x20
        damaged.append(bytes(raw))
    read = 0
    for raw in damaged:
        try:
            msh = read_msh(raw)
        except MshError:
            continue
        read += 1
        for block in msh.elements.values():
            assert block.nodes.size == 0 or 0 <= block.nodes.min() <= block.nodes.max() < len(msh.points)
    assert 0 < read < len(damaged)


@pytest.mark.parametrize("data, match", [
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" + "\u00b3".encode() + b"\n", r"\$Nodes starts with '\u00b3', not a count"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n" + b"9" * 5000 + b"\n", r"\$Nodes starts with '9{40}\.\.\.', not a count$"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n2 " + b"1" * 5000 + b' "a"\n', r"is not 'dimension tag"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n9007199254740993 0 0 0\n$EndNodes\n", r"beyond the 2\*\*53"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n1\n1 0 0 nan\n$EndNodes\n", r"'nan', which is not a finite number"),
    (b"$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\x1b[31m\n", r"found '\$Nodes\\x1b\[31m'$"),
])
def test_counts_tags_and_names_beyond_what_is_read_say_so_in_one_line(data, match):
    """Found by fuzzing: counts in other scripts' digits or of 5000 digits raised ValueError,
    text tags past 2**53 were rounded onto other nodes, control bytes reached the message."""
    with pytest.raises(MshError, match=match):
        read_msh(data)


def _parametric22(binary: bool) -> bytes:
    """MSH 2.2 with $ParametricNodes (Gmsh's Mesh.SaveParametric): 'tag x y z dim entity',
    then u on a curve and u v on a surface; the three triangles of TRIANGLES[:3] on surface 1."""
    dims = np.arange(len(POINTS)) % 4
    head = f"$MeshFormat\n2.2 {int(binary)} 8\n".encode() + (b"\x01\x00\x00\x00\n" if binary else b"")
    head += b"$EndMeshFormat\n$ParametricNodes\n" + f"{len(POINTS)}\n".encode()
    if binary:
        body = b"".join(np.array([k + 1], "<i4").tobytes() + POINTS[k].astype("<f8").tobytes()
                        + np.array([dims[k], 5], "<i4").tobytes() + np.full(dims[k] if dims[k] in (1, 2) else 0, 0.5).tobytes()
                        for k in range(len(POINTS)))
        elements = np.concatenate([[2, 3, 2], np.column_stack([np.arange(1, 4), np.full(3, 4), np.ones(3, int),
                                                                TRIANGLES[:3] + 1]).ravel()]).astype("<i4").tobytes()
    else:
        body = "".join(f"{k + 1} {' '.join(repr(float(v)) for v in POINTS[k])} {dims[k]} 5"
                       + " 0.5" * (dims[k] if dims[k] in (1, 2) else 0) + "\n" for k in range(len(POINTS))).encode()
        elements = "".join(f"{k + 1} 2 2 4 1 {' '.join(str(v + 1) for v in TRIANGLES[k])}\n" for k in range(3)).encode()
    return head + body + b"\n$EndParametricNodes\n$Elements\n3\n" + elements + b"\n$EndElements\n"


@pytest.mark.parametrize("binary", [False, True])
def test_msh_22_parametric_nodes_are_read(binary):
    msh = read_msh(_parametric22(binary))
    assert np.array_equal(msh.points, POINTS)
    assert np.array_equal(msh.elements[TRIANGLE].nodes, TRIANGLES[:3])
    assert list(msh.elements[TRIANGLE].physical) == [4] * 3 and list(msh.elements[TRIANGLE].entity) == [1] * 3


def test_msh_22_copies_of_an_element_in_two_groups_are_one_element(tmp_path):
    """Gmsh's MSH 2 writer lists an element once per physical group: read once, in the first
    group, as MSH 4.1 gives it; an element repeated in one group stays repeated."""
    rows = np.concatenate([TRIANGLES, TRIANGLES[:4], TRIANGLES[5:6]])
    physical = np.concatenate([np.ones(12, int), np.full(4, 2), np.ones(1, int)])
    mesh = meshio.Mesh(POINTS, [("triangle", rows)], cell_data={"gmsh:physical": [physical],
                                                               "gmsh:geometrical": [np.ones(17, int)]})
    meshio.write(tmp_path / "copies.msh", mesh, file_format="gmsh22", binary=False)
    msh = read_msh((tmp_path / "copies.msh").read_bytes())
    assert np.array_equal(msh.elements[TRIANGLE].nodes, np.concatenate([TRIANGLES, TRIANGLES[5:6]]))
    assert set(msh.elements[TRIANGLE].physical) == {1}


def _partitioned41() -> bytes:
    """A 4.1 ASCII file of a surface cut in two partitions: surface 1 (physical 5) is
    partitioned into surfaces 7 and 8, and surface 9 is an interface whose parent is volume
    1; the triangles on 7 and 8 are the model's, the one on 9 is no part of it."""
    n = len(POINTS)
    lines = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$Entities", "0 0 1 0", "1 0 0 0 1 1 1 1 5 0",
             "$EndEntities", "$PartitionedEntities", "2", "0", "0 0 3 0",
             "7 2 1 1 1 0 0 0 1 1 1 1 5 0", "8 2 1 1 2 0 0 0 1 1 1 1 5 0", "9 3 1 2 1 2 0 0 0 1 1 1 0 0",
             "$EndPartitionedEntities", "$Nodes", f"1 {n} 1 {n}", f"2 7 0 {n}"]
    lines += [str(k + 1) for k in range(n)] + [" ".join(repr(float(v)) for v in p) for p in POINTS]
    lines += ["$EndNodes", "$Elements", "3 5 1 5", "2 7 2 2", "1 1 2 3", "2 2 3 4", "2 8 2 2", "3 3 4 5", "4 4 5 6",
              "2 9 2 1", "5 7 8 9", "$EndElements", ""]
    return "\n".join(lines).encode()


def test_msh_41_partitioned_elements_take_their_parent_entity_and_groups():
    msh = read_msh(_partitioned41())
    assert np.array_equal(msh.elements[TRIANGLE].nodes, [[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5]])
    assert set(msh.elements[TRIANGLE].entity) == {1} and set(msh.elements[TRIANGLE].physical) == {5}


@pytest.mark.parametrize("change, match", [
    (("2 7 2 2", "3 7 2 2"), r"puts triangle elements on an entity of dimension 3"),
    (("2 8 2 2", "2 99 2 2"), r"names entity 99 of dimension 2, which \$Entities does not list"),
])
def test_msh_41_element_blocks_must_name_listed_entities_of_their_dimension(change, match):
    with pytest.raises(MshError, match=match):
        read_msh(_partitioned41().replace(change[0].encode(), change[1].encode(), 1))


def test_a_byte_order_mark_is_read_past_and_a_msh_of_neither_kind_says_so(tmp_path, capsys):
    path = tmp_path / "bom.msh"
    write_mesh(path, POINTS, TETS)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes())
    assert np.array_equal(read_mesh(path)[1], TETS)
    path.write_bytes(b"$MeshFormet\n2.2 0 8\n$EndMeshFormat\n")
    assert main(["check", str(path)]) == 2
    assert capsys.readouterr().err.strip().endswith(
        "not a Gmsh MSH file (it does not start with $MeshFormat), nor an ANSYS one")


@pytest.mark.parametrize("kind", ["triangle6", "quad9"])
def test_second_order_surfaces_read_as_their_corners(tmp_path, kind):
    """A 1 x 2 x 3 box's surface as second-order elements (Gmsh types 9 and 10), their edge
    and face nodes pushed off the flat faces: the surface is the triangles between the
    corners, and the solid the box (a second-order mesh is refused no more)."""
    from paroct import load_surface
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 2, 0], [0, 0, 3], [1, 0, 3], [1, 2, 3], [0, 2, 3]], float)
    quads = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    polygons = quads if kind == "quad9" else np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    points, cells = list(corners), []
    for poly in polygons:
        extra = []
        for a, b in zip(poly, np.roll(poly, -1)):  # edge nodes, then (quads) the centre node
            extra.append(len(points))
            points.append((corners[a] + corners[b]) / 2 + RNG.normal(size=3) * 0.05)
        if kind == "quad9":
            extra.append(len(points))
            points.append(corners[poly].mean(axis=0) + RNG.normal(size=3) * 0.05)
        cells.append(list(poly) + extra)
    path = tmp_path / f"box_{kind}.msh"
    meshio.write(path, meshio.Mesh(np.array(points), [(kind, np.array(cells))]), file_format="gmsh22", binary=False)
    surface = load_surface(path)
    assert surface.volume == pytest.approx(6.0, rel=1e-12) and surface.faces.shape == (12, 3)
    assert (surface.components, surface.genus) == (1, 0)
