"""Boundary patches: the surface split at sharp edges, the mesh's boundary triangles tagged,
and the tags written where each format keeps them."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import manifold3d
import meshio
import numpy as np
import pytest

import paroct
from paroct import ParoctError, boundary_patches, load_surface, surface_patches
from paroct.cli import main
from paroct.io import read_mesh, write_mesh
from paroct.topology import TET_FACES, boundary_faces, match_faces

from . import naive

DATA = Path(__file__).resolve().parent.parent / "data"
BOX = (1.0, 2.0, 3.0)


def _rotated(solid: manifold3d.Manifold, seed: int) -> manifold3d.Manifold:
    return solid.rotate(list(np.random.default_rng(seed).uniform(0, 360, 3)))


@pytest.fixture(scope="module")
def box_mesh():
    """A 1 x 2 x 3 box meshed at size 0.1: (result, boundary patches)."""
    result = paroct.mesh(manifold3d.Manifold.cube(list(BOX)), size=0.1)
    return result, result.boundary_patches()


@pytest.mark.parametrize("solid, angle, count", [
    (manifold3d.Manifold.cube([1, 2, 3]), 40, 6),
    (manifold3d.Manifold.cylinder(2.0, 1.0, 1.0, 64), 40, 3),  # sides turn 5.6 deg, caps 90
    (manifold3d.Manifold.cylinder(2.0, 1.0, 1.0, 8), 40, 10),  # sides turn 45 deg: each its own patch
    (manifold3d.Manifold.cylinder(2.0, 1.0, 1.0, 8), 50, 3),
    (manifold3d.Manifold.sphere(1.0, 48), 40, 1),
    (manifold3d.Manifold.sphere(1.0, 48), 5, None),  # many: compared with the reference only
])
def test_surface_patches_match_the_reference(solid, angle, count):
    for seed in range(2):  # the rule does not depend on the pose
        surface = load_surface(_rotated(solid, seed))
        labels = surface_patches(surface, angle)
        assert np.array_equal(labels, naive.surface_patches(surface.vertices, surface.faces, angle))
        if count is not None:
            assert labels.max() == count and set(labels.tolist()) == set(range(1, count + 1))


def test_patches_of_random_csg_parts_match_the_reference():
    rng = np.random.default_rng(3)
    for _ in range(3):
        part = manifold3d.Manifold.cube([1, 1, 1], center=True)
        for _ in range(3):
            cut = manifold3d.Manifold.cylinder(2.0, rng.uniform(0.1, 0.4), rng.uniform(0.1, 0.4), int(rng.integers(6, 24)),
                                               center=True).rotate(list(rng.uniform(0, 180, 3)))
            part = part - cut.translate(list(rng.uniform(-0.4, 0.4, 3)))
        surface = load_surface(part)
        for angle in (20.0, 40.0, 75.0):
            assert np.array_equal(surface_patches(surface, angle),
                                  naive.surface_patches(surface.vertices, surface.faces, angle))


def test_a_zero_area_triangle_joins_the_patch_across_its_longest_edge():
    # A unit cube whose top face has a vertex m in the middle of its edge a-b: the top is
    # three triangles, and the flat triangle (a, b, m) closes the edge a-b against the side.
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1], [0.5, 0, 1]], float)
    a, b, m = 4, 5, 8
    faces = np.array([[0, 2, 1], [0, 3, 2],  # bottom
                      [m, 6, 7], [a, m, 7], [m, b, 6],  # top
                      [a, b, m],  # flat: its longest edge a-b is the front side's
                      [0, 1, 5], [0, 5, 4],  # front (y = 0)
                      [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    surface = load_surface((v, faces))
    labels = surface_patches(surface, 40)
    assert labels.max() == 6
    corners = surface.vertices[surface.faces]  # (F, 3, 3): load_surface may number vertices anew
    holds = [np.any(np.all(corners == v[i], axis=2), axis=1) for i in (a, b, m)]
    flat = np.flatnonzero(holds[0] & holds[1] & holds[2])
    front = np.flatnonzero(holds[0] & holds[1] & ~holds[2])  # the side's triangle on a-b
    assert flat.size == front.size == 1 and labels[flat[0]] == labels[front[0]]
    assert np.array_equal(labels, naive.surface_patches(surface.vertices, surface.faces, 40))


def test_boundary_patches_tag_every_boundary_triangle(box_mesh):
    result, patches = box_mesh
    tets = result.mesh.tets.astype(np.int64)
    faces = boundary_faces(tets, match_faces(tets)[0])
    assert np.array_equal(patches.faces, faces)  # every one, outward, in the same order
    assert np.array_equal(tets[patches.tets[:, None], TET_FACES[patches.tet_faces]], patches.faces)
    assert patches.n_patches == 6 and set(patches.patches.tolist()) == set(range(1, 7))


def test_box_faces_away_from_the_edges_lie_on_their_patch(box_mesh):
    """A triangle whose centroid is more than two sizes from every edge of the box lies on
    one side of it: its patch is that side's.  Near the edges stuffing cuts the corner, so
    each side's tagged area is its own within a band of two sizes along its perimeter."""
    result, patches = box_mesh
    points, size = result.mesh.points, result.report.size
    corners = points[patches.faces]
    centroids = corners.mean(axis=1)
    hi = np.array(BOX)
    gap = np.minimum(centroids, hi - centroids)  # distance to each pair of sides
    on_side = gap.min(axis=1) < 1e-6 * size  # the surface is snapped to fixed point (rays.snap_surface)
    side_axis = np.argmin(gap, axis=1)
    side_key = 2 * side_axis + (centroids[np.arange(len(centroids)), side_axis] > hi[side_axis] / 2)
    away = np.sort(gap, axis=1)[:, 1] > 2 * size  # far from the side's edges
    assert on_side[away].all() and away.sum() > len(away) / 2
    for key in range(6):  # one patch per side, the same for all its faces away from the edges
        assert np.unique(patches.patches[away & (side_key == key)]).size == 1
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    for key in range(6):
        axis = key // 2
        patch = patches.patches[away & (side_key == key)][0]
        others = [hi[i] for i in range(3) if i != axis]
        tagged = areas[patches.patches == patch].sum()
        assert abs(tagged - others[0] * others[1]) < 2 * size * 2 * sum(others)


def test_a_result_without_its_surface_names_the_function_to_call(box_mesh):
    result, _ = box_mesh
    bare = paroct.MeshResult(result.mesh, result.report)
    with pytest.raises(ParoctError, match="paroct.boundary_patches"):
        bare.boundary_patches()
    for angle in (0, -5, 181, float("nan")):
        with pytest.raises(ParoctError, match="feature angle"):
            result.boundary_patches(angle)


def _tagged(faces: np.ndarray, patches: np.ndarray) -> set:
    """{(sorted triangle, patch)}: triangles and tags whatever their order and rotation."""
    return {(tuple(sorted(f)), int(p)) for f, p in zip(faces.tolist(), np.asarray(patches).tolist())}


def test_gmsh_file_holds_the_patches_as_physical_groups(tmp_path, box_mesh):
    result, patches = box_mesh
    path = tmp_path / "box.msh"
    write_mesh(path, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(path)
    assert np.array_equal(back.points, result.mesh.points) and back.cells[0].type == "tetra"
    assert np.array_equal(back.cells[0].data, result.mesh.tets)
    assert set(back.cell_data["gmsh:physical"][0]) == {1}
    triangles = [(b.data, tags) for b, tags in zip(back.cells, back.cell_data["gmsh:physical"]) if b.type == "triangle"]
    assert _tagged(np.concatenate([t for t, _ in triangles]), np.concatenate([p for _, p in triangles])) \
        == _tagged(patches.faces, patches.patches)
    assert {name: tuple(v) for name, v in back.field_data.items()} == {
        "solid": (1, 3), **{f"patch_{p}": (p, 2) for p in range(1, 7)}}
    again = tmp_path / "again.msh"
    write_mesh(again, result.mesh.points, result.mesh.tets, boundary=patches)
    assert again.read_bytes() == path.read_bytes()
    points, tets = read_mesh(path)
    assert np.array_equal(points, result.mesh.points) and np.array_equal(tets, result.mesh.tets)


def test_gmsh_file_of_a_patch_with_no_triangle_still_reads(tmp_path):
    # angle_block at diag/40 has a patch narrower than the lattice: its physical group is
    # named, with no element block (meshio cannot read an empty one).
    result = paroct.mesh(DATA / "angle_block.stl")
    patches = result.boundary_patches()
    empty = set(range(1, patches.n_patches + 1)) - set(patches.patches.tolist())
    assert empty
    path = tmp_path / "part.msh"
    write_mesh(path, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(path)
    assert len(back.field_data) == patches.n_patches + 1
    assert sum(len(b.data) for b in back.cells if b.type == "triangle") == len(patches.faces)


@pytest.mark.parametrize("suffix, key", [(".vtu", "boundary_patch"), (".vtk", "boundary_patch"), (".mesh", "medit:ref")])
def test_other_formats_hold_triangles_with_their_patch(tmp_path, box_mesh, suffix, key):
    result, patches = box_mesh
    path = tmp_path / f"box{suffix}"
    write_mesh(path, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(path)
    kinds = [b.type for b in back.cells]
    assert kinds == ["tetra", "triangle"] and np.array_equal(back.cells[0].data, result.mesh.tets)
    assert np.array_equal(back.cells[1].data, patches.faces) and np.array_equal(back.cell_data[key][1], patches.patches)
    assert set(back.cell_data[key][0]) == ({1} if suffix == ".mesh" else {0})
    points, tets = read_mesh(path)
    assert np.array_equal(tets, result.mesh.tets)


def test_vtu_pads_cell_data_over_the_triangles(tmp_path, box_mesh):
    result, patches = box_mesh
    quality = np.linspace(1, 2, len(result.mesh.tets))
    path = tmp_path / "box.vtu"
    write_mesh(path, result.mesh.points, result.mesh.tets, {"quality": quality}, boundary=patches)
    back = meshio.read(path)
    assert np.array_equal(back.cell_data["quality"][0], quality) and not back.cell_data["quality"][1].any()


def test_abaqus_surfaces_and_node_sets_name_the_patch_faces(tmp_path, box_mesh):
    """Each *SURFACE's element sets with their face S1 .. S4 give back the patch's triangles
    (C3D4 faces: S1 = nodes 1-2-3, S2 = 1-4-2, S3 = 2-4-3, S4 = 3-4-1)."""
    result, patches = box_mesh
    path = tmp_path / "box.inp"
    write_mesh(path, result.mesh.points, result.mesh.tets, boundary=patches)
    back = meshio.read(path)
    tets = back.cells[0].data
    assert np.array_equal(tets, result.mesh.tets)
    nodes_of_side = {1: [0, 1, 2], 2: [0, 3, 1], 3: [1, 3, 2], 4: [2, 3, 0]}
    found = set()
    for name, ids in back.cell_sets.items():
        if not name.startswith("PATCH_"):
            continue
        _, p, side = name.split("_")
        rows = tets[np.concatenate(ids)][:, nodes_of_side[int(side[1])]]
        found |= _tagged(rows, np.full(len(rows), int(p)))
    assert found == _tagged(patches.faces, patches.patches)
    for p in range(1, 7):
        assert np.array_equal(np.sort(back.point_sets[f"PATCH_{p}"]), np.unique(patches.faces[patches.patches == p]))
    text = path.read_text()
    assert text.count("*SURFACE, NAME=PATCH_") == 6 and "*ELEMENT, TYPE=C3D4, ELSET=SOLID" in text


def test_cli_writes_the_patches(tmp_path, capsys):
    out = tmp_path / "block.msh"
    assert main(["mesh", str(DATA / "xyz_cube.stl"), "-o", str(out), "--divisions", "20", "--patches"]) == 0
    summary = capsys.readouterr().out
    n = int(surface_patches(load_surface(DATA / "xyz_cube.stl")).max())
    assert f"in {n} patches (feature angle 40 deg)" in summary
    back = meshio.read(out)
    assert len(back.field_data) == n + 1 and any(b.type == "triangle" for b in back.cells)
    assert main(["mesh", str(DATA / "xyz_cube.stl"), "-o", str(tmp_path / "x.vtu"), "--patches", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["paroct: error: feature angle = 0.0: must be a number of degrees in (0, 180]"]


def test_boundary_patches_is_a_function_of_the_arrays(box_mesh):
    result, patches = box_mesh
    again = boundary_patches(result.mesh.points, result.mesh.tets, result.surface)
    for name in ("faces", "tets", "tet_faces", "patches"):
        assert np.array_equal(getattr(again, name), getattr(patches, name))


def test_write_mesh_refuses_patches_of_another_mesh_and_formats_that_drop_them(tmp_path, box_mesh):
    result, patches = box_mesh
    other = paroct.mesh(manifold3d.Manifold.cube([1, 2, 3]), size=0.2)
    with pytest.raises(ParoctError, match="the patches of another mesh"):
        write_mesh(tmp_path / "m.vtu", other.mesh.points, other.mesh.tets, boundary=patches)
    with pytest.raises(ParoctError, match="is the name the boundary's patches are written under"):
        write_mesh(tmp_path / "m.vtu", result.mesh.points, result.mesh.tets,
                   {"boundary_patch": np.zeros(len(result.mesh.tets))}, boundary=patches)
    for suffix in (".vol", ".ele", ".su2", ".dat", ".xml"):
        with pytest.raises(ParoctError, match="hold no boundary patches here"):
            write_mesh(tmp_path / f"m{suffix}", result.mesh.points, result.mesh.tets, boundary=patches)
    with pytest.raises(ParoctError, match="give the BoundaryPatches of these tets"):
        write_mesh(tmp_path / "m.vtu", result.mesh.points, result.mesh.tets, boundary={"faces": patches.faces})


def test_gmsh_file_holds_cell_data_beside_the_patches(tmp_path, box_mesh):
    result, patches = box_mesh
    quality = np.linspace(0, 1, len(result.mesh.tets))
    write_mesh(tmp_path / "m.msh", result.mesh.points, result.mesh.tets, {"quality": quality}, boundary=patches)
    back = meshio.read(tmp_path / "m.msh")
    assert np.array_equal(back.cell_data["quality"][0], quality)
    assert all(not block.any() for block in back.cell_data["quality"][1:])


def test_boundary_patches_takes_any_surface_source_and_refuses_bad_arrays(box_mesh):
    result, patches = box_mesh
    again = boundary_patches(result.mesh.points, result.mesh.tets, manifold3d.Manifold.cube(list(BOX)))
    assert np.array_equal(again.patches, patches.patches)
    for points, tets, match in ((result.mesh.points[:, :2], result.mesh.tets, r"points.shape = \(\d+, 2\)"),
                                (result.mesh.points, result.mesh.tets[:, :3], r"tets.shape = \(\d+, 3\)"),
                                (result.mesh.points, result.mesh.tets - 1, r"tet vertex indices span -1"),
                                (result.mesh.points, result.mesh.tets + 0.5, "tets.dtype = float64")):
        with pytest.raises(ParoctError, match=match):
            boundary_patches(points, tets, result.surface)


@pytest.mark.parametrize("source, divisions", [
    (DATA / "angle_block.stl", 35),  # the pinch repair removes tets: its boundary updated around them
    (DATA / "bunny.stl", 20),
    (manifold3d.Manifold.cube([1, 1, 0.04]), 25),  # a thin plate: the band refined near its walls
])
def test_patches_from_the_kept_boundary_faces_equal_those_from_matching(source, divisions):
    """MeshResult keeps the boundary the pinch repair found; tagging from it (their tets found
    in the vertices' stars) gives exactly what matching every face of the tets gives."""
    from paroct.boundary import _tagged_boundary

    result = paroct.mesh(source, divisions=divisions)
    assert result.boundary_faces is not None
    kept = result.boundary_patches()
    matched = _tagged_boundary(result.mesh.points, result.mesh.tets, result.surface, None, None, result.point_faces)
    for name in ("faces", "tets", "tet_faces", "patches"):
        assert np.array_equal(getattr(kept, name), getattr(matched, name)), name
    bogus = result.boundary_faces[:, [0, 0, 0]]  # one vertex three times: no tet's face
    with pytest.raises(ParoctError, match="no tet's faces"):
        _tagged_boundary(result.mesh.points, result.mesh.tets, result.surface, None, bogus)


@pytest.mark.parametrize("source, divisions", [
    (DATA / "angle_block.stl", 35),  # sharp edges: triangles straddling seams
    (DATA / "bunny.stl", 40),  # a scan at 40 degrees: many small patches
    (manifold3d.Manifold.cube([1, 1, 0.04]), 25),  # a band refined near thin walls (template edges cut)
])
def test_boundary_vertices_know_their_surface_triangle(source, divisions):
    """Every boundary vertex stuffing placed lies on the surface triangle MeshResult.point_faces
    names (its cut point's); interior vertices name none, nor those the pinch repair exposed.  A boundary triangle whose three
    vertices lie on one patch takes it; the others, and a search of every centroid's nearest
    triangle, agree with it but for chords beside a seam."""
    from paroct.check import nearest_triangles

    result = paroct.mesh(source, divisions=divisions)
    points, faces, surface = result.mesh.points, result.boundary_faces, result.surface
    on_boundary = np.zeros(points.shape[0], dtype=bool)
    on_boundary[faces.ravel()] = True
    placed = np.flatnonzero(result.point_faces >= 0)
    # The others are inside vertices that the pinch repair's removed tets laid bare.
    assert np.all(on_boundary[placed]) and np.count_nonzero(on_boundary) - placed.size <= 4 * result.report.repaired_tets
    corners = surface.vertices[surface.faces[result.point_faces[placed]]]
    gap = [naive.point_triangle_distance(p, *c) for p, c in zip(points[placed], corners)]
    assert max(gap) < 1e-6 * result.report.size

    tagged = result.boundary_patches()
    labels = surface_patches(surface) if surface.face_groups is None else surface.face_groups + 1
    vertex_patch = np.where(result.point_faces >= 0, labels[np.maximum(result.point_faces, 0)], 0)[tagged.faces]
    agree = (vertex_patch[:, 0] > 0) & (vertex_patch == vertex_patch[:, :1]).all(axis=1)
    assert np.array_equal(tagged.patches[agree], vertex_patch[agree, 0]) and 0 < (~agree).sum() < agree.sum()
    nearest = labels[nearest_triangles(points[tagged.faces].mean(axis=1), surface.vertices, surface.faces)[1]]
    assert np.array_equal(tagged.patches[~agree], nearest[~agree])
    differ = np.flatnonzero(tagged.patches != nearest)
    assert differ.size <= 1e-3 * tagged.patches.size
    tiny = paroct.load_surface(manifold3d.Manifold.tetrahedron())  # 4 triangles: not the meshed surface's
    with pytest.raises(ParoctError, match="belong to another surface"):
        dataclasses.replace(result, surface=tiny).boundary_patches()


def test_feature_angles_are_numbers_of_degrees_and_patches_read_any_surface():
    """numpy integers are angles (np.int64(40) was refused as 'feature angle = 40'); a bool is
    no angle (True was 1 degree); surface_patches reads what load_surface reads ((vertices,
    faces) raised AttributeError)."""
    surface = load_surface(DATA / "xyz_cube.stl")
    assert np.array_equal(surface_patches(surface, np.int64(40)), surface_patches(surface, 40))
    assert np.array_equal(surface_patches((surface.vertices, surface.faces), 40), surface_patches(surface, 40))
    for bad in (True, np.bool_(True), 0, 181, "40", None):
        with pytest.raises(ParoctError, match="feature angle"):
            surface_patches(surface, bad)
    with pytest.raises(ParoctError, match="cannot mesh a NoneType"):
        surface_patches(None)
