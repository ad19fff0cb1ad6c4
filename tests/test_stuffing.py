"""Isosurface stuffing on its own: lattices and graded octrees cut by planes.

A plane cuts every tet exactly where linear interpolation says, so the stuffed volume must
equal the clipped volume exactly, whatever the tets are: fat lattice tets, coarse ones or
transition templates.  On the uniform lattice the warps and stencils must also keep
Labelle & Shewchuk's dihedral bound.
"""

from __future__ import annotations

import numpy as np
import pytest

from paroct import lattice, stuffing
from paroct.frame import LATTICE_TO_SPACE
from paroct.octant import morton_keys
from paroct.quality import tet_quality
from paroct.stuffing import (DIHEDRAL_BOUND, PRISM_TETS, TET_CHUNKS, CutEdges, _chain_cut_edges, _chunk_starts,
                              _group_by_vertex, _move_kept, _place_again, _retarget, _row_shifts, _shift_offsets,
                              _signs, _star_options, _star_score, _stencil_offsets, _stencils, _stencils_in_chunks,
                              _warped, collect_cut_edges, restuff, retarget_warps, stuff, warp_targets)
from paroct.topology import int32_ids, match_faces, touching

from .naive import cut_edges as naive_cut_edges
from .naive import group_by_vertex as naive_group_by_vertex
from .naive import retarget as naive_retarget
from .naive import star_violation
from .naive import warp_targets as naive_warp_targets
from .test_grading import _random_balanced_tree

#: Labelle & Shewchuk's bound for the BCC lattice, degrees.
LS_MIN, LS_MAX = 10.7, 164.8


def _clipped_volume(points, tets, phi):
    """Volume of {phi > 0} in each tet for a linear phi (values at the vertices, distinct in a
    tet): V * sum over positive i of phi_i^3 / prod_{j != i} (phi_i - phi_j) (the divided
    difference of the truncated cube)."""
    vol = np.abs(tet_quality(points, tets).volume)
    f = phi[tets]
    frac = np.zeros(tets.shape[0])
    for i in range(4):
        den = np.ones(tets.shape[0])
        for j in range(4):
            if j != i:
                den *= f[:, i] - f[:, j]
        frac += np.where(f[:, i] > 0, f[:, i] ** 3 / den, 0.0)
    return float((vol * frac).sum())


def _cuts_and_warps(coords, tets, phi, fracs_of, warp, spacing=None):
    """What stuffing the tets (lattice coords (V, 3), tets (M, 4)) against the level set
    phi (V,) > 0 takes: (lattice points in space, inside, cut edges, warp targets), the cut of
    edge (start, end) at fracs_of(x, starts, ends); warps by warp_targets (spacing: each
    vertex's finest leaf side, default 1), never for vertices on the hull of coords."""
    x = coords @ LATTICE_TO_SPACE.T
    inside = phi > 0
    starts, ends, _, *table = collect_cut_edges(tets, inside, coords)
    fracs = fracs_of(x, starts, ends)
    cut_points = x[starts] + fracs[:, None] * (x[ends] - x[starts])
    cuts = CutEdges(starts, ends, np.full(starts.shape[0], -1), fracs, cut_points, tuple(table))
    targets = np.full(coords.shape[0], -1, dtype=np.int64)
    if warp:
        targets = warp_targets(cuts, coords, 1.0, spacing)
        targets[_on_box(coords)] = -1
    return x, inside, cuts, targets


def _on_box(coords):
    """Mask (V,) of the lattice points on the faces of their bounding box."""
    return ((coords == coords.min(axis=0)) | (coords == coords.max(axis=0))).any(axis=1)


def _stuff(coords, tets, phi, fracs_of, warp, spacing=None, first_centre=None):
    """Stuff as _cuts_and_warps sets up; returns (lattice points in space, output points, output
    tets).  first_centre: LeafVertices.first_centre of a graded octree's vertices."""
    x, inside, cuts, targets = _cuts_and_warps(coords, tets, phi, fracs_of, warp, spacing)
    points, out, _ = stuff(x, coords, tets, inside, cuts, targets, first_centre=first_centre)
    return x, points, out


def _plane(coords, normal, offset):
    """phi and exact cut fractions of the plane normal . x = offset."""
    phi = coords @ LATTICE_TO_SPACE.T @ normal - offset
    return phi, lambda x, s, e: phi[s] / (phi[s] - phi[e])


def _sphere(coords, centre, radius):
    """phi = radius - |x - centre| and the exact cut fractions (the root of a quadratic)."""
    x = coords @ LATTICE_TO_SPACE.T
    phi = radius - np.linalg.norm(x - centre, axis=1)

    def fracs(x, s, e):
        d = x[e] - x[s]
        m = x[s] - centre
        a, b, c = (d * d).sum(axis=1), 2 * (m * d).sum(axis=1), (m * m).sum(axis=1) - radius**2
        root = np.sqrt(b * b - 4 * a * c)
        t1, t2 = (-b - root) / (2 * a), (-b + root) / (2 * a)
        return np.where((t1 >= 0) & (t1 <= 1), t1, t2)

    return phi, fracs


def _boundary_triangles(points, out):
    """Space triangles (K, 3, 3) of the faces of out that only one tet has."""
    neighbour, overloaded, same_side = match_faces(out)
    assert overloaded == 0 and same_side == 0
    t, f = np.nonzero(neighbour < 0)
    opposite = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    return points[out[t[:, None], opposite[f]]]


def _on_hull(tri_points, coords):
    """Triangles (K, 3, 3) in space lying on a face of the box of the lattice coords (V, 3)."""
    u = tri_points @ np.linalg.inv(LATTICE_TO_SPACE).T
    out = np.zeros(tri_points.shape[0], dtype=bool)
    for i in range(3):
        for bound in (coords[:, i].min(), coords[:, i].max()):
            out |= (np.abs(u[:, :, i] - bound) < 1e-9).all(axis=1)
    return out


def _check_plane_cut(coords, tets, normal, offset, warp, spacing=None, first_centre=None):
    """Stuff against a plane and check: positive tets, every interior face shared by two tets
    on opposite sides, boundary faces on the plane or the box, volume the clipped volume."""
    phi, fracs = _plane(coords, normal, offset)
    x, points, out = _stuff(coords, tets, phi, fracs, warp, spacing, first_centre)
    q = tet_quality(points, out)
    assert np.all(q.volume > 0)
    tri = _boundary_triangles(points, out)
    on_plane = (np.abs(tri @ normal - offset) < 1e-9).all(axis=1)
    assert np.all(on_plane | _on_hull(tri, coords))
    assert q.volume.sum() == pytest.approx(_clipped_volume(x, tets, phi), rel=1e-9)


def _random_plane(rng, coords):
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    x = coords @ LATTICE_TO_SPACE.T
    return normal, float(rng.uniform(*np.quantile(x @ normal, [0.2, 0.8])))


@pytest.mark.parametrize("seed", range(3))
def test_uniform_lattice_keeps_the_labelle_shewchuk_bound(seed):
    """Spheres inside a uniform lattice block: the warps and stencils keep every dihedral
    angle in [10.7, 164.8] degrees (Labelle & Shewchuk, Theorem 1) and the boundary closed
    and on the sphere."""
    rng = np.random.default_rng(seed)
    n = 10
    anchors = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = lattice.leaf_tets(anchors, np.ones(anchors.shape[0], dtype=np.int64))
    x = coords @ LATTICE_TO_SPACE.T
    middle = x.mean(axis=0)
    for _ in range(40):
        centre = middle + rng.uniform(-0.5, 0.5, size=3)
        radius = rng.uniform(1.0, 2.5)
        phi, fracs = _sphere(coords, centre, radius)
        _, points, out = _stuff(coords, tets, phi, fracs, warp=True)
        q = tet_quality(points, out)
        assert np.all(q.volume > 0)
        assert LS_MIN <= q.min_dihedral.min() and q.max_dihedral.max() <= LS_MAX
        tri = _boundary_triangles(points, out)
        assert np.allclose(np.linalg.norm(tri - centre, axis=2), radius)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("warp", [False, True])
def test_graded_octrees_stuff_conforming_with_the_clipped_volume(seed, warp):
    """Coarse fat tets and transition templates are cut too: faces off the finest lattice take
    the rule of the lattice they lie in, or the template rule (corners, then face centres that
    are no leaf's corner, each by coordinates: stuffing._vertex_before).  With
    warps (warp_targets' rule for template edges and vertices shared with finer leaves; no
    angle bound is proven there, docs/thin_study measures it) every tet stays positive."""
    rng = np.random.default_rng(1000 + seed)
    anchors, sides = _random_balanced_tree(seed, 3 + seed % 2)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    spacing = lattice.vertex_spacing(vertices, sides)
    for _ in range(20):
        normal, offset = _random_plane(rng, coords)
        _check_plane_cut(coords, tets, normal, offset, warp, spacing, vertices.first_centre)


@pytest.mark.parametrize("seed", range(4))
def test_warp_targets_match_the_naive_rule_on_graded_octrees(seed):
    """Lattice edges of several spacings and template edges, cut at random fractions (a tenth
    exactly at an end, and many ties between equal distances), with each vertex's finest
    leaf side as its spacing."""
    rng = np.random.default_rng(seed)
    anchors, sides = _random_balanced_tree(seed, 3 + seed % 2)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    spacing = lattice.vertex_spacing(vertices, sides)
    inside = rng.random(coords.shape[0]) < 0.5
    starts, ends, dirs, *table = collect_cut_edges(tets, inside, coords)
    fracs = rng.choice([0.0, 0.1, 0.2, 0.25, 0.4, 0.5, 0.75, 1.0], starts.shape[0])
    fracs[::3] = rng.random(fracs[::3].shape[0])
    cuts = CutEdges(starts, ends, dirs, fracs, np.zeros((starts.shape[0], 3)), tuple(table))
    h = 0.7
    targets = warp_targets(cuts, coords, h, spacing)
    assert np.array_equal(targets, naive_warp_targets(coords, starts, ends, fracs, spacing, h))
    assert (targets >= 0).sum() > coords.shape[0] // 10 and (dirs < 0).any()


def test_vertex_spacing_is_the_finest_leaf_side_at_each_vertex():
    for seed in range(4):
        anchors, sides = _random_balanced_tree(seed, 4)
        vertices = lattice.number_vertices(anchors, sides)
        spacing = lattice.vertex_spacing(vertices, sides)
        holds = [(np.all(anchors <= c, axis=1) & np.all(c <= anchors + sides[:, None], axis=1)) for c in vertices.coords]
        assert np.array_equal(spacing, [sides[h].min() for h in holds])


@pytest.mark.parametrize("seed", range(6))
def test_quad_rules_never_cycle_on_lattice_and_template_tets(seed):
    """Every tet of a random balanced octree with every one of its vertices outside (a +++-
    prism, whose three quads all lie on faces of the tet): the face rules never cycle, so
    three tets always fill the prism.  Each case gets its own copy of the tet's vertices,
    the face centres that are no leaf's corner last, as number_vertices numbers them (the
    rule off the lattices puts those last).  (3000 such trees of 3-6 levels: none cycled.)"""
    anchors, sides = _random_balanced_tree(seed, 3 + seed % 3)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    n = tets.shape[0]
    rank = np.empty(4 * n, dtype=np.int64)
    rank[np.argsort(tets.ravel(), kind="stable")] = np.arange(4 * n)
    copies = rank.reshape(n, 4)
    copy_coords = np.empty((4 * n, 3), dtype=np.int64)
    copy_coords[copies] = coords[tets]
    first_centre = int(np.count_nonzero(tets < vertices.first_centre))
    assert first_centre < 4 * n  # templates with face centres are among the tets
    for outside in range(4):
        phi = np.ones(4 * n)
        phi[copies[:, outside]] = -1.0
        x, points, out = _stuff(copy_coords, copies, phi, lambda x, s, e: np.full(s.shape[0], 0.5), warp=False,
                                first_centre=first_centre)
        assert out.shape[0] == 3 * n


@pytest.mark.parametrize("seed", range(4))
def test_stuffed_graded_octrees_do_not_depend_on_how_the_corners_are_numbered(seed):
    """A graded octree cut by spheres, stuffed with its vertices as number_vertices numbers
    them and with the leaf corners numbered at random (the face centres that are no leaf's
    corner still last, first_centre the same): the same tets, point for point.  The cut
    edges, warps and the quad rule on lattice and template faces follow the coordinates."""
    rng = np.random.default_rng(seed)
    anchors, sides = _random_balanced_tree(seed, 4 + seed % 2)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    spacing = lattice.vertex_spacing(vertices, sides)
    first_centre = vertices.first_centre
    new_id = np.concatenate([rng.permutation(first_centre), np.arange(first_centre, coords.shape[0])])
    x = coords @ LATTICE_TO_SPACE.T
    lo, hi = x.min(axis=0), x.max(axis=0)
    templates = 0
    for _ in range(5):
        centre = rng.uniform(lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo))
        phi, fracs = _sphere(coords, centre, rng.uniform(1.0, 0.4 * (hi - lo).min()))
        meshes = []
        for ids in (np.arange(coords.shape[0]), new_id):
            order = np.argsort(ids)  # the old vertex of each new id
            _, points, out = _stuff(coords[order], ids[tets], phi[order], fracs, True, spacing[order], first_centre)
            meshes.append(_canonical_tets(points, out))
        assert meshes[0].shape == meshes[1].shape and np.array_equal(meshes[0], meshes[1])
        signs = phi[tets] > 0
        cut = signs.any(axis=1) & ~signs.all(axis=1)
        templates += int(np.count_nonzero(cut & np.any(tets >= first_centre, axis=1)))
    assert templates > 0  # cut tets with a face centre: the quad rule on template faces was asked


def _canonical_tets(points, out):
    """The tets' corner positions (M, 12), each tet's corners in lexicographic order and the
    tets sorted: equal for the same tets however the points are numbered."""
    p = np.ascontiguousarray(np.round(points[out], 9))
    corners = np.sort(p.view([("x", "f8"), ("y", "f8"), ("z", "f8")]).reshape(p.shape[0], 4), axis=1)
    flat = corners.view("f8").reshape(p.shape[0], 12)
    return flat[np.lexsort(flat.T[::-1])]


def test_stuff_orients_by_the_volume_before_the_warps():
    """A vertex warped onto a far cut point folds tets of its star: stuff orients each tet as
    its piece of the lattice tet lies before the warps, so the folded ones come out negative
    (and are refused unless flat_ok), never turned over to overlap their neighbours."""
    n = 6
    anchors = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = lattice.leaf_tets(anchors, np.ones(anchors.shape[0], dtype=np.int64))
    phi, fracs = _plane(coords, np.array([0.0, 0.0, 1.0]), float((coords @ LATTICE_TO_SPACE.T)[:, 2].mean()) + 0.1)
    x, inside, cuts, targets = _cuts_and_warps(coords, tets, phi, fracs, warp=True)
    assert np.all(tet_quality(*stuff(x, coords, tets, inside, cuts, targets)[:2]).volume > 0)
    v = int(np.argmin(np.linalg.norm(x - x.mean(axis=0), axis=1)))  # a vertex in the middle...
    targets[v] = int(np.argmax(np.linalg.norm(cuts.points - x[v], axis=1)))  # ...onto the farthest cut point
    with pytest.raises(AssertionError, match="folded"):
        stuff(x, coords, tets, inside, cuts, targets)
    points, out, _ = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True)
    folded = tet_quality(points, out).volume <= 0
    assert folded.any() and np.all(np.any(out[folded] == v, axis=1))


def test_stuff_gives_the_same_for_int32_and_int64_tets():
    """stuff and collect_cut_edges take any integer tets (topology.int32_ids: one int32
    specialization of their kernels); ids beyond int32 are refused, not wrapped."""
    n = 5
    anchors = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    coords, tets = lattice.leaf_tets(anchors, np.ones(anchors.shape[0], dtype=np.int64))
    phi, fracs = _plane(coords, np.array([0.0, 0.0, 1.0]), float((coords @ LATTICE_TO_SPACE.T)[:, 2].mean()) + 0.1)
    got = [_stuff(coords, tets.astype(dtype), phi, fracs, warp=True) for dtype in (np.int32, np.int64)]
    assert np.array_equal(got[0][1], got[1][1]) and np.array_equal(got[0][2], got[1][2]) and got[0][2].shape[0] > 0
    same = np.ascontiguousarray(tets, dtype=np.int32)
    assert int32_ids(same) is same
    assert int32_ids(np.array([[0, 1, 2, 2**31 - 1]])).dtype == np.int32
    with pytest.raises(ValueError, match="do not fit in int32"):
        int32_ids(np.array([[0, 1, 2, 2**31]]))


@pytest.mark.parametrize("seed", range(4))
def test_star_score_is_the_worst_violation_of_the_stuffed_star(seed):
    """_star_score (the measure retarget_warps minimises) against stuffing the star alone and
    measuring every tet (tests/naive.py), for random vertices of graded octrees cut by planes
    and each warp they may take (none, or onto the cut point of one of their edges whose other
    end is not warped there too: that would collapse the edge)."""
    rng = np.random.default_rng(2000 + seed)
    anchors, sides = _random_balanced_tree(seed, 4)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, np.ascontiguousarray(lattice.graded_tets(vertices))
    spacing = lattice.vertex_spacing(vertices, sides)
    checked = 0
    for _ in range(4):
        normal, offset = _random_plane(rng, coords)
        x, inside, cuts, targets = _cuts_and_warps(coords, tets, *_plane(coords, normal, offset), True, spacing)
        for v in rng.choice(np.unique(np.concatenate([cuts.starts, cuts.ends])), 8):
            star = np.nonzero(np.any(tets == v, axis=1))[0]
            own = np.nonzero((cuts.starts == v) | (cuts.ends == v))[0]
            other = np.where(cuts.starts[own] == v, cuts.ends[own], cuts.starts[own])
            for e in np.append(own[targets[other] != own], -1):
                trial = targets.copy()
                trial[v] = e
                points, signs = _warped(x, inside, cuts, trial)
                worst, _ = _star_score(star, tets, signs, points, x, coords, vertices.first_centre, cuts.table, PRISM_TETS,
                                          *DIHEDRAL_BOUND)
                naive = star_violation(x, coords, tets, inside, cuts, trial, star, DIHEDRAL_BOUND, vertices.first_centre)
                assert worst == pytest.approx(naive, abs=1e-9)
                checked += 1
    assert checked >= 64


def _sphere_cuts(seed, k):
    """Sphere k of seed cutting a random balanced octree of 4 or 5 levels, warped by warp_targets."""
    rng = np.random.default_rng([seed, k])
    anchors, sides = _random_balanced_tree(seed, 4 + seed % 2)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    x = coords @ LATTICE_TO_SPACE.T
    lo, hi = x.min(axis=0), x.max(axis=0)
    centre = rng.uniform(lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo))
    radius = rng.uniform(1.0, 0.4 * (hi - lo).min())
    phi, fracs = _sphere(coords, centre, radius)
    return (coords, tets, (centre, radius), _cuts_and_warps(coords, tets, phi, fracs, True,
                                                            lattice.vertex_spacing(vertices, sides)),
            vertices.first_centre)


def _violations(points, out, coords):
    """Violation of DIHEDRAL_BOUND per output tet (180 if folded), 0 for tets with a vertex on
    the block's faces (their warps see only part of a lattice)."""
    q = tet_quality(points, out)
    worst = np.maximum(DIHEDRAL_BOUND[0] - q.min_dihedral, q.max_dihedral - DIHEDRAL_BOUND[1])
    worst = np.where(q.volume <= 0, 180.0, np.maximum(worst, 0.0))
    lattice_ids = np.where(out < coords.shape[0], out, 0)
    return np.where(np.any((out < coords.shape[0]) & _on_box(coords)[lattice_ids], axis=1), 0.0, worst)


def _radius_ratios(points, out, coords):
    """3r/R per output tet, 1 for tets with a vertex on the block's faces (as _violations)."""
    q = tet_quality(points, out)
    lattice_ids = np.where(out < coords.shape[0], out, 0)
    on_box = np.any((out < coords.shape[0]) & _on_box(coords)[lattice_ids], axis=1)
    return np.where(on_box, 1.0, np.where(q.volume > 0, q.radius_ratio, 0.0))


def test_warped_moves_the_warped_vertices_onto_their_cut_points_and_appends_the_cut_points():
    k = next(k for k in range(20) if (_sphere_cuts(0, k)[3][3] >= 0).any())
    coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(0, k)
    points, signs = _warped(x, inside, cuts, targets)
    want = np.concatenate([x, cuts.points])
    want[: x.shape[0]][targets >= 0] = cuts.points[targets[targets >= 0]]
    assert np.array_equal(points, want)
    assert np.array_equal(signs, np.where(targets >= 0, 0, np.where(inside, 1, -1)))


def _check_cut_edges(tets, inside, coords):
    """collect_cut_edges against the dict twin, and its table finds every edge's number: each
    edge is on the chain of its smaller end, and each chain holds only that end's edges."""
    starts, ends, dirs, head, upper, chain = collect_cut_edges(tets, inside, coords)
    want = naive_cut_edges(tets, inside, coords)
    assert np.array_equal(starts, want[0]) and np.array_equal(ends, want[1]) and np.array_equal(dirs, want[2])
    assert head.shape == (coords.shape[0],) and upper.shape == chain.shape == starts.shape
    on_chain = []
    for a in range(coords.shape[0]):
        s = head[a]
        while s >= 0:
            assert min(starts[s], ends[s]) == a and upper[s] == max(starts[s], ends[s])
            on_chain.append(s)
            s = chain[s]
    assert np.array_equal(np.sort(on_chain), np.arange(starts.size))
    return dirs


@pytest.mark.parametrize("n_vertices, n_tets", [(1, 0), (4, 1), (3, 5), (50, 63), (50, 64), (50, 65), (70, 1000),
                                                (2000, 3000)])
def test_cut_edges_are_the_distinct_mixed_edges_in_order_of_first_occurrence(n_vertices, n_tets):
    """Random tets (repeated vertices too), fewer vertices than VERTEX_RANGES and more."""
    rng = np.random.default_rng(n_vertices + n_tets)
    coords = rng.integers(0, 3, (n_vertices, 3))
    inside = rng.random(n_vertices) < 0.5
    tets = rng.integers(0, n_vertices, (n_tets, 4)).astype(np.int32)
    _check_cut_edges(tets, inside, coords)
    _check_cut_edges(tets.astype(np.int64), inside, coords)
    mixed = inside[tets].any(axis=1) & ~inside[tets].all(axis=1)
    _check_cut_edges(tets[mixed], inside, coords)


@pytest.mark.parametrize("n_chunks", [2, 3, 7])
def test_cut_edges_chained_in_parallel_runs_are_those_of_one_run(n_chunks, monkeypatch):
    """Runs of tets chained apart and merged: the same edges, order and table as one run, down
    to runs with no tet or no new edge; through collect_cut_edges too (against the dict twin)."""
    rng = np.random.default_rng(n_chunks)
    for n_vertices, n_tets in [(5, 2), (40, 300), (3000, 5000)]:
        coords = rng.integers(0, 3, (n_vertices, 3))
        inside = rng.random(n_vertices) < 0.5
        tets = rng.integers(0, n_vertices, (n_tets, 4)).astype(np.int32)
        one = _chain_cut_edges(tets, inside, n_vertices, 1)
        runs = _chain_cut_edges(tets, inside, n_vertices, n_chunks)
        assert all(np.array_equal(a, b) for a, b in zip(one, runs))
    monkeypatch.setattr(stuffing, "PARALLEL_CUT_EDGE_TETS", 0)
    _check_cut_edges(tets, inside, coords)


@pytest.mark.parametrize("seed", range(2))
def test_cut_edges_of_lattices_cut_by_a_sphere(seed):
    """A graded octree's coarse and template edges, and a uniform block's unit edges of all
    seven directions, each edge in several tets."""
    k = next(k for k in range(20) if _sphere_cuts(seed, k)[3][2].starts.size >= 50)
    coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
    assert (_check_cut_edges(tets, inside, coords) < 0).all()
    anchors = np.stack(np.meshgrid(*[np.arange(6)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    anchors = anchors[np.argsort(morton_keys(anchors))]
    vertices = lattice.number_vertices(anchors, np.ones(anchors.shape[0], dtype=np.int64))
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    inside = np.linalg.norm(coords @ LATTICE_TO_SPACE.T - 3.0 - 0.1 * seed, axis=1) < 2.2
    dirs = _check_cut_edges(tets, inside, coords)
    assert np.array_equal(np.unique(dirs), np.arange(7))


@pytest.mark.parametrize("seed", range(4))
def test_cell_cut_edges_are_the_cut_edges_of_the_cells_tets(seed):
    """cell_cut_edges reads each cut edge from the cell anchored at its start: over every
    cell of a one-level lattice with corners of both classes, the same edges (ends, in the
    same orientation, and directions) as collect_cut_edges over the cells' tets, in another
    order, with arrays of the same types, and a lookup table that finds each edge.  The
    classes: a ball, with random corners flipped, all well inside the lattice, so that every
    cell a cut edge lies in is one of the lattice's."""
    from paroct.mesher import _restrict

    rng = np.random.default_rng(900 + seed)
    anchors = np.stack(np.meshgrid(*[np.arange(8)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    anchors = anchors[np.argsort(morton_keys(anchors))]
    vertices = lattice.number_vertices(anchors, np.ones(anchors.shape[0], dtype=np.int64))
    coords = vertices.coords
    inside = np.linalg.norm(coords - rng.uniform(3.5, 4.5, 3), axis=1) < rng.uniform(1.2, 2.8)
    interior = np.flatnonzero((coords >= 1).all(axis=1) & (coords <= 6).all(axis=1))
    inside[rng.choice(interior, 20, replace=False)] ^= True
    cells, kept = _restrict(vertices, stuffing.mixed_rows(vertices.corner_ids, inside))
    inside = inside[kept]
    ours = stuffing.cell_cut_edges(cells.corner_ids, inside)
    theirs = collect_cut_edges(lattice.graded_tets(cells), inside, cells.coords)
    assert [a.dtype for a in ours] == [a.dtype for a in theirs]
    assert ours[0].shape[0] == theirs[0].shape[0] > 50
    assert sorted(zip(*(a.tolist() for a in ours[:3]))) == sorted(zip(*(a.tolist() for a in theirs[:3])))
    head, upper, chain = ours[3:]
    for e, (a, b) in enumerate(zip(ours[0], ours[1])):
        assert stuffing._edge_of(head, upper, chain, min(a, b), max(a, b)) == e


@pytest.mark.parametrize("seed", range(3))
def test_stencils_in_chunks_writes_what_the_serial_kernel_writes(seed):
    """The parallel driver hands chunks of lattice tets to the serial kernel, each from the row
    _chunk_starts gives it (the per-tet offsets at the chunk's first tet): same tets, same
    touched flags, for every prefix of the lattice tets (down to fewer tets than chunks), and
    the tets stuff gives, oriented."""
    k = next(k for k in range(20) if _sphere_cuts(seed, k)[3][2].starts.size >= 50)
    coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
    points, signs = _warped(x, inside, cuts, targets)
    for n in (tets.shape[0], 37, 1):
        part = np.ascontiguousarray(tets[:n])
        offsets = _stencil_offsets(part, signs)
        assert offsets.shape == (n + 1,) and offsets[0] == 0 and (np.diff(offsets) >= 0).all()
        n_chunks = min(n, TET_CHUNKS)
        starts = _chunk_starts(part, signs, n_chunks)
        assert np.array_equal(starts, offsets[np.arange(n_chunks + 1) * n // n_chunks])
        outputs = []
        for kernel, start in ((_stencils, 0), (_stencils_in_chunks, starts)):
            out = np.full((int(offsets[-1]), 4), -1, dtype=np.int32)
            touched = np.zeros(out.shape[0], dtype=np.bool_)
            assert kernel(part, signs, coords, first_centre, cuts.table, coords.shape[0], PRISM_TETS, start, out,
                          touched) == 0
            outputs.append((out, touched))
        assert np.array_equal(outputs[0][0], outputs[1][0]) and np.array_equal(outputs[0][1], outputs[1][1])
        assert (outputs[0][0] >= 0).all()
        # stuff gives these tets, each oriented (positive after the warps); the untouched ones
        # are the lattice tets, as they were.
        stuffed = stuff(x, coords, part, inside, cuts, targets, first_centre=first_centre, with_offsets=False)[1]
        assert (tet_quality(points, stuffed).volume > 0).all()
        assert np.array_equal(np.sort(stuffed, axis=1), np.sort(outputs[0][0], axis=1))
        lattice_of = np.repeat(np.arange(n), np.diff(offsets))  # each output row's lattice tet
        untouched = ~outputs[0][1]
        assert np.array_equal(outputs[0][0][untouched], part[lattice_of[untouched]])


@pytest.mark.parametrize("seed", range(4))
def test_restuff_gives_what_stuff_gives_and_keeps_the_flags_of_the_tets_it_kept(seed):
    """Stuffing again only around the vertices whose warps changed gives the very tets and
    offsets stuff gives with the new warps, in place when they are not more; the kept tets
    keep their flags, the ones stuffed again (named by again) get 0."""
    rng = np.random.default_rng(500 + seed)
    k = next(k for k in range(20) if _sphere_cuts(seed, k)[3][2].starts.size >= 50)
    coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
    points, out, offsets = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
    flags = rng.integers(1, 256, out.shape[0]).astype(np.uint8)
    grown = shrunk = 0
    for _ in range(6):
        new = targets.copy()
        ends = np.concatenate([cuts.starts, cuts.ends])
        for v in rng.choice(ends, 6):  # another cut edge of v, or no warp at all
            own = np.nonzero((cuts.starts == v) | (cuts.ends == v))[0]
            new[v] = rng.choice(np.append(own, -1))
        other = np.where(new >= 0, np.where(cuts.starts[np.maximum(new, 0)] == np.arange(len(new)),
                                            cuts.ends[np.maximum(new, 0)], cuts.starts[np.maximum(new, 0)]), -1)
        new[(new >= 0) & (new[np.maximum(other, 0)] == new)] = -1  # both ends onto one cut point: none
        want_points, want, want_offsets = stuff(x, coords, tets, inside, cuts, new, flat_ok=True, first_centre=first_centre)
        before, before_flags, before_offsets = out.copy(), flags.copy(), offsets.copy()
        got_points, got, again, got_offsets, got_flags = restuff(x, coords, tets, inside, cuts, targets, out, new,
                                                                 offsets=offsets, first_centre=first_centre, flat_ok=True, flags=flags)
        assert np.array_equal(got_points, want_points) and np.array_equal(got, want)
        assert np.array_equal(got_offsets, want_offsets)
        # Flags follow their tets; the tets stuffed again are exactly those through a vertex
        # whose warp changed, and they are few.
        changed = np.flatnonzero(new != targets)
        want_flags, want_again = [], []
        for t in range(tets.shape[0]):
            lo, hi = got_offsets[t], got_offsets[t + 1]
            if np.isin(tets[t], changed).any():
                want_flags.append(np.zeros(hi - lo, dtype=np.uint8))
                want_again.append(np.arange(lo, hi))
            else:
                assert hi - lo == before_offsets[t + 1] - before_offsets[t]
                assert np.array_equal(got[lo:hi], before[before_offsets[t]:before_offsets[t + 1]])
                want_flags.append(before_flags[before_offsets[t]:before_offsets[t + 1]])
        assert np.array_equal(got_flags, np.concatenate(want_flags))
        assert np.array_equal(again, np.concatenate(want_again)) and 0 < again.size < 0.5 * len(got)
        # In place unless there are more tets than before.
        assert np.shares_memory(got, out) == (len(got) <= len(before))
        grown, shrunk = grown + (len(got) > len(before)), shrunk + (len(got) < len(before))
        targets, out, offsets, flags = new, got, got_offsets, got_flags
    assert grown + shrunk > 0


@pytest.mark.parametrize("seed", range(6))
def test_group_by_vertex_against_naive(seed):
    """Rows grouped by the marked vertices they hold, column by column (the order retarget_warps
    tries a vertex's cut edges in: those it starts, then those it ends), as the slow twin;
    repeated vertices in a row, no marked vertex and no rows included."""
    rng = np.random.default_rng(900 + seed)
    n, k, n_vertices = [(0, 4, 5), (1, 2, 3), (40, 4, 30), (200, 2, 50), (300, 4, 10), (50, 3, 1)][seed]
    owners = rng.integers(0, n_vertices, (n, k)).astype(np.int32 if k == 4 else np.int64)
    vertices = np.unique(rng.choice(n_vertices, size=min(n_vertices, 1 + seed * 3))).astype(np.int64)
    if seed == 1:
        vertices = vertices[:0]
    marked = np.zeros(n_vertices, dtype=bool)
    marked[vertices] = True
    first, grouped = _group_by_vertex(vertices, marked, owners)
    assert first.shape == (vertices.size + 1,) and first[0] == 0
    got = [grouped[first[i]:first[i + 1]].tolist() for i in range(vertices.size)]
    assert got == naive_group_by_vertex(vertices, owners)


@pytest.mark.parametrize("seed", range(6))
def test_in_place_splice_against_concatenation(seed):
    """_move_kept, _shift_offsets (by _row_shifts) and _place_again put lattice tet t's new
    tets where the rows stuffed again replace theirs (counts changed, to none included), in
    place in a buffer with
    room for them, as concatenating each lattice tet's tets in order does; flags move with the
    kept tets and are 0 for the others.  Rows at the ends, no rows, blocks moving both ways and
    fewer lattice tets than chunks included."""
    rng = np.random.default_rng(1000 + seed)
    n = [0, 3, 50, 1000, 5000, 400][seed]
    counts = rng.integers(0, 4, n)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    out = rng.integers(0, 10**6, (offsets[-1], 4)).astype(np.int32)
    flags = rng.integers(1, 256, out.shape[0]).astype(np.uint8)
    rows = np.unique(np.concatenate([rng.choice(n, size=min(n, 7)) if n else [], [0, n - 1] if n > 1 else []]))
    rows = rows.astype(np.int64)
    again_counts = rng.integers(0, 4, rows.size)
    if seed == 5:  # one row grows a lot, the next shrinks: blocks move up, then down
        again_counts[:] = counts[rows]
        again_counts[1], counts[rows[2]] = 9, 9
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        out = rng.integers(0, 10**6, (offsets[-1], 4)).astype(np.int32)
        flags = rng.integers(1, 256, out.shape[0]).astype(np.uint8)
        again_counts[2] = 0
    again_offsets = np.concatenate([[0], np.cumsum(again_counts)]).astype(np.int64)
    again = rng.integers(-10**6, 0, (again_offsets[-1], 4)).astype(np.int32)
    pieces, flag_pieces = [], []
    for t in range(n):
        j = np.searchsorted(rows, t)
        if j < rows.size and rows[j] == t:
            pieces.append(again[again_offsets[j]:again_offsets[j + 1]])
            flag_pieces.append(np.zeros(again_counts[j], dtype=np.uint8))
        else:
            pieces.append(out[offsets[t]:offsets[t + 1]])
            flag_pieces.append(flags[offsets[t]:offsets[t + 1]])
    want = np.concatenate(pieces) if pieces else np.empty((0, 4), dtype=np.int32)
    total = want.shape[0]
    room = max(total, out.shape[0])
    buffer = np.full((room, 4), -7, dtype=np.int32)
    buffer[:out.shape[0]] = out
    buffer_flags = np.zeros(room, dtype=np.uint8)
    buffer_flags[:out.shape[0]] = flags
    shift = _row_shifts(offsets, rows, again_offsets)
    _move_kept(buffer, buffer_flags, offsets, rows, shift)
    _shift_offsets(offsets, rows, shift)
    np.testing.assert_array_equal(offsets, np.concatenate([[0], np.cumsum([len(p) for p in pieces])]))
    _place_again(buffer, buffer_flags, offsets[rows], again, again_offsets)
    np.testing.assert_array_equal(buffer[:total], want)
    np.testing.assert_array_equal(buffer_flags[:total], np.concatenate(flag_pieces) if flag_pieces else [])


def _stars(tets, vertices, n_points):
    """Stars of the vertices (sorted) as retarget_warps groups them: (first, rows of tets)."""
    marked = np.zeros(n_points, dtype=bool)
    marked[vertices] = True
    rows = np.flatnonzero(touching(tets, marked))
    first, grouped = _group_by_vertex(vertices, marked, np.take(tets, rows, axis=0))
    return first, rows[grouped], marked


@pytest.mark.parametrize("seed", range(3))
def test_star_options_are_each_vertex_cut_edges_in_order(seed):
    """_star_options finds a vertex's cut edges through the edge table from its star's tets:
    the same groups as grouping every cut edge by its ends, each in order of the other ends'
    coordinates (sorted here by numpy); vertices with no cut edge (inside the solid) included."""
    rng = np.random.default_rng(950 + seed)
    found = 0
    for k in range(4):
        coords, tets, _, (x, inside, cuts, _), first_centre = _sphere_cuts(seed, k)
        ends = np.unique(np.concatenate([cuts.starts, cuts.ends]))
        vertices = np.unique(np.concatenate([rng.choice(ends, size=min(40, ends.size), replace=False),
                                             rng.integers(0, x.shape[0], 10)])).astype(np.int64)
        star_first, stars, marked = _stars(tets, vertices, x.shape[0])
        first, options = _star_options(vertices, star_first, stars, tets, coords, *cuts.table)
        want_first, want = _group_by_vertex(vertices, marked, np.stack((cuts.starts, cuts.ends), axis=1))
        np.testing.assert_array_equal(first, want_first)
        for i, v in enumerate(vertices):
            group = want[want_first[i]:want_first[i + 1]]
            other = np.where(cuts.starts[group] == v, cuts.ends[group], cuts.starts[group])
            np.testing.assert_array_equal(options[first[i]:first[i + 1]], group[np.lexsort(coords[other].T[::-1])])
        found += options.size
    assert found > 100


@pytest.mark.parametrize("seed", range(3))
def test_retarget_skips_only_stars_that_did_not_change(seed):
    """_retarget skips a vertex whose star's vertices did not move since its last visit; the
    slow twin visits every vertex in every sweep.  The warps, signs and points they leave agree
    exactly, on spheres where some vertices move more than once."""
    moved = 0
    for k in range(6):
        coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
        points, out, offsets = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
        worst = _violations(points, out, coords) + (_radius_ratios(points, out, coords) < 0.15)
        if not worst.any():
            continue
        owners = np.searchsorted(offsets, np.nonzero(worst)[0], side="right") - 1
        vertices = np.unique(tets[owners].ravel()).astype(np.int64)
        star_first, stars, _ = _stars(tets, vertices, x.shape[0])
        option_first, options = _star_options(vertices, star_first, stars, tets, coords, *cuts.table)
        results = []
        for search in (_retarget, naive_retarget):
            new, signs, warped = targets.copy(), _signs(inside, targets), points.copy()
            search(vertices, stuffing._coords_order(coords, vertices), star_first, stars, option_first, options, tets, signs, new, warped, x, inside, coords,
                   first_centre, cuts.table, PRISM_TETS, DIHEDRAL_BOUND[0], DIHEDRAL_BOUND[1], 0.15,
                   stuffing.RETARGET_SWEEPS)
            results.append((new, signs, warped))
        for a, b in zip(*results):
            np.testing.assert_array_equal(a, b)
        moved += np.count_nonzero(results[0][0] != targets)
    assert moved > 0


def test_retarget_warps_mends_needles_and_keeps_the_bound_first():
    """Needles (3r/R below min_ratio, their dihedral angles possibly good) given to
    retarget_warps with the tets outside the bound: at least five in six are mended over the
    spheres, the worst violation never rises (the bound comes first: a needle may be traded
    for a tet inside it), and where no tet was outside the bound the smallest 3r/R never
    falls (then an accepted change raises its star's smallest 3r/R and changes nothing else)."""
    floor = 0.15
    before = after = pure = 0
    for seed in range(8):
        for k in range(10):
            coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
            points, out, offsets = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
            worst, ratio = _violations(points, out, coords), _radius_ratios(points, out, coords)
            needles = np.nonzero((worst == 0) & (ratio < floor))[0]
            if needles.size == 0:
                continue
            new = retarget_warps(x, coords, tets, inside, cuts, targets, np.union1d(np.nonzero(worst)[0], needles), floor,
                                 offsets=offsets, first_centre=first_centre).targets
            points, out, _ = stuff(x, coords, tets, inside, cuts, new, flat_ok=True, first_centre=first_centre)
            mended, mended_ratio = _violations(points, out, coords), _radius_ratios(points, out, coords)
            assert mended.max() <= worst.max() + 1e-9
            if not worst.any():
                assert mended_ratio.min() >= ratio.min() - 1e-12
                pure += 1
            before += needles.size
            after += np.count_nonzero((mended == 0) & (mended_ratio < floor))
    assert before > 100 and after <= before / 6 and pure >= 2  # without the floor: 212 -> 51


def test_retarget_warps_names_the_tets_to_stuff_again_and_a_settled_search_moves_nothing_again():
    """Retargeted.rows are exactly the lattice tets through a vertex whose warp changed (the
    scan restuff makes without them); searched are the vertices of the bad tets' lattice
    tets; and after a settled search, searching any of those vertices again from the new
    warps (points updated in place) moves none, as retarget_warps assumes when it skips that
    search (settled)."""
    settled = searched_again = 0
    for seed in range(8):
        for k in range(10):
            coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
            points, out, offsets = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
            bad = np.nonzero(_violations(points, out, coords))[0]
            if bad.size == 0:
                continue
            found = retarget_warps(x, coords, tets, inside, cuts, targets, bad, 0.15, offsets=offsets, first_centre=first_centre, points=points)
            changed = found.targets != targets
            assert found.changed == np.count_nonzero(changed)
            np.testing.assert_array_equal(found.rows, np.flatnonzero(touching(tets, changed)))
            owners = np.searchsorted(offsets, bad, side="right") - 1
            np.testing.assert_array_equal(found.searched, np.unique(tets[owners]))
            if not found.settled:
                continue
            settled += 1
            rng = np.random.default_rng([seed, k])
            # Lattice tets of searched vertices only, with stuffed tets to name them by.
            subset = np.flatnonzero(np.isin(tets, found.searched).all(axis=1) & (np.diff(offsets) > 0))
            some = rng.choice(subset, min(subset.size, 5), replace=False)
            again = retarget_warps(x, coords, tets, inside, cuts, found.targets, offsets[some], 0.15, offsets=offsets, first_centre=first_centre,
                                   points=points)
            assert again.changed == 0 and again.rows.size == 0
            skipped = retarget_warps(x, coords, tets, inside, cuts, found.targets, offsets[some], 0.15, offsets=offsets, first_centre=first_centre,
                                     points=points, settled=found.searched)  # the search _mend skips
            assert skipped.changed == 0 and skipped.targets is found.targets
            np.testing.assert_array_equal(skipped.searched, again.searched)
            searched_again += 1
    assert settled > 20 and searched_again == settled


def test_a_search_of_one_sweep_settles_only_if_it_moves_nothing(monkeypatch):
    """With one sweep, the sweep that must move nothing for Retargeted.settled is the one
    that may have moved vertices: settled exactly when none changed."""
    monkeypatch.setattr(stuffing, "RETARGET_SWEEPS", 1)
    outcomes = set()
    for seed in range(4):
        for k in range(10):
            coords, tets, _, (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
            points, out, offsets = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
            bad = np.nonzero(_violations(points, out, coords))[0]
            if bad.size:
                found = retarget_warps(x, coords, tets, inside, cuts, targets, bad, 0.15, offsets=offsets, first_centre=first_centre)
                assert found.settled == (found.changed == 0)
                outcomes.add(found.settled)
    assert False in outcomes  # searches that moved vertices were seen


def test_retarget_warps_mends_most_tets_outside_the_bound_and_never_worsens_the_worst():
    """Spheres through random balanced octrees, where the band changes level everywhere: the
    warps of warp_targets leave tets outside [10.7, 164.8] (tets at the block's faces, whose
    warps see part of a lattice, not counted); retarget_warps must mend at least nine in ten
    and never raise the worst violation (an accepted change lowers the worst of its vertex's
    star, and only that star changes), move only warps next to bad tets, keep every warped
    vertex on a cut point of one of its own edges, and keep the mesh conforming with its boundary on the sphere."""
    before = after = 0
    for seed in range(8):
        for k in range(10):
            coords, tets, (centre, radius), (x, inside, cuts, targets), first_centre = _sphere_cuts(seed, k)
            points, out, offsets = stuff(x, coords, tets, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
            worst = _violations(points, out, coords)
            if not worst.any():
                continue
            found = retarget_warps(x, coords, tets, inside, cuts, targets, np.nonzero(worst)[0], offsets=offsets, first_centre=first_centre)
            new, changed = found.targets, found.changed
            # Only vertices of the lattice tets that gave bad tets move: each shares a lattice
            # tet with a lattice vertex or cut edge end of a bad tet.
            ids = out[worst > 0].ravel().astype(np.int64)
            cut = ids[ids >= x.shape[0]] - x.shape[0]
            seen = np.unique(np.concatenate([ids[ids < x.shape[0]], cuts.starts[cut], cuts.ends[cut]]))
            near = np.unique(tets[np.isin(tets, seen).any(axis=1)])
            moved = np.nonzero(new != targets)[0]
            assert changed == moved.size and np.isin(moved, near).all()
            points, out, _ = stuff(x, coords, tets, inside, cuts, new, flat_ok=True, first_centre=first_centre)
            mended = _violations(points, out, coords)
            assert mended.max() <= worst.max() + 1e-9
            before, after = before + np.count_nonzero(worst), after + np.count_nonzero(mended)
            warped = np.nonzero(new >= 0)[0]
            assert np.all((cuts.starts[new[warped]] == warped) | (cuts.ends[new[warped]] == warped))
            # Conforming (each face shared by two tets or on the boundary), and the boundary away
            # from the block's faces (whose vertices may warp too) on the sphere.
            tri = _boundary_triangles(points, out)
            u = tri @ np.linalg.inv(LATTICE_TO_SPACE).T
            near_box = np.any((np.abs(u - coords.min(axis=0)) < 1e-9) | (np.abs(u - coords.max(axis=0)) < 1e-9), axis=(1, 2))
            assert np.allclose(np.linalg.norm(tri[~near_box] - centre, axis=2), radius)
    assert before > 100 and after <= before / 10


@pytest.mark.parametrize("seed", range(3))
def test_mending_does_not_depend_on_how_the_corners_are_numbered(seed):
    """retarget_warps on spheres through graded octrees, with the vertices as number_vertices
    numbers them and with the leaf corners numbered at random (the face centres that are no
    leaf's corner still last): the same warps, named by coordinates, and the same mended
    tets.  Its sweeps visit the vertices in order of their coordinates and try each one's
    cut edges in order of their other ends' coordinates, so a search split among partitions
    can settle as the one pass does."""
    changed = 0
    for k in range(10):
        coords, tets, (centre, radius), _, first_centre = _sphere_cuts(seed, k)
        rng = np.random.default_rng([seed, k, 1])
        anchors, sides = _random_balanced_tree(seed, 4 + seed % 2)
        spacing = lattice.vertex_spacing(lattice.number_vertices(anchors, sides), sides)
        new_id = np.concatenate([rng.permutation(first_centre), np.arange(first_centre, coords.shape[0])])
        results = []
        for ids in (np.arange(coords.shape[0]), new_id):
            order = np.argsort(ids)  # the old vertex of each new id
            c, t = coords[order], ids[tets]
            phi, fracs = _sphere(c, centre, radius)
            x, inside, cuts, targets = _cuts_and_warps(c, t, phi, fracs, True, spacing[order])
            points, out, offsets = stuff(x, c, t, inside, cuts, targets, flat_ok=True, first_centre=first_centre)
            bad = np.nonzero(_violations(points, out, c) + (_radius_ratios(points, out, c) < 0.15))[0]
            if bad.size == 0:
                break
            found = retarget_warps(x, c, t, inside, cuts, targets, bad, 0.15, offsets=offsets, first_centre=first_centre)
            warped = {tuple(c[v]): (tuple(c[cuts.starts[e]]), tuple(c[cuts.ends[e]]))
                      for v, e in enumerate(found.targets) if e >= 0}
            points, out, _ = stuff(x, c, t, inside, cuts, found.targets, flat_ok=True, first_centre=first_centre)
            results.append((warped, _canonical_tets(points, out), found.changed))
        if len(results) < 2:
            continue
        assert results[0][0] == results[1][0] and np.array_equal(results[0][1], results[1][1])
        changed += results[0][2]
    assert changed > 0  # searches that moved warps were compared


@pytest.mark.parametrize("seed", range(3))
def test_cut_edges_and_warps_do_not_depend_on_the_numbering(seed):
    """The cut edges' directions (so the float cut points found along them) and the warps'
    ties follow the points' places, not their ids nor the order of the tets: a graded octree
    cut by a sphere centred on a lattice point (many cut points at equal distances), its
    vertices renumbered at random and its tets shuffled, gives the same edges, cut points
    and warps.  (A partition of the leaves would number its points its own way.)"""
    from paroct.stuffing import ALPHA_LONG, ALPHA_SHORT, _violations

    rng = np.random.default_rng(seed)
    anchors, sides = _random_balanced_tree(seed, 4)
    vertices = lattice.number_vertices(anchors, sides)
    coords, tets = vertices.coords, lattice.graded_tets(vertices)
    spacing = lattice.vertex_spacing(vertices, sides)
    x = coords @ LATTICE_TO_SPACE.T
    middle = coords[np.argmin(np.abs(coords - coords.mean(axis=0)).sum(axis=1))]
    centre, radius = middle @ LATTICE_TO_SPACE.T, 0.37 * (x.max(axis=0) - x.min(axis=0)).min()

    def cut_and_warp(coords, tets, spacing):
        """{(start, end) coordinates: cut fraction} and each vertex's target as its edge's ends."""
        x = coords @ LATTICE_TO_SPACE.T
        phi, fracs_of = _sphere(coords, centre, radius)
        starts, ends, dirs, *table = collect_cut_edges(tets, phi > 0, coords)
        fracs = fracs_of(x, starts, ends)
        cuts = CutEdges(starts, ends, dirs, fracs, x[starts] + fracs[:, None] * (x[ends] - x[starts]), tuple(table))
        targets = warp_targets(cuts, coords, 1.0, spacing)
        distance, violated = _violations(coords, starts, ends, fracs, spacing, LATTICE_TO_SPACE, 1.0, ALPHA_LONG,
                                         ALPHA_SHORT)
        edges = {(tuple(coords[s]), tuple(coords[e])): f for s, e, f in zip(starts, ends, fracs)}
        warped = {tuple(coords[v]): (tuple(coords[starts[t]]), tuple(coords[ends[t]])) for v, t in enumerate(targets)
                  if t >= 0}
        at = np.where(violated == 0, starts, ends)[violated >= 0]
        pairs = np.stack([at, distance[violated >= 0]])  # (vertex, distance) of each violating cut
        ties = np.unique(pairs, axis=1).shape[1] < pairs.shape[1]  # a vertex with two at one distance
        return edges, warped, ties, (dirs < 0).sum()

    edges, warped, ties, off_lattice = cut_and_warp(coords, tets, spacing)
    perm = rng.permutation(coords.shape[0])  # old vertex v is new vertex perm[v]
    moved = np.empty_like(coords)
    moved[perm] = coords
    moved_spacing = np.empty_like(spacing)
    moved_spacing[perm] = spacing
    again = cut_and_warp(moved, perm[tets][rng.permutation(tets.shape[0])].astype(np.int32), moved_spacing)
    assert edges == again[0] and warped == again[1]
    assert len(edges) > 100 and len(warped) > 20 and off_lattice > 0 and ties  # the rules are exercised


@pytest.mark.parametrize("n_rows, width", [(0, 4), (1, 4), (300, 8), (5000, 4)])
def test_mixed_rows_are_rows_of_both_classes(n_rows, width):
    """mixed_rows against numpy: a row is mixed iff its vertices' classes are not all equal."""
    rng = np.random.default_rng(n_rows)
    classes = rng.random(40) < 0.5
    ids = rng.integers(0, 40, (n_rows, width)).astype(np.int32)
    want = classes[ids].any(axis=1) & ~classes[ids].all(axis=1)
    assert np.array_equal(stuffing.mixed_rows(ids, classes), want)
