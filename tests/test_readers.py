"""Surface files as they are found, and bad input of every kind (session 38's fuzzing): each
valid file reads as the solid it holds, each bad one gives one ParoctError that says why."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import meshio
import numpy as np
import pytest

import paroct
from paroct import ParoctError, load_surface
from paroct.check import check_mesh
from paroct.cli import main
from paroct.readers import read_surface_file

DATA = Path(__file__).resolve().parent.parent / "data"
CUBE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
CUBE_F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                   [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
BOX_V = CUBE_V * [1, 2, 3]  # volume 6, so an axis swap or a lost face shows


def _is_box(path) -> bool:
    surface = load_surface(path)
    return surface.volume == pytest.approx(6.0, rel=1e-12) and (surface.components, surface.genus) == (1, 0)


def _obj_lines(faces, corner) -> str:
    text = "# a box\nmtllib box.mtl\no box\n" + "".join(f"v {x:g} {y:g} {z:g}\n" for x, y, z in BOX_V)
    text += "vt 0 0\nvn 0 0 1\ns off\ng sides\nusemtl grey\n"
    return text + "".join("f " + " ".join(corner(i) for i in f) + "\n" for f in faces)


@pytest.mark.parametrize("corner", [
    lambda i: f"{i + 1}",
    lambda i: f"{i - 8}",  # relative: -1 is the latest vertex
    lambda i: f"{i + 1}/1",
    lambda i: f"{i + 1}/1/1",
    lambda i: f"{i + 1}//1",
])
def test_obj_corners_in_every_form(tmp_path, corner):
    path = tmp_path / "box.obj"
    path.write_text(_obj_lines(CUBE_F, corner))
    assert _is_box(path)


def test_obj_quads_split_into_fans(tmp_path):
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    path = tmp_path / "box.obj"
    path.write_text(_obj_lines(quads, lambda i: f"{i + 1}"))
    assert _is_box(path) and read_surface_file(path)[1].shape == (12, 3)


def test_obj_statements_continued_on_the_next_line(tmp_path):
    # Rhino ends long face lines with a backslash; a statement may run over several lines.
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    text = _obj_lines(quads, lambda i: f"{i + 1}/{i + 1}/1")
    text = text.replace("f 1/1/1 4/4/1 ", "f 1/1/1 \\\n4/4/1 \\\n ").replace("v 1 0 0", "v 1 \\\n0 0")
    assert text.count("\\") == 3
    path = tmp_path / "box.obj"
    path.write_text(text + "f 1 2 x\n")  # a bad corner after the continued lines: its own line number
    with pytest.raises(ParoctError, match=f"line {text.count(chr(10)) + 1} reads 'f 1 2 x'"):
        load_surface(path)
    path.write_text(text)
    assert _is_box(path) and read_surface_file(path)[1].shape == (12, 3)


def _ply(fmt: str, vertex_props: list, face_list: str = "vertex_indices", faces=CUBE_F, extra=b"") -> bytes:
    """A PLY of the box: vertex properties in the given order (x, y, z among others), faces."""
    header = [f"ply\nformat {fmt} 1.0\ncomment made by hand\nelement vertex 8\n"]
    header += [f"property {t} {n}\n" for n, t in vertex_props]
    header += [f"element face {len(faces)}\nproperty list uchar int {face_list}\nproperty uchar flags\n"]
    header += ["element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"]
    values = [[{"x": x, "y": y, "z": z}.get(n, 7) for n, _ in vertex_props] for x, y, z in BOX_V]
    if fmt == "ascii":
        body = "".join(" ".join(f"{v:g}" for v in row) + "\n" for row in values)
        body += "".join(f"{len(f)} " + " ".join(map(str, f)) + " 0\n" for f in faces) + "0 1\n"
        return "".join(header).encode() + body.encode() + extra
    order = "<" if fmt == "binary_little_endian" else ">"
    codes = {"float": "f", "double": "d", "uchar": "B", "int": "i", "short": "h"}
    body = b"".join(struct.pack(order + "".join(codes[t] for _, t in vertex_props), *row) for row in values)
    body += b"".join(struct.pack(f"{order}B{len(f)}iB", len(f), *f, 0) for f in faces)
    return "".join(header).encode() + body + struct.pack(order + "ii", 0, 1) + extra


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("props, face_list", [
    ([("x", "float"), ("y", "float"), ("z", "float")], "vertex_indices"),
    ([("z", "double"), ("nx", "float"), ("y", "double"), ("x", "double"), ("red", "uchar")], "vertex_index"),
])
def test_ply_in_every_byte_order_and_property_order(tmp_path, fmt, props, face_list):
    path = tmp_path / "box.ply"
    path.write_bytes(_ply(fmt, props, face_list))
    assert _is_box(path)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_with_elements_of_no_properties_and_end_header_in_a_comment(tmp_path, fmt):
    data = _ply(fmt, [("x", "float"), ("y", "float"), ("z", "float")])
    data = data.replace(b"comment made by hand\n", b"comment made by hand, up to end_header\nelement nothing 4611686018427387904\n")
    path = tmp_path / "box.ply"
    path.write_bytes(data)
    assert _is_box(path)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_with_mixed_polygons(tmp_path, fmt):
    faces = [[0, 3, 2, 1], [4, 5, 6], [4, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    path = tmp_path / "box.ply"
    path.write_bytes(_ply(fmt, [("x", "float"), ("y", "float"), ("z", "float")], faces=faces))
    assert _is_box(path)


def test_ply_files_meshio_writes_read_the_same(tmp_path):
    ref = load_surface(DATA / "angle_block.stl")
    for binary in (True, False):
        path = tmp_path / f"part{binary}.ply"
        meshio.write(path, meshio.Mesh(ref.vertices, [("triangle", ref.faces)]), binary=binary)
        back = load_surface(path)
        assert np.array_equal(back.vertices, ref.vertices) and np.array_equal(back.faces, ref.faces)


def _ascii_stl(keyword=str) -> str:
    lines = [keyword("solid") + " box"]
    for f in CUBE_F:
        lines += [keyword("facet normal") + " 0 0 0", keyword("outer loop")]
        lines += [f"{keyword('vertex')} {x:g} {y:g} {z:g}" for x, y, z in BOX_V[f]]
        lines += [keyword("endloop"), keyword("endfacet")]
    return "\n".join(lines + [keyword("endsolid") + " box", ""])


@pytest.mark.parametrize("encode", [
    lambda t: t.encode(),
    lambda t: b"\xef\xbb\xbf" + t.encode(),  # UTF-8 byte-order mark
    lambda t: t.encode("utf-16"),  # with its byte-order mark
    lambda t: t.replace("\n", "\r\n").encode(),
])
def test_ascii_stl_as_editors_save_it(tmp_path, encode):
    path = tmp_path / "box.stl"
    path.write_bytes(encode(_ascii_stl()))
    assert _is_box(path)
    path.write_bytes(encode(_ascii_stl(str.upper)))
    assert _is_box(path)


def _binary_stl(faces, count=None) -> bytes:
    """A binary STL of the 1 x 2 x 3 box (normals zero) whose header gives count (default: the truth)."""
    body = b"".join(struct.pack("<12fH", 0, 0, 0, *BOX_V[f].ravel(), 0) for f in faces)
    return bytes(80) + struct.pack("<I", len(faces) if count is None else count) + body


def test_binary_stl_counts(tmp_path):
    """The header's count is the file's: facets past it are padding, as exporters write; but a
    count of 0 before whole facets is a streaming writer that never went back to write it."""
    path = tmp_path / "box.stl"
    path.write_bytes(_binary_stl(CUBE_F))
    assert _is_box(path)
    path.write_bytes(_binary_stl(CUBE_F, count=0))
    assert _is_box(path)
    path.write_bytes(_binary_stl(CUBE_F) + bytes(50))  # padding after the counted facets
    assert _is_box(path)
    path.write_bytes(_binary_stl(CUBE_F, count=5))
    with pytest.raises(ParoctError, match=r"open surface.*its header counts 5 triangles, but 12 whole 50-byte facet records follow"):
        load_surface(path)


def _head(fmt: str, n_faces: int, count: str = "uchar") -> bytes:
    """The header of a PLY of three vertices and n_faces faces."""
    return (f"ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            f"element face {n_faces}\nproperty list {count} int vertex_indices\nend_header\n").encode()


@pytest.mark.parametrize("name, content, match", [
    ("x.obj", b"f 1 2 3\n", r"a face refers to vertex 3 \(counting from 1\), but there are 0 vertices"),
    ("x.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", r"line 4 reads 'f 0 1 2': vertex indices count from 1"),
    ("x.obj", b"v 0 0 0\nv 1 0 0\nf 1 2\n", r"line 3 reads 'f 1 2': a face needs at least 3 corners"),
    ("x.obj", b"v 0 0 zero\n", r"a vertex coordinate 'zero' is not a number"),
    ("x.ply", b"ply\nformat ascii 1.0\nend_header\n", r"expected 'vertex' and 'face' elements, the header declares none"),
    ("x.ply", _head("ascii", 1) + b"0 0 0\n1 0 0\n", r"the header says 3 vertex elements, the file ends before them"),
    ("x.ply", _head("binary_little_endian", 2000000000) + bytes(36 + 13),
     r"the header says 2000000000 face elements, at least 2000000000 bytes, but 13 are left"),
    ("x.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty quad x\nend_header\n",
     r"header line 'property quad x' is not PLY"),
    ("x.off", b"OFF\n0 0 0\n", r"empty surface \(len\(vertices\) = 0, len\(faces\) = 0\)"),
    ("x.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n",
     r"1 'facet', 0 'endfacet' and 2 'vertex' keywords"),
    ("x.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 " + b"9" * 100000 + b"x\nvertex 1 0 0\n"
              b"vertex 0 1 0\nendloop\nendfacet\nendsolid\n", r"a vertex coordinate '9+x' is not a number"),
    ("x.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 3 99999999999999999999\n", r"line 4 reads .*: a corner is not a vertex index"),
    ("x.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 2 99999999999999999999\n", r"a face line reads .*: vertex 99999999999999999999 of 3"),
    ("x.ply", _head("ascii", 1) + b"0 0 0\n1 0 0\n0 1 0\n-1 0 1 2\n", r"a face list of -1 items"),
    ("x.ply", _head("binary_little_endian", 1, "uint") + bytes(36) + b"\xff\xff\xff\xff" + bytes(12),
     r"a face list of 4294967295 items runs past the end of the file"),
    # Python reads '1_0' as 10 and int(1.7) as 1; a file means neither (session 42's fuzzing)
    ("x.obj", b"v 1_0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"a vertex coordinate '1_0' is not a number"),
    ("x.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0_3\n", r"line 4 reads 'f 1 2 0_3': a corner is not a vertex index"),
    ("x.off", b"OFF\n3 1 0\n0 0 0\n1_0 0 0\n0 1 0\n3 0 1 2\n", r"a vertex coordinate '1_0' is not a number"),
    ("x.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 0_2\n", r"a face line reads '3 0 1 0_2'"),
    ("x.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1_0 0 0\nvertex 0 1 0\nendloop\n"
              b"endfacet\nendsolid\n", r"a vertex coordinate '1_0' is not a number"),
    ("x.ply", _head("ascii", 1) + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 1.7\n", r"a face index '1.7' is not an integer"),
    ("x.ply", _head("ascii", 1) + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 nan\n", r"a face index 'nan' is not an integer"),
    ("x.ply", _head("ascii", 1) + b"0 0 0\n1 0 0\n0 1 0\n3 0 1 1_0\n", r"a face value '1_0' is not a number"),
])
def test_malformed_files_are_refused_saying_why(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ParoctError, match=match):
        load_surface(path)


def test_things_that_are_not_files_are_refused_without_waiting(tmp_path):
    fifo = tmp_path / "pipe.stl"
    os.mkfifo(fifo)
    with pytest.raises(ParoctError, match="is not a regular file"):
        load_surface(fifo)
    assert main(["check", str(fifo)]) == 2
    with pytest.raises(ParoctError, match="is a directory"):
        load_surface(tmp_path)


@pytest.mark.parametrize("vertices, faces, match", [
    ([[0, 0, 0], [1, 0, 0], [0, 1]], [[0, 1, 2]], r"must be \(V, 3\) and \(F, 3\) arrays"),
    (CUBE_V, [[0, 1, 2], [0, 1]], r"must be \(V, 3\) and \(F, 3\) arrays"),
    (CUBE_V, np.where(CUBE_F == 7, 2**64 - 1, CUBE_F).astype(np.uint64),
     r"face indices span 0..18446744073709551615 but len\(vertices\) = 8"),
])
def test_arrays_of_the_wrong_shape_are_refused(vertices, faces, match):
    with pytest.raises(ParoctError, match=match):
        load_surface((vertices, faces))


def test_an_inside_out_shell_is_refused_not_dropped():
    beside = (np.vstack([CUBE_V, CUBE_V + [3, 0, 0]]), np.vstack([CUBE_F, CUBE_F[:, ::-1] + 8]))
    around = (np.vstack([CUBE_V * 3 - 1, CUBE_V]), np.vstack([CUBE_F[:, ::-1], CUBE_F + 8]))
    for source, centre in ((beside, r"\(3.5, 0.5, 0.5\)"), (around, r"\(0.5, 0.5, 0.5\)")):
        with pytest.raises(ParoctError, match=r"a shell of 12 triangles around " + centre + r" encloses negative volume"):
            load_surface(source)
    hollow = (np.vstack([CUBE_V * 3 - 1, CUBE_V]), np.vstack([CUBE_F, CUBE_F[:, ::-1] + 8]))  # a cavity: fine
    assert load_surface(hollow).volume == pytest.approx(26.0)


def test_a_surface_built_by_hand_is_checked_before_meshing():
    open_box = paroct.Surface(CUBE_V, CUBE_F[2:].astype(np.int32), 1.0, 6.0, 0, 1)
    with pytest.raises(ParoctError, match="open surface, 4 boundary edges"):
        paroct.mesh(open_box, divisions=12)
    wrong_volume = paroct.Surface(CUBE_V, CUBE_F.astype(np.int32), -5.0, 0.0, 0, 1)
    assert load_surface(wrong_volume).volume == pytest.approx(1.0)  # measured again, not taken
    ours = load_surface((CUBE_V, CUBE_F))
    assert load_surface(ours) is ours


@pytest.mark.parametrize("vertices, faces, match", [
    (CUBE_V.ravel(), CUBE_F, r"vertices shape \(24,\) float64"),
    ("abc", CUBE_F, r"vertices shape \(\) <U3"),
    (CUBE_V, 5, r"faces shape \(\) int64"),
    (CUBE_V, CUBE_F.astype(float), r"faces shape \(12, 3\) float64"),
    (CUBE_V[:, :2], CUBE_F, r"vertices shape \(8, 2\)"),
    ([[0, 0], [1]], CUBE_F, r"vertices of type list"),
])
def test_a_surface_built_by_hand_with_wrong_arrays_is_refused_in_one_line(vertices, faces, match):
    """Not (V, 3) numbers and (F, 3) integers: a ParoctError that states what came (a numba
    typing error, a ValueError or an IndexError from the box before); lists of numbers are
    arrays."""
    with pytest.raises(ParoctError, match=r"Surface: " + ".*" + match):
        paroct.Surface(vertices, faces, 1.0, 6.0, 0, 1)
    assert paroct.Surface(CUBE_V.tolist(), CUBE_F.tolist(), 1.0, 6.0, 0, 1).bbox_max.tolist() == [1.0, 1.0, 1.0]


def test_meshing_and_checking_do_not_depend_on_the_scale():
    """The same cube from 1e-99 to 1e99 across: the same mesh, angles and check (the quality
    measures' fourth powers of lengths over- and underflowed at 1e77)."""
    ref = paroct.mesh((CUBE_V, CUBE_F), divisions=12)
    ref_check = check_mesh(ref.mesh.points, ref.mesh.tets, load_surface((CUBE_V, CUBE_F)))
    for scale in (1e-99, 1e-80, 1e80, 1e99):
        source = (CUBE_V * scale, CUBE_F)
        result = paroct.mesh(source, divisions=12)
        assert np.array_equal(result.mesh.tets, ref.mesh.tets) and not result.report.warnings
        assert (result.report.min_dihedral, result.report.max_dihedral) == pytest.approx(
            (ref.report.min_dihedral, ref.report.max_dihedral), abs=1e-9)
        checked = check_mesh(result.mesh.points, result.mesh.tets, load_surface(source))
        assert checked.ok and checked.min_dihedral == pytest.approx(ref_check.min_dihedral, abs=1e-9)
        assert checked.hausdorff == pytest.approx(ref_check.hausdorff, rel=1e-9)
        assert checked.volume_error == pytest.approx(ref_check.volume_error, abs=1e-12)


def test_a_polygon_of_millions_of_corners_is_refused_at_once(tmp_path):
    """A fuzzed OBJ face of 600 k corners: 200 k copies of one triangle, a vertex of 600 k faces
    (link_fans compared every pair of a vertex's faces: minutes)."""
    path = tmp_path / "fan.obj"
    path.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf " + b"1 2 3 " * 200_000 + b"\n")
    with pytest.raises(ParoctError, match="non-manifold surface, 3 edges shared by more than two triangles"):
        load_surface(path)


def test_a_vertex_of_many_faces_has_its_fans_counted_right():
    """A double cone of 300 triangles a side: its apexes have degree 300, above the pairwise
    scan's limit, and the fans by sort agree with the reference."""
    from paroct.topology import vertex_fans

    from . import naive

    n = 300
    ring = np.c_[np.cos(np.arange(n) * 2 * np.pi / n), np.sin(np.arange(n) * 2 * np.pi / n), np.zeros(n)]
    vertices = np.vstack([[0, 0, 1], [0, 0, -1], ring])
    faces = np.array([[0, 2 + i, 2 + (i + 1) % n] for i in range(n)] + [[1, 2 + (i + 1) % n, 2 + i] for i in range(n)])
    assert np.all(vertex_fans(faces, len(vertices)) == 1)
    pinched = np.vstack([faces, faces[:n] + [0, 0, 0]])  # every upper triangle twice: no fans at the apex
    assert np.array_equal(vertex_fans(pinched, len(vertices)) < 0, naive.nonmanifold_vertices(pinched, len(vertices)))
    assert load_surface((vertices, faces)).volume == pytest.approx(2 * np.pi / 3, rel=1e-3)


def test_a_part_of_1e_90_is_measured_and_meshed():
    """Its area's squared cross products underflowed to 0 (then a division by it)."""
    import manifold3d

    sphere = load_surface(manifold3d.Manifold.sphere(1.0, 32))
    tiny = load_surface((sphere.vertices * 1e-90, sphere.faces))
    assert tiny.area == pytest.approx(sphere.area * 1e-180, rel=1e-12)
    assert tiny.volume == pytest.approx(sphere.volume * 1e-270, rel=1e-12)
    assert paroct.mesh(tiny, divisions=12).report.n_tets == paroct.mesh(sphere, divisions=12).report.n_tets


def test_a_part_too_small_for_its_coordinates_is_refused():
    with pytest.raises(ParoctError, match=r"less than 256 steps of float64 .* move the part near the origin"):
        paroct.mesh((CUBE_V * 1e-6 + 1e9, CUBE_F), divisions=12)


def test_cli_reads_negative_numbers_as_numbers(tmp_path, capsys):
    for value in ("-inf", "-1e-3"):
        assert main(["mesh", DATA / "xyz_cube.stl", "-o", tmp_path / "x.vtu", "--size", value]) == 2
        assert capsys.readouterr().err.strip() == f"paroct: error: size = {float(value)}: must be a positive number"


def test_check_names_what_a_bad_mesh_file_lacks(tmp_path, capsys):
    points = np.eye(4, 3)
    meshio.write(tmp_path / "empty.vtu", meshio.Mesh(points, [("tetra", np.zeros((0, 4), int))]))
    (tmp_path / "bad.inp").write_text("*NODE\n1, 0, 0, 0\n2, 1, 0, 0\n*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n")
    for name, why in (("empty.vtu", "it holds no cells"), ("bad.inp", "a cell refers to node 3, which the file does not define")):
        assert main(["check", str(tmp_path / name)]) == 2
        assert capsys.readouterr().err.strip().endswith(why)
