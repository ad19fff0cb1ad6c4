"""Named groups of the input's triangles (the solids of an ASCII STL, an OBJ's g groups): read,
carried with the triangles through welding and the union of shells, and written as named
boundary patches."""

from __future__ import annotations

import dataclasses

import manifold3d
import meshio
import numpy as np
import pytest

import paroct
from paroct import ParoctError, boundary_patches, load_surface
from paroct.cli import main
from paroct.io import _abaqus_names, _gmsh_names, write_mesh
from paroct.readers import read_surface_file
from paroct.surface import Surface, surface_from_arrays

CUBE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
BOX = np.array([1.0, 2.0, 3.0])
BOX_V = CUBE_V * BOX
# Two triangles a side, outward: z = 0, z = 3, y = 0, x = 1, y = 2, x = 0.
SIDE_FACES = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                       [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]]).reshape(6, 2, 3)
SIDE_AXIS_HIGH = [(2, False), (2, True), (1, False), (0, True), (1, True), (0, False)]


def _stl_solid(name: str, faces: np.ndarray, keyword: str = "solid") -> str:
    facets = "".join("facet normal 0 0 0\n outer loop\n" + "".join(f"  vertex {x:g} {y:g} {z:g}\n" for x, y, z in BOX_V[f])
                     + " endloop\nendfacet\n" for f in faces)
    return f"{keyword} {name}\n{facets}end{keyword} {name}\n"


def _side_of(centroids: np.ndarray, size: float) -> np.ndarray:
    """Side 0 .. 5 (SIDE_FACES' order) of each boundary triangle's centroid more than two sizes
    from every edge of the box; -1 near the edges, where stuffing cuts the corner."""
    gap = np.minimum(centroids, BOX - centroids)
    axis = np.argmin(gap, axis=1)
    high = centroids[np.arange(len(centroids)), axis] > BOX[axis] / 2
    side = np.array([SIDE_AXIS_HIGH.index((int(a), bool(h))) for a, h in zip(axis, high)])
    return np.where(np.sort(gap, axis=1)[:, 1] > 2 * size, side, -1)


NAMES = ["bottom", "top", "front face", "right", "back", "left"]


@pytest.fixture(scope="module")
def named_box(tmp_path_factory):
    """An ASCII STL of the 1 x 2 x 3 box, one named solid a side, and its mesh at size 0.1."""
    path = tmp_path_factory.mktemp("groups") / "box.stl"
    path.write_text("".join(_stl_solid(name, faces) for name, faces in zip(NAMES, SIDE_FACES)))
    return path, paroct.mesh(path, size=0.1)


def test_ascii_stl_solids_are_groups(named_box):
    path, _ = named_box
    read = read_surface_file(path)
    assert read.group_names == tuple(NAMES)
    assert np.array_equal(read.face_groups, np.repeat(np.arange(6), 2))
    surface = load_surface(path)  # welded: 8 vertices, the faces in file order
    assert surface.group_names == tuple(NAMES) and np.array_equal(surface.face_groups, read.face_groups)
    assert surface.volume == pytest.approx(6.0, rel=1e-12)


def test_named_groups_are_the_boundary_patches(named_box):
    """Every boundary triangle away from the box's edges is tagged with its side's group, by name;
    asked for a feature angle, the patches are the sides again, numbered by first triangle."""
    _, result = named_box
    patches = result.boundary_patches()
    assert patches.feature_angle is None and patches.names == tuple(NAMES) and patches.n_patches == 6
    side = _side_of(result.mesh.points[patches.faces].mean(axis=1), result.report.size)
    assert (side >= 0).sum() > len(side) / 2
    assert np.array_equal(patches.patches[side >= 0], side[side >= 0] + 1)
    by_angle = result.boundary_patches(40)
    assert by_angle.feature_angle == 40 and by_angle.names == tuple(f"patch_{p}" for p in range(1, 7))
    same = boundary_patches(result.mesh.points, result.mesh.tets, result.surface)
    assert np.array_equal(same.patches, patches.patches) and same.names == patches.names


def test_groups_need_not_follow_sharp_edges(tmp_path):
    """An OBJ putting three sides in ``hot`` and three in ``cold`` (quads, so the line parser
    reads it): two patches, each side's triangles in its group."""
    hot = {0, 2, 5}
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]  # SIDE_FACES' sides
    text = "".join(f"v {x:g} {y:g} {z:g}\n" for x, y, z in BOX_V)
    for s, quad in enumerate(quads):
        text += f"g {'hot' if s in hot else 'cold'}\nf " + " ".join(str(i + 1) for i in quad) + "\n"
    path = tmp_path / "box.obj"
    path.write_text(text)
    read = read_surface_file(path)
    assert read.group_names == ("hot", "cold") and read.faces.shape == (12, 3)
    assert np.array_equal(read.face_groups, np.repeat([0 if s in hot else 1 for s in range(6)], 2))
    result = paroct.mesh(path, size=0.1)
    patches = result.boundary_patches()
    side = _side_of(result.mesh.points[patches.faces].mean(axis=1), result.report.size)
    want = np.where(np.isin(side, list(hot)), 1, 2)
    assert patches.n_patches == 2 and np.array_equal(patches.patches[side >= 0], want[side >= 0])


@pytest.mark.parametrize("text, names, groups", [
    # the fast path (triangles, plain indices): faces before the first g are in "default"
    ("f 1 3 2\ng wall one\nf 1 4 3\ng b\nf 5 6 7\ng wall one\nf 5 7 8\n", ("default", "wall one", "b"), [0, 1, 2, 1]),
    # o only: objects are the groups; a nameless statement is "default"
    ("o a\nf 1 3 2\nf 1 4 3\no\nf 5 6 7\nf 5 7 8\n", ("a", "default"), [0, 0, 1, 1]),
    # g wins over o; a quad (slow path) gives two triangles of its group
    ("o x\ng a\nf 1 4 3 2\no y\ng b\nf 5 6 7 8\n", ("a", "b"), [0, 0, 1, 1]),
    # one group, or none: no groups
    ("g a\nf 1 3 2\nf 1 4 3\n", (), None),
    ("f 1 3 2\nf 1 4 3\n", (), None),
])
def test_obj_groups(tmp_path, text, names, groups):
    path = tmp_path / "part.obj"
    path.write_text("".join(f"v {x:g} {y:g} {z:g}\n" for x, y, z in BOX_V) + text)
    read = read_surface_file(path)
    assert read.group_names == names
    assert (read.face_groups is None) if groups is None else np.array_equal(read.face_groups, groups)


@pytest.mark.parametrize("encoding, bom", [("utf-8", b""), ("utf-8", b"\xef\xbb\xbf"), ("latin-1", b"")])
def test_group_names_keep_their_characters(tmp_path, encoding, bom):
    """Names are read as UTF-8 (with or without a byte-order mark), as CAD programs write them;
    a file that is not UTF-8 as Latin-1 (it once read every file so: "ñandú" became "Ã±andÃº")."""
    names = ["ñandú", "Größe", "façade", "x", "y", "z"] if encoding == "latin-1" else ["ñandú", "Wärme 😀", "面", "x", "y", "z"]
    path = tmp_path / "box.stl"
    path.write_bytes(bom + "".join(_stl_solid(n, f) for n, f in zip(names, SIDE_FACES)).encode(encoding))
    assert read_surface_file(path).group_names == tuple(names)
    obj = tmp_path / "box.obj"
    text = "".join(f"v {x:g} {y:g} {z:g}\n" for x, y, z in BOX_V)
    text += "".join(f"g {n}\nf {a + 1} {b + 1} {c + 1}\nf {d + 1} {e + 1} {g + 1}\n"
                    for n, ((a, b, c), (d, e, g)) in zip(names, SIDE_FACES))
    obj.write_bytes(bom + text.encode(encoding))
    assert read_surface_file(obj).group_names == tuple(names)


def test_stl_solid_names_as_found(tmp_path):
    """Upper-case keywords, CRLF line ends, a solid with no name (solid_<k>), a name used twice
    (one group); one solid alone is no group."""
    text = (_stl_solid("", SIDE_FACES[0], "SOLID") + _stl_solid("Side A", SIDE_FACES[1]) + _stl_solid("Side A", SIDE_FACES[2])
            + "".join(_stl_solid(f"s{k}", SIDE_FACES[k]) for k in range(3, 6)))
    path = tmp_path / "box.stl"
    path.write_bytes(text.replace("\n", "\r\n").encode())
    read = read_surface_file(path)
    assert read.group_names == ("solid_1", "Side A", "s3", "s4", "s5")
    assert np.array_equal(read.face_groups, [0, 0, 1, 1, 1, 1, 2, 2, 3, 3, 4, 4])
    one = tmp_path / "one.stl"
    one.write_text(_stl_solid("box", SIDE_FACES.reshape(-1, 3)))
    assert read_surface_file(one).face_groups is None and load_surface(one).face_groups is None


def test_groups_follow_the_triangles_through_welding_and_union():
    """Degenerate triangles dropped by the weld take their group with them; two overlapping
    cubes, each a group, are united by manifold3d, and each group's area is what is left of
    its cube's surface."""
    cube = manifold3d.Manifold.cube([1, 1, 1]).to_mesh64()
    v = np.asarray(cube.vert_properties)[:, :3]
    f = np.asarray(cube.tri_verts).astype(np.int64)
    vertices = np.vstack([v, v + 0.5, [[5.0, 5.0, 5.0]]])
    flat = np.array([[0, 0, 3], [16, 16, 16]])  # repeated vertices: dropped
    faces = np.vstack([flat[:1], f, flat[1:], f + len(v)])
    groups = np.concatenate([[2], np.zeros(len(f), int), [2], np.ones(len(f), int)])
    surface = surface_from_arrays(vertices, faces, face_groups=groups, group_names=("a", "b", "flat"))
    assert surface.components == 1 and surface.volume == pytest.approx(2 - 0.125, rel=1e-12)
    corners = surface.vertices[surface.faces]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert np.bincount(surface.face_groups, weights=area, minlength=3) == pytest.approx([5.25, 5.25, 0.0], rel=1e-12)
    # Overlapping solids around a cavity (subtracted): the cavity's triangles keep their group.
    hollow = surface_from_arrays(np.vstack([4 * v, 4 * v + [2, 0, 0], v + 1.5]), np.vstack([f, f + 8, (f + 16)[:, ::-1]]),
                                 face_groups=np.repeat([0, 1, 2], len(f)), group_names=("a", "b", "cavity"))
    corners = hollow.vertices[hollow.faces]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    assert hollow.volume == pytest.approx(95.0, rel=1e-12)
    groups_area = np.bincount(hollow.face_groups, weights=area, minlength=3)
    assert groups_area[2] == pytest.approx(6.0, rel=1e-12) and groups_area[:2].sum() == pytest.approx(128.0, rel=1e-12)
    apart = surface_from_arrays(np.vstack([v, v + 2.0]), np.vstack([f, f + len(v)]),
                                face_groups=np.repeat([1, 0], len(f)), group_names=("a", "b"))
    assert apart.components == 2 and np.array_equal(apart.face_groups, np.repeat([1, 0], len(f)))


@pytest.mark.parametrize("groups, names, match", [
    (np.zeros(5, int), ("a",), r"face_groups.shape = \(5,\)"),
    (np.full(12, 1), ("a",), r"face_groups span 1 .. 1, but len\(group_names\) = 1"),
    (np.zeros(12), ("a",), "expected \\(12,\\) integers"),
    (None, ("a",), "1 group names but no face_groups"),
    (np.zeros(12, int), (1,), "group_names must be a sequence of strings"),
    (np.zeros(12, int), "ab", "group_names must be a sequence of strings"),
])
def test_bad_groups_are_refused_saying_why(groups, names, match):
    faces = SIDE_FACES.reshape(-1, 3)
    with pytest.raises(ParoctError, match=match):
        surface_from_arrays(BOX_V, faces, face_groups=groups, group_names=names)
    with pytest.raises(ParoctError, match=match):
        Surface(BOX_V, faces, 6.0, 22.0, 0, 1, groups, names)


def test_gmsh_and_abaqus_files_name_the_groups(tmp_path, named_box):
    _, result = named_box
    patches = result.boundary_patches()
    msh = tmp_path / "box.msh"
    write_mesh(msh, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(msh)
    assert {name: tuple(v) for name, v in back.field_data.items()} == {
        "solid": (1, 3), **{name: (p, 2) for p, name in enumerate(NAMES, start=1)}}
    inp = tmp_path / "box.inp"
    write_mesh(inp, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(inp)
    for p, name in enumerate(_abaqus_names(patches.names), start=1):
        assert np.array_equal(np.sort(back.point_sets[name]), np.unique(patches.faces[patches.patches == p]))
    assert "*SURFACE, NAME=FRONT_FACE, TYPE=ELEMENT" in inp.read_text()


def test_abaqus_names_are_valid_and_distinct():
    names = _abaqus_names(("inlet wall", "Inlet_Wall", "3d", "a" * 100, "a" * 100, "x\"y", "INLET_WALL_2", "inlet wall"))
    assert names[:3] == ["INLET_WALL", "INLET_WALL_2", "P_3D"] and names[5] == "X_Y"
    assert len(set(names)) == len(names)
    assert all(len(n) <= 77 and n[0].isalpha() and n.replace("_", "").isalnum() for n in names)


def test_gmsh_names_read_back_distinct(tmp_path, named_box):
    """Names that ended a .msh name's quotes (a quote, a backslash: meshio splits the line as a
    shell would), a tab, 300 characters (Gmsh 4.15 dropped every physical group), two equal
    after the cut, and "solid" (the volume's): each patch's group comes back under its own
    name, within _GMSH_NAME_BYTES bytes of UTF-8."""
    _, result = named_box
    odd = ('c\\"d', "tab\there", "é" * 300, "é" * 300 + "x", "solid", "top")
    names = _gmsh_names(odd)
    assert names[:2] == ["c__d", "tab_here"] and names[4] == "solid_5" and names[5] == "top"
    assert len(set(names)) == 6 and all(len(n.encode()) <= 128 for n in names)
    patches = result.boundary_patches()
    patches = dataclasses.replace(patches, names=odd)
    msh = tmp_path / "odd.msh"
    write_mesh(msh, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(msh)
    assert {name: tuple(v) for name, v in back.field_data.items()} == {
        "solid": (1, 3), **{name: (p, 2) for p, name in enumerate(names, start=1)}}


def test_cli_lists_the_named_patches(tmp_path, named_box, capsys):
    path, _ = named_box
    out = tmp_path / "box.msh"
    assert main(["mesh", str(path), "-o", str(out), "--size", "0.2", "--patches"]) == 0
    summary = capsys.readouterr().out
    assert "in 6 patches (the input's named groups)" in summary and "patch 3 'front face':" in summary
    assert main(["mesh", str(path), "-o", str(out), "--size", "0.2", "--patches", "40"]) == 0
    assert "in 6 patches (feature angle 40 deg)" in capsys.readouterr().out
    assert set(meshio.read(out).field_data) == {"solid", *(f"patch_{p}" for p in range(1, 7))}


def test_groups_given_with_arrays_or_a_hand_made_surface_reach_the_patches():
    """A CAD kernel's face labels: surface_from_arrays takes them, and a hand-made Surface keeps
    them when mesh() validates it."""
    faces = SIDE_FACES.reshape(-1, 3)
    groups = np.repeat([0, 0, 1, 1, 1, 0], 2)
    built = paroct.surface_from_arrays(BOX_V, faces, face_groups=groups, group_names=("ends", "sides"))
    by_hand = Surface(BOX_V, faces, 6.0, 22.0, 0, 1, groups, ("ends", "sides"))
    for surface in (built, by_hand):
        result = paroct.mesh(surface, size=0.2)
        patches = result.boundary_patches()
        assert patches.names == ("ends", "sides") and set(patches.patches.tolist()) == {1, 2}
        assert np.array_equal(result.surface.face_groups, groups)


def test_cli_info_describes_the_surface_and_its_groups(named_box, capsys):
    path, _ = named_box
    assert main(["info", str(path), "--size", "0.1"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith("12 triangles, 8 vertices, 1 shell, genus 0") and out[1] == "volume 6, area 22"
    assert "named groups: 6 (paroct mesh --patches writes them as the patches)" in out
    assert "  3 'front face': 2 triangles" in out
    assert "at 40 degrees: 6 patches, 12 edges between them, 8 corners" in out
    assert out[-1] == "no wall or gap thinner than 2 x size = 0.2 found along the lattice rows"
    assert main(["info", str(path), "--divisions", "0"]) == 2
    assert "divisions" in capsys.readouterr().err


def test_cli_info_names_the_thinnest_wall(tmp_path, capsys):
    """A 1 x 1 x 0.05 plate at size 0.1: its thickness is the thinnest wall."""
    path = tmp_path / "plate.stl"
    plate = manifold3d.Manifold.cube([1.0, 1.0, 0.05]).to_mesh64()
    vertices, faces = np.asarray(plate.vert_properties)[:, :3], np.asarray(plate.tri_verts)
    path.write_text("solid plate\n" + "".join(
        "facet normal 0 0 0\nouter loop\n" + "".join("vertex %.17g %.17g %.17g\n" % tuple(vertices[v]) for v in f)
        + "endloop\nendfacet\n" for f in faces) + "endsolid plate\n")
    assert main(["info", str(path), "--size", "0.1"]) == 0
    last = capsys.readouterr().out.splitlines()[-1]
    assert last.startswith("thinner than 2 x size = 0.2: thinnest wall 0.05 near (")


def test_gmsh_surfaces_are_read_with_their_groups(tmp_path):
    """A Gmsh surface mesh: with physical surfaces and their names (the sides as named groups,
    the meshed box's patches named so); binary, with geometrical surfaces only (the CAD faces,
    surface_<tag>) and quads, split in two.  (meshio writes MSH 4.1 without physical groups;
    Gmsh's own 4.1 files, with them, read the same: checked by hand with gmsh 4.15.)"""
    faces = SIDE_FACES.reshape(-1, 3)
    named = meshio.Mesh(BOX_V, [("triangle", faces)],
                        cell_data={"gmsh:physical": [np.repeat(np.arange(1, 7), 2)],
                                   "gmsh:geometrical": [np.repeat(np.arange(1, 7), 2)]},
                        field_data={name: np.array([p, 2]) for p, name in enumerate(NAMES, start=1)})
    path = tmp_path / "box22.msh"
    meshio.write(path, named, file_format="gmsh22", binary=False)
    read = read_surface_file(path)
    assert read.group_names == tuple(NAMES) and np.array_equal(read.face_groups, np.repeat(np.arange(6), 2))
    result = paroct.mesh(path, size=0.2)
    assert result.surface.volume == pytest.approx(6.0, rel=1e-12)
    assert result.boundary_patches().names == tuple(NAMES)

    quads = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    cad = meshio.Mesh(BOX_V, [("quad", quads)], cell_data={"gmsh:geometrical": [np.arange(11, 17)]})
    path = tmp_path / "box_cad.msh"
    meshio.write(path, cad, file_format="gmsh22", binary=True)
    read = read_surface_file(path)
    assert read.faces.shape == (12, 3) and read.group_names == tuple(f"surface_{t}" for t in range(11, 17))
    assert load_surface(path).volume == pytest.approx(6.0, rel=1e-12)


def test_gmsh_files_without_a_surface_or_damaged_are_refused(tmp_path):
    tet = meshio.Mesh(BOX_V, [("tetra", np.array([[0, 1, 3, 4]]))])
    path = tmp_path / "volume.msh"
    meshio.write(path, tet, file_format="gmsh22", binary=False)
    with pytest.raises(ParoctError, match=r"no triangles or quads \(it holds tetra\): give paroct the part's surface"):
        load_surface(path)
    some = meshio.Mesh(BOX_V, [("triangle", SIDE_FACES[:4].reshape(-1, 3))],
                       cell_data={"gmsh:physical": [np.ones(8, dtype=int)], "gmsh:geometrical": [np.ones(8, dtype=int)]})
    meshio.write(path, some, file_format="gmsh22", binary=False)  # four sides in a physical group, two left out
    with pytest.raises(ParoctError, match=r"open surface, \d+ boundary edges.*put every surface of the part in one"):
        load_surface(path)
    path.write_bytes(b"$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\nxx\n")
    with pytest.raises(ParoctError, match=r"as MSH: section \$Nodes has no \$EndNodes$"):
        load_surface(path)


def test_a_paroct_msh_with_patches_meshes_again_with_its_named_patches(tmp_path, named_box, capsys):
    """paroct's own .msh written with --patches holds the boundary triangles in named physical
    groups: read as a surface (its tets ignored), it meshes again with the same patch names."""
    path, _ = named_box
    first = tmp_path / "first.msh"
    assert main(["mesh", str(path), "-o", str(first), "--size", "0.2", "--patches", "-q"]) == 0
    read = read_surface_file(first)
    assert read.group_names == tuple(NAMES)
    again = paroct.mesh(first, size=0.2)
    assert again.surface.volume == pytest.approx(paroct.mesh(path, size=0.2).report.mesh_volume, rel=1e-12)
    assert again.boundary_patches().names == tuple(NAMES)
