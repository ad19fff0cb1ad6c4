"""End-to-end properties of paroct.mesh on the bundled parts and constructed solids."""

import warnings
from pathlib import Path

import manifold3d
import numpy as np
import pytest

import paroct

from paroct import rays
from paroct.check import distances_to_triangles
from paroct.errors import ParoctError
from paroct.features import FACING, ThinFeatures, thin_features
from paroct.frame import EDGE_DIRECTIONS, LATTICE_TO_SPACE, X_AXIS_DIRECTION, fat_frame
from paroct.lattice import leaf_tets
from paroct.mesher import _compact, _cut_points, _direction_counts, _next_ask, _thin_asks, _used_ids, mesh
from paroct.octree import octant_lattice_anchors, uniform_leaves
from paroct.quality import tet_dihedral_angles, tet_quality
from paroct.stuffing import PRISM_TETS
from paroct.surface import load_surface
from paroct.topology import boundary_faces, match_faces, surface_topology

from . import naive

DATA = Path(__file__).resolve().parent.parent / "data"
FAT_RATIO = 3 / np.sqrt(10)  # = (3/2) sqrt(2/5) = 0.948683; '3 sqrt(2/5)' is a misprint
LS_MIN, LS_MAX = 10.7, 164.8


def _assert_valid(points, tets, surface):
    q = tet_quality(points, tets)
    assert q.volume.min() > 0, "inverted or flat tet"
    neighbour, overloaded, same_side = match_faces(tets)
    assert overloaded == 0 and same_side == 0, "non-conforming"
    faces = boundary_faces(tets, neighbour)
    topo = surface_topology(faces, points.shape[0])
    assert topo.manifold, f"boundary not a closed manifold: {topo}"
    assert LS_MIN <= q.min_dihedral.min() and q.max_dihedral.max() <= LS_MAX
    # Tets away from the boundary are exactly Todd's fat tet.
    on_boundary = np.zeros(points.shape[0], dtype=bool)
    on_boundary[faces.ravel()] = True
    interior = ~on_boundary[tets].any(axis=1)
    assert interior.sum() > 0
    # Away from the boundary: Todd's fat tet (60 and 90 degrees only) or a transition template
    # tet (30 .. 120 degrees, 3r/R >= 0.544; the issue asks for 30 .. 135 and 0.40).
    fat = interior & (np.abs(q.radius_ratio - FAT_RATIO) < 1e-9)
    angles = tet_dihedral_angles(points, tets[fat])
    assert np.all((np.abs(angles - 60) < 1e-7) | (np.abs(angles - 90) < 1e-7))
    assert q.min_dihedral[interior].min() >= 30 - 1e-9 and q.max_dihedral[interior].max() <= 120 + 1e-9
    assert q.radius_ratio[interior].min() >= 0.544
    return faces, topo


@pytest.mark.parametrize("name,divisions", [("angle_block", 40), ("angle_block", 35), ("xyz_cube", 40), ("bunny", 40),
                                            ("bunny", 80)])
def test_bundled_parts_mesh_validly_with_proven_angles(name, divisions):
    surface = load_surface(DATA / f"{name}.stl")
    result = mesh(surface, divisions=divisions)
    faces, topo = _assert_valid(result.mesh.points, result.mesh.tets, surface)
    assert topo.genus == surface.genus and topo.components == surface.components
    rep = result.report
    assert rep.n_tets == result.mesh.tets.shape[0]
    # The report's boundary comes from matching only the faces without a core vertex (repair.stuffed_boundary).
    assert (rep.boundary_components, rep.boundary_genus, rep.boundary_manifold) == (topo.components, topo.genus, True)
    if divisions == 80:
        assert abs(rep.volume_error) < 0.01


def test_boundary_vertices_lie_on_the_input_surface():
    surface = load_surface(DATA / "angle_block.stl")
    result = mesh(surface, divisions=30)
    neighbour, _, _ = match_faces(result.mesh.tets)
    verts = np.unique(boundary_faces(result.mesh.tets, neighbour))
    # Signed distance to the surface: angle_block is a union of planar faces; use manifold3d to
    # measure: a tiny ball around each boundary vertex must meet both inside and outside.
    solid = surface.to_manifold()
    x = result.mesh.points[verts]
    eps = 1e-7 * surface.diagonal
    for p in x[:: max(1, len(x) // 200)]:
        hits_up = solid.ray_cast(p - [0, 0, eps], p + [0, 0, eps])
        hits_x = solid.ray_cast(p - [eps, 0, 0], p + [eps, 0, 0])
        hits_y = solid.ray_cast(p - [0, eps, 0], p + [0, eps, 0])
        assert hits_up or hits_x or hits_y, f"boundary vertex {p} is off the surface"


def test_box_mesh_volume_and_exact_faces():
    # A box whose faces are not lattice-aligned: volume within stuffing's error, all angles proven.
    box = manifold3d.Manifold.cube([1.0, 0.8, 0.6]).rotate([10, 20, 30])
    surface = load_surface(box)
    result = mesh(surface, size=0.05)
    _assert_valid(result.mesh.points, result.mesh.tets, surface)
    assert abs(result.report.volume_error) < 0.01


def test_classification_matches_manifold3d_ray_cast_reference():
    surface = load_surface(DATA / "bunny.stl")
    h = surface.diagonal / 30
    frame = fat_frame(surface.bbox_min, surface.bbox_max, h)
    keys, _ = uniform_leaves(frame, surface.bbox_min - h, surface.bbox_max + h, frame.levels)
    coords, _ = leaf_tets(octant_lattice_anchors(keys, frame), np.ones(len(keys), dtype=np.int64))
    snapped = rays.snap_surface(frame, surface.vertices)
    inside = rays.winding_numbers(rays.row_crossings(frame, snapped, surface.faces.astype(np.int64), X_AXIS_DIRECTION), coords) > 0
    x = frame.to_space(coords)
    start_x = surface.bbox_min[0] - 1.0
    rng = np.random.default_rng(0)
    for i in rng.choice(len(x), size=600, replace=False):
        hits = surface.to_manifold().ray_cast([start_x, x[i, 1], x[i, 2]], x[i])
        winding = sum(1 if hit.normal[0] < 0 else -1 for hit in hits)
        assert (winding > 0) == inside[i]


def test_overlapping_shells_are_unioned():
    a = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    b = manifold3d.Manifold.cube([1.0, 1.0, 1.0]).translate([0.5, 0.5, 0.5])
    ma, mb = a.to_mesh64(), b.to_mesh64()
    va, vb = np.asarray(ma.vert_properties)[:, :3], np.asarray(mb.vert_properties)[:, :3]
    faces = np.vstack([np.asarray(ma.tri_verts), np.asarray(mb.tri_verts) + len(va)])
    surface = load_surface((np.vstack([va, vb]), faces))
    assert surface.volume == pytest.approx(2 - 0.125)
    result = mesh(surface, size=0.05)
    _assert_valid(result.mesh.points, result.mesh.tets, surface)
    assert result.report.mesh_volume == pytest.approx(1.875, rel=0.01)


def test_meshing_is_deterministic():
    surface = load_surface(DATA / "xyz_cube.stl")
    a = mesh(surface, divisions=25).mesh
    b = mesh(DATA / "xyz_cube.stl", divisions=25).mesh
    assert np.array_equal(a.points, b.points) and np.array_equal(a.tets, b.tets)


def test_thin_solid_warns_or_fails_with_advice_when_refinement_is_off():
    # A 1 x 1 x 0.02 plate at size 0.05: nothing survives, and the error names the thickness.
    plate = manifold3d.Manifold.cube([1.0, 1.0, 0.02])
    with pytest.raises(ParoctError, match=r"thinnest wall 0\.02"):
        mesh(plate, size=0.05, thin_features=False)
    # Thicker, a few scraps survive: less than half the volume is an error too, not a mesh.
    with pytest.raises(ParoctError, match=r"keeps only 0\.43% of the solid's volume; thinnest wall 0\.035"):
        mesh(manifold3d.Manifold.cube([1.0, 1.0, 0.035]).rotate([23, 41, 67]), size=0.05, thin_features=False)
    # Refinement on, but max_memory holds the boundary at size: the error says so first.
    thin = manifold3d.Manifold.cube([1.0, 1.0, 0.035]).rotate([23, 41, 67])
    with pytest.raises(ParoctError, match=r"keeps only 0\.43% .*; a boundary size below 0\.05 would not fit in memory "
                                          r"\(max_memory\); thinnest wall 0\.035"):
        mesh(thin, size=0.05, max_memory=3e6)
    # A block with a thin fin: the fin is lost, and the warning says so with a size that keeps it.
    result = mesh(_FIN_PART, size=0.1, thin_features=False)
    assert result.report.warnings and "thinnest wall" in result.report.warnings[0]
    assert "size = 0.015" in result.report.warnings[0]


_BUNNY = DATA / "bunny.stl"
_FIN_PART = manifold3d.Manifold.cube([1.0, 1.0, 0.5]) + manifold3d.Manifold.cube([1.0, 0.03, 0.5]).translate([0, 0, 0.5])


@pytest.mark.parametrize("facing", [-0.9, -0.6])
def test_thin_features_filtered_by_facing_are_those_measured_at_it(facing):
    """One pass of the rows serves the advice (FACING) and the walls to refine (a stricter
    limit): facing_below gives the samples thin_features finds at that limit, in order."""
    surface = load_surface(_FIN_PART.rotate([17, 29, 41]) + manifold3d.Manifold.cylinder(0.6, 0.2, 0.05, 24))
    frame = fat_frame(surface.bbox_min, surface.bbox_max, 0.05)
    snapped = rays.snap_surface(frame, surface.vertices)
    faces = np.asarray(surface.faces, dtype=np.int64)
    crossings = {d: rays.row_crossings(frame, snapped, faces, d) for d in range(EDGE_DIRECTIONS.shape[0])}
    loose = thin_features(frame, crossings, surface.vertices, faces)
    strict = thin_features(frame, crossings, surface.vertices, faces, facing)
    assert np.all(loose.facing < FACING) and 0 < strict.thickness.size < loose.thickness.size
    got = loose.facing_below(facing)
    for name in ("thickness", "points", "is_wall", "facing"):
        assert np.array_equal(getattr(got, name), getattr(strict, name)), name


def test_thin_walls_refine_the_boundary_until_two_layers_span_them():
    surface = load_surface(_FIN_PART)
    result = mesh(surface, size=0.1)
    rep = result.report
    # 0.03 thick: two layers need size <= 0.015, so 0.1 halves three times to 0.0125.
    assert rep.size == pytest.approx(0.0125) and rep.requested_size == pytest.approx(0.1)
    assert any("wall 0.03" in note for note in rep.notes) and not rep.warnings
    assert abs(rep.volume_error) < 0.01
    assert (rep.boundary_components, rep.boundary_genus) == (surface.components, surface.genus)
    _assert_valid(result.mesh.points, result.mesh.tets, surface)
    # The interior still coarsens (towards max_size = 8 x the requested size).
    assert rep.max_size == pytest.approx(0.8) and max(rep.leaf_levels) >= 3  # 0.1 and coarser inside
    # Only the fin's band is fine: the block keeps the requested size along its boundary.
    everywhere = mesh(surface, size=0.0125, max_size=0.8, thin_features=False)
    assert rep.n_tets < 0.5 * everywhere.report.n_tets


@pytest.mark.parametrize("thickness, steps", [
    # Two layers across 1/64 of the coarse size need 7 levels: the cap (3) deepens alone
    # while it holds them short, then every sample with the cap.
    ([1 / 64, 0.5], [(4, 0), (5, 0), (6, 0), (6, 1), (6, 2), (6, 3), (6, 4), None]),
    # Samples within the cap: the shallow one deepens first, then both with the cap.
    ([0.3, 1.0], [(3, 1), (3, 2), (4, 3), (5, 4), (6, 5), None]),
])
def test_losing_rounds_deepen_held_samples_first_then_all(thickness, steps):
    coarse = fat_frame(np.zeros(3), np.ones(3), 1.0)
    k = len(thickness)
    walls = ThinFeatures(np.array(thickness), np.full((k, 3), 0.5), np.ones(k, dtype=bool), np.full(k, -1.0))
    max_depth, cap, extra = 6, 3, 0
    for want in steps:
        depth = _thin_asks(coarse, walls, cap, extra)[1]
        got = _next_ask(_thin_asks(coarse, walls, max_depth, 0)[1], depth, cap, extra, max_depth)
        assert got == want
        if got is None:
            assert (_thin_asks(coarse, walls, max_depth, extra)[1] == max_depth).all()
            break
        assert got[0] <= max_depth and (got[0], got[1]) != (cap, extra)
        cap, extra = got


@pytest.mark.parametrize("halving_lost", [False, True])
def test_whole_band_fallback_goes_by_halves_coarsest_first(monkeypatch, halving_lost):
    """When the rounds near thin places fail, the whole band shrinks by halves (skipping the
    sizes the rounds tried, here size / 2) until a pass keeps the solid, even with a wall far
    thinner than the floor; each pass here 'loses' until size / 4."""
    from paroct import mesher

    real, sizes, h = mesher._mesh_at, [], 0.1
    thin = ThinFeatures(np.array([h / 100]), np.full((1, 3), 0.5), np.ones(1, dtype=bool), np.full(1, -1.0))

    def pass_losing_above_quarter(surface, field, report, progress):
        result, _, _, _ = real(surface, field, report, progress)
        sizes.append(field.size)
        return result, ("the mesh lost a wall" if field.size > h / 3 else ""), "advice", thin

    def rounds(surface, field, walls, floor, budget, lost, wholes, *args):
        assert wholes == pytest.approx([h / 2, h / 4])  # above the floor, size / 8
        half = mesher.LosingPass(h / 2, "the mesh lost a wall", "", mesher.MeshReport(size=h / 2, levels=0), None, None)
        tried = [half] if halving_lost else []
        return None, "the rounds failed", tried, [f"tried {p.band}" for p in tried]

    monkeypatch.setattr(mesher, "_mesh_at", pass_losing_above_quarter)
    monkeypatch.setattr(mesher, "_thin_locally", rounds)
    result = mesh(manifold3d.Manifold.cube([1, 1, 1]), size=h)
    assert sizes == pytest.approx([h, h / 4] if halving_lost else [h, h / 2, h / 4])
    assert result.report.size == pytest.approx(h / 4) and not result.report.warnings
    assert result.report.notes[-1].startswith(f"boundary size {h if halving_lost else h / 2:.4g} -> {h / 4:.4g}")
    assert (f"tried {h / 2}" in result.report.notes) == halving_lost


def _cubes_sharing_an_edge(degrees_x: float, degrees_y: float) -> tuple[np.ndarray, np.ndarray]:
    """Two unit cubes sharing the edge x = y = 1 as two shells (vertices, faces), turned about
    x then y (fixed axes)."""
    corners = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float)
    box = manifold3d.Manifold.cube([1, 1, 1]).to_mesh()
    vertices = np.asarray(box.vert_properties[:, :3], dtype=float)
    faces = np.asarray(box.tri_verts, dtype=np.int64)
    assert len(vertices) == 8 and set(map(tuple, vertices)) == set(map(tuple, corners))
    a, b = np.radians(degrees_x), np.radians(degrees_y)
    turn_x = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    turn_y = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    both = np.vstack([vertices, vertices + [1.0, 1.0, 0.0]]) @ (turn_y @ turn_x).T
    return both, np.vstack([faces, faces + 8])


def test_halving_stops_where_a_finer_band_joins_touching_parts_more():
    """Two cubes sharing an edge, turned off the lattice: no size keeps them apart (nothing
    between them is thinner than the lattice, it is not there), and finer boundaries join
    them more (a pass at size / 4 has a larger genus).  The halving keeps the pass nearest the
    input (fewest component and genus differences, then least volume error) instead of going
    on to min_size, and says why."""
    cubes = _cubes_sharing_an_edge(30.0, 40.0)
    surface = load_surface(cubes)
    h = surface.diagonal / 30

    def distance(report):
        return abs(report.boundary_components - 2) + report.boundary_genus

    quarter = mesh(surface, size=h / 4, max_size=8 * h, thin_features=False).report  # as mesh(size=h)'s passes
    result = mesh(surface, size=h)
    report = result.report
    assert report.input_components == 2 and report.input_genus == 0
    assert distance(quarter) > distance(report)  # finer joins more
    assert report.size < h and report.n_tets < quarter.n_tets
    assert any("is kept" in w and "touching along an edge" in w for w in report.warnings)
    tried = [mesh(surface, size=s, max_size=8 * h, thin_features=False).report for s in (h, h / 2)]
    best = min(tried, key=lambda r: (distance(r), abs(r.volume_error)))
    assert report.size == best.size and report.n_tets == best.n_tets
    _assert_valid(result.mesh.points, result.mesh.tets, surface)


@pytest.mark.parametrize("changes_at", [None, 1])
def test_rounds_at_min_size_stop_once_they_lose_the_same(monkeypatch, changes_at):
    """Once the samples are at min_size (cap = max_depth), rounds that each go a level deeper
    for the others stop when SAME_LOSS_ROUNDS in a row lost the same as the round before; a
    loss that changes restarts the count.  Every round here 'loses' the same but round
    changes_at; a wall far below min_size and one needing a level keep the asks changing."""
    from paroct import mesher

    h, rounds = 0.1, []
    top = np.array([[0.5, 0.5, 1.0], [0.2, 0.2, 1.0]])
    thin = ThinFeatures(np.array([1e-4, 0.19]), top, np.ones(2, dtype=bool), np.full(2, -1.0))

    def losses(report, surface):
        if report.size == h:  # the first pass
            return "the mesh lost a wall"
        return "the boundary has 3 components" if len(rounds) - 1 == changes_at else "the boundary has 2 components"

    def local(*args, **kwargs):
        rounds.append(1)
        return real_local(*args, **kwargs)

    def first_pass_with_thin_walls(surface, field, report, progress, **kwargs):
        result, _, advice, _ = real_at(surface, field, report, progress, **kwargs)
        return result, losses(report, surface), advice, thin

    real_local, real_at = mesher._mesh_locally, mesher._mesh_at
    monkeypatch.setattr(mesher, "_losses", losses)
    monkeypatch.setattr(mesher, "_next_ask", lambda needs, depth, cap, extra, max_depth: (max_depth, extra + 1))
    monkeypatch.setattr(mesher, "_mesh_locally", local)
    monkeypatch.setattr(mesher, "_mesh_at", first_pass_with_thin_walls)
    monkeypatch.setattr(mesher, "_fits", lambda *args: False)  # no whole band: only the rounds
    result = mesh(manifold3d.Manifold.cube([1, 1, 1]), size=h, min_size=h / 64)
    # The first round is below the floor's cap; then one with a change, if any, and
    # SAME_LOSS_ROUNDS + 1 alike.  Without the rule they would run until the thick wall's
    # asks reach max_depth (five after the first).
    assert len(rounds) == 1 + (changes_at is not None) + mesher.SAME_LOSS_ROUNDS + 1
    assert any(f"{mesher.SAME_LOSS_ROUNDS} rounds one level deeper each" in note for note in result.report.notes)
    assert result.report.warnings


@pytest.mark.parametrize("tighter", [5.0, 12.0])
def test_a_one_level_pass_outside_the_bound_is_made_again_and_mended(monkeypatch, tighter):
    """A one-level pass whose measured extremes leave DIHEDRAL_BOUND (here one tighter than
    the proven bound by ``tighter`` degrees at both ends) runs again measuring every stuffed
    tet and trying other warps near the bad ones: 5 degrees in, all mend; 12 in, the tets
    still outside are counted and warned about."""
    from paroct import mesher, stuffing

    plain = mesh(_BUNNY, divisions=40)
    assert "warps" not in plain.report.stage_seconds  # no measuring pass where the bound holds
    bound = (plain.report.min_dihedral + tighter, plain.report.max_dihedral - tighter)
    monkeypatch.setattr(mesher, "DIHEDRAL_BOUND", bound)
    monkeypatch.setattr(stuffing, "DIHEDRAL_BOUND", bound)
    mended = mesh(_BUNNY, divisions=40, thin_features=False)
    rep = mended.report
    q = tet_quality(mended.mesh.points, mended.mesh.tets)
    outside = int(((q.min_dihedral < bound[0]) | (q.max_dihedral > bound[1])).sum())
    assert "warps" in rep.stage_seconds and outside <= rep.bad_tets
    assert (rep.bad_tets > 0) == (tighter > 10) == any(f"{rep.bad_tets} tets stayed outside" in w for w in rep.warnings)
    if tighter < 10:
        assert outside == 0 and bound[0] <= rep.min_dihedral and rep.max_dihedral <= bound[1]
    assert rep.min_dihedral > plain.report.min_dihedral and rep.max_dihedral < plain.report.max_dihedral
    _assert_valid(mended.mesh.points, mended.mesh.tets, load_surface(_BUNNY))


def test_bound_check_skips_only_copied_lattice_tets(monkeypatch):
    """_outside_bound measures only tets with a vertex that is not core.  The tets it skips
    (stuffing's copies of lattice tets) are never outside the bound nor needles, and on the
    fin's passes, whose band changes level, it finds the bad tets and needles that measuring
    every tet finds."""
    from paroct import mesher
    from paroct.quality import NEEDLE, OUTSIDE

    calls = []
    restricted = mesher._outside_bound

    def both(points, tets, core):
        got = restricted(points, tets, core)
        q = tet_quality(points, tets)
        outside = (q.min_dihedral < mesher.DIHEDRAL_BOUND[0]) | (q.max_dihedral > mesher.DIHEDRAL_BOUND[1])
        needle = ~outside & (q.radius_ratio < mesher.NEEDLE_RATIO)
        copied = core[tets].all(axis=1)
        assert not (outside | needle)[copied].any()
        assert q.min_dihedral[copied].min(initial=90) > 30 - 1e-9 and q.radius_ratio[copied].min(initial=1) >= 0.4
        np.testing.assert_array_equal(got, np.where(outside, OUTSIDE, np.where(needle, NEEDLE, 0)))
        calls.append((int(copied.sum()), int((outside | needle).sum())))
        return got

    monkeypatch.setattr(mesher, "_outside_bound", both)
    mesh(_FIN_PART, size=0.1)
    assert calls[0][0] > 0  # the first call, over all tets, skipped some (later ones: restuffed tets)
    assert sum(n_bad for _, n_bad in calls) > 0  # and it had bad tets or needles to find


def test_min_size_floor_is_reported_in_one_line():
    """The fin (0.03) is lost at size 0.1 (3.7 % of the volume) and full of holes at min_size
    0.05 (genus 171, 2.3 %): nearer in volume, further in topology, the pass at 0.05 keeps
    more by one measure, so no coarser pass is returned for it, and the one warning says why
    it went no finer and what would keep the fin."""
    result = mesh(_FIN_PART, size=0.1, min_size=0.05)
    rep = result.report
    assert rep.size == pytest.approx(0.05) and rep.boundary_genus > 0
    assert len(rep.warnings) == 1 and rep.warnings[0].startswith("min_size = 0.05 reached; the mesh lost")
    assert "thinnest wall" in rep.warnings[0]


def _fins_part(fin: float, rod: float) -> manifold3d.Manifold:
    """A slab with a fin 1e-5 thick, which no size above min_size keeps, and a fin ``fin``
    thick and a rod of radius ``rod`` (each left out if 0), which finer passes may keep."""
    part = (manifold3d.Manifold.cube([1.0, 1.0, 0.2])
            + manifold3d.Manifold.cube([0.6, 1e-5, 0.4]).translate([0.2, 0.8, 0.2]))
    if fin:
        part += manifold3d.Manifold.cube([0.6, fin, 0.4]).translate([0.2, 0.3, 0.2])
    if rod:
        part += manifold3d.Manifold.cylinder(1.0, rod, rod, 16).translate([0.5, 0.5, 0.2])
    return part


def _fin_tips(surface) -> np.ndarray:
    """Ids of the 1e-5 fin's top vertices."""
    return np.flatnonzero((surface.vertices[:, 2] > 0.6 - 1e-9) & (surface.vertices[:, 1] > 0.8 - 1e-9))


def test_the_coarsest_pass_keeping_as_much_as_the_finer_ones_is_kept():
    """Every pass loses the 1e-5 fin.  At size the 0.06 fin comes out full of holes; size / 2
    keeps it, and the finer passes (size / 4 tried before the rounds near thin places, then
    the whole band at size / 8) keep no more: size / 2 is kept, made again (only the pass at
    size is held), the same as a pass there alone, with the fin's tips its only misses."""
    h = 0.1
    surface = load_surface(_fins_part(fin=0.06, rod=0.0))
    result = mesh(surface, size=h)
    rep = result.report
    assert rep.size == pytest.approx(h / 2) and rep.boundary_genus == 0 and abs(rep.volume_error) < 0.01
    assert np.array_equal(rep.missed_vertices, _fin_tips(surface))
    assert any(note.startswith(f"boundary size {h:.4g} -> {h / 8:.4g}") for note in rep.notes)
    assert len(rep.warnings) == 1 and "the pass at boundary size 0.05 is kept" in rep.warnings[0]
    alone = mesh(surface, size=h / 2, max_size=8 * h, thin_features=False)
    assert np.array_equal(result.mesh.tets, alone.mesh.tets) and np.array_equal(result.mesh.points, alone.mesh.points)
    _assert_valid(result.mesh.points, result.mesh.tets, surface)


def test_a_finer_pass_that_misses_less_of_the_surface_is_kept():
    """The rod (0.02 across) is dropped at size, / 2 and / 4 with no change of topology or
    volume; only the whole band at size / 8 keeps it.  Its boundary misses fewer surface
    vertices, by the coarser passes' reach too, so it is the mesh returned, warning only of
    the 1e-5 fin."""
    surface = load_surface(_fins_part(fin=0.0, rod=0.01))
    result = mesh(surface, divisions=15)
    rep = result.report
    assert rep.size == pytest.approx(rep.requested_size / 8)
    assert np.array_equal(rep.missed_vertices, _fin_tips(surface))
    assert result.mesh.points[:, 2].max() > 1.2 - 0.01  # the rod's top
    assert len(rep.warnings) == 1 and "is kept" not in rep.warnings[0]


_ROD_PART = (manifold3d.Manifold.cube([1.0, 1.0, 0.2])
             + manifold3d.Manifold.cylinder(1.0, 0.0035, 0.0035, 16).translate([0.5, 0.5, 0.2]))


def test_a_rod_thinner_than_the_lattice_is_reported_then_kept():
    # The rod (0.007 across, size/6.6 at diag/40) changes neither topology nor volume (0.02 %)
    # when stuffing drops it: only the surface vertices the boundary misses tell.
    surface = load_surface(_ROD_PART)
    dropped = mesh(surface, divisions=40, thin_features=False).report
    assert dropped.missed_vertices.size > 0 and abs(dropped.volume_error) < 0.01
    assert (dropped.boundary_components, dropped.boundary_genus) == (1, 0)
    assert len(dropped.warnings) == 1 and "misses" in dropped.warnings[0]
    tip = surface.vertices[:, 2] > 1.2 - 1e-9
    assert np.all(np.isin(np.flatnonzero(tip), dropped.missed_vertices))
    # By default the band is refined along the rod (around the triangles at the missed vertices,
    # not only where a lattice row happened to cross it) until it is kept.
    result = mesh(surface, divisions=40)
    rep = result.report
    assert not rep.warnings and rep.missed_vertices.size == 0 and abs(rep.volume_error) < 0.01
    assert result.mesh.points[:, 2].max() > 1.2 - 0.01
    _assert_valid(result.mesh.points, result.mesh.tets, surface)


def test_a_shell_between_the_lattice_rows_is_kept():
    # A cube of side 0.0066 (size/9 at diag/40) one unit away from a unit cube: no lattice row
    # crosses it, so only the missed surface vertices say where to refine.
    surface = load_surface(manifold3d.Manifold.cube([1.0, 1.0, 1.0])
                           + manifold3d.Manifold.cube([0.0066] * 3).translate([2.0, 0.5, 0.5]))
    result = mesh(surface, divisions=40)
    rep = result.report
    assert not rep.warnings and rep.missed_vertices.size == 0
    assert (rep.boundary_components, rep.boundary_genus) == (2, 0) and abs(rep.volume_error) < 0.01
    _assert_valid(result.mesh.points, result.mesh.tets, surface)


def test_a_filled_gap_counts_as_a_loss():
    # A slot 0.028 wide and 0.7 deep through a unit cube, at diag/20: stuffing fills it and the
    # mesh gains volume (found by fuzzing: only losses were reported).
    slotted = manifold3d.Manifold.cube([1.0, 1.0, 1.0]) - manifold3d.Manifold.cube([2.0, 0.028, 0.8]).translate([-0.5, 0.5, -0.1])
    rep = mesh(slotted, divisions=20, thin_features=False).report
    assert rep.volume_error > 0.01
    assert len(rep.warnings) == 1 and "gained" in rep.warnings[0] and "thinnest gap 0.028" in rep.warnings[0]
    rep = mesh(slotted, divisions=20).report
    assert not rep.warnings and abs(rep.volume_error) < 0.01


def test_size_checks():
    box = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    for bad in (0, -1, float("nan"), float("inf")):
        with pytest.raises(ParoctError, match="size"):
            mesh(box, size=bad)
    with pytest.raises(ParoctError, match="GiB"):
        mesh(box, size=1e-4)  # ~1.2e13 tets: refused before any work
    with pytest.raises(ParoctError, match=r"about 1.16e\+05 lattice tets and [\d.]+ MiB, more than the 1000 bytes allowed"):
        mesh(box, size=0.05, max_memory=1000)


@pytest.mark.parametrize("options, match", [
    (dict(divisions="12"), r"divisions = '12': must be a positive number"),
    (dict(divisions=[12]), r"divisions = \[12\]: must be a positive number"),
    (dict(size=True), r"size = True: must be a positive number"),
    (dict(size=1e-300), r"size = 1e-300 is too small for the part: its bounding-box diagonal 1.73205 is more than 2\^"),
    (dict(size=5e-324), r"size = 4.94066e-324 is too small for the part"),
    (dict(size=1e308), r"size = 1e\+308 is larger than the whole part \(its bounding-box diagonal is 1.73205\)"),
    (dict(divisions=1e308), r"is too small for the part"),
    (dict(divisions=12, max_size="10"), r"max_size = '10': must be a positive number"),
    (dict(divisions=12, min_size="abc"), r"min_size = 'abc': must be a positive number"),
    (dict(divisions=12, max_memory=float("nan")), r"max_memory = nan: must be a positive number"),
    (dict(divisions=12, max_memory=-1), r"max_memory = -1: must be a positive number"),
    (dict(divisions=12, regions=None), r"regions = None: must be a list of paroct.Box and paroct.Sphere"),
    (dict(divisions=12, regions=paroct.Box((0, 0, 0), (1, 1, 1), 1)), r"must be a list of paroct.Box"),
    (dict(divisions=12, regions=[paroct.Box((0, 0), (1, 1), 1)]), r"refinement box lo = \(0, 0\): must be three finite"),
    (dict(divisions=12, regions=[paroct.Box(("a", 0, 0), (1, 1, 1), 1)]), r"refinement box lo = \('a', 0, 0\)"),
    (dict(divisions=12, regions=[paroct.Box((0, 0, 0), (1, 1, 1), None)]), r"refinement region size = None"),
    (dict(divisions=12, regions=[paroct.Sphere((0, 0, 0), "1", 1)]), r"refinement sphere radius = '1'"),
    (dict(divisions=12, regions=[paroct.Sphere((np.nan, 0, 0), 1, 1)]), r"refinement sphere center = \(nan, 0, 0\)"),
    (dict(divisions=12, progress=1), r"progress = 1: must be a function"),
    (dict(size=0.1, divisions=8), r"size = 0.1 and divisions = 8: give one"),
    (dict(divisions=12, thin_features="no"), r"thin_features = 'no': must be True or False"),
    (dict(divisions=12, max_memory=-10**400), r"max_memory = -10000000\.\.\. \(401 digits\): must be a positive"),
    (dict(divisions=12, regions=[paroct.Sphere((0, 0, 0), np.array([0.1, 0.2]), 1)]),
     r"refinement sphere radius = array\(\[0\.1, 0\.2\]\): must be a positive number"),
    (dict(divisions=12, regions=[paroct.Sphere((0, 0, 0), False, 1)]), r"refinement sphere radius = False"),
    (dict(size=0.1, min_size=0.2), r"min_size = 0\.2 must be at most size = 0\.1"),
    (dict(divisions=12, regions=[paroct.Box((0, 0, 1), (1, 1, 0), 1)]), r"lo = \(0, 0, 1\) exceeds hi = \(1, 1, 0\)"),
])
def test_options_of_the_wrong_kind_are_refused_by_name(options, match):
    """Every option is checked before any work, and a wrong one named in a ParoctError (not a
    TypeError from deep inside, nor a mesh of something else)."""
    with pytest.raises(ParoctError, match=match):
        mesh(manifold3d.Manifold.cube([1.0, 1.0, 1.0]), **options)


def test_progress_hears_each_stage_and_an_exception_from_it_cancels():
    """progress is called with each stage's name as it ends, in order; an exception it raises
    stops the meshing there and reaches the caller as it is (the way to cancel a long run)."""
    box = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    heard: list[str] = []
    paroct.mesh(box, divisions=10, progress=heard.append)
    assert heard[0] == "load" and heard[-1] == "quality"
    assert [stage for stage in heard if stage in ("frame", "octree", "stuff", "quality")] == \
        ["frame", "octree", "stuff", "quality"]

    class Cancelled(Exception):
        pass

    def cancel_at_octree(stage: str) -> None:
        heard.append(stage)
        if stage == "octree":
            raise Cancelled(stage)

    heard.clear()
    with pytest.raises(Cancelled, match="octree"):
        paroct.mesh(box, divisions=10, progress=cancel_at_octree)
    assert heard[-1] == "octree" and "stuff" not in heard


def test_a_sphere_past_every_part_asks_its_size_everywhere():
    """A refinement sphere of radius 1e200 around the box asks its size on the whole box, as
    one of radius 10 does (its squared radius overflowed: OverflowError); a centre 1e300 away
    asks nothing, without overflow warnings."""
    box = manifold3d.Manifold.cube([1.0, 1.0, 1.0])

    def tets(*regions):
        return mesh(box, size=0.2, regions=list(regions), thin_features=False).report.n_tets

    near = tets(paroct.Sphere((0, 0, 0), 10.0, 0.1))
    assert tets(paroct.Sphere((0, 0, 0), 1e200, 0.1)) == near
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        far = tets(paroct.Sphere((1e300, 0, 0), 1.0, 0.1))
    assert far == tets() < near


def test_numpy_numbers_and_unbounded_memory_are_accepted():
    box = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    ref = mesh(box, size=0.25)
    for options in (dict(size=np.float32(0.25)), dict(divisions=np.int64(4) * np.sqrt(3)), dict(size=0.25, max_memory=np.inf)):
        assert mesh(box, **options).mesh.tets.shape == ref.mesh.tets.shape


def test_a_region_asking_below_size_is_noted():
    box = manifold3d.Manifold.cube([1.0, 1.0, 1.0])
    report = mesh(box, size=0.2, regions=[paroct.Sphere((0.5, 0.5, 0.5), 0.2, 0.05)]).report
    assert any("refinement sphere asks for size 0.05, below size = 0.2" in note for note in report.notes)


def test_prism_table_tets_are_valid_for_a_convex_prism():
    # Each non-cyclic diagonal choice splits a straight prism into three positive tets of total volume.
    bottom = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    prism = np.vstack([bottom, bottom + [0.1, 0.2, 1.0]])
    for choice in range(8):
        table = PRISM_TETS[choice]
        if choice in (0, 7):
            assert (table < 0).all()
            continue
        vols = [np.linalg.det(prism[t[1:]] - prism[t[0]]) / 6 for t in table]
        assert np.isclose(sum(abs(v) for v in vols), 0.5) and min(abs(v) for v in vols) > 0


def test_prism_table_is_the_brute_force_search():
    # The table is written out; its slow twin searches the triples of tets for each diagonal choice.
    assert np.array_equal(PRISM_TETS, naive.prism_triangulations())
    assert PRISM_TETS.dtype == np.int64 and PRISM_TETS.flags.c_contiguous


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply", ".stl", "ascii.stl"])
def test_surface_formats_load_the_same_solid(tmp_path, ext):
    import meshio

    ref = load_surface(DATA / "angle_block.stl")
    path = tmp_path / f"part{ext}"
    options = {"binary": ext == ".stl"} if ext.endswith(".stl") else {}
    meshio.write(path, meshio.Mesh(ref.vertices, [("triangle", ref.faces)]), **options)
    surface = load_surface(path)
    assert surface.volume == pytest.approx(ref.volume, rel=1e-6)
    assert surface.genus == ref.genus and surface.faces.shape == ref.faces.shape


def test_binary_stl_reader_matches_meshio():
    import meshio

    from paroct.surface import read_surface_file, surface_from_arrays

    path = DATA / "bunny.stl"
    corners, soup = read_surface_file(path)[:2]
    assert soup.shape[0] * 3 == corners.shape[0]  # the fast path: a soup, welded later
    raw = meshio.read(path)
    ours, theirs = surface_from_arrays(corners, soup), surface_from_arrays(raw.points, raw.cells[0].data)
    assert np.array_equal(ours.vertices, theirs.vertices) and np.array_equal(ours.faces, theirs.faces)


_BOX_CORNERS = "0 0 0\n1 0 0\n1 2 0\n0 2 0\n0 0 3\n1 0 3\n1 2 3\n0 2 3\n"
_PENTAGON = [(0, 0), (2, 0), (3, 1.5), (1, 3), (-1, 1.5)]  # counter-clockwise, area 7.5


@pytest.mark.parametrize("text", [
    "OFF\n8 6 12\n" + _BOX_CORNERS + "4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n",
    # counts on the header line, comments, tabs and runs of spaces, colours after faces
    "OFF 8 6 0 # a box\n# corners\n" + _BOX_CORNERS.replace(" ", "\t") + "\n4  0 3 2 1  255 0 0\n"
    "4 4 5 6 7 0 255 0\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7  # last\n",
    # COFF: a colour on every vertex line; a prism of two pentagons (area 7.5) and five quads
    "COFF\n10 7 0\n" + "".join(f"{x} {y} {z} 1 1 1 1\n" for z in (0, 1) for x, y in _PENTAGON)
    + "5 4 3 2 1 0\n5 5 6 7 8 9\n" + "".join(f"4 {i} {(i + 1) % 5} {(i + 1) % 5 + 5} {i + 5}\n" for i in range(5)),
])
def test_off_files_beyond_meshios_reader(tmp_path, text):
    """OFF as it is found: quads and polygons (meshio reads triangles only), counts on the
    header line, comments, tabs, colours: the 1 x 2 x 3 box, or a pentagonal prism."""
    path = tmp_path / "part.off"
    path.write_text(text)
    surface = load_surface(path)
    volume = 7.5 if text.startswith("COFF") else 6.0
    assert surface.volume == pytest.approx(volume, rel=1e-12) and (surface.components, surface.genus) == (1, 0)


def test_off_fast_path_reads_what_the_line_parser_reads(tmp_path):
    import meshio

    from paroct.readers import _off_triangles, read_surface_file

    ref = load_surface(DATA / "angle_block.stl")
    path = tmp_path / "part.off"
    meshio.write(path, meshio.Mesh(ref.vertices, [("triangle", ref.faces)]))  # a comment after OFF
    fast = _off_triangles(path.read_text())
    assert fast is not None
    slow_path = tmp_path / "slow.off"  # a comment after the counts: the line parser reads it
    slow_path.write_text(path.read_text() + "# the end\n")
    assert _off_triangles(slow_path.read_text()) is None
    slow = read_surface_file(slow_path)
    assert np.array_equal(fast[0], slow[0]) and np.array_equal(fast[1], slow[1])
    assert np.array_equal(fast[1], ref.faces)


@pytest.mark.parametrize("text,match", [
    ("OFF\n8 6 0\n" + _BOX_CORNERS + "4 0 3 2 1\n", "the header says 8 vertices and 6 faces, the file holds 8 and 1"),
    ("OFF\neight six\n", "expected the counts 'vertices faces \\[edges\\]', got 'eight six'"),
    ("PLY\n", "the first line must be OFF"),
    ("OFF\n8 1 0\n" + _BOX_CORNERS + "4 0 1 2\n", "a face line reads '4 0 1 2'"),
])
def test_malformed_off_files_are_refused_saying_why(tmp_path, text, match):
    path = tmp_path / "bad.off"
    path.write_text(text)
    with pytest.raises(ParoctError, match=match):
        load_surface(path)


def test_quads_are_split_into_triangles(tmp_path):
    import meshio

    box = manifold3d.Manifold.cube([1.0, 2.0, 3.0])
    # A unit-cell cube as 6 quads in an OBJ file.
    v = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float) * [1, 2, 3]
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
    meshio.write(tmp_path / "box.obj", meshio.Mesh(v, [("quad", quads)]))
    surface = load_surface(tmp_path / "box.obj")
    assert surface.volume == pytest.approx(box.volume()) and surface.faces.shape == (12, 3)


@pytest.mark.parametrize("seed", range(3))
def test_summary_reduces_tet_quality_exactly(seed):
    from paroct.quality import summarize

    rng = np.random.default_rng(seed)
    points = rng.normal(size=(60, 3))
    tets = np.array([rng.choice(60, 4, replace=False) for _ in range(500)], dtype=np.int32)
    core = rng.random(60) < 0.7
    q = tet_quality(points, tets)
    fat_ratio = float(q.radius_ratio[7])
    s = summarize(points, tets, core, fat_ratio)
    assert s.min_dihedral == q.min_dihedral.min() and s.max_dihedral == q.max_dihedral.max()
    assert s.min_radius_ratio == q.radius_ratio.min()
    assert s.volume == pytest.approx(q.volume.sum(), rel=1e-12, abs=1e-12)
    interior = core[tets].all(axis=1)
    assert s.interior_min_dihedral == q.min_dihedral[interior].min()
    assert s.interior_max_dihedral == q.max_dihedral[interior].max()
    assert s.n_fat == int((np.abs(q.radius_ratio - fat_ratio) < 1e-9).sum())


@pytest.mark.parametrize("seed", range(3))
def test_outlier_flags_are_tet_qualitys_verdicts(seed):
    """The cosine shortcut decides as the angles in degrees do: random tets (some inverted),
    flat ones, and bounds set exactly at measured angles; tets of four skipped vertices get 0,
    the others their verdicts."""
    from paroct.quality import NEEDLE, OUTSIDE, outlier_flags

    rng = np.random.default_rng(seed)
    points = np.concatenate([rng.normal(size=(60, 3)), [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]])
    tets = np.array([rng.choice(60, 4, replace=False) for _ in range(2000)] + [[60, 61, 62, 63]], dtype=np.int32)
    flip = tet_quality(points, tets).volume < 0
    flip[:20] = False  # some stay inverted
    tets[flip] = tets[flip][:, [1, 0, 2, 3]]
    q = tet_quality(points, tets)
    assert (q.volume[20:-1] > 0).all() and (q.volume[:20] < 0).any()
    skip = rng.random(len(points)) < 0.7
    skip[60:] = False
    skipped = skip[tets].all(axis=1)
    assert 0 < skipped.sum() < len(tets) / 2
    seen = np.zeros(4, dtype=int)
    for lo, hi, ratio in [(10.7, 164.8, 0.05), (float(q.min_dihedral[30]), float(q.max_dihedral[50]), 0.2),
                          (1.0, 179.0, float(q.radius_ratio[90]))]:
        bad = (q.min_dihedral < lo) | (q.max_dihedral > hi)
        want = np.where(bad, OUTSIDE, np.where(q.radius_ratio < ratio, NEEDLE, 0))
        np.testing.assert_array_equal(outlier_flags(points, tets, np.zeros(len(points), dtype=bool), lo, hi, ratio), want)
        got = outlier_flags(points, tets, skip, lo, hi, ratio)
        np.testing.assert_array_equal(got, np.where(skipped, 0, want))
        assert got[-1] == OUTSIDE  # the flat tet
        seen += [(want == OUTSIDE).sum(), (want == 0).sum(), (want == NEEDLE).sum(), (want[skipped] > 0).sum()]
    assert seen.all()  # every verdict was given


@pytest.mark.parametrize("seed", range(4))
def test_match_faces_matches_a_dictionary(seed):
    rng = np.random.default_rng(seed)
    # A lattice block (every interior face twice), shuffled, with a few tets repeated (overloaded
    # faces) or flipped (same-side faces), and sparse vertex ids.
    coords, tets = leaf_tets(np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3),
                             np.ones(27, dtype=np.int64))
    tets = tets[rng.permutation(len(tets))].astype(np.int64)
    extra = tets[rng.choice(len(tets), 5)]
    flipped = tets[rng.choice(len(tets), 5)][:, [1, 0, 2, 3]]
    tets = np.vstack([tets, extra, flipped]) * int(rng.integers(1, 7))
    got = match_faces(tets)
    want = naive.match_faces(tets)
    assert got[1] == want[1] and got[2] == want[2]
    assert np.array_equal(got[0], want[0])


@pytest.mark.parametrize("name", ["angle_block", "bunny", "shell"])
def test_solid_tets_bounds_the_tets_made_and_is_near_them(name):
    from paroct.mesher import solid_tets

    if name == "shell":  # walls two sizes thick: the band estimate counts both sides of each
        shell = manifold3d.Manifold.cube([1.0, 1.0, 1.0], True) - manifold3d.Manifold.cube([0.9, 0.9, 0.9], True)
        surface, h = load_surface(shell.rotate([23.0, 41.0, 67.0])), 0.025
    else:
        surface = load_surface(DATA / f"{name}.stl")
        h = surface.diagonal / 30
    made = mesh(surface, size=h, max_size=h, thin_features=False).report.n_tets
    assert made <= solid_tets(surface, h) <= 2.5 * made


def test_refinement_stops_where_memory_ends_and_says_so():
    # At size 0.1 the fin part fits in 10 MB; a boundary half as fine would not.
    result = mesh(_FIN_PART, size=0.1, max_memory=10 * 2**20)
    rep = result.report
    assert rep.size == pytest.approx(0.1)
    assert len(rep.notes) == 1 and "only near thin places: it would not fit in memory" in rep.notes[0]
    assert len(rep.warnings) == 1 and "would not fit in memory" in rep.warnings[0] and "thinnest wall" in rep.warnings[0]


@pytest.mark.parametrize("name,max_factor", [("bunny", 8), ("xyz_cube", 1), ("angle_block", 4)])
def test_vertex_classes_from_leaves_equal_winding_numbers(name, max_factor):
    from paroct.lattice import number_vertices
    from paroct.mesher import MeshReport, graded_leaves, vertex_classes
    from paroct.sizing import size_field

    surface = load_surface(DATA / f"{name}.stl")
    h = surface.diagonal / 50
    field = size_field(h, max_factor * h)
    frame = fat_frame(surface.bbox_min, surface.bbox_max, h)
    snapped = rays.snap_surface(frame, surface.vertices)
    faces = surface.faces.astype(np.int64)
    crossings = {X_AXIS_DIRECTION: rays.row_crossings(frame, snapped, faces, X_AXIS_DIRECTION)}
    report = MeshReport(size=h, requested_size=h, levels=0, max_size=field.max_size, solid_volume=surface.volume,
                        input_genus=surface.genus, input_components=surface.components)
    keys, levels, band = graded_leaves(frame, snapped, faces, crossings, surface, field, report)
    vertices = number_vertices(octant_lattice_anchors(keys, frame), np.int64(1) << (frame.levels - levels.astype(np.int64)),
                               prefix=band.coords)
    inside = vertex_classes(vertices, band.inside)
    assert inside.any() and not inside.all()
    assert np.array_equal(inside, rays.winding_numbers(crossings[X_AXIS_DIRECTION], vertices.coords) > 0)


@pytest.mark.parametrize("n_edges", [0, 1, 1000])
def test_cut_points_are_the_frames_space_points_along_the_edges_rounded_alike(n_edges):
    """_cut_points against numpy's lattice points along the edges, mapped by FatFrame.to_space:
    bit for bit (fractions 0 and 1 included)."""
    rng = np.random.default_rng(n_edges)
    frame = fat_frame(np.array([-1.5, 0.25, 3.0]), np.array([2.0, 1.75, 4.5]), 0.037)
    coords = rng.integers(0, 1 << frame.levels, (50, 3))
    starts, ends = rng.integers(0, 50, n_edges), rng.integers(0, 50, n_edges)
    fracs = np.where(rng.random(n_edges) < 0.1, rng.integers(0, 2, n_edges).astype(float), rng.random(n_edges))
    want = frame.to_space(coords[starts] + fracs[:, None] * (coords[ends] - coords[starts]))
    got = _cut_points(coords, starts, ends, fracs, frame.origin, float(frame.h), LATTICE_TO_SPACE)
    assert got.shape == (n_edges, 3) and np.array_equal(got, want)


@pytest.mark.parametrize("n_edges", [0, 1, 1000])
def test_direction_counts_are_numpys_bincount(n_edges):
    dirs = np.random.default_rng(n_edges).integers(-1, EDGE_DIRECTIONS.shape[0], n_edges)
    want = np.bincount(dirs + 1, minlength=EDGE_DIRECTIONS.shape[0] + 1)[1:]
    assert np.array_equal(_direction_counts(dirs, EDGE_DIRECTIONS.shape[0]), want)


@pytest.mark.parametrize("n_points, n_tets", [(0, 0), (5, 0), (1, 1), (70, 3), (1000, 40), (5000, 3000)])
def test_compact_keeps_the_used_points_in_order(n_points, n_tets):
    """_used_ids numbers the points the tets use in point order, and
    _compact drops the others, renumbering the tets in place: the same points and tets as
    numpy's unique and searchsorted."""
    rng = np.random.default_rng(n_points + n_tets)
    tets = rng.integers(0, max(n_points, 1), (n_tets, 4)).astype(np.int32)
    points = rng.random((n_points, 3))
    used = np.unique(tets)
    want = np.full(n_points, -1)
    want[used] = np.arange(used.size)
    np.testing.assert_array_equal(_used_ids(tets, n_points), want)
    want_tets = np.searchsorted(used, tets)
    got_points, got_tets, new_id = _compact(points, tets)
    np.testing.assert_array_equal(new_id, want)
    np.testing.assert_array_equal(got_points, points[used])
    np.testing.assert_array_equal(got_tets, want_tets)
    assert got_tets is tets  # renumbered in place


def _bent_bar_overlapping_itself():
    """One closed shell without an edge or vertex out of place whose ends pass through each
    other: a 7 x 1 x 1 bar bent round a circle of circumference 6 (and risen along it)."""
    radius = 6.0 / (2 * np.pi)

    def bend(p):
        angle = p[0] / radius
        return [(radius + p[1]) * np.cos(angle), (radius + p[1]) * np.sin(angle), p[2] + 0.15 * angle]

    ring = manifold3d.Manifold.cube([7.0, 1.0, 1.0]).refine(40).warp(bend).to_mesh()
    return np.asarray(ring.vert_properties, dtype=np.float64)[:, :3], np.asarray(ring.tri_verts)[:, ::-1].copy()


def test_a_surface_overlapping_itself_is_refused_where_it_does():
    """Its faces pass every check of a closed manifold, and its signed volume is positive, but
    its ends overlap: no mesh of it could match its volume and topology.  The point named lies
    on the surface where the lines enter the solid a second time, in the overlap."""
    vertices, faces = _bent_bar_overlapping_itself()
    surface = load_surface((vertices, faces))
    assert surface.volume > 0 and surface.components == 1
    with pytest.raises(ParoctError, match=r"the surface intersects itself: a line through \(([-\d.e+]+), ([-\d.e+]+), "
                                          r"([-\d.e+]+)\) enters or leaves the solid twice in a row") as error:
        mesh(surface, divisions=20)
    point = np.array([float(x) for x in error.value.args[0].split("(")[1].split(")")[0].split(",")])
    assert distances_to_triangles(point[None], vertices, faces)[0] < 1e-5 * surface.diagonal
    angle = np.arctan2(point[1], point[0]) % (2 * np.pi)
    assert angle < 2 * np.pi * 1.0 / 7 + 0.3 or angle > 2 * np.pi - 0.3  # where the ends meet, near angle 0


def test_info_refuses_a_surface_overlapping_itself_as_mesh_does(tmp_path, capsys):
    """paroct info described the bent bar and exited 0 (session 42's fuzzing), promising a
    mesh that paroct mesh refuses: it now fails the same way, in one line."""
    import meshio

    from paroct.cli import main

    vertices, faces = _bent_bar_overlapping_itself()
    path = tmp_path / "bar.obj"
    meshio.write(path, meshio.Mesh(vertices, [("triangle", faces)]))
    assert main(["info", str(path), "--divisions", "20"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the surface intersects itself" in err


def test_the_mesh_does_not_depend_on_the_thread_count():
    """Test suites need the same mesh on every machine: the parallel kernels split their work
    into chunks of a fixed count and write disjoint outputs, so one thread gives the same
    points, tets, boundary and tags as every thread, through the thin-feature rounds (the fin
    refines locally and mends warps), the sharp edges and the patches."""
    import numba

    def everything():
        result = mesh(_FIN_PART.rotate([17, 29, 41]), size=0.1)
        sharp = result.with_sharp_edges()
        return (result.mesh.points, result.mesh.tets, result.boundary_faces, result.point_faces,
                sharp.mesh.points, result.boundary_patches().patches, result.report.notes)

    threads = numba.get_num_threads()
    if threads < 2:
        pytest.skip("numba has one thread here: nothing to compare")
    every = everything()
    try:
        numba.set_num_threads(1)
        one = everything()
    finally:
        numba.set_num_threads(threads)
    assert "near the" in " ".join(every[-1])  # the rounds near thin places ran
    for a, b in zip(every, one):
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b


def test_an_infinite_size_asks_nothing_there():
    """size_function may say "no bound" with inf: no refinement there and no numpy warning
    (log2 of 0 once leaked one), the finite part refined as asked."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = mesh(manifold3d.Manifold.cube([1.0, 1.0, 1.0]), size=0.25,
                      size_function=lambda x: np.where(x[:, 0] < 0.5, np.inf, 0.1))
    edges = np.linalg.norm(result.mesh.points[result.boundary_faces] - result.mesh.points[np.roll(result.boundary_faces, 1, axis=1)], axis=2)
    centres = result.mesh.points[result.boundary_faces].mean(axis=1)
    assert edges.max(axis=1)[centres[:, 0] > 0.75].max() < 0.25 * 0.75  # refined where the function bounds
    assert edges.max(axis=1)[centres[:, 0] < 0.25].max() > 0.25 * 0.75  # size where it is inf
