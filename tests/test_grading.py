"""Graded octrees: transition templates, random balanced trees, surface cells, size control."""

import itertools

import manifold3d
import numba
import numpy as np
import pytest

from paroct import lattice, octant
from paroct.errors import ParoctError
from paroct.frame import LATTICE_TO_SPACE, fat_frame
from paroct.mesher import mesh
from paroct.octree import balance, surface_cells, tree_is_balanced
from paroct.quality import tet_quality
from paroct.sizing import Box, Sphere
from paroct.surface import load_surface
from paroct.topology import boundary_faces, match_faces
from paroct.transitions import (
    CHAIN_IS_ODD,
    CHAIN_SPLITS,
    CHAINS,
    EAGER_MASKS,
    SPLIT_POINT_OFFSETS,
    TEMPLATES,
)

from .naive import cells_meeting_triangles, face_centres, vertex_order

FAT_RATIO = 3 / np.sqrt(10)
ML = octant.MAX_LEVEL
EPS = 1e-9


def _chain_points(chain, side=2):
    """Space points (9, 3) of the template labels v0..v3, m01, m12, m23, m02, m13 of a chain."""
    corners = np.array([[(c >> i) & 1 for i in range(3)] for c in chain]) * side
    pairs = ((0, 1), (1, 2), (2, 3), (0, 2), (1, 3))
    mids = np.array([(corners[i] + corners[j]) / 2 for i, j in pairs])
    return np.vstack([corners, mids]) @ LATTICE_TO_SPACE.T


@pytest.mark.parametrize("mask", sorted(TEMPLATES))
def test_each_template_tiles_its_chain_tet_with_good_angles(mask):
    for c, chain in enumerate(CHAINS):
        pts = _chain_points(chain)
        tets = np.array(TEMPLATES[mask], dtype=np.int64)
        if CHAIN_IS_ODD[c]:
            tets = tets[:, [0, 2, 1, 3]]
        q = tet_quality(pts, tets.astype(np.int32))
        whole = tet_quality(pts, np.array([[0, 1, 2, 3]] if not CHAIN_IS_ODD[c] else [[0, 2, 1, 3]], dtype=np.int32))
        assert np.all(q.volume > 0), f"mask {mask} chain {chain}: inverted tet"
        assert q.volume.sum() == pytest.approx(whole.volume[0], rel=1e-12)
        # Interior faces are shared by two tets on opposite sides, so the tets tile the chain tet.
        _, overloaded, same_side = match_faces(tets.astype(np.int32))
        assert overloaded == 0 and same_side == 0
        # Each template vertex it uses that is a split point must be flagged by the mask.
        used = set(tets.ravel().tolist())
        assert all((mask >> (k - 4)) & 1 for k in used if k >= 4)
        # The issue asks for [30, 135] and 3r/R >= 0.40; the minimal rule's lone split cube
        # edge meets 30 exactly, the eager rule's masks keep 35.26.
        assert q.min_dihedral.min() >= 30 - EPS and q.max_dihedral.max() <= 120 + EPS
        assert q.radius_ratio.min() >= 0.544
        if mask in EAGER_MASKS:
            assert q.min_dihedral.min() >= 35.26


def test_split_point_tables_agree_with_chain_midpoints():
    for chain, splits in zip(CHAINS, CHAIN_SPLITS):
        corners = np.array([[(c >> i) & 1 for i in range(3)] for c in chain])
        for (i, j), p in zip(((0, 1), (1, 2), (2, 3), (0, 2), (1, 3)), splits):
            assert np.array_equal(corners[i] + corners[j], SPLIT_POINT_OFFSETS[p])
    assert len({tuple(o) for o in SPLIT_POINT_OFFSETS}) == 18


def _random_balanced_tree(seed, max_level):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 10))
    levels = rng.integers(1, max_level + 1, size=n)
    keys = [octant.morton_key(*(rng.integers(0, 1 << lev, size=3) << (ML - lev))) for lev in levels]
    keys, levels = balance(np.array(keys, dtype=np.int64), levels.astype(np.int8))
    assert tree_is_balanced(keys, levels)
    anchors = octant.morton_decode(keys) >> (ML - max_level)
    sides = np.int64(1) << (max_level - levels.astype(np.int64))
    return anchors, sides


@pytest.mark.parametrize("rule,min_angle", [("minimal", 30 - EPS), ("eager", 35.26), ("mixed", 30 - EPS)])
@pytest.mark.parametrize("seed", range(16))
def test_random_balanced_trees_conform_with_template_quality(seed, rule, min_angle):
    max_level = 3 + seed % 3
    anchors, sides = _random_balanced_tree(seed, max_level)
    eager = _eager_leaves(rule, len(sides), seed)
    coords, tets = lattice.leaf_tets(anchors, sides, eager=eager)
    points = coords @ LATTICE_TO_SPACE.T
    q = tet_quality(points, tets)
    assert np.all(q.volume > 0)
    root = 1 << max_level
    assert q.volume.sum() == pytest.approx(0.5 * root**3, rel=1e-12)  # det(LATTICE_TO_SPACE) = 1/2
    neighbour, overloaded, same_side = match_faces(tets)
    assert overloaded == 0 and same_side == 0
    # No hanging vertex: the only boundary faces lie on the root cube's faces.
    face_coords = coords[boundary_faces(tets, neighbour)]
    on_root = ((face_coords == 0) | (face_coords == root)).all(axis=1).any(axis=1)
    assert on_root.all()
    assert q.min_dihedral.min() >= min_angle and q.max_dihedral.max() <= 120 + EPS
    assert q.radius_ratio.min() >= 0.544
    # Leaves with no finer neighbour keep their six fat tets.
    vertices = lattice.number_vertices(anchors, sides, eager=eager)
    plain = np.ones(len(sides), dtype=bool)
    plain[sides >= 2] = (vertices.split_ids < 0).all(axis=1)
    assert np.isclose(q.radius_ratio, FAT_RATIO, atol=1e-9).sum() >= 6 * plain.sum()


@pytest.mark.parametrize("marking", ["random", "none", "all", "ends_unmarked"])
@pytest.mark.parametrize("seed", range(4))
def test_marked_tets_are_the_tets_with_a_marked_vertex_in_order(seed, marking):
    """graded_tets(vertices, marked) keeps exactly the tets of graded_tets(vertices) with a
    marked vertex, in their order: plain leaves (six fat tets, read straight from their
    corners) and split leaves (templates) alike, also with both ends of every chain
    (corners 0 and 7) unmarked."""
    anchors, sides = _random_balanced_tree(700 + seed, 3 + seed % 3)
    vertices = lattice.number_vertices(anchors, sides, eager=_eager_leaves("mixed", len(sides), seed))
    everything = lattice.graded_tets(vertices)
    rng = np.random.default_rng(seed)
    n = vertices.coords.shape[0]
    marked = {"random": rng.random(n) < 0.3, "none": np.zeros(n, dtype=bool), "all": np.ones(n, dtype=bool)}.get(marking)
    if marking == "ends_unmarked":
        marked = rng.random(n) < 0.5
        marked[vertices.corner_ids[:, [0, 7]]] = False
    assert (sides == 1).any() and (sides >= 2).any()
    want = everything[marked[everything].any(axis=1)]
    assert len(want) < len(everything) or marking == "all"
    assert np.array_equal(lattice.graded_tets(vertices, marked), want)


@pytest.mark.parametrize("rule", ["minimal", "eager", "mixed"])
@pytest.mark.parametrize("seed", range(6))
def test_vertex_ids_follow_the_numbering_order(seed, rule):
    """Ids in order of first use, face centres last (eager leaves' first): the parallel
    lookups and the ordered numbering of the new face centres give the leaf-by-leaf order."""
    anchors, sides = _random_balanced_tree(400 + seed, 3 + seed % 3)
    eager = _eager_leaves(rule, len(sides), seed)
    corners = (anchors[:, None, :] + sides[:, None, None] * lattice.CUBE_CORNERS[None]).reshape(-1, 3)
    prefix = np.unique(corners[np.random.default_rng(seed).random(len(corners)) < 0.2], axis=0)[::-1]
    vertices = lattice.number_vertices(anchors, sides, prefix, eager=eager)
    assert np.array_equal(vertices.coords, vertex_order(anchors, sides, eager, prefix))
    assert np.array_equal(vertices.coords[vertices.corner_ids], corners.reshape(-1, 8, 3))


def test_hashed_vertex_numbering_grows_its_table_and_keeps_the_ids(monkeypatch):
    """Leaves sharing no corner have 8 vertices each, more than the hash table's first size
    holds at half load: it must grow (twice) mid-loop and still number as the dense index."""
    grid = np.array(list(itertools.product(range(0, 24, 2), repeat=3)), dtype=np.int64)
    anchors = grid[np.argsort(octant.morton_keys(grid), kind="stable")]
    sides = np.ones(len(anchors), dtype=np.int64)
    prefix = anchors[::7] + 1  # far corners of some leaves, numbered first
    results = []
    for per_leaf in (1e9, 0):
        monkeypatch.setattr(lattice, "DENSE_SLOTS_PER_LEAF", per_leaf)
        results.append(lattice.number_vertices(anchors, sides, prefix))
    dense, hashed = results
    assert len(dense.coords) == 8 * len(anchors)
    assert np.array_equal(dense.coords[: len(prefix)], prefix)
    for a, b in zip((dense.corner_ids, dense.coords), (hashed.corner_ids, hashed.coords)):
        assert np.array_equal(a, b)
    assert np.array_equal(dense.coords[dense.corner_ids], anchors[:, None, :] + lattice.CUBE_CORNERS[None, :, :])


@numba.njit
def _summed_axis_parts(table, box_lo, stride, points):
    out = np.empty((points.shape[0], 2), dtype=np.int64)
    for i in range(points.shape[0]):
        out[i] = 0
        for k in range(3):
            brick, morton = lattice._axis_part(table, box_lo, stride, k, points[i, k])
            out[i, 0] += brick
            out[i, 1] |= morton
    return out


def test_axis_parts_sum_to_the_points_brick_and_morton_index():
    """Slow twin of _axis_part: the dense index's parts of a point sum to its brick's index in
    the box (x fastest) and its bits below BRICK_BITS interleaved (x lowest); the hash table's
    to its Morton key."""
    rng = np.random.default_rng(7)
    box_lo, bricks = np.array([-40, 16, 3]), np.array([5, 3, 7])
    side = lattice._BRICK_SIDE
    points = box_lo + rng.integers(0, bricks * side, size=(500, 3))
    stride = np.array([1, bricks[0], bricks[0] * bricks[1]])
    offsets = points - box_lo
    b = offsets // side
    low = offsets % side
    morton = sum(((low[:, k] >> bit) & 1) << (3 * bit + k) for k in range(3) for bit in range(lattice.BRICK_BITS))
    dense = _summed_axis_parts(np.zeros(1, dtype=np.int32), box_lo, stride, points)
    assert np.array_equal(dense[:, 0], (b[:, 2] * bricks[1] + b[:, 1]) * bricks[0] + b[:, 0])
    assert np.array_equal(dense[:, 1], morton)
    hashed = _summed_axis_parts(np.zeros((1, 2), dtype=np.int64), box_lo, stride, points - box_lo)
    assert np.array_equal(hashed[:, 0], np.zeros(len(points)))
    assert np.array_equal(hashed[:, 1], octant.morton_keys(points - box_lo))


@pytest.mark.parametrize("seed", range(3))
def test_dense_bricked_and_hashed_vertex_numbering_agree(monkeypatch, seed):
    anchors, sides = _random_balanced_tree(100 + seed, 5)  # leaves of side 16: bricks between their points
    # A second tree far away leaves the box mostly empty, as a band refined locally does.
    anchors = np.concatenate([anchors, anchors + np.array([400, 16, 192])])
    sides = np.concatenate([sides, sides])
    side, slots = lattice._BRICK_SIDE, lattice._BRICK_SLOTS
    box_lo, box_hi = anchors.min(axis=0) // side * side, (anchors + sides[:, None]).max(axis=0)  # as number_vertices
    bricks = (box_hi - box_lo + side) // side
    directory, used = lattice._brick_directory(anchors, sides, np.zeros((0, 3), dtype=np.int64), box_lo, bricks)
    # Slow twin: the bricks placed are exactly those holding a leaf point, every point in a
    # brick lies at a multiple of 2**shift from box_lo, and the bricks' slots do not overlap.
    points = np.array([a + np.array(o) * max(s // 2, 1) for a, s in zip(anchors, sides)
                       for o in itertools.product(range(3 if s > 1 else 2), repeat=3)])
    b = (points - box_lo) // side
    brick_of = (b[:, 2] * bricks[1] + b[:, 1]) * bricks[0] + b[:, 0]
    held = np.unique(brick_of)
    assert np.array_equal(np.flatnonzero(directory >= 0), held)
    shift = directory[brick_of] & lattice._SHIFT_MASK
    assert np.all((points - box_lo) % (1 << shift)[:, None] == 0)
    first = directory[held] >> lattice._SHIFT_BITS
    size = (side >> (directory[held] & lattice._SHIFT_MASK)) ** 3
    order = np.argsort(first)
    ends = first[order] + size[order]
    assert first[order][0] >= 0 and np.all(first[order][1:] >= ends[:-1]) and ends[-1] <= used
    assert used < slots * len(held) / 2  # the trees' coarse leaves share few slots
    n_bricks = int(np.prod(bricks))
    results = []
    # Whole box, only the bricks in use (a budget the whole box exceeds), and hashing.
    for per_leaf in (1e9, (2 * n_bricks + used + 1) / len(sides), 0):
        monkeypatch.setattr(lattice, "DENSE_SLOTS_PER_LEAF", per_leaf)
        results.append(lattice.number_vertices(anchors, sides))
    assert slots * n_bricks > (2 * n_bricks + used) * 2  # the middle budget picks the bricks
    dense = results[0]
    for other in results[1:]:
        for a, b in zip((dense.corner_ids, dense.split_ids, dense.coords),
                        (other.corner_ids, other.split_ids, other.coords)):
            assert np.array_equal(a, b)
    corners = anchors[:, None, :] + sides[:, None, None] * lattice.CUBE_CORNERS[None, :, :]
    assert np.array_equal(dense.coords[dense.corner_ids], corners)
    assert len(np.unique(dense.coords, axis=0)) == len(dense.coords)
    rows = np.nonzero(dense.split_row >= 0)[0]
    expected = anchors[rows, None, :] + (sides[rows, None, None] // 2) * SPLIT_POINT_OFFSETS[None]
    has = dense.split_ids[dense.split_row[rows]] >= 0
    assert np.array_equal(dense.coords[dense.split_ids[dense.split_row[rows]][has]], expected[has])


def _eager_leaves(rule, n, seed):
    """Leaves marked for the eager face-centre rule: none, all, or a random half."""
    if rule == "mixed":
        return np.random.default_rng(300 + seed).random(n) < 0.5
    return np.full(n, rule == "eager")


@pytest.mark.parametrize("rule", ["minimal", "eager", "mixed"])
@pytest.mark.parametrize("seed", range(4))
def test_face_centre_rules_match_their_definition(seed, rule):
    anchors, sides = _random_balanced_tree(200 + seed, 3 + seed % 2)
    eager = _eager_leaves(rule, len(sides), seed)
    vertices = lattice.number_vertices(anchors, sides, eager=eager)
    rows = vertices.split_row[vertices.split_row >= 0]
    ids = vertices.split_ids[rows][:, 12:]
    got = {tuple(c) for c in vertices.coords[ids[ids >= 0]].tolist()}
    assert got == face_centres(anchors, sides, eager)
    # Marking more leaves eager only adds face centres.
    assert face_centres(anchors, sides, np.zeros(len(sides), bool)) <= got <= face_centres(anchors, sides, np.ones(len(sides), bool))


@pytest.mark.parametrize("seed", range(4))
def test_surface_cells_match_polygon_clipping(seed):
    rng = np.random.default_rng(seed)
    frame = fat_frame(np.zeros(3), np.ones(3), 0.25)  # levels small enough for a brute-force twin
    n_cells = 1 << frame.levels
    bits = 28 - frame.levels
    # Random triangles plus degenerate ones: axis-aligned, on cell planes, needles.
    tris = rng.uniform(0.5, n_cells - 0.5, size=(6, 3, 3))
    # Small ones, most inside one cell (the kernel's shortcut); their third vertex spreads
    # 8 x wider, so some cross a cell face.
    small = rng.integers(0, n_cells - 1, size=(6, 1, 3)) + rng.uniform(0.05, 0.95, size=(1, 1, 3)) \
        + rng.uniform(-0.04, 0.04, size=(6, 3, 3)) * np.array([1, 1, 8])[:, None]
    tris = np.concatenate([tris, small, [[[2, 2, 2], [5, 2, 2], [2, 5, 2]], [[3, 3, 1.5], [3, 3, 6.5], [3.0000001, 3, 4]]]])
    tris = np.round(tris * (1 << bits)) / (1 << bits)
    snapped = (tris.reshape(-1, 3) * (1 << bits)).astype(np.int64)
    faces = np.arange(len(snapped)).reshape(-1, 3)
    for level in (frame.levels, frame.levels - 1):
        side = 1 << (frame.levels - level)
        got = surface_cells(frame, snapped, faces, bits, level) >> (3 * (ML - frame.levels))
        got = {tuple(int(v) // side for v in c) for c in octant.morton_decode(got)}
        want = cells_meeting_triangles(tris, side, n_cells // side)
        assert want <= got  # never misses a cell
        extra = got - want  # only cells touching within the rounding margin
        assert len(extra) <= 0.05 * len(want) + 2


def _edge_lengths(points, tets):
    p = points[tets]
    return np.stack([np.linalg.norm(p[:, i] - p[:, j], axis=1) for i, j in itertools.combinations(range(4), 2)], 1)


def test_graded_mesh_is_coarse_inside_fine_at_the_boundary_and_interior_tets_good():
    surface = load_surface(manifold3d.Manifold.sphere(1.0, 64))
    graded = mesh(surface, size=0.05)
    uniform = mesh(surface, size=0.05, max_size=0.05)
    r = graded.report
    assert r.leaf_levels == (0, 1, 2, 3)
    assert r.n_tets < 0.6 * uniform.report.n_tets  # 0.52 here; the ratio falls as size shrinks
    assert r.interior_min_dihedral >= 30 - EPS and r.interior_max_dihedral <= 120 + EPS
    assert 10.7 <= r.min_dihedral and r.max_dihedral <= 164.8
    assert abs(r.volume_error) < 0.01 and r.boundary_components == 1 and r.boundary_genus == 0
    # Same boundary: the finest band is the same in both meshes.
    b_graded = boundary_faces(graded.mesh.tets, match_faces(graded.mesh.tets)[0])
    b_uniform = boundary_faces(uniform.mesh.tets, match_faces(uniform.mesh.tets)[0])
    assert len(b_graded) == len(b_uniform)
    assert np.allclose(np.sort(graded.mesh.points[b_graded].reshape(-1, 3), axis=0),
                       np.sort(uniform.mesh.points[b_uniform].reshape(-1, 3), axis=0))
    # Edges grow towards max_size = 8 * size inside (0.4 * sqrt(3)/2: short edges of the coarsest
    # leaves, which all border finer ones in a ball this small), never beyond.
    longest = _edge_lengths(graded.mesh.points, graded.mesh.tets).max()
    assert 0.4 * np.sqrt(3) / 2 - 1e-9 <= longest <= 0.4 + 1e-9


def test_regions_and_size_function_refine_where_asked():
    box = manifold3d.Manifold.cube([2.0, 2.0, 2.0])
    base = mesh(box, size=0.1).mesh
    sphere = Sphere(center=(1.0, 1.0, 1.0), radius=0.3, size=0.1)
    refined = mesh(box, size=0.1, regions=[sphere]).mesh
    near = lambda m: np.linalg.norm(m.points[m.tets].mean(axis=1) - 1.0, axis=1) < 0.3  # noqa: E731
    assert _edge_lengths(base.points, base.tets)[near(base)].max() > 0.3
    assert _edge_lengths(refined.points, refined.tets)[near(refined)].max() <= 0.1 + 1e-9
    by_function = mesh(box, size=0.1, size_function=lambda x: np.where(np.linalg.norm(x - 1.0, axis=1) < 0.5, 0.1, 1.0)).mesh
    assert _edge_lengths(by_function.points, by_function.tets)[near(by_function)].max() <= 0.1 + 1e-9
    boxed = mesh(box, size=0.1, regions=[Box(lo=(0.8, 0.8, 0.8), hi=(1.2, 1.2, 1.2), size=0.2)]).mesh
    assert _edge_lengths(boxed.points, boxed.tets)[near(boxed)].max() <= 0.2 + 1e-9


@pytest.mark.parametrize("kwargs,match", [
    ({"max_size": 0.05}, "max_size"),
    ({"regions": [Sphere((0, 0, 0), 1.0, -1.0)]}, "region size"),
    ({"regions": ["box"]}, "Box or Sphere"),
    ({"size_function": lambda x: np.ones(3)}, "shape"),
    ({"size_function": lambda x: -np.ones(len(x))}, "non-positive"),
    ({"size_function": lambda x: np.where(x[:, 0] > 0.5, np.nan, 0.2)},
     r"non-positive or NaN size, nan at \(0\.\d+, -?[\d.e-]+, -?[\d.e-]+\), one of the points"),
    ({"size_function": lambda x: 1 / 0}, "size_function failed"),
])
def test_size_control_errors_are_one_line(kwargs, match):
    with pytest.raises(ParoctError, match=match):
        mesh(manifold3d.Manifold.cube([1.0, 1.0, 1.0]), size=0.1, **kwargs)


@pytest.mark.parametrize("seed", range(3))
def test_restrict_keeps_the_selected_leaves_vertices_in_order(seed):
    """mesher._restrict against numpy's gathers: the selected leaves' corners, renumbered in
    the order of the old ids, and the mask of the old vertices kept."""
    from paroct.mesher import _restrict

    rng = np.random.default_rng(seed)
    grid = np.array(list(itertools.product(range(6), repeat=3)), dtype=np.int64)
    anchors = grid[np.argsort(octant.morton_keys(grid), kind="stable")]
    vertices = lattice.number_vertices(anchors, np.ones(len(anchors), dtype=np.int64))
    leaves = rng.random(len(anchors)) < 0.3
    got, kept = _restrict(vertices, leaves)
    want_kept = np.zeros(len(vertices.coords), dtype=bool)
    want_kept[vertices.corner_ids[leaves].ravel()] = True
    new_id = np.cumsum(want_kept) - 1
    assert np.array_equal(kept, want_kept)
    assert np.array_equal(got.coords, vertices.coords[want_kept])
    assert np.array_equal(got.corner_ids, new_id[vertices.corner_ids[leaves]])
    assert got.corner_ids.dtype == np.int32 and np.all(got.split_row == -1)


def test_cells_around_are_the_eight_cells_at_each_marked_point():
    """mesher._cells_around against numpy's broadcast: the cells having a marked point as a
    corner, of non-negative anchor, keyed at octree resolution."""
    from paroct.mesher import _cells_around

    rng = np.random.default_rng(7)
    coords = rng.integers(0, 4, (200, 3)).astype(np.int64)
    marked = rng.random(200) < 0.5
    around = (coords[marked][:, None, :] - lattice.CUBE_CORNERS[None, :, :]).reshape(-1, 3)
    around = around[(around >= 0).all(axis=1)]
    want = octant.morton_keys(around << 5)
    assert np.array_equal(_cells_around(coords, marked, 5), want)
