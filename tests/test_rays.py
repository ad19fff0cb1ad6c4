"""The exact row-ray kernel against Python-integer and fraction references."""

from pathlib import Path

import numpy as np
import pytest

from paroct import octant, rays
from paroct.frame import EDGE_DIRECTIONS, LATTICE_TO_SPACE, X_AXIS_DIRECTION, fat_frame, row_basis
from paroct.lattice import leaf_tets
from paroct.octree import octant_lattice_anchors, uniform_leaves

from . import naive

RNG = np.random.default_rng(7)
DATA = Path(__file__).resolve().parent.parent / "data"


def test_sign_sum_of_products_is_exact_at_the_limits():
    for _ in range(20000):
        w = RNG.integers(-(1 << 60), 1 << 60, size=3)
        d = RNG.integers(-(1 << 30) + 1, 1 << 30, size=3)
        if RNG.random() < 0.3:  # force exact cancellation
            d[2] = 0
            w[1] = -w[0]
            d[1] = d[0]
        exact = sum(int(a) * int(b) for a, b in zip(w, d))
        assert rays.sign_sum_of_products(w[0], d[0], w[1], d[1], w[2], d[2]) == (exact > 0) - (exact < 0)


def test_row_bases_are_unimodular_and_map_each_direction_to_e1():
    for k, d in enumerate(EDGE_DIRECTIONS):
        T = row_basis(k)
        assert round(np.linalg.det(T)) == 1
        assert np.array_equal(T @ d, [1, 0, 0])
        assert np.abs(T).max() == 1


def _box_surface(lo, hi):
    v = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    f = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                  [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])
    return lo + (hi - lo) * v, f


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _lattice_points(frame, lo, hi):
    keys, _ = uniform_leaves(frame, lo, hi, frame.levels)
    points, _ = leaf_tets(octant_lattice_anchors(keys, frame), np.ones(len(keys), dtype=np.int64))
    return points


@pytest.mark.parametrize("seed", range(4))
def test_winding_of_rotated_box_matches_fraction_reference(seed):
    rng = np.random.default_rng(seed)
    v, f = _box_surface(np.zeros(3), np.array([1.0, 0.7, 0.4]))
    v = v @ _rotation(rng).T + rng.normal(size=3)
    frame = fat_frame(v.min(0), v.max(0), 0.15)
    snapped = rays.snap_surface(frame, v)
    points = _lattice_points(frame, v.min(0), v.max(0))
    pick = rng.choice(len(points), size=min(150, len(points)), replace=False)
    for d in (X_AXIS_DIRECTION, 0, 6):
        crossings = rays.row_crossings(frame, snapped, f, d)
        w = rays.winding_numbers(crossings, points)
        assert set(np.unique(w)) <= {0, 1}
        for i in pick:
            # The reference moves the point by -eps along d; in snapped units points are exact.
            p = points[i] * (1 << rays.snap_bits(frame))
            assert w[i] == naive.winding_number(p, snapped, f, EDGE_DIRECTIONS[d])


def test_all_seven_directions_agree_off_the_surface():
    v, f = _box_surface(np.zeros(3), np.ones(3))
    frame = fat_frame(v.min(0), v.max(0), 0.1)
    snapped = rays.snap_surface(frame, v)
    points = _lattice_points(frame, v.min(0), v.max(0))
    classes = [rays.winding_numbers(rays.row_crossings(frame, snapped, f, d), points) for d in range(7)]
    x = frame.to_space(points)
    inside = np.all((x > 0) & (x < 1), axis=1)
    for w in classes:
        assert np.array_equal(w > 0, inside)


def test_watertight_when_rows_pass_exactly_through_vertices_and_edges():
    # A box whose corners and edges sit exactly on lattice rows: every hit is a tie.
    from paroct.frame import FatFrame

    frame = FatFrame(origin=np.zeros(3), h=1.0, levels=6)
    lo, hi = np.array([4.0, 4.0, 4.0]), np.array([12.0, 10.0, 8.0])
    v, f = _box_surface(lo, hi)
    snapped = rays.snap_surface(frame, v)
    n = np.arange(0, 40)
    points = np.stack(np.meshgrid(n, n, n, indexing="ij"), -1).reshape(-1, 3)
    for d in range(7):
        w = rays.winding_numbers(rays.row_crossings(frame, snapped, f, d), points)
        assert set(np.unique(w)) <= {0, 1}, d
        x = frame.to_space(points)
        strictly_in = np.all((x > lo) & (x < hi), axis=1)
        strictly_out = np.any((x < lo) | (x > hi), axis=1)
        assert np.all(w[strictly_in] == 1) and np.all(w[strictly_out] == 0)


def test_cut_fractions_lie_on_the_surface():
    v, f = _box_surface(np.zeros(3), np.ones(3))
    v = v @ _rotation(np.random.default_rng(3)).T
    frame = fat_frame(v.min(0), v.max(0), 0.1)
    snapped = rays.snap_surface(frame, v)
    points = _lattice_points(frame, v.min(0), v.max(0))
    inside = rays.winding_numbers(rays.row_crossings(frame, snapped, f, X_AXIS_DIRECTION), points) > 0
    lookup = {tuple(p): i for i, p in enumerate(points)}
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    for d in range(7):
        ends = [lookup.get(tuple(p + EDGE_DIRECTIONS[d]), -1) for p in points]
        ends = np.array(ends)
        cut = (ends >= 0) & (inside != inside[np.maximum(ends, 0)])
        starts = points[cut]
        frac, unresolved, crossed = rays.edge_cut_fractions(rays.row_crossings(frame, snapped, f, d), starts, inside[cut])
        assert not unresolved.any()
        x = frame.to_space(starts + frac[:, None] * EDGE_DIRECTIONS[d])
        # Distance to the nearest face plane of the unit box (rotated) is ~0, and to the triangle said.
        local = x @ _rotation(np.random.default_rng(3))
        dist = np.min(np.abs(np.concatenate([local, local - 1], axis=1)), axis=1)
        assert dist.max() < 1e-6
        assert max(naive.point_triangle_distance(p, *v[f[t]]) for p, t in zip(x, crossed)) < 1e-6


def test_edge_cuts_of_all_directions_at_once_are_each_directions_own():
    # add_edge_cut_fractions takes the cut edges of every direction in one call, in blocks of
    # rays.EDGE_BLOCK grouped by direction: the same cuts as one direction at a time.
    rng = np.random.default_rng(11)
    v, f = _box_surface(np.zeros(3), np.ones(3))
    v = v @ _rotation(rng).T
    frame = fat_frame(v.min(0), v.max(0), 0.05)
    snapped = rays.snap_surface(frame, v)
    points = _lattice_points(frame, v.min(0), v.max(0))
    inside = rays.winding_numbers(rays.row_crossings(frame, snapped, f, X_AXIS_DIRECTION), points) > 0
    lookup = {tuple(p): i for i, p in enumerate(points)}
    starts, dirs = [], []
    for d in range(7):
        ends = np.array([lookup.get(tuple(p + EDGE_DIRECTIONS[d]), -1) for p in points])
        cut = np.flatnonzero((ends >= 0) & (inside != inside[np.maximum(ends, 0)]))
        starts.append(cut)
        dirs.append(np.full(cut.shape[0], d, dtype=np.int8))
    order = rng.permutation(sum(s.shape[0] for s in starts))
    starts, dirs = np.concatenate(starts)[order], np.concatenate(dirs)[order]
    dirs[rng.random(dirs.shape[0]) < 0.05] = -1  # not unit lattice edges: left alone
    assert dirs.shape[0] > 3 * rays.EDGE_BLOCK
    crossings = {d: rays.row_crossings(frame, snapped, f, d) for d in range(7)}
    fracs, status = np.full(dirs.shape[0], -2.0), np.full(dirs.shape[0], 7, dtype=np.int8)
    crossed = np.full(dirs.shape[0], -2, dtype=np.int32)
    rays.add_edge_cut_fractions(crossings, points, starts, inside, dirs, fracs, status, crossed)
    other = dirs < 0
    assert np.all(fracs[other] == -2.0) and np.all(status[other] == 7) and np.all(crossed[other] == -2)
    for d in range(7):
        mine = dirs == d
        want = rays.edge_cut_fractions(crossings[d], points[starts[mine]], inside[starts[mine]])
        for got, expected in zip((fracs[mine], status[mine], crossed[mine]), want):
            assert np.array_equal(got, expected), d
    with pytest.raises(ValueError, match="without crossings"):
        rays.add_edge_cut_fractions({d: crossings[d] for d in range(6)}, points, starts, inside, dirs, fracs, status,
                                    crossed)


def _row_sums_reference(crossings, points):
    """Slow twin of winding_numbers: per point, the signs of the crossings on its row in cells before it."""
    T = row_basis(crossings.direction)
    off = rays._KEY_OFFSET
    rows = {}
    for key, sign in zip(crossings.keys.tolist(), crossings.signs.tolist()):
        row, cell = key >> rays._KEY_BITS, (key & ((1 << rays._KEY_BITS) - 1)) - off
        rows.setdefault(row, []).append((cell, sign))
    out = []
    for p in points:
        t, r2, r3 = (int(x) for x in T @ p)
        row = ((r2 + off) << rays._KEY_BITS) | (r3 + off)
        out.append(sum(s for cell, s in rows.get(row, []) if cell < t))
    return np.array(out)


def test_winding_numbers_and_cut_search_on_rows_with_many_crossings():
    # Twelve disjoint slabs along x: rows cross up to 24 triangles, so the galloping search runs long.
    boxes = [_box_surface(np.array([0.3 * k, 0.0, 0.0]), np.array([0.3 * k + 0.17, 1.0, 0.8])) for k in range(12)]
    v = np.concatenate([b[0] for b in boxes])
    f = np.concatenate([b[1] + 8 * k for k, b in enumerate(boxes)])
    frame = fat_frame(v.min(0), v.max(0), 0.05)
    snapped = rays.snap_surface(frame, v)
    rng = np.random.default_rng(5)
    # Lattice points of the slabs' box (the root cube is mostly empty) and a few beyond it.
    lo = np.floor(frame.to_lattice(v).min(0)).astype(np.int64) - 2
    hi = np.ceil(frame.to_lattice(v).max(0)).astype(np.int64) + 2
    points = rng.integers(lo, hi, size=(3000, 3))
    for d in (X_AXIS_DIRECTION, 0, 3, 6):
        crossings = rays.row_crossings(frame, snapped, f, d)
        if d == X_AXIS_DIRECTION:  # the space x axis: through every slab
            assert np.unique(crossings.keys >> rays._KEY_BITS, return_counts=True)[1].max() >= 24
        assert np.array_equal(rays.winding_numbers(crossings, points), _row_sums_reference(crossings, points))


def test_crossings_are_ordered_by_row_cell_fraction_and_face():
    # Rows through the box's vertices and edges give crossings that tie in cell and fraction.
    from paroct.frame import FatFrame

    frame = FatFrame(origin=np.zeros(3), h=1.0, levels=6)
    v, f = _box_surface(np.array([4.0, 4.0, 4.0]), np.array([12.0, 10.0, 8.0]))
    snapped = rays.snap_surface(frame, v)
    for d in range(7):
        c = rays.row_crossings(frame, snapped, f, d)
        assert np.array_equal(np.lexsort((c.faces, c.fracs, c.keys)), np.arange(c.keys.size))
    # The in-cell insertion sort against np.lexsort on random columns full of ties.
    keys = RNG.integers(0, 40, size=5000)
    fracs = RNG.integers(0, 4, size=5000) / 4.0
    faces = RNG.integers(0, 30, size=5000).astype(np.int32)
    order = np.argsort(keys, kind="stable")
    rays._order_cells(keys, fracs, faces, order)
    assert np.array_equal(order, np.lexsort((faces, fracs, keys)))


def test_row_counting_sort_orders_as_argsort(monkeypatch):
    """row_crossings' counting sort by row against its argsort path (the box limit set below
    any box), on a curved part with many rows and a CAD part with ties, every direction; and
    _row_order alone on random keys full of ties, with a box too large for it."""
    from paroct.surface import load_surface

    for name, divisions in [("bunny", 60), ("angle_block", 30)]:
        surface = load_surface(DATA / f"{name}.stl")
        frame = fat_frame(surface.bbox_min, surface.bbox_max, surface.diagonal / divisions)
        snapped = rays.snap_surface(frame, surface.vertices)
        faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
        for d in range(7):
            counted = rays.row_crossings(frame, snapped, faces, d)
            with monkeypatch.context() as m:
                m.setattr(rays, "ROW_SORT_BOX", 0)
                m.setattr(rays, "ROW_SORT_FLOOR", -1)
                sorted_ = rays.row_crossings(frame, snapped, faces, d)
            assert counted.keys.size > 100
            for field in ("keys", "fracs", "signs", "faces"):
                assert np.array_equal(getattr(counted, field), getattr(sorted_, field)), (name, d, field)
            # Searches through the row index and by galloping (no index) find the same: lattice
            # points in and around the box of the crossed rows, with edges from each.
            assert counted.row_starts.size > 1 and sorted_.row_starts.size == 0
            points = RNG.integers(-3, (1 << frame.levels) + 4, size=(3000, 3)).astype(np.int64)
            points = points[np.argsort(octant.morton_keys(points + 3), kind="stable")]
            assert np.array_equal(rays.winding_numbers(counted, points), rays.winding_numbers(sorted_, points))
            start_inside = RNG.random(len(points)) < 0.5
            for a, b in zip(rays.edge_cut_fractions(counted, points, start_inside),
                            rays.edge_cut_fractions(sorted_, points, start_inside)):
                assert np.array_equal(a, b), (name, d)
    rows = RNG.integers(0, 30, size=(4000, 2)) + rays._KEY_OFFSET
    keys = (rows[:, 0] << (2 * rays._KEY_BITS)) | (rows[:, 1] << rays._KEY_BITS) | RNG.integers(0, 5, size=4000)
    fracs = RNG.integers(0, 4, size=4000) / 4.0
    faces = RNG.integers(0, 30, size=4000).astype(np.int32)
    written = np.sort(RNG.choice(5000, size=4000, replace=False))
    keys_at, fracs_at, faces_at = (np.zeros(5000, dtype=a.dtype) for a in (keys, fracs, faces))
    keys_at[written], fracs_at[written], faces_at[written] = keys, fracs, faces
    order, (lo2, lo3, width), starts = rays._row_order(keys_at, fracs_at, faces_at, written, 30 * 30)
    assert np.array_equal(order, written[np.lexsort((faces, fracs, keys))])
    # The row index: row r (row-major over the box) holds exactly the crossings starts[r]..
    r2, r3 = rows[np.lexsort((faces, fracs, keys))].T
    r = (r2 - lo2) * width + r3 - lo3
    at = np.arange(len(r))
    assert starts.shape == (30 * 30 + 1,) and np.all(np.diff(starts) >= 0) and starts[-1] == len(r)
    assert np.all((starts[r] <= at) & (at < starts[r + 1]))
    assert rays._row_order(keys_at, fracs_at, faces_at, written, 30 * 30 - 1)[0].size == 0


def test_crossings_of_only_the_triangles_whose_boxes_hold_rows_are_all_crossings(monkeypatch):
    """row_crossings filling in only the triangles whose boxes hold a row (the bunny at
    diag/20: most triangles are smaller than the rows' spacing) against filling in every
    triangle, every direction, whole and on a subset of the faces."""
    from paroct.surface import load_surface

    surface = load_surface(DATA / "bunny.stl")
    frame = fat_frame(surface.bbox_min, surface.bbox_max, surface.diagonal / 20)
    snapped = rays.snap_surface(frame, surface.vertices)
    faces = np.ascontiguousarray(surface.faces, dtype=np.int64)
    some = np.flatnonzero(RNG.random(faces.shape[0]) < 0.5)
    for d in range(7):
        for face_ids in (None, some):
            with monkeypatch.context() as m:
                m.setattr(rays, "SPARSE_CROSSING", 1.01)
                sparse = rays.row_crossings(frame, snapped, faces, d, face_ids)
                m.setattr(rays, "SPARSE_CROSSING", 0.0)
                full = rays.row_crossings(frame, snapped, faces, d, face_ids)
            assert full.keys.size > 50
            for field in ("keys", "fracs", "signs", "faces"):
                assert np.array_equal(getattr(sparse, field), getattr(full, field)), (d, field)


@pytest.mark.parametrize("n", [0, 1, 1000])
def test_to_space_rounds_as_the_matrix_product(n):
    """The parallel kernel gives numpy's origin + h * (u @ LATTICE_TO_SPACE.T) to the bit, for
    integer and fractional lattice points."""
    frame = fat_frame(np.array([-1.3, 0.2, 7.0]), np.array([2.9, 3.1, 9.5]), 0.0123)
    rng = np.random.default_rng(n)
    for u in (rng.integers(0, 1 << frame.levels, (n, 3)), rng.uniform(0, 1 << frame.levels, (n, 3)),
              rng.integers(0, 1 << frame.levels, (n, 3)).astype(np.int32)):
        want = frame.origin + frame.h * (u.astype(np.float64) @ LATTICE_TO_SPACE.T)
        got = frame.to_space(u)
        assert got.shape == (n, 3) and np.array_equal(got, want)
        assert np.array_equal(frame.to_space(u.reshape(1, -1, 3)), want.reshape(1, -1, 3))



@pytest.mark.parametrize("seed", range(6))
def test_first_winding_outside_is_the_naive_scan(seed):
    """Random rows of crossings (entering and leaving in turn, or not), with ties and near
    ties inside a cell and across a cell's end, against the naive per-row scan."""
    rng = np.random.default_rng(seed)
    keys, fracs, signs = [], [], []
    for row in range(40):
        n = 2 * rng.integers(1, 5)
        cells = np.sort(rng.integers(0, 6, size=n))
        f = np.sort(rng.random(n))
        if rng.random() < 0.3:  # a tie or a near tie with the crossing before
            i = rng.integers(1, n)
            cells[i], f[i] = cells[i - 1], f[i - 1] + rng.choice([0.0, 1e-12, 1e-6])
        if rng.random() < 0.2:  # a near tie across the end of a cell
            i = rng.integers(1, n)
            cells[i - 1], f[i - 1], cells[i], f[i] = 2, 1 - 1e-12, 3, 1e-13
        order = np.lexsort((f, cells))
        s = np.where(np.arange(n) % 2 == 0, 1, -1).astype(np.int8)
        if rng.random() < 0.4:
            s = rng.choice(np.array([-1, 1], dtype=np.int8), size=n)
        keys.append(((row + rays._KEY_OFFSET) << rays._KEY_BITS) + cells[order] + rays._KEY_OFFSET)
        fracs.append(f[order])
        signs.append(s)
    keys, fracs, signs = np.concatenate(keys), np.concatenate(fracs), np.concatenate(signs)
    crossings = rays.RowCrossings(0, keys, fracs, signs, np.zeros(keys.shape[0], dtype=np.int32),
                                  np.zeros(3, dtype=np.int64), np.empty(0, dtype=np.int32))
    want = naive.first_winding_outside(keys, fracs, signs, rays.WINDING_TIE, rays._KEY_BITS)
    assert rays.first_winding_outside(crossings) == want
    for end in range(0, keys.shape[0], 7):  # every prefix of rows
        part = rays.RowCrossings(0, keys[:end], fracs[:end], signs[:end], crossings.faces[:end], crossings.row_box,
                                 crossings.row_starts)
        assert rays.first_winding_outside(part) == naive.first_winding_outside(keys[:end], fracs[:end], signs[:end],
                                                                                rays.WINDING_TIE, rays._KEY_BITS)


def _manifold_arrays(solid):
    m = solid.to_mesh()
    vertices, faces = np.asarray(m.vert_properties, dtype=np.float64)[:, :3], np.asarray(m.tri_verts, dtype=np.int64)
    return vertices, faces


def test_valid_solids_keep_winding_0_or_1_and_overlapping_shells_do_not():
    """The watertight box with every hit a tie, a box with a cavity holding an island, and two
    spheres touching at a vertex are entered and left in turn along the rows of all seven
    directions; two boxes overlapping as separate shells (not united) are not, and the
    crossing found lies on the second box's surface inside the first."""
    import manifold3d

    from paroct.frame import FatFrame

    frame = FatFrame(origin=np.zeros(3), h=1.0, levels=6)
    v, f = _box_surface(np.array([4.0, 4.0, 4.0]), np.array([12.0, 10.0, 8.0]))
    nested = (manifold3d.Manifold.cube([20.0, 20.0, 20.0]) - manifold3d.Manifold.cube([12.0, 12.0, 12.0]).translate([4, 4, 4])
              + manifold3d.Manifold.cube([4.0, 4.0, 4.0]).translate([8, 8, 8])).translate([5.5, 5.25, 5.125])
    sphere = manifold3d.Manifold.sphere(5.0, 24)
    sv, sf = _manifold_arrays(sphere)
    # Two spheres sharing one vertex, the lowest of one and the highest of the other (a pinch).
    top = int(np.argmax(sv[:, 2]))
    other = sv - sv[top] + sv[int(np.argmin(sv[:, 2]))]
    ids = np.arange(sv.shape[0]) + sv.shape[0]
    ids[top] = int(np.argmin(sv[:, 2]))
    pinched = (np.vstack([sv, other]) + [20.3, 20.2, 20.1], np.vstack([sf, ids[sf]]))
    for vertices, faces in [(v, f), _manifold_arrays(nested), pinched]:
        snapped = rays.snap_surface(frame, vertices)
        for d in range(7):
            assert rays.first_winding_outside(rays.row_crossings(frame, snapped, faces, d)) == -1, d
    a_lo, a_hi, b_lo, b_hi = np.array([4.0, 4, 4]), np.array([12.0, 10, 8]), np.array([9.5, 6.5, 5.5]), np.array([16.0, 14, 12])
    (av, af), (bv, bf) = _box_surface(a_lo, a_hi), _box_surface(b_lo, b_hi)
    overlap = np.vstack([av, bv]), np.vstack([af, bf + av.shape[0]])
    snapped = rays.snap_surface(frame, overlap[0])
    for d in range(7):
        crossings = rays.row_crossings(frame, snapped, overlap[1], d)
        bad = rays.first_winding_outside(crossings)
        assert bad >= 0, d
        x = rays.crossing_points(frame, crossings, np.array([bad]))[0]
        assert np.all(x >= a_lo - 1e-9) and np.all(x <= a_hi + 1e-9), d
        assert np.all(x >= b_lo - 1e-9) and np.all(x <= b_hi + 1e-9), d
        assert np.minimum(np.abs(x - b_lo), np.abs(x - b_hi)).min() < 1e-9, d  # on b's surface
