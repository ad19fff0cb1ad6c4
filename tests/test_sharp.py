"""Sharp edges and corners: boundary vertices moved onto the curves and corners between
patches, each only as far as the tets around it keep the guard."""

from __future__ import annotations

from pathlib import Path

import manifold3d
import numpy as np
import pytest

import paroct
from paroct.boundary import surface_patches
from paroct.check import check_mesh
from paroct.cli import main
from paroct.quality import tet_quality
from paroct.sharp import (SNAP_MAX_ANGLE, SNAP_MIN_ANGLE, SNAP_MIN_RATIO, _curve_targets, _nearest_corners,
                          feature_curves)

from . import naive

DATA = Path(__file__).resolve().parent.parent / "data"


def _rotated_box(seed: int) -> manifold3d.Manifold:
    return manifold3d.Manifold.cube([1.0, 2.0, 3.0]).rotate(list(np.random.default_rng(seed).uniform(0, 360, 3)))


@pytest.mark.parametrize("seed", [0, 1])
def test_box_corners_become_mesh_vertices_and_the_volume_error_falls(seed):
    """A rotated 1 x 2 x 3 box: its corners become mesh vertices, exactly, where the guard lets
    them (at least 6 of 8 here; the others part of the way, within half a size); the volume
    error falls at least fivefold and the Hausdorff distance too; the mesh stays valid, with
    the same tets."""
    result = paroct.mesh(_rotated_box(seed), size=0.15)
    sharp = result.with_sharp_edges()
    corners = feature_curves(result.surface, surface_patches(result.surface, 40)).corners
    assert corners.size == 8
    nearest = np.array([np.linalg.norm(sharp.mesh.points - result.surface.vertices[c], axis=1).min() for c in corners])
    before = np.array([np.linalg.norm(result.mesh.points - result.surface.vertices[c], axis=1).min() for c in corners])
    assert (nearest == 0).sum() >= 6 and nearest.max() < 0.5 * result.report.size and (before > 0).all()
    assert abs(sharp.report.volume_error) * 5 < abs(result.report.volume_error)
    report = check_mesh(sharp.mesh.points, sharp.mesh.tets, result.surface)
    assert report.n_inverted == 0 and report.boundary_manifold and report.overloaded_faces == 0
    assert report.hausdorff < check_mesh(result.mesh.points, result.mesh.tets, result.surface).hausdorff
    assert np.array_equal(sharp.mesh.tets, result.mesh.tets)
    assert "sharp edges:" in sharp.report.notes[-1]


def test_the_guard_holds_on_every_moved_star():
    """Every tet that changed keeps dihedral angles in [15, 150] and 3r/R >= 0.2, or the worst
    of its star before; no tet leaves stuffing's bound.  The report's extremes are the mesh's."""
    result = paroct.mesh(DATA / "angle_block.stl", divisions=30)
    sharp = result.with_sharp_edges()
    before = tet_quality(result.mesh.points, result.mesh.tets)
    after = tet_quality(sharp.mesh.points, sharp.mesh.tets)
    moved = np.flatnonzero(np.any(sharp.mesh.points != result.mesh.points, axis=1))
    assert moved.size > 100
    changed = np.isin(result.mesh.tets, moved).any(axis=1)
    # Each move keeps its star within the guard or the star's worst at the time, so the tets
    # that changed are within the guard or the worst of those tets before.
    assert after.min_dihedral[changed].min() >= min(SNAP_MIN_ANGLE, before.min_dihedral[changed].min()) - 1e-9
    assert after.max_dihedral[changed].max() <= max(SNAP_MAX_ANGLE, before.max_dihedral[changed].max()) + 1e-9
    assert after.radius_ratio[changed].min() >= min(SNAP_MIN_RATIO, before.radius_ratio[changed].min()) - 1e-12
    assert after.volume.min() > 0 and after.min_dihedral.min() >= 10.7 and after.max_dihedral.max() <= 164.8
    assert sharp.report.min_dihedral == pytest.approx(after.min_dihedral.min(), abs=1e-9)
    assert sharp.report.mesh_volume == pytest.approx(after.volume.sum(), rel=1e-12)
    assert np.array_equal(sharp.mesh.points[~np.isin(np.arange(len(result.mesh.points)), moved)],
                          result.mesh.points[~np.isin(np.arange(len(result.mesh.points)), moved)])


def test_moved_vertices_lie_on_the_curves_between_their_patches():
    """A cylinder's rims (caps at 90 degrees to the side): every vertex that moved came closer
    to a rim's polygon, most of them onto it; the boundary still does not cross itself."""
    from paroct.intersections import crossing_triangles

    solid = manifold3d.Manifold.cylinder(2.0, 1.0, 1.0, 48)
    result = paroct.mesh(solid, size=0.12)
    sharp = result.with_sharp_edges()
    moved = np.flatnonzero(np.any(sharp.mesh.points != result.mesh.points, axis=1))
    rims = [np.column_stack([np.cos(t), np.sin(t), np.full(48, z)]) for t in [np.arange(48) * 2 * np.pi / 48]
            for z in (0.0, 2.0)]

    def rim_distance(q):  # to the nearest of the two 48-gons' sides
        a = np.concatenate([r for r in rims])
        b = np.concatenate([np.roll(r, -1, axis=0) for r in rims])
        return min(naive.nearest_on_segments(q, a, b)[1], np.inf)

    before = np.array([rim_distance(q) for q in result.mesh.points[moved]])
    after = np.array([rim_distance(q) for q in sharp.mesh.points[moved]])
    assert moved.size > 50 and (after < before).all() and (after < 1e-6).mean() > 0.7
    # A moved vertex may have left its cut point's triangle: the result no longer names one.
    assert (sharp.point_faces[moved] == -1).all() and (result.point_faces[moved] >= 0).all()
    still = np.ones(sharp.point_faces.size, dtype=bool)
    still[moved] = False
    assert np.array_equal(sharp.point_faces[still], result.point_faces[still])
    boundary = sharp.boundary_patches(40)
    faces = boundary.faces.astype(np.int64)
    assert (crossing_triangles(sharp.mesh.points, faces, np.arange(len(faces))) < 0).all()


def test_named_groups_are_the_curves_kept(tmp_path):
    """A box whose groups split one face in two halves along x = 0.5 (no sharp edge there):
    with the groups as patches, vertices move onto the border x = 0.5; by angle, the box's
    6 faces, none moves there."""
    solid = manifold3d.Manifold.cube([1.0, 1.0, 1.0]).refine(4)
    mesh = solid.to_mesh64()
    vertices = np.asarray(mesh.vert_properties)[:, :3]
    faces = np.asarray(mesh.tri_verts).astype(np.int64)
    centroids = vertices[faces].mean(axis=1)
    groups = np.where((centroids[:, 2] > 1 - 1e-9) & (centroids[:, 0] > 0.5), 1, 0)
    surface = paroct.surface_from_arrays(vertices, faces, face_groups=groups, group_names=("rest", "half lid"))
    result = paroct.mesh(surface, size=0.1)
    by_groups = result.with_sharp_edges()
    by_angle = result.with_sharp_edges(40)
    for sharp, expect in ((by_groups, True), (by_angle, False)):
        moved = np.any(sharp.mesh.points != result.mesh.points, axis=1)
        p = sharp.mesh.points[moved]
        on_border = (np.abs(p[:, 0] - 0.5) < 1e-12) & (p[:, 2] > 1 - 1e-12)
        assert on_border.any() == expect


@pytest.mark.parametrize("seed", range(3))
def test_curve_targets_match_the_naive_search(seed):
    rng = np.random.default_rng(seed)
    vertices = rng.uniform(-1, 1, (40, 3))
    segments = rng.integers(0, 40, (60, 2))
    segments[:5, 1] = segments[:5, 0]  # zero-length segments: points
    keys = np.sort(rng.integers(0, 4, 60))
    queries = rng.uniform(-1.2, 1.2, (30, 3))
    query_keys = rng.integers(0, 5, 30)  # key 4 has no segment
    targets, distance = _curve_targets(vertices, segments, keys, queries, query_keys)
    for k in range(30):
        sel = keys == query_keys[k]
        if not sel.any():
            assert distance[k] == np.inf
            continue
        point, d = naive.nearest_on_segments(queries[k], vertices[segments[sel, 0]], vertices[segments[sel, 1]])
        assert distance[k] == pytest.approx(d, abs=1e-12) and np.linalg.norm(targets[k] - queries[k]) == pytest.approx(d)


@pytest.mark.parametrize("seed", range(3))
def test_nearest_corners_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    corners = rng.uniform(0, 1, (50, 3))
    corners[10] = corners[3]  # a tie: the first in x order wins either way, at the same distance
    queries = rng.uniform(0, 1, (80, 3))
    nearest, distance = _nearest_corners(corners, queries, 0.15)
    all_d = np.linalg.norm(queries[:, None] - corners[None], axis=2)
    want = np.where(all_d.min(axis=1) <= 0.15, all_d.min(axis=1), np.inf)
    assert np.allclose(distance, want)
    found = nearest >= 0
    assert np.array_equal(found, np.isfinite(want))
    assert np.allclose(all_d[np.flatnonzero(found), nearest[found]], want[found])


def test_feature_curves_match_the_naive_ones():
    surface = paroct.load_surface(DATA / "angle_block.stl")
    labels = surface_patches(surface, 40)
    curves = feature_curves(surface, labels)
    ours = {(tuple(sorted(e)), tuple(p)) for e, p in zip(curves.segments.tolist(), curves.pairs.tolist())}
    theirs, corners = naive.feature_curves(surface.faces, labels)
    assert ours == theirs and set(curves.corners.tolist()) == corners and len(corners) > 0


def test_cli_sharp_edges(tmp_path, capsys):
    out = tmp_path / "block.vtu"
    assert main(["mesh", str(DATA / "angle_block.stl"), "-o", str(out), "--divisions", "20", "--sharp-edges"]) == 0
    summary = capsys.readouterr().out
    assert "note: sharp edges:" in summary
    assert main(["mesh", str(DATA / "angle_block.stl"), "-o", str(out), "--sharp-edges", "200"]) == 2
    assert "feature angle = 200.0" in capsys.readouterr().err


def test_a_box_comes_out_exactly():
    """An axis-aligned 1 x 2 x 3 box at size 0.1: afterwards every boundary triangle lies on a
    side, each side's patch has its area and the mesh the box's volume, up to the surface's
    fixed-point snap (before: chamfered edges, 1.3 of the 22 area units on slanted triangles)."""
    result = paroct.mesh(manifold3d.Manifold.cube([1.0, 2.0, 3.0]), size=0.1)
    sharp = result.with_sharp_edges()
    patches = sharp.boundary_patches(40)
    corners = sharp.mesh.points[patches.faces]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    # within the fixed-point snap of the surface (rays.snap_surface): cut points lie on the snapped one
    on_side = np.any([np.ptp(corners[:, :, axis], axis=1) < 1e-6 * result.report.size for axis in range(3)], axis=0)
    assert on_side.all()
    assert np.sort(np.bincount(patches.patches, weights=areas)[1:]) == pytest.approx([2, 2, 3, 3, 6, 6], rel=1e-6)
    assert sharp.report.mesh_volume == pytest.approx(6.0, rel=1e-6)
    assert abs(result.report.mesh_volume - 6.0) > 1e-3


def test_a_result_without_its_surface_says_what_to_call():
    result = paroct.mesh(manifold3d.Manifold.cube([1.0, 1.0, 1.0]), size=0.25)
    with pytest.raises(paroct.ParoctError, match="no surface"):
        paroct.MeshResult(result.mesh, result.report).with_sharp_edges()


@pytest.mark.parametrize("seed", [3, 8])
def test_csg_parts_stay_valid_and_closed(seed):
    """Random unions and differences of boxes, cylinders and spheres, rotated: after the moves
    no tet is inverted, the boundary is a closed 2-manifold of the same topology that crosses
    itself nowhere, and the volume error is no worse than a tenth of a percent off before's."""
    from paroct.intersections import crossing_triangles

    rng = np.random.default_rng(seed)
    solid = manifold3d.Manifold.cube([2.0, 1.5, 1.0], center=True)
    for _ in range(3):
        r = rng.uniform(0.15, 0.4)
        tool = (manifold3d.Manifold.cylinder(2.0, r, r, 32, center=True) if rng.random() < 0.5
                else manifold3d.Manifold.sphere(r, 32)).translate(list(rng.uniform(-0.8, 0.8, 3)))
        solid = solid - tool if rng.random() < 0.6 else solid + tool
    solid = solid.rotate(list(rng.uniform(0, 360, 3)))
    result = paroct.mesh(solid, divisions=30)
    sharp = result.with_sharp_edges()
    report = check_mesh(sharp.mesh.points, sharp.mesh.tets, result.surface)
    assert report.n_inverted == 0 and report.boundary_manifold and report.overloaded_faces == 0
    assert (report.boundary_components, report.boundary_genus) == (result.report.boundary_components,
                                                                   result.report.boundary_genus)
    faces = sharp.boundary_patches(40).faces.astype(np.int64)
    assert (crossing_triangles(sharp.mesh.points, faces, np.arange(len(faces))) < 0).all()
    assert abs(sharp.report.volume_error) <= abs(result.report.volume_error) + 1e-3
    assert sharp.report.min_dihedral >= min(SNAP_MIN_ANGLE, result.report.min_dihedral) - 1e-9


def test_half_edge_twins_run_the_other_way():
    """On a closed surface every half-edge has exactly one twin, running the same edge the other
    way, and the twin of the twin is itself; a surface with a hole leaves its rim's half-edges
    without one."""
    from paroct.topology import half_edge_twins

    surface = paroct.load_surface(DATA / "angle_block.stl")
    faces = np.asarray(surface.faces, dtype=np.int64)
    twin = half_edge_twins(faces, surface.vertices.shape[0])
    h = np.arange(3 * len(faces))
    start, end = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    assert (twin >= 0).all() and np.array_equal(twin[twin], h)
    assert np.array_equal(start[twin], end) and np.array_equal(end[twin], start)
    open_twin = half_edge_twins(faces[1:], surface.vertices.shape[0])
    assert (open_twin < 0).sum() == 3
