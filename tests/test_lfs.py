"""Sizing from the surface itself: curvature (elements per turn) and layers across walls."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import manifold3d
import numpy as np
import pytest

import paroct
from paroct.boundary import surface_patches
from paroct.cli import main
from paroct.errors import ParoctError
from paroct.features import face_normals
from paroct.frame import fat_frame
from paroct.lfs import bent_cells, cells_met, curvature_asks, triangle_pieces
from paroct.mesher import BYTES_PER_TET
from paroct.stuffing import DIHEDRAL_BOUND
from paroct.surface import load_surface

from . import naive

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"


def _area(tris: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_triangle_pieces_match_recursive_bisection(seed):
    """Random triangles, slivers and a degenerate one: the same pieces as the recursive
    reference, in order of triangle; no edge over spacing; areas add up."""
    rng = np.random.default_rng(seed)
    tris = rng.uniform(-3, 3, (12, 3, 3))
    tris[0] = [[0, 0, 0], [10, 0, 0], [10, 0.01, 0]]  # a sliver
    tris[1] = [[1, 1, 1], [1, 1, 1], [4, 2, 1]]  # two corners alike
    spacing = 0.7
    pieces, owner = triangle_pieces(tris, spacing)
    want, want_owner = naive.triangle_pieces(tris, spacing)
    assert owner.tolist() == want_owner
    for t in range(tris.shape[0]):
        got = sorted(map(tuple, np.round(pieces[owner == t].reshape(-1, 9), 12)))
        ref = sorted(map(tuple, np.round(np.array([p for p, o in zip(want, want_owner) if o == t]).reshape(-1, 9), 12)))
        assert got == ref
    edges = np.linalg.norm(pieces - np.roll(pieces, 1, axis=1), axis=2)
    assert edges.max() <= spacing
    np.testing.assert_allclose(np.bincount(owner, _area(pieces)), _area(tris), rtol=1e-12, atol=1e-12)


def test_a_sliver_is_cut_along_its_length_only():
    """A 100 x 0.01 sliver at spacing 1: pieces in proportion to its length, not its square."""
    pieces, _ = triangle_pieces(np.array([[[0, 0, 0], [100, 0, 0], [100, 0.01, 0]]]), 1.0)
    assert 100 <= pieces.shape[0] <= 256


def test_triangle_pieces_end_when_an_edge_squares_above_the_spacing():
    """An edge of length sqrt(13) at spacing math.sqrt(13): its square rounds above the
    spacing's, its root to it, so one strip would cut it into itself (it looped forever)."""
    spacing = math.sqrt(13.0)
    assert spacing * spacing < 13.0
    tris = np.array([[[0, 0, 0], [2, 3, 0], [2, 0, 0]]], dtype=np.float64)
    pieces, owner = triangle_pieces(tris, spacing)
    edges = pieces[:, [1, 2, 0]] - pieces
    assert 1 < pieces.shape[0] <= 8 and np.all(np.einsum("pij,pij->pi", edges, edges) <= spacing * spacing)
    np.testing.assert_allclose(_area(pieces).sum(), 3.0, rtol=1e-12)


def test_a_group_of_degenerate_triangles_asks_no_curvature():
    """Samples of no area (degenerate triangles) in a cell of their own patch: curvature 0, a
    finite mean point, and the other groups' fits as without them (it divided by zero)."""
    points, normals, area = _paraboloid_samples(0.3, -0.1, 0.05)
    cells = np.floor(points / 0.5).astype(np.int64)
    patch = np.zeros(len(points), dtype=np.int64)
    _, want, _ = bent_cells(cells, patch, points, normals, area)
    extra = points[:3] + 0.01
    with_zero = (np.r_[cells, np.floor(extra / 0.5).astype(np.int64)], np.r_[patch, [1, 1, 1]],
                 np.r_[points, extra], np.r_[normals, normals[:3]], np.r_[area, [0.0, 0.0, 0.0]])
    centres, curvature, group = bent_cells(*with_zero)
    zero = group[-1]
    assert curvature[zero] == 0.0 and np.all(np.isfinite(centres))
    np.testing.assert_array_equal(np.delete(curvature, zero), want)


def _paraboloid_samples(a: float, b: float, step: float):
    """Points of z = a x^2 + b y^2 on a grid, their unit normals and equal areas."""
    x, y = np.meshgrid(np.arange(-2, 2, step), np.arange(-2, 2, step), indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), a * x.ravel() ** 2 + b * y.ravel() ** 2], axis=1)
    normals = np.stack([-2 * a * points[:, 0], -2 * b * points[:, 1], np.ones(len(points))], axis=1)
    return points, normals / np.linalg.norm(normals, axis=1)[:, None], np.full(len(points), step * step)


def test_bent_cells_fit_matches_the_normal_equations():
    """Each group's curvature is the largest singular value of the least-squares normal field
    over its own and the 26 cells around: compared with the spelled-out fit on a paraboloid."""
    points, normals, area = _paraboloid_samples(0.3, -0.1, 0.05)
    cells = np.floor(points / 0.5).astype(np.int64)
    patch = np.zeros(len(points), dtype=np.int64)
    centres, curvature, group = bent_cells(cells, patch, points, normals, area)
    means = {}
    for g in range(centres.shape[0]):
        mine = group == g
        total = normals[mine].T @ area[mine]
        means[tuple(cells[mine][0])] = (centres[g], total / np.linalg.norm(total), area[mine].sum())
    checked = 0
    for g in range(centres.shape[0]):
        cell = tuple(cells[group == g][0])
        around = [means[c] for c in (tuple(np.add(cell, (dx, dy, dz))) for dx in (-1, 0, 1) for dy in (-1, 0, 1)
                                     for dz in (-1, 0, 1)) if c in means]
        if len(around) < 9:  # the grid's rim: too few cells for both tangent directions
            continue
        want = naive.largest_principal_curvature(np.array([m[0] for m in around]), np.array([m[1] for m in around]),
                                                 np.array([m[2] for m in around]))
        assert curvature[g] == pytest.approx(want, rel=1e-9)
        checked += 1
    assert checked > 20


@pytest.mark.parametrize("shape, radius", [("sphere", 2.0), ("cylinder", 1.5)])
def test_bent_cells_measure_the_radius(shape, radius):
    """1 / r on a sphere and across a cylinder's side (within 2 %, a chord's error), zero on
    flat faces, at a cell edge of a fifth of the radius."""
    solid = (manifold3d.Manifold.sphere(radius, 128) if shape == "sphere"
             else manifold3d.Manifold.cylinder(4.0, radius, radius, 96))
    surface = load_surface(solid)
    frame = fat_frame(surface.bbox_min, surface.bbox_max, radius / 5)
    pieces, owner = triangle_pieces(surface.vertices[surface.faces], frame.h)
    centroids = pieces.mean(axis=1)
    cells = np.floor(frame.to_lattice(centroids)).astype(np.int64)
    normals = face_normals(surface.vertices, surface.faces)[owner]
    centres, curvature, group = bent_cells(cells, surface_patches(surface, 40)[owner], centroids, normals, _area(pieces))
    flat = np.abs(normals[:, 2]) > 0.999  # the cylinder's caps
    side = np.bincount(group, ~flat, minlength=centres.shape[0]) == np.bincount(group, minlength=centres.shape[0])
    if shape == "cylinder":
        assert np.all(curvature[~side] < 1e-9)
        away = side & (centres[:, 2] > radius / 2) & (centres[:, 2] < 4.0 - radius / 2)  # fits not reaching the rims
        side = away
    assert np.median(curvature[side]) == pytest.approx(1 / radius, rel=0.02)
    assert np.all(np.abs(curvature[side] * radius - 1) < 0.05)


@pytest.mark.parametrize("per_turn", [12, 18, 36, 72])
def test_a_sphere_asks_the_levels_its_radius_needs(per_turn):
    """Radius 2 at size 1: elements of 2 pi r / N ask ceil(log2(N / (4 pi))) levels (none at
    N = 12; the others half a level from the next, beyond the facets' error), everywhere on
    the sphere alike."""
    surface = load_surface(manifold3d.Manifold.sphere(2.0, 128))
    frame = fat_frame(surface.bbox_min, surface.bbox_max, 1.0)
    asks = curvature_asks(surface, frame, per_turn, 4, 40.0)
    need = math.ceil(math.log2(per_turn / (4 * math.pi)))
    if need <= 0:
        assert asks.empty
        return
    assert int(asks.depth.max()) == need
    deepest = np.unique(np.floor(frame.to_lattice(asks.points[asks.depth == need])).astype(np.int64), axis=0)
    met = cells_met(frame, triangle_pieces(surface.vertices[surface.faces], 0.25)[0])
    assert deepest.shape[0] == met.shape[0]  # every cell the sphere meets


@pytest.mark.parametrize("per_turn", [200, 1000, 1e6])
def test_more_elements_a_turn_than_the_facets_turn_still_refine(per_turn):
    """The sphere's facets turn about 2.8 degrees, more than 360 / N here: split at 360 / N,
    each facet was a flat patch of its own and nothing was asked (the fuzzing of session 42:
    bunny's tets fell from 478 k at N = 32 to 30 k at N = 1e5).  The split stays at
    MIN_CURVATURE_SPLIT: the sphere asks the deepest level allowed, everywhere."""
    surface = load_surface(manifold3d.Manifold.sphere(2.0, 128))
    frame = fat_frame(surface.bbox_min, surface.bbox_max, 1.0)
    asks = curvature_asks(surface, frame, per_turn, 4, 40.0)
    assert int(asks.depth.max()) == 4
    deepest = np.unique(np.floor(frame.to_lattice(asks.points[asks.depth == 4])).astype(np.int64), axis=0)
    met = cells_met(frame, triangle_pieces(surface.vertices[surface.faces], 0.25)[0])
    assert deepest.shape[0] == met.shape[0]


def _ridge(angle: float) -> manifold3d.Manifold:
    """A 10 x 10 prism whose top turns by ``angle`` degrees along a ridge (a crease)."""
    rise = 5 * math.tan(math.radians(angle / 2))
    section = manifold3d.CrossSection([[(0, 0), (10, 0), (10, 3), (5, 3 + rise), (0, 3)]])
    return manifold3d.Manifold.extrude(section, 10.0)


@pytest.mark.parametrize("per_turn", [8, 12])
def test_a_crease_asks_nothing(per_turn):
    """A ridge turning 35 degrees, under the feature angle: no element size resolves a crease,
    so nothing is asked (at N = 8 it is measured, 35 < 45 per element, and does not shrink;
    at 12 it is an edge of the part, 35 > 30)."""
    surface = load_surface(_ridge(35.0))
    frame = fat_frame(surface.bbox_min, surface.bbox_max, 1.0)
    assert curvature_asks(surface, frame, per_turn, 4, 40.0).empty


def _plate_with_hole() -> manifold3d.Manifold:
    return manifold3d.Manifold.cube((12, 12, 3)) - manifold3d.Manifold.cylinder(5, 1.5, 1.5, 96).translate((6, 6, -1))


def _edges_on_hole(result) -> np.ndarray:
    """Longest edge of each boundary triangle on the hole's wall (radius 1.5 about (6, 6))."""
    p, f = result.mesh.points, result.boundary_faces
    n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    c = p[f].mean(axis=1)
    on = (np.abs(np.hypot(c[:, 0] - 6, c[:, 1] - 6) - 1.5) < 0.05) & (np.abs(n[:, 2]) < 0.5 * np.linalg.norm(n, axis=1))
    return np.linalg.norm(p[f[on]] - p[np.roll(f[on], 1, axis=1)], axis=2).max(axis=1)


def test_curvature_refines_the_hole_and_keeps_the_bound():
    """Size 1 with 24 elements per turn on a hole of radius 1.5: 2 pi r / N = 0.39, two levels
    below size.  Nearly all the hole's boundary triangles get there (a few beside coarser
    leaves' warped corners reach twice the level's edge), against few without; every tet
    within the dihedral bound; the same mesh twice."""
    plain = paroct.mesh(_plate_with_hole(), size=1.0)
    sized = paroct.mesh(_plate_with_hole(), size=1.0, curvature=24)
    target = 2 * math.pi * 1.5 / 24
    assert np.mean(_edges_on_hole(plain) <= target) < 0.2
    edges = _edges_on_hole(sized)
    assert np.mean(edges <= target) > 0.95
    assert edges.max() <= 2 * 0.25 * (1 + 1e-6)
    assert DIHEDRAL_BOUND[0] <= sized.report.min_dihedral <= sized.report.max_dihedral <= DIHEDRAL_BOUND[1]
    assert sized.report.n_tets < 2 * plain.report.n_tets  # only near the hole
    assert any("curves more than 24 elements per turn" in note for note in sized.report.notes)
    again = paroct.mesh(_plate_with_hole(), size=1.0, curvature=24)
    assert np.array_equal(again.mesh.tets, sized.mesh.tets) and np.array_equal(again.mesh.points, sized.mesh.points)


def test_layers_refine_a_thin_slab():
    """A slab 1.2 thick at size 1 with 5 layers: the band on its faces at 1/8 (the first
    half-size below 1.2 / 5), the faces' boundary edges mostly under 0.24; within the bound."""
    result = paroct.mesh(manifold3d.Manifold.cube((8, 8, 1.2)), size=1.0, layers=5)
    p, f = result.mesh.points, result.boundary_faces
    c = p[f].mean(axis=1)
    faces = (np.abs(c[:, 2]) < 1e-6) | (np.abs(c[:, 2] - 1.2) < 1e-6)
    edges = np.linalg.norm(p[f[faces]] - p[np.roll(f[faces], 1, axis=1)], axis=2).max(axis=1)
    assert np.mean(edges <= 1.2 / 5) > 0.95
    assert any("walls thinner than 5 x size" in note for note in result.report.notes)
    assert DIHEDRAL_BOUND[0] <= result.report.min_dihedral <= result.report.max_dihedral <= DIHEDRAL_BOUND[1]
    assert abs(result.report.volume_error) < 0.01


def test_layers_past_min_size_ask_nothing_and_say_so():
    """The slab (1.2 thick, 8 wide) at size 1 with 1000 layers would need 7-10 levels below
    size, past the 4 that the default min_size (size / 16) allows: nothing is asked, the mesh
    is the one without layers, and a note says why (it said nothing: fuzzing took layers=160
    on a cube for ignored)."""
    slab = manifold3d.Manifold.cube((8, 8, 1.2))
    plain = paroct.mesh(slab, size=1.0)
    many = paroct.mesh(slab, size=1.0, layers=1000)
    assert np.array_equal(plain.mesh.tets, many.mesh.tets)
    assert any("walls thinner than 1000 x size = 1000 would need more than the 4 levels below size that min_size "
               "allows: not asked" in note for note in many.report.notes)


def test_nothing_asked_leaves_the_mesh_unchanged():
    """A box has no curvature and no wall thinner than 2 x size: the same mesh as without."""
    box = manifold3d.Manifold.cube((4, 5, 6))
    plain = paroct.mesh(box, size=0.5)
    sized = paroct.mesh(box, size=0.5, curvature=12, layers=2)
    assert np.array_equal(plain.mesh.tets, sized.mesh.tets) and np.array_equal(plain.mesh.points, sized.mesh.points)


@pytest.mark.parametrize("bad", [0, -2.0, float("nan"), float("inf"), "12", True])
@pytest.mark.parametrize("name", ["curvature", "layers"])
def test_bad_values_are_refused(name, bad):
    with pytest.raises(ParoctError, match=name):
        paroct.mesh(manifold3d.Manifold.cube((1, 1, 1)), size=0.5, **{name: bad})


def test_cli_curvature_and_layers(tmp_path, capsys):
    out = tmp_path / "a.vtu"
    assert main(["mesh", str(DATA / "angle_block.stl"), "--curvature", "16", "--layers", "3", "-o", str(out)]) == 0
    assert out.exists()
    assert "curves more than 16 elements per turn" in capsys.readouterr().out
    assert main(["mesh", str(DATA / "angle_block.stl"), "--layers", "0", "-o", str(out)]) == 2
    assert "--layers" in capsys.readouterr().err


def test_info_says_where_curvature_and_layers_refine(capsys):
    """paroct info --curvature: the levels and an upper estimate of the tets, at least the
    mesh's; nothing asked on a box."""
    assert main(["info", str(DATA / "angle_block.stl"), "--curvature", "16"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("--curvature 16:"))
    estimate = float(line.split("at most about ")[1].split(" tets")[0])
    made = paroct.mesh(DATA / "angle_block.stl", curvature=16).report.n_tets
    assert estimate >= made
    assert main(["info", str(DATA / "angle_block.stl"), "--layers", "2", "--size", "0.02"]) == 0
    assert "--layers 2: nothing finer than size asked" in capsys.readouterr().out
    assert main(["info", str(DATA / "angle_block.stl"), "--curvature", "0"]) == 2
    assert "--curvature" in capsys.readouterr().err


def test_asks_that_do_not_fit_warn_and_mesh_without_them():
    """A memory budget the refined band does not fit: the plain mesh, and a warning saying the
    curvature was not honoured and why (not a silent coarser mesh)."""
    plain = paroct.mesh(_plate_with_hole(), size=1.0)
    budget = 2 * plain.report.n_tets * BYTES_PER_TET  # room for the plain passes, not for size / 8 on the hole
    result = paroct.mesh(_plate_with_hole(), size=1.0, curvature=48, max_memory=budget)
    assert result.report.n_tets == plain.report.n_tets
    assert any("not honoured" in w and "memory" in w for w in result.report.warnings)


@pytest.fixture(scope="module")
def named_box_file(tmp_path_factory):
    from .test_groups import NAMES, SIDE_FACES, _stl_solid

    path = tmp_path_factory.mktemp("patch_sizes") / "box.stl"
    path.write_text("".join(_stl_solid(name, faces) for name, faces in zip(NAMES, SIDE_FACES)))
    return path


def _side_edges(result, size: float) -> list[np.ndarray]:
    """Longest edge of each boundary triangle on each side of the 1 x 2 x 3 box (away from its edges)."""
    from .test_groups import _side_of

    p, f = result.mesh.points, result.boundary_faces
    side = _side_of(p[f].mean(axis=1), size)
    edges = np.linalg.norm(p[f] - p[np.roll(f, 1, axis=1)], axis=2).max(axis=1)
    return [edges[side == k] for k in range(6)]


def test_patch_sizes_refine_only_their_patches(named_box_file):
    """The box's named sides at size 0.1: 'top' asked 0.03 (two levels, 0.025) and 'left' 0.06
    (one level, 0.05); their boundary triangles get there, the other sides keep 0.1; within the
    bound; the note names them."""
    result = paroct.mesh(named_box_file, size=0.1, patch_sizes={"top": 0.03, "left": 0.06})
    edges = _side_edges(result, 0.1)
    assert np.percentile(edges[1], 95) <= 0.03 and np.percentile(edges[5], 95) <= 0.06
    for k in (0, 2, 3, 4):
        assert np.median(edges[k]) > 0.06
    assert DIHEDRAL_BOUND[0] <= result.report.min_dihedral <= result.report.max_dihedral <= DIHEDRAL_BOUND[1]
    assert any("patch 'top' asks 0.03 and patch 'left' asks 0.06" in note for note in result.report.notes)


def test_patch_sizes_by_angle_and_notes(named_box_file):
    """Without named groups the patches are patch_1, ... at 40 degrees; a size of at least size
    asks nothing and says so; an unknown name is refused with the names there are."""
    box = manifold3d.Manifold.cube((1, 2, 3))
    result = paroct.mesh(box, size=0.2, patch_sizes={"patch_1": 0.5, "patch_2": 0.05})
    assert any("patch 'patch_1' asks size 0.5, at least size" in note for note in result.report.notes)
    assert any("patch 'patch_2' asks 0.05" in note for note in result.report.notes)
    with pytest.raises(ParoctError, match="'patch_7' is not one of the surface's 6 patches"):
        paroct.mesh(box, size=0.2, patch_sizes={"patch_7": 0.1})
    with pytest.raises(ParoctError, match="'tpo' is not one of the surface's 6 named groups: 'bottom', 'top'"):
        paroct.mesh(named_box_file, size=0.2, patch_sizes={"tpo": 0.1})
    with pytest.raises(ParoctError, match="size of patch 'top'"):
        paroct.mesh(named_box_file, size=0.2, patch_sizes={"top": -1})
    with pytest.raises(ParoctError, match="patch_sizes"):
        paroct.mesh(named_box_file, size=0.2, patch_sizes=3)


def test_a_patch_size_memory_cannot_hold_is_not_honoured_and_says_so():
    """A patch of a unit box asked at 1e-4 at size 0.1, min_size 1e-5: the x rows of the
    refined frame alone would take GiB (they were crossed before any estimate: 4.2 GiB asked
    here, 10 GiB on bunny at diag/10 with a patch at 1e-5, and a MemoryError or the machine's
    memory killer); within max_memory = 200 MiB the pass is made without the ask, and warns."""
    box = manifold3d.Manifold.cube((1, 1, 1))
    result = paroct.mesh(box, size=0.1, patch_sizes={"patch_1": 1e-4}, min_size=1e-5, max_memory=200 * 2**20)
    assert result.report.size == pytest.approx(0.1) and result.report.n_tets > 0
    assert any("patch 'patch_1' asks 0.0001" in w and "would not fit in memory" in w for w in result.report.warnings)


def test_cli_refine_patch(named_box_file, tmp_path, capsys):
    out = tmp_path / "box.vtu"
    assert main(["mesh", str(named_box_file), "--size", "0.1", "--refine-patch", "top", "0.03", "-o", str(out)]) == 0
    assert "patch 'top' asks 0.03" in capsys.readouterr().out
    assert main(["mesh", str(named_box_file), "--refine-patch", "top", "fine", "-o", str(out)]) == 2
    assert "--refine-patch top fine: the size must be a number" in capsys.readouterr().err
    assert main(["mesh", str(named_box_file), "--refine-patch", "nowhere", "0.1", "-o", str(out)]) == 2
    assert "'nowhere' is not one of the surface's 6 named groups" in capsys.readouterr().err
    assert main(["info", str(DATA / "angle_block.stl")]) == 0
    assert "  patch_1: 8 triangles" in capsys.readouterr().out
    assert main(["info", str(named_box_file), "--size", "0.1", "--refine-patch", "top", "0.03"]) == 0
    assert "--refine-patch top 0.03: the boundary refined to 0.025 at most where patch 'top' asks 0.03" in \
        capsys.readouterr().out


def test_asks_survive_the_passes_after_a_loss():
    """A 2-thick plate with a rod of radius 0.6 at size 1 loses volume at size (its edges cut
    by stuffing, away from its thin places, so no round near them is made): the whole band
    at size / 2 follows, keeping the asks deeper than that (the rod at 0.25 for 12 elements a
    turn; patch_1 at 0.5 is met by the halved band).  The mesh keeps the volume within 1 %, the rod's wall stays at its
    lattice level, and every tet is within the bound."""
    part = manifold3d.Manifold.cube((10, 10, 2)) + manifold3d.Manifold.cylinder(6, 0.6, 0.6, 48).translate((5, 5, 2))
    sized = paroct.mesh(part, size=1.0, curvature=12)
    notes = sized.report.notes
    assert any(n.startswith("boundary size 1 -> 0.5: at 1 the mesh lost") for n in notes)
    assert "curves more than 12 elements per turn" in notes[-1]
    assert abs(sized.report.volume_error) < 0.01

    def rod_edges(result):
        p, f = result.mesh.points, result.boundary_faces
        c = p[f].mean(axis=1)
        n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        rod = (np.abs(np.hypot(c[:, 0] - 5, c[:, 1] - 5) - 0.6) < 0.05) & (c[:, 2] > 2.5) & (c[:, 2] < 7.5) \
            & (np.abs(n[:, 2]) < 0.5 * np.linalg.norm(n, axis=1))
        return np.linalg.norm(p[f[rod]] - p[np.roll(f[rod], 1, axis=1)], axis=2).max(axis=1)

    # Stuffing warps lattice vertices by up to 0.41 of an edge onto the surface, so boundary
    # edges spread about the lattice's long edge: 0.25 here, 0.5 for the halved band alone.
    edges, plain = rod_edges(sized), rod_edges(paroct.mesh(part, size=1.0))
    assert edges.size > 2 * plain.size and np.median(edges) < 0.7 * np.median(plain)
    assert DIHEDRAL_BOUND[0] <= sized.report.min_dihedral <= sized.report.max_dihedral <= DIHEDRAL_BOUND[1]
    patched = paroct.mesh(part, size=1.0, patch_sizes={"patch_1": 0.5})
    assert any("near the" in n and "thin" in n for n in patched.report.notes)
    assert abs(patched.report.volume_error) < 0.01 and not patched.report.warnings


def test_a_region_below_size_refines_the_boundary_in_it():
    """A box region asking 0.05 around the x = 1 face of a unit cube meshed at size 0.2: the
    boundary triangles on that face get two levels finer (median longest edge near 0.05,
    against 0.2 on the other faces), the interior stays at least size, every tet in the
    bound, and the note says both."""
    cube = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    result = paroct.mesh(cube, size=0.2, regions=[paroct.Box((0.8, -0.1, -0.1), (1.1, 1.1, 1.1), 0.05)])
    p, f = result.mesh.points, result.boundary_faces
    c = p[f].mean(axis=1)
    edges = np.linalg.norm(p[f] - p[np.roll(f, 1, axis=1)], axis=2).max(axis=1)
    face = (np.abs(c[:, 0] - 1) < 1e-6) & np.all((c[:, 1:] > 0.25) & (c[:, 1:] < 0.75), axis=1)
    far = (np.abs(c[:, 0]) < 1e-6) & np.all((c[:, 1:] > 0.25) & (c[:, 1:] < 0.75), axis=1)
    assert face.sum() > 4 * far.sum() and np.median(edges[face]) <= 0.05 * 1.2 and np.median(edges[far]) >= 0.15
    assert DIHEDRAL_BOUND[0] <= result.report.min_dihedral <= result.report.max_dihedral <= DIHEDRAL_BOUND[1]
    assert any("the boundary in it is refined to 0.05, its interior elements stay at least size" in n
               for n in result.report.notes)


def test_a_size_function_below_size_refines_the_boundary():
    """h(x) = 0.05 near the x = 1 face of a unit cube at size 0.2, 1 elsewhere: that face's
    boundary triangles two levels finer, the others at size, within the bound, with a note;
    a function that fails on the surface's points is refused in one line."""
    cube = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    result = paroct.mesh(cube, size=0.2, size_function=lambda x: np.where(x[:, 0] > 0.8, 0.05, 1.0))
    p, f = result.mesh.points, result.boundary_faces
    c = p[f].mean(axis=1)
    edges = np.linalg.norm(p[f] - p[np.roll(f, 1, axis=1)], axis=2).max(axis=1)
    middle = np.all((c[:, 1:] > 0.25) & (c[:, 1:] < 0.75), axis=1)
    face, far = middle & (np.abs(c[:, 0] - 1) < 1e-6), middle & (np.abs(c[:, 0]) < 1e-6)
    assert np.median(edges[face]) <= 0.05 * 1.2 and np.median(edges[far]) >= 0.15
    assert DIHEDRAL_BOUND[0] <= result.report.min_dihedral <= result.report.max_dihedral <= DIHEDRAL_BOUND[1]
    assert any("size_function asks down to 0.05 on the boundary" in n for n in result.report.notes)

    def failing(points):
        raise ValueError("boom")

    with pytest.raises(ParoctError, match="size_function failed on [0-9]+ points of the surface: boom"):
        paroct.mesh(cube, size=0.2, size_function=failing)


def test_a_bent_cell_with_no_finer_piece_in_it_asks_nothing_finer():
    """A group binned by its pieces' centroids can have no piece of the finer cut whose
    centroid stays in its cell (a small piece near the cell's corner): curvature_asks crashed
    there (numba's min of an empty array) on bench_generated's CSG part 607 at diag/40,
    N = 48 (session 42).  It now stops descending, as for any cell whose finer pieces lie
    elsewhere, and meshes."""
    spec = importlib.util.spec_from_file_location("bench_generated", ROOT / "bench" / "bench_generated.py")
    generated = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generated)
    part = generated.csg_part(607)
    surface = load_surface(part)
    frame = fat_frame(surface.bbox_min, surface.bbox_max, surface.diagonal / 40)
    asks = curvature_asks(surface, frame, 48, 4, 40.0)
    assert asks.empty  # its one bent cell had nothing finer to measure
    assert paroct.mesh(part, divisions=40, curvature=48).report.n_tets > 0
